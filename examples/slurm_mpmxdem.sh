#!/bin/bash
# The MPMxDEM column over a Slurm cluster: 8 nodes x 4 processes x 8 threads = 256 cores.
# Build once on the cluster (an MPI module loaded, libclang available):
#   cargo build --release --features mpi
# Prepare the RVE once (one process), then submit this script with `sbatch examples/slurm_mpmxdem.sh`.
#SBATCH --job-name=granite-column
#SBATCH --nodes=8
#SBATCH --ntasks-per-node=4
#SBATCH --cpus-per-task=8
#SBATCH --time=48:00:00
#SBATCH --output=granite-column-%j.log

set -euo pipefail
GRANITE=${GRANITE:-target/release/granite}
RVE=${RVE:-out/rve_column/rve.json}
OUT=${OUT:-out/column_mpi_$SLURM_JOB_ID}

# Each process steps its RVEs on the cores Slurm gave it; all processes write nothing but the
# first, into $OUT on the shared file system.
srun --cpu-bind=cores "$GRANITE" run scripts/mpmxdem/column_collapse.rhai \
    --threads "$SLURM_CPUS_PER_TASK" --out "$OUT" --quiet \
    --set rve="$RVE" --set cell_size=0.1 --set points_per_cell=2 --set dt=1.46e-6 \
    --set settle_time=1.0 --set collapse_time=2.5
