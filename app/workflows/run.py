"""One simulation from a resolved config to a result directory (used by the CLI and the tests)."""

from __future__ import annotations

import time
from dataclasses import asdict

from app import logging_setup, timing
from app.onset.crossing import Crossing, CrossingDetector, locate_crossing
from app.io.output import ResultWriter, versions
from app.model.problem import Problem
from app.solvers.stability import StabilityAnalyzer
from app.solvers.stepping import StepFailure, StepRecord, TimeStepper

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


def simulate(cfg: dict, outdir, comm, problem: Problem | None = None, progress: bool = True) -> dict:
    """Run the transient problem of ``cfg``; write results to ``outdir``; return the summary."""
    log = logging_setup.get()
    wall0 = time.perf_counter()
    columns = StepRecord.COLUMNS + (("negative_eigenvalues", "lambda_min") if cfg["stability"]["enabled"] else ())
    writer = ResultWriter(outdir, comm, cfg, columns=columns)
    scfg = cfg["stability"]
    with timing.timed("setup"):
        if problem is None:
            problem = Problem.from_config(cfg, comm)
        stepper = TimeStepper(problem, cfg, log=log.info)
        analyzer = StabilityAnalyzer(problem, scfg["tau"]) if scfg["enabled"] else None
    mats = problem.materials
    log.info(f"hydrobuckle: {cfg['geometry']['kind']} mesh with {problem.cells()} cells, {problem.dofs()} dofs "
             f"on {comm.size} rank(s); film mu0 = {mats['film'].mu0:.4f} MPa, "
             f"substrate mu0 = {mats['substrate'].mu0:.4f} MPa")
    out = cfg["output"]
    if out["fields"]:
        writer.setup_fields(problem)
    first = stepper.initial_record()
    count = 0
    detector = None
    if analyzer is not None:
        detector = CrossingDetector(stepper, analyzer, scfg["screening"], log=log.info if progress else log.debug)
        count = detector.start()
        first.extra.update({"negative_eigenvalues": count, "lambda_min": float("nan")})
    writer.history_row(row_of(first))
    if out["fields"]:
        writer.write_fields(0.0)
    status, message = "completed", ""
    crossings: list[Crossing] = []
    try:
        while not stepper.done():
            rec = stepper.advance()
            if out["fields"] and rec.step % out["every"] == 0:
                writer.write_fields(rec.time)
            nneg, bracket = None, None
            if detector is not None:
                nneg = detector.screen()
                if nneg > count:
                    bracket = detector.confirm(count, nneg)
                    nneg = bracket[0] if bracket is not None else count
                lam = float("nan")
                if scfg["eigen_every"] and rec.step % scfg["eigen_every"] == 0:
                    lam = analyzer.lambda_min(nneg)
                rec.extra.update({"negative_eigenvalues": nneg, "lambda_min": lam})
            writer.history_row(row_of(rec))
            (log.info if progress else log.debug)(f"step {rec.step:5d}  t = {rec.time:10.5f} s  dt = {rec.dt:9.3e} s  "
                     f"newton {rec.newton_its:2d}  growth = {1e3 * rec.growth_mm:9.4f} um  "
                     f"mu_bar = {rec.mu_bar:9.3f} MPa" + (f"  neg.eig. {nneg}" if nneg is not None else ""))
            if bracket is not None:
                nneg, lo, snap_unstable = bracket
                log.info(f"  K lost positive definiteness between t = {lo.t:.6f} and {rec.time:.6f} s "
                         f"({nneg - count} new negative eigenvalue(s))")
                stop = False
                while count < nneg:  # one bisection per new negative eigenvalue
                    crossing = locate_crossing(stepper, analyzer, lo, snap_unstable, count, scfg["tolerance"],
                                               scfg["modes"], log=log.info if progress else log.debug)
                    crossings.append(crossing)
                    log.info(f"  crossing #{len(crossings)}: t = {crossing.time:.6f} s, "
                             f"growth = {1e3 * crossing.growth_mm:.4f} um, N = {crossing.wrinkle_count:g}")
                    if len(crossings) == 1:
                        writer.write_mode(problem, crossing)
                    count += 1
                    lo = crossing.hi if crossing.hi_count == count else crossing.lo
                    stop = scfg["stop_at_onset"] or len(crossings) >= scfg["max_crossings"]
                    if stop:
                        break
                count = max(count, nneg)
                stepper.restore(snap_unstable)
                if stop:
                    break
                detector.restart(snap_unstable)
            elif detector is not None:
                detector.accepted(stepper.snapshot())
    except StepFailure as err:
        status, message = "failed", str(err)
        log.info(f"hydrobuckle: solver failure: {message}")
    if status != "failed" and analyzer is not None:
        status = "buckled" if crossings else "stable"
    last = writer.rows[-1]
    summary = {
        "status": status,
        "message": message,
        "final": {"time": last["time"], "growth_mm": last["growth_mm"]},
        "mesh": {"cells": problem.cells(), "dofs": problem.dofs(), **problem.tm.info},
        "materials": {k: {**m.as_dict(), "s0": m.s0, "mu0": m.mu0} for k, m in mats.items()},
        "ranks": comm.size,
        **({"critical": crossings[0].as_dict()} if crossings else {}),
        **({"crossings": [c.as_dict() for c in crossings]} if len(crossings) > 1 or
           (crossings and not scfg["stop_at_onset"]) else {}),
        "steps": stepper.step,
        "rejected_steps": stepper.rejected,
        "failed_solves": stepper.failed_solves,
        "linear_solver": {"kind": cfg["solver"]["linear"], "krylov_iterations": stepper.solver.linear_iterations},
        **({"stability_tests": {"screening": scfg["screening"], "screened_steps": detector.screened_steps,
                                "exact_tests": analyzer.tests, "false_alarms": detector.false_alarms,
                                "late_screens": detector.late_screens}}
           if detector is not None else {}),
        "wall_time_s": time.perf_counter() - wall0,
        "versions": versions(),
        "assumptions": list(ASSUMPTIONS),
        "config": cfg,
    }
    writer.close()
    writer.summary(summary)
    if cfg["output"]["plot"]:
        writer.plot_history(summary.get("critical"))
    stepper.solver.destroy()
    if analyzer is not None:
        analyzer.destroy()
    log.info(f"hydrobuckle: {status} after {stepper.step} steps, t = {last['time']:.5g} s, "
             f"growth = {1e3 * last['growth_mm']:.4f} um, wall {summary['wall_time_s']:.1f} s -> {outdir}")
    if crossings:
        c = crossings[0]
        log.info(f"hydrobuckle: critical growth g_c = {1e3 * c.growth_mm:.4f} um at t_c = {c.time:.6f} s, "
                 f"wrinkle count N_c = {c.wrinkle_count:g}")
    return summary
