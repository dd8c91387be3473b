#!/usr/bin/env bash
# Prove the test suite bites: apply deliberate breakages one at a time to a scratch copy of the
# working tree and run the tests that should notice; each must fail. Prints a Markdown table
# (docs/testing.md keeps the last one). Not part of .ci/run (several minutes).
#   bash scripts/mutation-check.sh [NAME ...]     (default: every mutation)
# Exit code 1 if the unmutated tests fail or any mutation survives (or no longer applies).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
[ -x "$here/.venv/bin/python" ] || bash "$here/scripts/install.sh"
source "$here/scripts/mpi-env.sh"
exec "$here/.venv/bin/python" - "$here" "$@" <<'PY'
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

here = Path(sys.argv[1])
only = set(sys.argv[2:])

# (name, file, regex, replacement, tests that must fail)
MUTATIONS = [
    ("penalty at 2x2 Gauss points again (volumetric locking)", "app/model/potential.py",
     r"constraint \* \(dx_coupling or dx\)", "constraint * dx",
     ["tests/test_stability.py::test_compression_wrinkling_matches_stiff_film_theory"]),
    ("dissipation term's factor off by 2", "app/model/hydrogel.py",
     r"/ \(2 \* tau \* J0", "/ (4 * tau * J0",
     ["tests/test_physics.py", "tests/test_loading.py"]),
    ("inertia count off by one", "app/solvers/stability.py",
     r"return int\(nneg\) \+ self", "return int(nneg) + 1 + self",
     ["tests/test_stability.py", "tests/test_screening.py"]),
    ("drained test without the elimination of the fluid content (S = K_uu: undrained)", "app/solvers/stability.py",
     r'P = B\.matTransposeMult\(sub\["uc"\]\)', 'P = B.matTransposeMult(sub["uc"]); P.scale(0.0)',
     ["tests/test_surface_instability.py", "tests/test_screening.py::test_criteria_are_ordered_and_rate_tends_to_the_limits"]),
    ("stiff-film formula's exponent changed", "app/model/theory.py",
     r"\(3 \* Es / Ef\) \*\* \(2 / 3\)", "(3 * Es / Ef) ** (1 / 2)",
     ["tests/test_stability.py::test_compression_wrinkling_matches_stiff_film_theory"]),
    ("surface potential at t_n instead of t_(n+1)", "app/solvers/stepping.py",
     r"p\.set_time\(self\.t \+ dt, dt\)", "p.set_time(self.t, dt)",
     ["tests/test_loading.py", "tests/test_physics.py"]),
    ("stop_at_onset ignored", "app/onset/policy.py",
     r"return self\.after is AfterCrossing\.STOP or ", "return ",
     ["tests/test_stability.py::test_summary_reports_modes_and_writes_mode_files"]),
    ("console script removed from pyproject.toml", "pyproject.toml",
     r'\nhydrobuckle = "app\.cli:main"\n', "\n",
     ["tests/test_console.py::test_install_into_fresh_venv_creates_console_script"]),
    ("install check fooled by the current directory", "scripts/install.sh",
     r'installed\(\) \{.*?\n\}\n',
     'installed() {\n  "$venv/bin/python" - "$here" >/dev/null 2>&1 <<\'PYCHECK\'\nimport sys, pathlib, app\n'
     'assert pathlib.Path(app.__file__).resolve().parent == pathlib.Path(sys.argv[1]).resolve() / "app"\n'
     'PYCHECK\n}\n',
     ["tests/test_console.py::test_install_into_fresh_venv_creates_console_script"]),
    ("accumulated flux not accumulated (Q_n = dQ)", "app/model/problem.py",
     r"s\[self\.q_dofs\] \+= a\[self\.q_dofs\]", "s[self.q_dofs] = a[self.q_dofs]",
     ["tests/test_physics.py"]),
    ("bench keeps a repeated --sizes entry", "app/cli.py",
     r"if twice:", "if False:",
     ["tests/test_bench.py::test_bench_rejects_bad_sizes"]),
    ("a history row that did not fit is left in part (not cut back off)", "app/io/writes.py",
     r"os\.ftruncate\(self\.fd, start\)", "pass",
     ["tests/test_write_errors.py::test_a_row_that_does_not_fit_is_cut_back_off"]),
]


def scratch_copy() -> Path:
    dst = Path(tempfile.mkdtemp(prefix="hb-mutant-"))
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=here, check=True,
                           capture_output=True, text=True).stdout.split("\n")
    for f in filter(None, files):
        src = here / f
        if src.is_file():
            (dst / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst / f)
    return dst


def pytest(root: Path, tests) -> tuple[int, float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run([str(here / ".venv/bin/python"), "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                           "--color=no", *tests], cwd=root, capture_output=True, text=True)
    last = [line for line in proc.stdout.splitlines() if line.strip()][-1:] or [""]
    return proc.returncode, time.perf_counter() - t0, last[0]


selected = [m for m in MUTATIONS if not only or any(o in m[0] for o in only)]
tests_all = sorted({t for m in selected for t in m[4]})
base = scratch_copy()
check = subprocess.run([str(here / ".venv/bin/python"), "-c", "import app; print(app.__file__)"], cwd=base,
                       capture_output=True, text=True).stdout.strip()
assert check.startswith(str(base)), f"the scratch copy's app is not the one imported: {check}"
rc, secs, last = pytest(base, tests_all)
print(f"unmutated: {last} ({secs:.0f} s)", flush=True)
if rc != 0:
    print("mutation-check: the unmutated tests fail; fix them first")
    sys.exit(1)
shutil.rmtree(base)

rows, survived = [], 0
for name, path, pattern, repl, tests in selected:
    root = scratch_copy()
    text = (root / path).read_text()
    new, n = re.subn(pattern, lambda _m: repl, text, count=1, flags=re.S)
    if n != 1:
        rows.append((name, path, "NOT APPLIED (pattern not found)", "", ""))
        survived += 1
        shutil.rmtree(root)
        continue
    (root / path).write_text(new)
    rc, secs, last = pytest(root, tests)
    caught = rc != 0
    survived += not caught
    rows.append((name, path, "caught" if caught else "SURVIVED", f"{secs:.0f}", last))
    print(f"{'caught  ' if caught else 'SURVIVED'} {name}: {last} ({secs:.0f} s)", flush=True)
    shutil.rmtree(root)

print()
print("| mutation | file | result | tests [s] | pytest's last line |")
print("|---|---|---|---|---|")
for r in rows:
    print("| " + " | ".join(r) + " |")
print(f"\n{len(rows) - survived}/{len(rows)} mutations caught")
sys.exit(1 if survived else 0)
PY
