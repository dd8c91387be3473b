#!/usr/bin/env bash
# Build the documentation site (docs/ -> docs/_build/html) with warnings as errors, then check the built
# home page and a generated reference page in a headless browser (Debian's chromium; scripts/docs_check.py).
# Installs what is missing: hydrobuckle (scripts/install.sh), the docs' tools into the venv
# (scripts/docs-requirements.txt, from PyPI), MathJax and chromium (apt). The tutorial (docs/tutorial.py)
# is executed during the build, on a small mesh.
#   HYDROBUCKLE_DOCS_EXECUTE=0   do not execute the demos (a quick look at the text; not what CI runs)
#   HYDROBUCKLE_DOCS_NO_BROWSER=1  skip the browser check (any other value: checked)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
start=$(date +%s)
HYDROBUCKLE_NO_WARMUP=1 bash scripts/install.sh >/dev/null
py="$here/.venv/bin/python"
want=$(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' scripts/docs-requirements.txt)
if ! "$py" - $want <<'PY' >/dev/null 2>&1
import sys
from importlib import metadata
for req in sys.argv[1:]:
    name, version = req.split("==")
    assert metadata.version(name) == version, req
PY
then
  echo "docs: installing scripts/docs-requirements.txt into .venv"
  "$py" -m pip install --quiet -r scripts/docs-requirements.txt 2>&1 | grep -v "^WARNING: Location" || true
  "$py" - $want <<'PY' || { echo "docs: error: cannot install scripts/docs-requirements.txt (PyPI unreachable?)" >&2; exit 1; }
import sys
from importlib import metadata
for req in sys.argv[1:]:
    name, version = req.split("==")
    assert metadata.version(name) == version, f"{name} {metadata.version(name)} installed, {version} wanted"
PY
fi
# Debian packages of the site: MathJax (formulas render offline; docs/conf.py copies its parts into the
# site) and chromium with a font for the browser check
debs=(libjs-mathjax)
[ "${HYDROBUCKLE_DOCS_NO_BROWSER:-0}" = 1 ] || debs+=(chromium fonts-dejavu-core)
missing=()
for p in "${debs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "docs: apt-get installing ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
source scripts/mpi-env.sh
rm -rf docs/_build/html docs/_build/jupyter_execute
echo "docs: sphinx-build -W (warnings are errors)"
"$py" -m sphinx -W --keep-going -q -b html docs docs/_build/html
echo "docs: built docs/_build/html ($(( $(date +%s) - start )) s)"
if [ "${HYDROBUCKLE_DOCS_NO_BROWSER:-0}" != 1 ]; then
  "$py" scripts/docs_check.py docs/_build/html index.html reference/generated/config.html \
    reference/generated/cli.html reference/api.html tutorial.html model.html
fi
echo "docs: ok ($(( $(date +%s) - start )) s) -> docs/_build/html/index.html"
