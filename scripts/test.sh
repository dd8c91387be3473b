#!/usr/bin/env bash
# Install what is missing, then run the test suite serially and under `mpirun -n 2`.
# Any failure, including "no tests collected" (pytest exit code 5), fails the script.
#   --quick   (first argument) the quick lane: every module, without the long physics (the tests of
#             tests/data/long-tests.txt, marked `long`) and the tests of about 2 s or more (marked `slow`):
#             pytest -m "not long and not slow", serially and on 2 ranks; under 5 minutes on 2 cores
#             (docs/testing.md). Without it: the full suite, what CI runs.
# Extra arguments go to pytest (e.g. `scripts/test.sh -k config`, `scripts/test.sh --quick tests/test_config.py`).
#   HYDROBUCKLE_TEST_PARTS=serial|mpi   only that half (.ci/run runs the halves of two stacks in turn)
#   HYDROBUCKLE_TEST_SHARE=k/n          of the long tests (tests/data/long-tests.txt) only share k of n;
#                                       every other test (.ci/run: Debian 12 1/2, Debian 13 2/2)
set -euo pipefail
parts="${HYDROBUCKLE_TEST_PARTS:-serial mpi}"
lane=()
if [ "${1:-}" = "--quick" ]; then
  shift
  lane=(-m "not long and not slow")
fi
# pytest's exit code: 5 (no test collected) fails, except in the quick lane over a selection (extra
# arguments) whose every test is long or slow: then it says so and passes
checked() {
  local rc=0
  "$@" || rc=$?
  if [ "$rc" -eq 5 ] && [ ${#lane[@]} -gt 0 ] && [ -n "$selection" ]; then
    echo "== test.sh --quick: every selected test is long or slow (none in the quick lane); run them without --quick"
    return 0
  fi
  return "$rc"
}
selection="$*"
start=$(date +%s)
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/install.sh
# the suite's tools, installed again whenever scripts/test-requirements.txt changes (a venv kept between runs,
# as the Debian 13 root's, then gets a tool added to the file)
stamp="$here/.venv/.test-requirements.sha256"
want=$(sha256sum scripts/test-requirements.txt | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "test: installing scripts/test-requirements.txt into .venv"
  "$here/.venv/bin/python" -m pip install --quiet -r scripts/test-requirements.txt \
    || { echo "test: error: cannot install scripts/test-requirements.txt (PyPI unreachable?)" >&2; exit 1; }
  echo "$want" > "$stamp"
fi
source scripts/mpi-env.sh
# The suite's measured values were taken with OpenBLAS's AVX2 (Haswell) kernels, and two post-buckling cases are
# decided by roundoff: with the AVX-512 (SkylakeX) kernels OpenBLAS picks on such a machine they take the other
# branch (docs/testing.md, "BLAS kernels"). The suite pins the kernels; runs keep the machine's own.
if [ -z "${OPENBLAS_CORETYPE:-}" ] && grep -qw avx2 /proc/cpuinfo 2>/dev/null; then
  export OPENBLAS_CORETYPE=Haswell
fi

if [[ " $parts " == *" serial "* ]]; then
  echo "== pytest, serial"
  checked "$here/.venv/bin/python" -m pytest -q -p no:cacheprovider --color=no "${lane[@]}" "$@"
  echo "== serial half: $(( $(date +%s) - start )) s since the start"
fi
if [[ " $parts " == *" mpi "* ]]; then
  echo "== pytest, mpirun -n 2"
  checked mpirun -n 2 $HB_MPIRUN_FLAGS bash scripts/pytest-rank.sh "${lane[@]}" "$@"
fi
echo "== test.sh${lane:+ --quick}: passed in $(( $(date +%s) - start )) s"
