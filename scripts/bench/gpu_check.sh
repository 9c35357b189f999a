#!/usr/bin/env bash
# The GPU device check in one command, on a machine with a GPU, from an already-built binary
# (`cargo build --release --features gpu`; see docs/gpu.md for a headless NVIDIA machine):
#
#   scripts/bench/gpu_check.sh [BINARY] [OUT_DIR]
#
# Writes OUT_DIR/gpu_check.md (default out/gpu_check/): the adapter's limits, then one markdown
# table of `granite bench mpmxdem --device gpu` over the thesis column's RVEs (copies 1, 132, 264,
# 400 of a 2000-sphere RVE; 1, 10 and 51 DEM steps a call; RVEs perturbed so that their searches
# fall at different steps), the same with the lists rebuilt every step, with workgroups of 128,
# 512 and 1024 invocations, and the oedometric scene.
# Each measurement sits beside all CPU threads of the same machine on the same RVEs; the JSON of
# each run lies beside the table. Meant to take under 5 minutes on an H100.
set -uo pipefail
cd "$(dirname "$0")/../.."
BIN="${1:-target/release/granite}"
OUT="${2:-out/gpu_check}"
mkdir -p "$OUT"
REPORT="$OUT/gpu_check.md"
TABLE="$OUT/table.md"
: > "$TABLE"
# A headless NVIDIA container without a Vulkan loader: the packages fetched into .gl/ (docs/gpu.md).
if ls .gl/*.deb >/dev/null 2>&1 && ! ldconfig -p | grep -q libvulkan.so.1; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
ICD=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -e "$ICD" ]; then
    export VK_DRIVER_FILES="$ICD"
fi
started=$(date +%s)
{
    echo "# granite GPU check ($(date -u +%Y-%m-%dT%H:%MZ), $(nproc) CPU threads)"
    echo
    echo '```'
    "$BIN" bench adapter 2>&1
    echo '```'
    echo
} > "$REPORT"
run() {
    local name="$1"
    shift
    echo "== $name: $BIN bench mpmxdem --device gpu $*" >&2
    if ! timeout 240 "$BIN" bench mpmxdem --device gpu --repeat 2 --table "$TABLE" --json "$OUT/$name.json" "$@" \
        > "$OUT/$name.log" 2>&1; then
        echo "| $name | failed: $(grep -v XDG_RUNTIME "$OUT/$name.log" | tail -1) |" >> "$TABLE"
    fi
}
# GPU_CHECK_COPIES and GPU_CHECK_MOST shrink the sweep for a dry run on a software adapter.
for copies in ${GPU_CHECK_COPIES:-1 132 264 400}; do
    run "column_$copies" --scene column --copies "$copies" --dem-steps 1,10,51 --perturb
done
run column_rebuilt --scene column --copies "${GPU_CHECK_MOST:-400}" --dem-steps 10 --perturb --force-rebuild
# Invocations per workgroup for 2000-sphere RVEs (256 is chosen by default): what occupancy buys.
for size in 128 512 1024; do
    run "column_workgroup_$size" --scene column --copies "${GPU_CHECK_MOST:-400}" --dem-steps 10 --perturb --workgroup "$size"
done
run oedometric --scene oedometric --dem-steps 51
cat "$TABLE" >> "$REPORT"
echo >> "$REPORT"
echo "($(($(date +%s) - started)) s in all)" >> "$REPORT"
cat "$REPORT"
