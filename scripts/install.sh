#!/usr/bin/env bash
# Install everything hydrobuckle needs on Debian 12 (bookworm): the FEniCSx stack from
# Debian packages, then a venv (.venv) made from /usr/bin/python3 with system site
# packages and hydrobuckle installed editable into it. Idempotent: a second run only checks.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${HYDROBUCKLE_VENV:-$here/.venv}"

packages=(
  python3-dolfinx-real python3-slepc4py-real python3-petsc4py-real python3-gmsh
  python3-mpi4py openmpi-bin libopenmpi-dev
  python3-pytest python3-pytest-mpi python3-matplotlib python3-scipy python3-venv python3-tqdm
  python3-pip python3-setuptools python3-wheel
  # optimized single-threaded BLAS/LAPACK: Debian's alternatives switch PETSc/MUMPS to it from the
  # reference BLAS, ~3x faster factorizations (docs/performance.md); serial, so MPI ranks don't
  # oversubscribe cores with BLAS threads
  libopenblas0-serial
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "install: apt-get installing ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

if [ -n "${HYDROBUCKLE_SYSTEM_ONLY:-}" ]; then
  exit 0  # system packages only (Docker's cached layer)
fi
if [ ! -x "$venv/bin/python" ]; then
  echo "install: creating venv $venv"
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi
# Editable install only when the package is not yet importable from this checkout.
if ! "$venv/bin/python" - "$here" <<'PY' 2>/dev/null
import sys, pathlib, app
assert pathlib.Path(app.__file__).resolve().parent == pathlib.Path(sys.argv[1]).resolve() / "app"
PY
then
  echo "install: installing hydrobuckle (editable) into $venv"
  "$venv/bin/python" -m pip install --quiet --no-build-isolation --no-deps -e "$here"
fi
"$venv/bin/python" -c "import dolfinx, slepc4py, gmsh; print('install: ok, dolfinx', dolfinx.__version__)"
