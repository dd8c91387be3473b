#!/usr/bin/env bash
# Install everything hydrobuckle needs on Debian 12 (bookworm): the FEniCSx stack from Debian
# packages (scripts/apt-packages.txt, via scripts/apt-install.sh), then a venv (.venv) made from
# /usr/bin/python3 with system site packages and hydrobuckle installed editable into it, then the
# form cache warmed (`hydrobuckle warmup`).
# Idempotent: a second run only checks.
#   HYDROBUCKLE_VENV=DIR       the venv to use (default .venv in the checkout)
#   HYDROBUCKLE_SYSTEM_ONLY=1  apt packages only
#   HYDROBUCKLE_NO_WARMUP=1    skip compiling the forms ahead of the first run
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${HYDROBUCKLE_VENV:-$here/.venv}"

bash "$here/scripts/apt-install.sh"

if [ -n "${HYDROBUCKLE_SYSTEM_ONLY:-}" ]; then
  exit 0
fi
if [ ! -x "$venv/bin/python" ]; then
  echo "install: creating venv $venv"
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi

# Is hydrobuckle installed in this venv from this checkout, with its console script? Checked from
# a neutral directory with -I (no current directory or PYTHON* variables on the import path), so a
# checkout that merely sits in the current directory cannot pass for an installed package.
installed() {
  [ -x "$venv/bin/hydrobuckle" ] || return 1
  (cd / && "$venv/bin/python" -I - "$here" <<'PY') >/dev/null 2>&1
import pathlib, sys
from importlib import metadata
import app
here = pathlib.Path(sys.argv[1]).resolve()
assert pathlib.Path(app.__file__).resolve().parent == here / "app", app.__file__
scripts = {e.name: e.value for e in metadata.distribution("hydrobuckle").entry_points if e.group == "console_scripts"}
assert scripts.get("hydrobuckle") == "app.cli:main", scripts
PY
}
if ! installed; then
  echo "install: installing hydrobuckle (editable) into $venv"
  "$venv/bin/python" -m pip install --quiet --no-build-isolation --no-deps -e "$here"
  installed || { echo "install: error: hydrobuckle is not importable from $venv or $venv/bin/hydrobuckle" \
                      "is missing after 'pip install -e $here'" >&2; exit 1; }
fi
# the pinned packages beyond Debian's (scripts/requirements.txt), without dependencies (numpy, scipy: Debian's)
"$venv/bin/python" -m pip install --quiet --no-deps -r "$here/scripts/requirements.txt" 2>&1 \
  | { grep -v "^WARNING: Location" || true; } || true  # a failure is named by the import check below
"$venv/bin/python" -c "import ipctk" 2>/dev/null \
  || { echo "install: error: pip could not install scripts/requirements.txt into $venv (PyPI unreachable?)" >&2; exit 1; }
versions=$(cd / && "$venv/bin/hydrobuckle" version)  # whole output: a pipe closed early kills it (SIGPIPE)
echo "install: ok, $(echo "$versions" | paste -sd ' ')"

# Compile the forms of the built-in geometries now (the JIT cache, ~/.cache/fenics or
# $XDG_CACHE_HOME/fenics), so the first run does not pay for it. Quick when already cached.
if [ -z "${HYDROBUCKLE_NO_WARMUP:-}" ]; then
  (cd / && "$venv/bin/hydrobuckle" warmup)
fi
