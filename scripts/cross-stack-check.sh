#!/usr/bin/env bash
# The two supported stacks against each other (Debian 12: dolfinx 0.5; Debian 13: dolfinx 0.9, in the
# root of scripts/debian13.sh), on a small bilayer:
#   - the same run on both: history.csv and the onset equal to 1e-10 relative;
#   - a run stopped by time.max_steps on one stack (checkpoint kept) and resumed with `run --resume` on
#     the other, both ways: equal to the uninterrupted run to 1e-10.
# Run by .ci/run after both suites; needs both installs (scripts/install.sh natively and in the root).
# Exit 75 (one line) when the Debian 13 root cannot be built.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
work=results/cross-stack
rm -rf "$work"
mkdir -p "$work"
small=(--set mesh.element_size=0.02 --set mesh.film_layers=2 --set geometry.length=0.4
       --set geometry.substrate_thickness=0.2 --set stability.error_estimate=false
       --set reduced.beside_2d=false --set output.checkpoint_every=5 -q)
d12() { .venv/bin/hydrobuckle "$@"; }
d13() { bash scripts/debian13.sh .venv/bin/hydrobuckle "$@"; }
stopped() {  # a run that time.max_steps ends early exits 1 and keeps its checkpoint
  local rc=0
  "$@" --set time.max_steps=12 || rc=$?
  [ "$rc" -eq 1 ] || { echo "cross-stack: expected exit 1 from a run stopped by time.max_steps, got $rc" >&2; exit 1; }
}

echo "== cross-stack: the small bilayer on Debian 12 and on Debian 13"
d12 run configs/bilayer.toml -o "$work/full12" "${small[@]}"
d13 run configs/bilayer.toml -o "$work/full13" "${small[@]}"
echo "== cross-stack: checkpoint written on Debian 12, resumed on Debian 13"
stopped d12 run configs/bilayer.toml -o "$work/from12" "${small[@]}"
d13 run configs/bilayer.toml --resume "$work/from12" "${small[@]}"
echo "== cross-stack: checkpoint written on Debian 13, resumed on Debian 12"
stopped d13 run configs/bilayer.toml -o "$work/from13" "${small[@]}"
d12 run configs/bilayer.toml --resume "$work/from13" "${small[@]}"

.venv/bin/python - "$work" <<'PY'
import json
import pathlib
import sys

sys.path.insert(0, "tests")
from conftest import read_csv, same_rows, same_summary  # noqa: E402

work = pathlib.Path(sys.argv[1])
ref = json.loads((work / "full12" / "summary.json").read_text())
ref_rows = read_csv(work / "full12" / "history.csv")
for name, what in (("full13", "the same run on Debian 13"), ("from12", "written on 12, resumed on 13"),
                   ("from13", "written on 13, resumed on 12")):
    got = json.loads((work / name / "summary.json").read_text())
    same_rows(ref_rows, read_csv(work / name / "history.csv"), 1e-10)
    same_summary(ref, got, 1e-10)
    c = got["critical"]
    print(f"cross-stack: {what}: {len(ref_rows)} history rows and the onset (g = {1e3 * c['growth_mm']:.6f} um, "
          f"N = {c['wrinkle_count']}) equal to Debian 12's uninterrupted run within 1e-10")
PY
echo "cross-stack: all checks passed"
