"""Backward-Euler time stepping with error-controlled adaptive steps and cut-back on divergence.

Step size control. Every step starts from a linear extrapolation of the last two states (the
predictor, also Newton's initial guess). For backward Euler the difference between the solution
and that predictor estimates the local truncation error,

    err ~ dt / (2 dt + dt_prev) * max_cells |s - s_pred|,

measured on the cell-averaged fluid content s, the quantity whose through-thickness profile in
the film decides the onset of wrinkling. A step with err > tolerance is rejected and retried
smaller; an accepted step proposes dt_next = dt * clamp(0.9 sqrt(tol/err), 0.2, 2). Steps never
cross a kink of the loading (the end of the ramp); after a kink, whose rate jump the predictor
cannot know, the history restarts. A step whose Newton iteration diverges is cut back by 4 until
``time.dt_min``, below which the run fails with a :class:`StepFailure`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import ufl
from mpi4py import MPI

from app import compat
from app.solvers.newton import NewtonSolver

CUTBACK = 0.25
SAFETY = 0.9
GROW_MAX = 2.0
SHRINK_MIN = 0.2


class StepFailure(RuntimeError):
    """The step could not be completed even at the smallest allowed step size."""


@dataclass
class StepRecord:
    step: int
    time: float
    dt: float
    newton_its: int
    growth_mm: float
    mu_bar: float
    fluid_volume: float
    inflow: float
    applied_strain: float
    error_estimate: float = float("nan")
    extra: dict = field(default_factory=dict)

    COLUMNS = ("step", "time", "dt", "newton_its", "growth_mm", "mu_bar", "fluid_volume", "inflow",
               "applied_strain", "error_estimate")


@dataclass
class Snapshot:
    """Everything needed to resume time stepping from an accepted state."""

    state: np.ndarray
    rate_u: np.ndarray
    dQ_prev: np.ndarray
    dt_prev: float
    history_valid: bool
    t: float
    step: int
    inflow: float
    dt_next: float


class TimeStepper:
    """Advances a :class:`app.model.problem.Problem` in time."""

    def __init__(self, problem, cfg: dict, log=None):
        self.p = problem
        tcfg, scfg = cfg["time"], cfg["solver"]
        self.end = tcfg["end"]
        self.dt_min, self.dt_max = tcfg["dt_min"], tcfg["dt_max"]
        self.tol, self.adaptive = tcfg["tolerance"], tcfg["adaptive"]
        self.dt_fixed = tcfg["dt_initial"]
        self.max_steps = tcfg["max_steps"]
        self.solver = NewtonSolver(problem, scfg["rtol"], scfg["atol"], scfg["max_it"],
                                   factorization=scfg["factorization"], linear=scfg["linear"],
                                   ksp_rtol=scfg["ksp_rtol"], ksp_max_it=scfg["ksp_max_it"])
        self.log = log or (lambda msg: None)
        self.kinks = sorted(k for k in problem.loading.kinks() if 0 < k < self.end)

        nu, nq = len(problem.u_dofs), len(problem.q_dofs)
        self.rate_u = np.zeros(nu)
        self.dQ_prev = np.zeros(nq)
        self.dt_prev = tcfg["dt_initial"]
        self.history_valid = False
        self.t = 0.0
        self.step = 0
        self.inflow = 0.0
        self.dt_next = tcfg["dt_initial"]
        self.rejected = 0
        self.failed_solves = 0
        self._setup_error_form()

    # --- error estimate --------------------------------------------------------------------

    def _setup_error_form(self):
        p = self.p
        V0 = compat.scalar_space(p.domain, "DG", 0)
        v0 = ufl.TestFunction(V0)
        self._err_fn = compat.Function(p.W)
        _, e = ufl.split(self._err_fn)
        self._err_form = compat.form(ufl.div(e) * v0 * ufl.dx)
        area = compat.assemble_vector(compat.form(v0 * ufl.dx))
        self._cell_area = area.array.copy()
        area.destroy()

    def _fluid_error(self, dQ_pred: np.ndarray) -> float:
        """Max over cells of |cell average of s - s_pred|."""
        a = self._err_fn.x.array
        a[:] = 0.0
        a[self.p.q_dofs] = self.p.w.x.array[self.p.q_dofs] - dQ_pred
        vec = compat.assemble_vector(self._err_form)
        local = np.max(np.abs(vec.array / self._cell_area)) if vec.array.size else 0.0
        vec.destroy()
        return self.p.comm.allreduce(float(local), op=MPI.MAX)

    # --- snapshots (for re-solving from an earlier state) ----------------------------------

    def snapshot(self) -> Snapshot:
        return Snapshot(self.p.state.x.array.copy(), self.rate_u.copy(), self.dQ_prev.copy(), self.dt_prev,
                        self.history_valid, self.t, self.step, self.inflow, self.dt_next)

    def restore(self, snap: Snapshot) -> None:
        self.p.state.x.array[:] = snap.state
        self.rate_u[:] = snap.rate_u
        self.dQ_prev[:] = snap.dQ_prev
        self.dt_prev, self.history_valid = snap.dt_prev, snap.history_valid
        self.t, self.step, self.inflow, self.dt_next = snap.t, snap.step, snap.inflow, snap.dt_next

    # --- one step --------------------------------------------------------------------------

    def _clip(self, dt: float, until: float | None = None) -> float:
        """Do not step across the end time, a loading kink or ``until``; avoid leaving a sliver."""
        t = self.t
        stops = sorted(self.kinks + [self.end] + ([until] if until is not None else []))
        for stop in stops:
            if t < stop - 1e-12 * max(1.0, stop):
                if t + dt > stop or stop - (t + dt) < 1e-3 * dt:
                    dt = stop - t
                break
        return dt

    def _predict(self, dt: float) -> np.ndarray:
        """Set problem.w to the predictor; return the predicted flux increment."""
        p = self.p
        r = dt / self.dt_prev if self.history_valid else 0.0
        u_n = p.state.x.array[p.u_dofs]
        dQ_pred = r * self.dQ_prev
        w = p.w.x.array
        w[:] = 0.0
        w[p.u_dofs] = u_n + r * self.rate_u
        w[p.q_dofs] = dQ_pred
        return dQ_pred

    def attempt(self, dt: float):
        """Solve one step of size dt from the current state; returns (newton result, err)."""
        p = self.p
        p.set_time(self.t + dt, dt)
        dQ_pred = self._predict(dt)
        res = self.solver.solve()
        err = float("nan")
        if res.converged and self.history_valid:
            err = dt / (2 * dt + self.dt_prev) * self._fluid_error(dQ_pred)
        return res, err

    def advance(self, until: float | None = None) -> StepRecord:
        """Take one accepted step (with rejections and cut-backs as needed), ending at ``until``
        at the latest."""
        if self.step >= self.max_steps:
            raise StepFailure(f"time.max_steps = {self.max_steps} reached at t = {self.t:.6g} s")
        dt = self.dt_next if self.adaptive else self.dt_fixed
        dt = min(dt, self.dt_max)
        while True:
            dt = self._clip(dt, until)
            res, err = self.attempt(dt)
            if not res.converged:
                self.failed_solves += 1
                new_dt = dt * CUTBACK
                self.log(f"  Newton did not converge (reason {res.reason}) at t = {self.t + dt:.6g} s, "
                         f"dt = {dt:.3g} s: cutting back to {new_dt:.3g} s")
                if new_dt < self.dt_min:
                    raise StepFailure(f"Newton failed to converge at t = {self.t:.6g} s even with "
                                      f"dt = {dt:.3g} s (time.dt_min = {self.dt_min:g} s); "
                                      f"last SNES reason {res.reason}")
                dt = new_dt
                continue
            if self.adaptive and math.isfinite(err) and err > self.tol and dt > self.dt_min:
                self.rejected += 1
                dt = max(dt * max(SHRINK_MIN, SAFETY * math.sqrt(self.tol / err)), self.dt_min)
                continue
            break
        return self._accept(dt, res.iterations, err)

    def _accept(self, dt: float, its: int, err: float) -> StepRecord:
        p = self.p
        influx = p.step_influx()
        u_old = p.state.x.array[p.u_dofs].copy()
        p.accept()
        self.rate_u[:] = p.state.x.array[p.u_dofs] - u_old
        self.dQ_prev[:] = p.w.x.array[p.q_dofs]
        self.dt_prev = dt
        self.t += dt
        self.step += 1
        self.inflow += influx
        crossed_kink = any(abs(self.t - k) <= 1e-12 * max(1.0, k) for k in self.kinks)
        self.history_valid = not crossed_kink
        if self.adaptive:
            if math.isfinite(err) and err > 0:
                factor = min(GROW_MAX, max(SHRINK_MIN, SAFETY * math.sqrt(self.tol / err)))
            elif math.isfinite(err):
                factor = GROW_MAX
            else:
                factor = 1.0  # no estimate yet (first step, or just after a kink)
            self.dt_next = min(self.dt_max, max(self.dt_min, dt * factor))
        return self.record(dt, its, err)

    def record(self, dt: float, its: int, err: float) -> StepRecord:
        p = self.p
        return StepRecord(self.step, self.t, dt, its, p.growth(), p.loading.mu_bar(self.t), p.fluid_volume(),
                          self.inflow, p.loading.applied_strain(self.t), err)

    def initial_record(self) -> StepRecord:
        return self.record(0.0, 0, float("nan"))

    def done(self) -> bool:
        return self.t >= self.end - 1e-12 * max(1.0, self.end)
