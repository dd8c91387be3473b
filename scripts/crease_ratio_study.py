"""Creases or wrinkles first in a compressed bilayer, over the film/substrate modulus ratio (docs/creases.md).

For each ratio, runs ``hydrobuckle run configs/bilayer-creases.toml --set material.film.modulus_ratio=R``
(any further ``--set`` is passed on) into OUTDIR/ratio-R and prints one table row from its summary.json:
the crease onset strain with its error bar, the depth of the crease at the onset, the linear (wrinkling)
onset of the run and of the exact 1D reduction, and which comes first: by least energy (the crease grown
to its size of least energy against the wrinkles) and by nucleation (a crease small against the film has
the film's own onset, the ratio-1 row's, against the exact wrinkling onset; docs/creases.md, "Nucleation
or least energy"). A ratio whose run exists already (its summary.json) is read, not run again.

    python scripts/crease_ratio_study.py OUTDIR [R ...] [--set KEY=VALUE ...]
    (default ratios: 1 1.5 2 2.5 3 3.5 4 5; each run is serial, about 3-8 minutes)
"""

import json
import subprocess
import sys
from pathlib import Path

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "bilayer-creases.toml"
RATIOS = ["1", "1.5", "2", "2.5", "3", "3.5", "4", "5"]


def row(ratio: str, s: dict, nucleation: float | None) -> str:
    cr = s.get("creases", {})
    onset, cfg = cr.get("onset"), s["config"]
    strain, end = cfg["loading"]["compression_strain"], cfg["time"]["end"]
    crease = (f"{onset['applied_strain']:.4f} +- {onset['applied_strain_error']:.4f}" if onset else
              cr.get("error", "none up to time.end"))
    depth = next((lv.get("depth_mm") for lv in reversed(cr.get("levels", [])) if lv.get("depth_mm")), None)
    linear = s["critical"]["applied_strain"] if s.get("critical") else None
    red = s.get("reduced") or {}
    # the compression ramp: applied strain = compression_strain * min(t / time.end, 1)
    exact = strain * min(red["time"] / end, 1.0) if red.get("time") is not None else None
    by_nucleation = "-" if nucleation is None or exact is None else ("crease" if nucleation < exact else "wrinkle")
    cols = [ratio, crease, f"{depth:.4f}" if depth else "-", f"{linear:.4f}" if linear else "-",
            f"{exact:.4f}" if exact else "-", str(cr.get("first")), by_nucleation]
    return "| " + " | ".join(cols) + " |"


def main(argv: list[str]) -> int:
    if not argv or argv[0].startswith("-"):
        print(__doc__, file=sys.stderr)
        return 2
    outdir, rest = Path(argv[0]), argv[1:]
    sets = rest[rest.index("--set"):] if "--set" in rest else []
    ratios = [r for r in rest[: len(rest) - len(sets)]] or RATIOS
    print("| modulus ratio | crease onset strain | crease depth at onset [mm] | wrinkling onset (2D) "
          "| wrinkling onset (1D, exact) | first (least energy) | first (nucleation) |")
    print("|---|---|---|---|---|---|---|")
    nucleation = None  # the film's own crease onset: the homogeneous layer's (ratio 1), once run
    for ratio in ratios:
        out = outdir / f"ratio-{ratio}"
        if not (out / "summary.json").exists():
            cmd = [sys.executable, "-m", "app", "run", str(CONFIG),
                   "--set", f"material.film.modulus_ratio={ratio}", *sets,
                   "-o", str(out)]
            subprocess.run(cmd, check=False, stdout=subprocess.DEVNULL)
        if not (out / "summary.json").exists():
            print(f"| {ratio} | run failed: see {out} | | | | | |")
            continue
        summary = json.loads((out / "summary.json").read_text())
        if float(ratio) == 1.0 and (summary.get("creases") or {}).get("onset"):
            nucleation = summary["creases"]["onset"]["applied_strain"]
        print(row(ratio, summary, nucleation), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
