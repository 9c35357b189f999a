//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod bodies;

use std::path::{Path, PathBuf};

/// The repository root (tests run with the package root as working directory).
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn script(rel: &str) -> PathBuf {
    root().join("scripts").join(rel)
}

/// A fresh output folder under target/, unique per test name.
pub fn out_dir(name: &str) -> PathBuf {
    let dir = root().join("target").join("test-out").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

pub fn sets(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect()
}

/// Runs a script through the library, quietly, on `threads` threads.
pub fn run(
    script_rel: &str,
    name: &str,
    pairs: &[(&str, &str)],
    threads: usize,
) -> granite_core::Result<granite_script::RunReport> {
    granite::run(&script(script_rel), sets(pairs), Some(out_dir(name)), true, Some(threads))
}

/// The summary.json of a run's folder.
#[allow(dead_code)]
pub fn summary_of(dir: &Path) -> serde_json::Value {
    let path = dir.join("summary.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

pub fn summary_f64(report: &granite_script::RunReport, key: &str) -> f64 {
    report.summary.get(key).and_then(|v| v.as_f64()).unwrap_or_else(|| panic!("summary has no number `{key}`"))
}

/// Reads a CSV file with a header into (header, rows of numbers).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap_or_default().split(',').map(|s| s.to_string()).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap_or(f64::NAN)).collect()).collect();
    (header, rows)
}

pub fn column(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no column `{name}` in {header:?}"))
}

/// Runs script text (no overrides) into a fresh output folder named `name`; returns the folder.
pub fn run_text(name: &str, source: &str) -> PathBuf {
    let out = out_dir(name);
    let options =
        granite_script::RunOptions { out_dir: out.clone(), overrides: vec![], quiet: true, ..Default::default() };
    granite_script::run_source(&format!("{name}.rhai"), source, granite::registry(), options)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    out
}

/// Runs a script that must fail, and returns its error message.
#[allow(dead_code)]
pub fn run_text_err(name: &str, source: &str) -> String {
    let out = out_dir(name);
    let options = granite_script::RunOptions { out_dir: out, overrides: vec![], quiet: true, ..Default::default() };
    match granite_script::run_source(&format!("{name}.rhai"), source, granite::registry(), options) {
        Ok(_) => panic!("{name}: the script ran without an error"),
        Err(e) => e.to_string(),
    }
}

/// `granite run SCRIPT --out OUT` (quiet, one thread) under a shell limit such as `ulimit -f 200`;
/// the exit code and stderr.
#[cfg(unix)]
pub fn run_under_limit(limit: &str, script: &Path, out: &Path) -> (Option<i32>, String) {
    let run = std::process::Command::new("sh")
        .args(["-c", &format!("{limit} && exec \"$0\" run --quiet --threads 1 --out \"$1\" \"$2\"")])
        .arg(env!("CARGO_BIN_EXE_granite"))
        .arg(out)
        .arg(script)
        .output()
        .unwrap();
    (run.status.code(), String::from_utf8_lossy(&run.stderr).into_owned())
}

/// Waits until a run writing into `out` is stepping: its series.csv has rows past its first.
pub fn wait_until_running(out: &Path, timeout: std::time::Duration) {
    let started = std::time::Instant::now();
    while std::fs::read_to_string(out.join("series.csv")).map_or(0, |t| t.lines().count()) < 3 {
        assert!(started.elapsed() < timeout, "the run in {} did not start", out.display());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// `granite run --quiet --threads 1 --out OUT SCRIPT` started with stderr piped, returned once
/// it is stepping.
pub fn spawn_running(script: &Path, out: &Path) -> std::process::Child {
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_granite"))
        .args(["run", "--quiet", "--threads", "1", "--out"])
        .arg(out)
        .arg(script)
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    wait_until_running(out, std::time::Duration::from_secs(60));
    child
}

/// `mpirun -np N granite run SCRIPT --quiet --threads 1 --out OUT --set ...` (Open MPI's launcher
/// on the PATH); (exit code, stderr).
pub fn mpirun_granite(np: usize, script: &Path, out: &Path, sets: &[(&str, &str)]) -> (i32, String) {
    use std::process::Command;
    let mut cmd = Command::new("mpirun");
    let version = Command::new("mpirun").arg("--version").output().expect("mpirun on the PATH (Open MPI)");
    if String::from_utf8_lossy(&version.stdout).contains("Open MPI") {
        // Containers run as root; CI machines have fewer cores than some runs have processes.
        cmd.args(["--allow-run-as-root", "--oversubscribe"]);
        // Waiting processes give their core away instead of spinning (2-core machines).
        cmd.env("OMPI_MCA_mpi_yield_when_idle", "1");
    }
    cmd.args(["-np", &np.to_string(), env!("CARGO_BIN_EXE_granite"), "run"]).arg(script);
    cmd.args(["--quiet", "--threads", "1", "--out"]).arg(out);
    for (k, v) in sets {
        cmd.args(["--set", &format!("{k}={v}")]);
    }
    let output = cmd.output().expect("running mpirun");
    (output.status.code().unwrap_or(-1), String::from_utf8_lossy(&output.stderr).into_owned())
}

/// Holds every node of `sim`'s mesh at the velocity `field` gives at its position (a homogeneous
/// deformation of the whole mesh).
pub fn prescribe_node_velocities(sim: &mut granite_core::mpm::MpmSim, field: impl Fn([f64; 3]) -> [f64; 3]) {
    use granite_core::mpm::boundary::{TimeFunction, VelocityConstraint};
    for node in 0..sim.mesh.node_count() {
        let v = field(sim.mesh.node_position(node));
        for (axis, value) in v.into_iter().enumerate() {
            sim.boundary.velocity.push(VelocityConstraint {
                nodes: vec![node as u32],
                axis,
                value: TimeFunction::Constant(value),
            });
        }
    }
}

/// A DEM run straight and the same run saved half way and resumed from its file: `build()`
/// stepped `2 steps` times; `build()` stepped `steps` times (returned to check what the file
/// holds), saved as `name.json`, loaded and stepped `steps` more. (straight, written, resumed)
pub fn straight_and_resumed(
    build: impl Fn() -> granite_core::dem::DemSim,
    steps: usize,
    name: &str,
) -> (granite_core::dem::DemSim, granite_core::dem::DemSim, granite_core::dem::DemSim) {
    let mut straight = build();
    for _ in 0..2 * steps {
        straight.step().unwrap();
    }
    let mut written = build();
    for _ in 0..steps {
        written.step().unwrap();
    }
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}.json"));
    written.save(&path).unwrap();
    let mut resumed = granite_core::dem::DemSim::load(&path, &granite::registry()).unwrap();
    for _ in 0..steps {
        resumed.step().unwrap();
    }
    (straight, written, resumed)
}

/// `granite run --quiet --threads 1 --out OUT SCRIPT` killed (SIGKILL) `delay` after its first
/// checkpoint `ck` appeared: a run stopped at a moment it did not choose.
#[cfg(unix)]
#[allow(dead_code)]
pub fn kill_after_first_checkpoint(script: &Path, out: &Path, ck: &Path, delay: std::time::Duration, trial: usize) {
    use std::time::{Duration, Instant};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_granite"))
        .args(["run", "--quiet", "--threads", "1", "--out"])
        .arg(out)
        .arg(script)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while !ck.exists() {
        assert!(started.elapsed() < Duration::from_secs(60), "trial {trial}: no first checkpoint");
        std::thread::sleep(Duration::from_millis(1));
    }
    std::thread::sleep(delay);
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Runs `source` (as `name`) in this process into `out`, kept as it is (runs that resume one
/// another share it), with `--set` values `pairs`.
#[allow(dead_code)]
pub fn run_source_in(out: &Path, name: &str, source: &str, pairs: &[(&str, &str)]) -> granite_script::RunReport {
    let options = granite_script::RunOptions {
        out_dir: out.to_path_buf(),
        overrides: sets(pairs),
        quiet: true,
        ..Default::default()
    };
    granite_script::run_source(name, source, granite::registry(), options).unwrap()
}

/// [`run_source_in`] of a script that must fail: its error.
#[allow(dead_code)]
pub fn run_source_in_err(out: &Path, source: &str, pairs: &[(&str, &str)]) -> String {
    let options = granite_script::RunOptions {
        out_dir: out.to_path_buf(),
        overrides: sets(pairs),
        quiet: true,
        ..Default::default()
    };
    match granite_script::run_source("block.rhai", source, granite::registry(), options) {
        Ok(_) => panic!("the run in {} should fail", out.display()),
        Err(e) => e.to_string(),
    }
}

/// A small MPM block settling under gravity (`cells` cells a side, half of them filled), loaded
/// from its checkpoint `ck.json` when `--set resume=true`; `extra` is the test's outputs.
#[allow(dead_code)]
pub fn settling_block(cells: usize, extra: &str) -> String {
    SETTLING_BLOCK
        .replace("CELLS", &cells.to_string())
        .replace("SIDE", &format!("{:.2}", cells as f64 * 0.05 / 2.0))
        .replace("EXTRA", extra)
}

const SETTLING_BLOCK: &str = r#"
let resume = param("resume", false);
let steps = param("steps", 100000);
let sim = if resume {
    mpm_load("ck.json")
} else {
    let s = mpm(#{ dim: 2, origin: [0.0, 0.0], cell: 0.05, cells: [CELLS, CELLS] });
    let soil = s.material("linear_elastic", #{ density: 1800.0, young: 1e6, poisson: 0.3 });
    s.fill_box(soil, [0.0, 0.0], [SIDE, SIDE], #{ per_cell: 2 });
    s.fix("x-", "x"); s.fix("y-", "y");
    s.gravity([0.0, -9.81]);
    s.dt(1e-4);
    s
};
EXTRA
sim.run_steps(steps);
summary("end_step", sim.step);
"#;

/// The step a run stopped at, from its message on stderr (`... at step N ...`).
#[allow(dead_code)]
pub fn stopped_at_step(stderr: &str) -> u64 {
    stderr
        .split("at step ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no step in {stderr}"))
}

/// Whether this machine lets a test mount a tmpfs of its own (`unshare -rm`), which the disk-full
/// tests need; when it does not, says that the test is skipped.
#[allow(dead_code)]
pub fn can_mount_tmpfs() -> bool {
    let can = std::process::Command::new("unshare")
        .args(["-rm", "sh", "-c", "d=$(mktemp -d) && mount -t tmpfs -o size=1m none \"$d\""])
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !can {
        println!("skipped: `unshare -rm` with a tmpfs mount is not allowed here");
    }
    can
}

/// Numbers uniform in [0, 1) from `seed` (a 64-bit linear congruential generator, its top 53
/// bits): placements that vary but repeat from run to run.
pub fn uniform_stream(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}
