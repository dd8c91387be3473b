"""``hydrobuckle bench --factor``: how large a problem the direct solver holds on this machine
(docs/three-d.md, "Sizes and cost"). For each size, a process of its own builds the problem at its initial state,
assembles the incremental Hessian K (the rate criterion's matrix with tau = time.dt_initial) and factors it
once with the inertia test's MUMPS LDL^T options; it reports the dofs, the set-up and factorization wall times,
the inertia and its own peak resident memory (one process per size, so that each peak is that size's).
factor.json and factor.md hold the table.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from app import config, factory
from app.io import writes
from app.onset.criteria import CRITERIA
from app.workflows.bench import peak_memory_mb, size_config

HEADER = ("| size | element size [mm] | film layers | cells | dofs | set-up [s] | assemble + LDL^T [s] | inertia "
          "(-, 0, +) | peak RSS [MB] |\n|---|---|---|---|---|---|---|---|---|")


def factor_one(size: str, overrides: list[str], comm) -> dict:
    """One size's problem built, K assembled and factored once in this process: the row's numbers."""
    cfg = size_config(size, overrides)
    t0 = time.perf_counter()
    problem = factory.problem(cfg, comm)
    setup = time.perf_counter() - t0
    analyzer = CRITERIA.get("rate").analyzer(problem, {"tau": cfg["time"]["dt_initial"]})
    try:
        t0 = time.perf_counter()
        inertia = analyzer.inertia()
        factor = time.perf_counter() - t0
    finally:
        analyzer.destroy()
    return {"size": size, "element_size_mm": cfg["mesh"]["element_size"], "film_layers": cfg["mesh"]["film_layers"],
            "cells": problem.cells(), "dofs": problem.dofs(), "free_dofs": analyzer.n_free, "setup_s": setup,
            "assemble_and_factor_s": factor, "inertia": list(inertia), "peak_rss_mb": peak_memory_mb(False)}


def _row(r: dict) -> str:
    if "error" in r:
        return f"| {r['size']} | failed: {r['error']} |"
    return (f"| {r['size']} | {r['element_size_mm']:g} | {r['film_layers']} | {r['cells']:,} | {r['dofs']:,} | "
            f"{r['setup_s']:.2f} | {r['assemble_and_factor_s']:.2f} | {', '.join(map(str, r['inertia']))} | "
            f"{r['peak_rss_mb']:,.0f} |")


def command(sizes: list[str], overrides: list[str], outdir: Path, comm) -> str:
    """Every size in a process of its own (``hydrobuckle bench --factor-one``), one after the other; the table,
    also written as factor.md beside factor.json. A size whose process fails gets a row saying so."""
    if comm.size > 1:
        raise config.ConfigError("", "bench --factor runs one process per size itself; allowed: a serial launch "
                                 "(without mpirun)")
    rows = []
    for size in sizes:
        cmd = [sys.executable, "-m", "app", "bench", "--factor-one", size]
        for item in overrides:
            cmd += ["--set", item]
        done = subprocess.run(cmd, capture_output=True, text=True)
        lines = done.stdout.strip().splitlines()
        if done.returncode or not lines:
            why = (done.stderr.strip().splitlines() or [f"exit code {done.returncode}"])[-1]
            rows.append({"size": size, "error": why})
        else:
            rows.append(json.loads(lines[-1]))
    text = "\n".join([HEADER] + [_row(r) for r in rows])

    def files():
        writes.at(outdir, outdir.mkdir, parents=True, exist_ok=True)
        writes.at(outdir / "factor.json", writes.write_json, outdir / "factor.json", {"sizes": rows})
        writes.at(outdir / "factor.md", writes.write_text, outdir / "factor.md", text + "\n")

    writes.on_rank0(comm, outdir, files)
    return text
