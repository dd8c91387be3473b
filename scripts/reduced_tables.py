"""Print the 1D-reduction tables of docs/reproduction.md from results/<study>-reduced/study.csv.

Usage: .venv/bin/python scripts/reduced_tables.py [results]
"""

import csv
import sys
from pathlib import Path

from app.workflows.studies import STUDIES


def _f(row: dict, key: str, fmt: str) -> str:
    return format(float(row[key]), fmt) if row[key] not in ("", None) else "-"


def main(root: Path) -> None:
    for name, spec in STUDIES.items():
        path = root / f"{name}-reduced" / "study.csv"
        if not path.is_file():
            continue
        with open(path) as f:
            rows = list(csv.DictReader(f))
        print(f"### {name} (1D reduction)\n")
        print("| series | " + spec.param.split(".")[-1]
              + " | onset | g [um] | +- [um] | N_c | t [s] | mu [MPa] | 1D time [s] |")
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['series'] or '-'} | {r['value']} | {r['onset'] or r['status']} | {_f(r, 'g_c_um', '.3f')} | "
                  f"{_f(r, 'g_c_error_um', '.3f')} | {_f(r, 'N_c', 'g')} | {_f(r, 't_c', '.4f')} | "
                  f"{_f(r, 'mu_c', '.2f')} | {_f(r, 'wall_time_s', '.1f')} |")
        print()


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"))
