"""Write tests/data/long-tests.txt from pytest JUnit XML files of serial runs (one per stack):
every test that took at least --min-seconds in any of them, with its longest time.

    .venv/bin/python -m pytest -q -p no:cacheprovider --junitxml=/tmp/j12.xml
    bash scripts/debian13.sh .venv/bin/python -m pytest -q -p no:cacheprovider --junitxml=/tmp/j13.xml
    .venv/bin/python scripts/long_tests.py /tmp/j12.xml /var/cache/hydrobuckle/debian13/tmp/j13.xml

CI (HYDROBUCKLE_TEST_SHARE, tests/conftest.py) runs each listed test on one of the two stacks.
"""

from __future__ import annotations

import argparse
import xml.etree.ElementTree as ET
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "long-tests.txt"
#: long tests that stay on both stacks, and why
ON_BOTH = {
    "tests/test_creases_swelling.py::test_the_drained_crease_costs_less_than_the_undrained_one_and_comes_first":
        "the one quick test of the undrained crease's hold on every cell (fem_utils.dirichlet_function_on_cells, "
        "which differs between dolfinx 0.5 and 0.9)",
}


def durations(path: str) -> dict[str, float]:
    """Each test's time (setup, call and teardown) by node id."""
    times = {}
    for case in ET.parse(path).iter("testcase"):
        nodeid = case.get("classname").replace(".", "/") + ".py::" + case.get("name")
        times[nodeid] = float(case.get("time"))
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("junit", nargs="+")
    ap.add_argument("--min-seconds", type=float, default=5.0)
    args = ap.parse_args()
    longest: dict[str, float] = {}
    for path in args.junit:
        for nodeid, seconds in durations(path).items():
            longest[nodeid] = max(seconds, longest.get(nodeid, 0.0))
    rows = sorted(((s, n) for n, s in longest.items() if s >= args.min_seconds and n not in ON_BOTH), reverse=True)
    head = (f"# the suite's tests that take at least {args.min_seconds:g} s serially (the longest of "
            f"{len(args.junit)} stack(s)), written by scripts/long_tests.py;\n# CI runs each in one share of "
            "HYDROBUCKLE_TEST_SHARE (tests/conftest.py, docs/testing.md)\n")
    OUT.write_text(head + "".join(f"{s:.1f} {n}\n" for s, n in rows))
    print(f"{OUT}: {len(rows)} tests, {sum(s for s, _ in rows):.0f} s")


if __name__ == "__main__":
    main()
