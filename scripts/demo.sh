#!/usr/bin/env bash
# Install what is missing, then run the paper's bilayer on 2 MPI ranks (results/bilayer/).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/install.sh
source scripts/mpi-env.sh
mpirun -n 2 $HB_MPIRUN_FLAGS "$here/.venv/bin/hydrobuckle" run configs/bilayer.toml "$@"
