"""One simulation from a resolved config to a result directory (used by the CLI and the tests)."""

from __future__ import annotations

import time
from dataclasses import asdict

from app import logging_setup
from app.output import ResultWriter, versions
from app.problem import Problem
from app.stepping import StepFailure, StepRecord, TimeStepper

ASSUMPTIONS = (
    "material.shear_modulus (gamma_s) defaults to 0.1 MPa: the paper gives only ratios gamma_f/gamma_s",
    "each layer starts in its own stress-free preswollen state (s0, mu0 from its own gamma, eqs. 3.5-3.6); "
    "the surface chemical potential ramp starts at the film's mu0",
    "plane strain; growth = mean vertical displacement of the top surface",
)


def row_of(rec: StepRecord) -> dict:
    d = asdict(rec)
    extra = d.pop("extra")
    d.update(extra)
    return d


def simulate(cfg: dict, outdir, comm, problem: Problem | None = None) -> dict:
    """Run the transient problem of ``cfg``; write results to ``outdir``; return the summary."""
    log = logging_setup.get()
    wall0 = time.perf_counter()
    writer = ResultWriter(outdir, comm, cfg, columns=StepRecord.COLUMNS)
    if problem is None:
        problem = Problem(cfg, comm)
    mats = problem.materials
    log.info(f"hydrobuckle: {cfg['geometry']['kind']} mesh with {problem.cells()} cells, {problem.dofs()} dofs "
             f"on {comm.size} rank(s); film mu0 = {mats['film'].mu0:.4f} MPa, "
             f"substrate mu0 = {mats['substrate'].mu0:.4f} MPa")
    stepper = TimeStepper(problem, cfg, log=log.info)
    out = cfg["output"]
    if out["fields"]:
        writer.setup_fields(problem)
    writer.history_row(row_of(stepper.initial_record()))
    if out["fields"]:
        writer.write_fields(0.0)
    status, message = "completed", ""
    try:
        while not stepper.done():
            rec = stepper.advance()
            writer.history_row(row_of(rec))
            if out["fields"] and rec.step % out["every"] == 0:
                writer.write_fields(rec.time)
            log.info(f"step {rec.step:5d}  t = {rec.time:10.5f} s  dt = {rec.dt:9.3e} s  "
                     f"newton {rec.newton_its:2d}  growth = {1e3 * rec.growth_mm:9.4f} um  "
                     f"mu_bar = {rec.mu_bar:9.3f} MPa")
    except StepFailure as err:
        status, message = "failed", str(err)
        log.info(f"hydrobuckle: solver failure: {message}")
    last = writer.rows[-1]
    summary = {
        "status": status,
        "message": message,
        "final": {"time": last["time"], "growth_mm": last["growth_mm"]},
        "mesh": {"cells": problem.cells(), "dofs": problem.dofs(), **problem.tm.info},
        "materials": {k: {**m.as_dict(), "s0": m.s0, "mu0": m.mu0} for k, m in mats.items()},
        "ranks": comm.size,
        "steps": stepper.step,
        "rejected_steps": stepper.rejected,
        "failed_solves": stepper.failed_solves,
        "wall_time_s": time.perf_counter() - wall0,
        "versions": versions(),
        "assumptions": list(ASSUMPTIONS),
        "config": cfg,
    }
    writer.close()
    writer.summary(summary)
    if cfg["output"]["plot"]:
        writer.plot_history()
    stepper.solver.destroy()
    log.info(f"hydrobuckle: {status} after {stepper.step} steps, t = {last['time']:.5g} s, "
             f"growth = {1e3 * last['growth_mm']:.4f} um, wall {summary['wall_time_s']:.1f} s -> {outdir}")
    return summary
