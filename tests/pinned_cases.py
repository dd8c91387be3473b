"""Regression pins: results that a refactoring must not change (bit for bit where the arithmetic is the
same, else within 1e-10 relative). Not a physics check: these numbers are what the code computed when
they were pinned (``python tests/pinned_cases.py --write`` regenerates tests/data/pinned.json, serially;
do that only for a change that is meant to change results, and say why in the commit)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

PINNED = Path(__file__).resolve().parent / "data" / "pinned.json"

# name -> (config file or None for the defaults, --set overrides); coarse enough for seconds per case
CASES = {
    "bilayer-default-coarse": (None, ["mesh.element_size=0.016", "mesh.film_layers=2", "time.end=1.2",
                                      "stability.error_estimate=false", "output.fields=false",
                                      "output.plot=false", "stability.modes=4"]),
    "tube-coarse": ("configs/tube.toml", ["mesh.element_size=0.04", "mesh.film_layers=2",
                                          "stability.error_estimate=false", "output.fields=false",
                                          "output.plot=false"]),
    "compression-coarse": (None, ["loading.kind=compression", "geometry.length=0.6",
                                  "geometry.substrate_thickness=0.2", "mesh.element_size=0.01",
                                  "mesh.film_layers=2", "material.film.modulus_ratio=50",
                                  "loading.compression_strain=0.07", "time.end=1.0", "time.dt_initial=0.05",
                                  "time.dt_max=0.05", "stability.error_estimate=false", "output.fields=false",
                                  "output.plot=false"]),
}
HISTORY = ("time", "growth_mm", "fluid_volume", "inflow", "applied_strain", "negative_eigenvalues")
CRITICAL = ("time", "growth_mm", "wrinkle_count", "first_mode_wrinkle_count", "lambda_min_before",
            "lambda_min_after", "bracket")


def compute(name: str, outdir: Path, comm) -> dict:
    import csv

    from app import config
    from app.workflows.run import simulate

    root = Path(__file__).resolve().parents[1]
    path, overrides = CASES[name]
    # plain Newton, as when the results were pinned: factor reuse (solver.reuse) takes another path to each
    # converged state and moves it within Newton's tolerance (lambda_min_before of the bilayer by 2e-8
    # relative, g_c by 1e-12); tests/test_reuse.py compares the two solvers. The elementary step controller,
    # also as when pinned: the predictive default (time.controller) takes other steps to the same answers
    # within their time error, which tests/test_step_control.py and the physics tests check
    overrides = [*overrides, "solver.reuse=false", "time.controller=elementary"]
    cfg = config.load(root / path, overrides) if path else config.resolve({}, overrides)
    summary = simulate(cfg, outdir, comm, progress=False)
    with open(outdir / "history.csv") as f:
        rows = list(csv.DictReader(f))
    return {"status": summary["status"], "steps": summary["steps"],
            "critical": {k: summary["critical"][k] for k in CRITICAL},
            "modes": [m["eigenvalue"] for m in summary["critical"]["modes"]],
            "history": {c: [float(r[c]) for r in rows] for c in HISTORY}}


if __name__ == "__main__" and "--write" in sys.argv:
    import tempfile

    from mpi4py import MPI

    out = {name: compute(name, Path(tempfile.mkdtemp()), MPI.COMM_SELF) for name in CASES}
    PINNED.parent.mkdir(exist_ok=True)
    PINNED.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {PINNED}")
