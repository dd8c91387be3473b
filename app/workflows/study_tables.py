"""``hydrobuckle study --tables``: the markdown tables of docs/reproduction.md from the studies' results.

Each study's ``results/<study>/study.csv`` (the 2D runs) gives one table, and its ``<study>-reduced``
counterpart (the exact 1D reduction, ``study --reduced``) another; both have the same shape: a column per
quantity, each formatted its own way, "-" where a case has no value.
"""

from __future__ import annotations

import csv
from pathlib import Path

from app.workflows.studies import STUDIES, crossovers

#: (header, study.csv column, format) of the 2D table and of the 1D reduction's; the value's column (the
#: study's key) and the series come first
COLUMNS = {
    "": [("status", "status", None), ("g_c [um]", "g_c_um", ".3f"), ("N_c", "N_c", "g"), ("t_c [s]", "t_c", ".4f"),
         ("mu_c [MPa]", "mu_c", ".2f"), ("wall [s]", "wall_time_s", ".0f")],
    "-reduced": [("onset", "onset", None), ("g [um]", "g_c_um", ".3f"), ("+- [um]", "g_c_error_um", ".3f"),
                 ("N_c", "N_c", "g"), ("t [s]", "t_c", ".4f"), ("mu [MPa]", "mu_c", ".2f"),
                 ("1D time [s]", "wall_time_s", ".1f")],
}
#: a crease study's 2D table (StudySpec.creases)
CREASE_COLUMNS = [("status", "status", None), ("wrinkling strain (2D)", "strain_c", ".4f"),
                  ("wrinkling t (2D) [s]", "t_c", ".4f"), ("wrinkling t (1D) [s]", "t_reduced", ".4f"),
                  ("crease strain", "crease_strain", ".4f"), ("+-", "crease_strain_error", ".4f"),
                  ("crease depth [mm]", "crease_depth_mm", ".3f"), ("crease t [s]", "crease_t", ".4f"),
                  ("film's own crease t [s]", "film_crease_t", ".4f"), ("+- [s]", "film_crease_t_error", ".4f"),
                  ("first (least energy)", "first_least_energy", "word"), ("first (nucleation)", "first_nucleation",
                                                                           "word"), ("wall [s]", "wall_time_s", ".0f")]


def _cell(row: dict, column: str, fmt: str | None) -> str:
    value = row.get(column)
    if fmt == "word":
        return value or "-"
    if fmt is None:  # a word: the 1D onset's kind, else the case's status
        return value or row.get("status") or "-"
    return format(float(value), fmt) if value not in ("", None) else "-"


def table(rows: list[dict], param: str, suffix: str, creases: bool = False) -> str:
    """One study's rows (study.csv read as dicts) as a markdown table (``creases``: a crease study's 2D
    columns, with the crossovers below it)."""
    columns = CREASE_COLUMNS if creases and not suffix else COLUMNS[suffix]
    lines = ["| series | " + param.split(".")[-1] + " | " + " | ".join(h for h, _, _ in columns) + " |",
             "|" + "---|" * (len(columns) + 2)]
    for r in rows:
        lines.append(f"| {r.get('series') or '-'} | {r['value']} | "
                     + " | ".join(_cell(r, c, f) for _, c, f in columns) + " |")
    if creases and not suffix:
        found = crossovers(rows)
        lines.append("")
        lines += [f"Crossover by {name.replace('_', ' ')} (the crease's onset equals the wrinkling onset, "
                  f"interpolated between rows): " + (f"{param.split('.')[-1]} = {v:.3g}" if v is not None else
                                                      "none between these rows") for name, v in found.items()]
    return "\n".join(lines)


def tables(root: Path) -> str:
    """Every study's tables under ``root``: the 2D study (or "(not run)") and, where it was run, its 1D
    reduction."""
    out = []
    for name, spec in STUDIES.items():
        for suffix in COLUMNS:
            path = Path(root) / f"{name}{suffix}" / "study.csv"
            if not path.is_file():
                if not suffix:
                    out.append(f"### {name}\n\n(not run)\n")
                continue
            with open(path, newline="") as f:
                rows = list(csv.DictReader(f))
            title = (f"### {name}\n\n{spec.description}. Paper: {spec.paper_trend}.\n" if not suffix
                     else f"### {name} (1D reduction)\n")
            out.append(f"{title}\n{table(rows, spec.param, suffix, spec.creases)}\n")
    return "\n".join(out)
