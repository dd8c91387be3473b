#!/usr/bin/env bash
# Regenerate every parameter study of the paper (results/<study>/): study.csv, study.png, modes.png.
# Resumable: rerun to continue after an interruption. NP ranks (default 2), one case per rank.
# Extra arguments go to every `hydrobuckle study` call (e.g. --set mesh.element_size=0.008).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/install.sh >/dev/null
source scripts/mpi-env.sh
np="${NP:-2}"
hb() { mpirun -n "$np" $HB_MPIRUN_FLAGS "$here/.venv/bin/hydrobuckle" study "$@" --ranks-per-case 1 -q; }
hb tube-film-thickness "$@"
hb tube-substrate-thickness "$@"
hb tube-modulus-ratio "$@"
hb tube-aspect-ratio "$@"
hb bilayer-film-thickness "$@"
hb bilayer-modulus-ratio "$@"
hb bilayer-preswelling "$@"
