"""One simulation from a resolved config to a result directory (used by the CLI and the tests).

The config dict becomes objects here, once: the :class:`~app.model.problem.Problem` and the typed
settings of each consumer (:class:`RunSettings`). The loop then only steps, asks the onset tracker
and writes; the summary is assembled in :func:`summarize`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from app import factory, interrupt, logging_setup, timing
from app.io import checkpoint
from app.io.output import OutputSettings, ResultWriter, versions
from app.io.writes import ResultWriteError
from app.model import history
from app.model.patterns import branch_patterns
from app.model.problem import Problem
from app.model.surface import SurfaceProfiles, shape_of, surface_profile
from app.onset.contact import contact_summary
from app.onset.tracker import StabilitySettings, onset_tracker
from app.solvers.newton import SolverSettings
from app.solvers.step_control import TimeSettings
from app.solvers.stepped_problem import ModelLimit, StepFailure, StepRecord
from app.workflows.step_costs import StepCosts

ASSUMPTIONS = (
    "material.shear_modulus (gamma_s) defaults to 0.1 MPa: the paper gives only ratios gamma_f/gamma_s",
    "each layer starts in its own stress-free preswollen state (s0, mu0 from its own gamma, eqs. 3.5-3.6); "
    "the surface chemical potential ramp starts at the film's mu0",
    "plane strain; growth = mean vertical displacement of the top surface",
)


@dataclass(frozen=True)
class RunSettings:
    """The typed settings of one run, one per consumer: stepper, Newton, onset tracker, writer."""

    time: TimeSettings
    solver: SolverSettings
    stability: StabilitySettings
    output: OutputSettings

    @classmethod
    def from_config(cls, cfg: dict) -> RunSettings:
        return cls(factory.time_settings(cfg), factory.solver_settings(cfg), factory.stability_settings(cfg),
                   OutputSettings.from_config(cfg))


def progress_line(rec: StepRecord) -> str:
    nneg = rec.extra.get("negative_eigenvalues")
    return (f"step {rec.step:5d}  t = {rec.time:10.5f} s  dt = {rec.dt:9.3e} s  newton {rec.newton_its:2d}  "
            f"growth = {1e3 * rec.growth_mm:9.4f} um  mu_bar = {rec.mu_bar:9.3f} MPa"
            + (f"  neg.eig. {nneg}" if nneg is not None else ""))


def simulate(cfg: dict, outdir, comm, problem: Problem | None = None, progress: bool = True, after=(),
             resume: checkpoint.Resume | None = None, stop_after: int | None = None, monitor=None) -> dict:
    """Run the transient problem of ``cfg``; write results to ``outdir``; return the summary.

    ``after``: callables that amend the summary once the run has ended and its solvers are freed,
    before summary.json is written (the run pipeline's error estimate, :mod:`app.workflows.pipeline`).
    ``resume``: ``outdir``'s checked checkpoint (:func:`app.io.checkpoint.check`) to continue from; the
    directory is not touched before its state is in place (a :class:`~app.io.checkpoint.CheckpointError`
    before that leaves it as it was). ``stop_after``: stop as an interrupt would (checkpoint, status
    "interrupted") once this many steps are accepted (tests). ``monitor``: told every accepted step's
    record (a study's progress bar, :mod:`app.workflows.progress`).

    A result file that cannot be written (a full disk) stops the run after the current step, as a solver
    failure does (status "failed", the checkpoint of that step if it can be written, everything else
    that can be written); then the :class:`~app.io.writes.ResultWriteError` is raised, on every rank."""
    log = logging_setup.get()
    wall0 = time.perf_counter()
    settings = RunSettings.from_config(cfg)
    with interrupt.Watch(comm) as watch:  # SIGINT/SIGTERM: recorded, acted on between steps
        loop = RunLoop.build(cfg, outdir, comm, settings, problem, resume, progress, watch)
        loop.monitor = monitor
        status, message = loop.run(stop_after)
    problem, stepper, tracker, writer = loop.problem, loop.stepper, loop.tracker, loop.writer
    if status != "interrupted":  # the final state, also where it is not an output.every step
        writer.write_fields(stepper.t, stepper.step, last=True)
    summary = summarize(status if status == "interrupted" else tracker.status(status), message, writer.rows[-1],
                        problem, stepper, tracker, settings, cfg, time.perf_counter() - wall0)
    summary["step_cost"] = loop.costs.summary()  # this part of the run's steps (a resumed run: since the resume)
    if problem.contact is not None:
        summary["creases"] = contact_summary(problem, writer.rows)
    shape = shape_of(problem)
    if "postbuckling" in summary:
        last = writer.rows[-1]  # the branch's end: competing branches compare these at the same time
        energy, mu, fluid = (float(last[k]) for k in ("energy", "mu_bar", "fluid_volume"))
        summary["postbuckling"]["end"] = {"time": float(last["time"]), "stored_energy": energy,
                                          "fluid_volume": fluid, "grand_potential": energy - mu * fluid}
        if shape.surface_dim == 2:  # 3D: the pattern on the branch
            g_c = (summary.get("critical") or {}).get("growth_mm")
            summary["postbuckling"]["patterns"] = branch_patterns(loop.profiles, shape, g_c)
            if summary["postbuckling"]["patterns"]:
                summary["postbuckling"]["end"]["pattern"] = summary["postbuckling"]["patterns"][-1]["pattern"]
    if resume:  # provenance: steps and counters cover the whole run, wall_time_s this part only
        summary["resumed_from"] = {"step": resume.meta["step"], "time": resume.meta["t"],
                                   "ranks": resume.meta["ranks"]}
    writer.close()
    stepper.destroy()
    tracker.destroy()
    if status != "interrupted":  # under mpirun the ranks have 1 s after a SIGTERM (docs/reliability.md)
        writer.plot_history(summary.get("critical"))
        writer.plot_branch(loop.profiles, summary.get("critical"), shape,
                           (summary.get("postbuckling") or {}).get("patterns"))
    _report(summary, tracker, stepper.step, outdir, log)
    try:
        for step in after if writer.error is None else ():
            step(summary)
    except ResultWriteError as err:  # a companion run's file
        writer.error = writer.error or err
    except Exception as err:  # noqa: BLE001 - the run's own answer is kept: summary.json says what failed
        import traceback

        what = f"{type(err).__name__}: {err}"
        log.info(f"hydrobuckle: the step after the run failed ({what}); the run's result is kept, summary.json "
                 "records the failure under 'after_run_error'")
        log.debug(traceback.format_exc())
        summary["after_run_error"] = what
    if writer.error is not None:
        summary.update(status="failed", message=str(writer.error))
    writer.summary(summary)
    if writer.error is not None:  # the checkpoint stays (a summary.json that failed: the run can be resumed)
        raise writer.error
    if summary["status"] not in ("interrupted", "failed"):  # ended normally: nothing to resume
        loop.checkpoints.remove(comm)
    return summary


class RunLoop:
    """One run's objects and its time loop: the stepper steps, and after every accepted step the writer
    (fields, history row), the onset tracker (verdict, crossings), the progress line, the branch's surface
    profiles and the checkpoints are told, in that order. The loop ends at time.end, at a crossing the
    policy stops at, at equilibrium, at a model limit or a solver failure, or before a step when a signal
    came (every rank agrees) or a result file could not be written; the last two leave a checkpoint."""

    def __init__(self, problem, stepper, tracker, writer, checkpoints, watch, settings: RunSettings, profiles,
                 detail):
        self.problem, self.stepper, self.tracker, self.writer = problem, stepper, tracker, writer
        self.checkpoints, self.watch, self.settings, self.profiles = checkpoints, watch, settings, profiles
        self.log, self.detail = logging_setup.get(), detail
        self.monitor = None  # told every accepted step after the progress line (a study's progress)
        self.costs = StepCosts()  # each accepted step's wall time, by part of the run (summary.json step_cost)

    @classmethod
    def build(cls, cfg: dict, outdir, comm, settings: RunSettings, problem, resume, progress: bool, watch) -> RunLoop:
        """The problem (built unless given), stepper, tracker, writer and checkpoints of a run, with a resumed
        checkpoint's state in place; the initial state recorded (a new run)."""
        log = logging_setup.get()
        detail = log.info if progress else log.debug
        writer = None if resume else ResultWriter(outdir, comm, cfg, settings.output)
        with timing.timed("setup"):
            if problem is None:
                problem = factory.problem(cfg, comm)
            stepper = factory.time_stepper(problem, settings.time, settings.solver, log=log.info)
            tracker = onset_tracker(problem, stepper, settings.stability, log=log.info, detail=detail,
                                    on_first_crossing=lambda crossing: loop.writer.write_mode(problem, crossing),
                                    reference_length=factory.reference_length(cfg))
        # the stepper's columns, the model's (app.model.history) and the onset tracker's
        columns = StepRecord.COLUMNS + history.columns(problem) + tracker.COLUMNS
        if writer is not None:
            writer.columns = list(columns)  # before its first row
        watch.arm()  # gmsh reset SIGINT's handler
        checkpoints = checkpoint.Checkpoints(outdir, cfg, settings.output.checkpoint_every, log=log.info)
        if resume:
            try:
                checkpoints.resumed(checkpoint.restore(resume, problem, stepper, tracker), stepper.step)
                writer = ResultWriter(outdir, comm, cfg, settings.output, columns=columns, resume_rows=resume.rows,
                                      keep_mode=resume.crossings > 0)
            except BaseException:
                stepper.destroy()
                tracker.destroy()
                raise
        profiles = resume.profiles() if resume else SurfaceProfiles()  # the branch's: profiles.npz, wrinkles.png
        loop = cls(problem, stepper, tracker, writer, checkpoints, watch, settings, profiles, detail)
        mats = problem.materials
        log.info(f"hydrobuckle: {cfg['geometry']['kind']} mesh with {problem.cells()} cells, {problem.dofs()} "
                 f"dofs on {comm.size} rank(s); "
                 + ", ".join(f"{name} mu0 = {m.mu0:.4f} MPa" for name, m in mats.items()))
        writer.setup_fields(problem)
        if resume:
            log.info(f"hydrobuckle: resumed from {resume.path} at step {stepper.step}, t = {stepper.t:.6g} s "
                     f"(written on {resume.meta['ranks']} rank(s))")
            writer.write_fields(stepper.t, stepper.step)
        else:
            first = stepper.initial_record()
            tracker.start(first)
            writer.history_row(first.row())
            writer.write_fields(0.0)
            stepper.at_equilibrium(first)
        return loop

    def run(self, stop_after: int | None = None) -> tuple[str, str]:
        """Step to the end; the (status, message) the run ended with."""
        stepper = self.stepper
        try:
            while not stepper.done():
                stop = self._stop_before_step(stop_after)
                if stop is not None:
                    self._checkpoint()
                    return stop
                t0 = time.perf_counter()
                rec = stepper.advance()
                solve = time.perf_counter() - t0
                test = self._observe(rec)
                self.costs.add(solve, test, rec.newton_its, stepper.minimizing,
                               rec.values.get("contact_length_mm", 0.0) > 0, self.tracker.switches)
                end = self._end_after(rec)
                if end is not None:
                    return end
                if self.checkpoints.due(rec.step):
                    self._checkpoint()
        except ModelLimit as err:
            self.log.info(f"hydrobuckle: {err}")
            return err.limit.status, str(err)
        except StepFailure as err:
            self.log.info(f"hydrobuckle: solver failure: {err}")
            return "failed", str(err)
        return "completed", ""

    def _stop_before_step(self, stop_after: int | None) -> tuple[str, str] | None:
        """A result file that could not be written, or a signal (agreed on every rank), ``stop_after``."""
        writer, stepper = self.writer, self.stepper
        if writer.error is not None:  # agreed on every rank
            self.log.info(f"hydrobuckle: {writer.error}; stopping after {stepper.step} steps")
            return "failed", str(writer.error)
        sig = self.watch.requested()  # collective: every rank leaves after the same step
        if sig or (stop_after is not None and stepper.step >= stop_after):
            how = interrupt.name(sig) if sig else f"stop_after = {stop_after}"
            message = f"interrupted by {how} at t = {writer.rows[-1]['time']:.6g} s after {stepper.step} steps"
            self.log.info(f"hydrobuckle: {message}")
            return "interrupted", message
        return None

    def _observe(self, rec) -> float:
        """Everything told of an accepted step, in order (the tracker's columns go into the history row);
        the wall time of its stability test."""
        self.writer.write_fields(rec.time, rec.step)
        t0 = time.perf_counter()
        self.tracker.test(rec)
        test = time.perf_counter() - t0
        self.writer.history_row(rec.row())
        self.detail(progress_line(rec))
        if self.monitor is not None:
            self.monitor(rec)
        return test

    def _end_after(self, rec) -> tuple[str, str] | None:
        """The crossings located and the policy asked; on a branch the surface profile kept; equilibrium."""
        stepper, problem = self.stepper, self.problem
        if self.tracker.resolve():
            return "completed", ""
        if stepper.minimizing:  # on a followed branch: the surface profile of every state (wrinkles.png)
            pos, prof, _, closed = surface_profile(problem, problem.state.x.array)
            self.profiles.add(problem.growth(), stepper.t, pos, prof, closed)
        if stepper.at_equilibrium(rec):
            message = (f"equilibrium at t = {rec.time:.6g} s: relative fluid uptake rate {stepper.uptake_rate:.3g} "
                       f"< time.stop_at_equilibrium = {self.settings.time.stop_at_equilibrium:g}")
            self.log.info(f"hydrobuckle: {message}")
            return "equilibrium", message
        return None

    def _checkpoint(self) -> None:
        with timing.timed("output"):
            self.checkpoints.write(self.problem, self.stepper, self.tracker, self.writer.rows, self.profiles)


def _report(summary: dict, tracker, steps: int, outdir, log) -> None:
    """The run's closing log lines: status, g_c and N_c, the surface's short-wave onset."""
    last = summary["final"]
    log.info(f"hydrobuckle: {summary['status']} after {steps} steps, t = {last['time']:.5g} s, "
             f"growth = {1e3 * last['growth_mm']:.4f} um, wall {summary['wall_time_s']:.1f} s -> {outdir}")
    if tracker.crossings:
        c = tracker.crossings[0]
        log.info(f"hydrobuckle: critical growth g_c = {1e3 * c.growth_mm:.4f} um at t_c = {c.time:.6f} s, "
                 f"wrinkle count N_c = {c.wrinkle_count:g}")
    so = summary.get("surface_onset")
    if so is not None:
        where = ", ".join(f"{v:.4g}" for v in so["where"])
        first = ("before the onset above: that N_c is a wave this mesh resolves, after the surface's own "
                 "instability, which has no wavelength of its own" if tracker.crossings and so["before_critical"]
                 else "after the onset above" if tracker.crossings else "(K itself stayed positive definite)")
        log.info(f"hydrobuckle: the permeable surface is unstable at short waves (below the mesh) from t = "
                 f"{so['time']:.6f} s, growth = {so['growth_um']:.4f} um, at ({where}) mm, {first}")


def summarize(status: str, message: str, last: dict, problem, stepper, tracker, settings: RunSettings, cfg: dict,
              wall: float) -> dict:
    """summary.json's content (its keys are read by studies, converge, bench and the tests)."""
    return {
        "status": status,
        "message": message,
        "final": {"time": last["time"], "growth_mm": last["growth_mm"], "amplitude_mm": last["amplitude_mm"],
                  "wrinkle_count": last["wrinkle_count"]},
        "mesh": {"cells": problem.cells(), "dofs": problem.dofs(), **problem.tm.info},
        "materials": {k: {**m.as_dict(), "s0": m.s0, "mu0": m.mu0} for k, m in problem.materials.items()},
        "ranks": problem.comm.size,
        **tracker.onset_summary(),
        "steps": stepper.step,
        "rejected_steps": stepper.rejected,
        "failed_solves": stepper.failed_solves,
        "linear_solver": {"kind": settings.solver.linear, "krylov_iterations": stepper.linear_iterations,
                          "factor_reuse": settings.solver.reuse, **stepper.factor_counts()},
        **tracker.tests_summary(),
        **tracker.branch_summary(),
        "wall_time_s": wall,
        "versions": versions(),
        "assumptions": list(ASSUMPTIONS),
        "config": cfg,
    }
