"""Print the markdown tables of docs/reproduction.md from results/<study>/study.csv.

Usage: .venv/bin/python scripts/study_tables.py [results]
"""

import csv
import sys
from pathlib import Path

from app.workflows.studies import STUDIES


def _f(row: dict, key: str, fmt: str) -> str:
    return format(float(row[key]), fmt) if row[key] not in ("", None) else "-"


def main(root: Path) -> None:
    for name, spec in STUDIES.items():
        path = root / name / "study.csv"
        if not path.is_file():
            print(f"### {name}\n\n(not run)\n")
            continue
        with open(path) as f:
            rows = list(csv.DictReader(f))
        print(f"### {name}\n\n{spec.description}. Paper: {spec.paper_trend}.\n")
        print("| series | " + spec.param.split(".")[-1]
              + " | status | g_c [um] | N_c | t_c [s] | mu_c [MPa] | wall [s] |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['series'] or '-'} | {r['value']} | {r['status']} | {_f(r, 'g_c_um', '.3f')} | "
                  f"{_f(r, 'N_c', 'g')} | {_f(r, 't_c', '.4f')} | {_f(r, 'mu_c', '.2f')} | "
                  f"{_f(r, 'wall_time_s', '.0f')} |")
        print()


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "results"))
