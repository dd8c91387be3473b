"""How large a 3D problem the direct solver holds here: one LDL^T factorization (MUMPS, the inertia test's
options) of the incremental Hessian K at a config's initial state, at one or more mesh sizes; prints dofs,
the factorization's wall time and the process's peak resident memory (docs/three-d.md, "Sizes and cost").

    .venv/bin/python scripts/factor_size.py configs/plate.toml 0.0125 0.00625 0.005
    (one process per size, so each peak memory is its own; element sizes in mm, mesh.film_layers scaled
    like hydrobuckle bench's sizes)
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time


def one(path: str, size: float) -> dict:
    from mpi4py import MPI

    from app import config, factory
    from app.model.operators import zero_increment_hessian
    from app.solvers.stability import HessianOperator, StabilityAnalyzer

    base = config.load(path)
    scale = base["mesh"]["element_size"] / size
    layers = max(1, round(base["mesh"]["film_layers"] * scale))
    cfg = config.load(path, [f"mesh.element_size={size}", f"mesh.film_layers={layers}"])
    t0 = time.perf_counter()
    p = factory.problem(cfg, MPI.COMM_WORLD)
    setup = time.perf_counter() - t0
    analyzer = StabilityAnalyzer(HessianOperator(zero_increment_hessian(p, cfg["time"]["dt_initial"]), p.comm), p.comm)
    t0 = time.perf_counter()
    neg, zero, pos = analyzer.inertia()
    factor = time.perf_counter() - t0
    return {"element_size_mm": size, "film_layers": layers, "cells": p.cells(), "dofs": p.dofs(),
            "setup_s": round(setup, 2), "assemble_and_factor_s": round(factor, 2), "inertia": [neg, zero, pos],
            "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)}


def main(argv: list[str]) -> int:
    if len(argv) >= 3 and argv[1] == "--one":
        print(json.dumps(one(argv[2], float(argv[3]))))
        return 0
    if len(argv) < 3:
        print(__doc__)
        return 2
    print("| element size [mm] | film layers | cells | dofs | setup [s] | assemble + LDL^T [s] | peak RSS [MB] |")
    print("|---|---|---|---|---|---|---|")
    for size in argv[2:]:
        out = subprocess.run([sys.executable, __file__, "--one", argv[1], size], capture_output=True, text=True)
        if out.returncode:
            print(f"| {size} | failed: {(out.stderr.strip().splitlines() or ['?'])[-1]} |")
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"| {r['element_size_mm']:g} | {r['film_layers']} | {r['cells']:,} | {r['dofs']:,} | {r['setup_s']} | "
              f"{r['assemble_and_factor_s']} | {r['peak_rss_mb']:,} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
