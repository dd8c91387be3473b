#!/usr/bin/env bash
# One MPI rank of a parallel pytest run: rank 0 reports; the others report only if they fail.
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
rank="${OMPI_COMM_WORLD_RANK:-${PMI_RANK:-0}}"
if [ "$rank" = "0" ]; then
  exec "$here/.venv/bin/python" -m pytest -q -p no:cacheprovider --color=no "$@"
fi
log="$(mktemp)"
"$here/.venv/bin/python" -m pytest -q -p no:cacheprovider --color=no "$@" >"$log" 2>&1
status=$?
if [ $status -ne 0 ]; then
  echo "---- pytest output of rank $rank (exit $status) ----"
  cat "$log"
fi
rm -f "$log"
exit $status
