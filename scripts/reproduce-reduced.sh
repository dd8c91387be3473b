#!/usr/bin/env bash
# The six studies of the paper that the exact 1D reduction covers (results/<study>-reduced/): study.csv,
# study.png, isomodes.png, each case by `hydrobuckle study NAME --reduced` (one rank per case, about 10 s).
# Resumable. NP ranks (default 2). Extra arguments go to every call (e.g. --set stability.criterion=undrained).
# Then: hydrobuckle study --tables prints the tables of docs/reproduction.md.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/install.sh >/dev/null
source scripts/mpi-env.sh
np="${NP:-2}"
start=$(date +%s)
for study in bilayer-film-thickness bilayer-modulus-ratio bilayer-preswelling tube-film-thickness \
             tube-substrate-thickness tube-modulus-ratio; do
    mpirun -n "$np" $HB_MPIRUN_FLAGS "$here/.venv/bin/hydrobuckle" study "$study" --reduced -q "$@"
done
echo "reproduce-reduced: six studies in $(( $(date +%s) - start )) s"
