"""Backward-Euler time stepping with error-controlled adaptive steps and cut-back on divergence.

Step size control. Every step starts from a linear extrapolation of the last two states (the
predictor, also Newton's initial guess). For backward Euler the difference between the solution
and that predictor estimates the local truncation error,

    err ~ dt / (2 dt + dt_prev) * max_cells |s - s_pred|,

measured on the cell-averaged fluid content s, the quantity whose through-thickness profile in
the film decides the onset of wrinkling. What a step size becomes after an acceptance, a rejection
or a Newton divergence is :class:`app.solvers.step_control.StepControl`'s arithmetic. Steps never
cross a kink of the loading (the end of the ramp); after a kink, whose rate jump the predictor
cannot know, the history restarts. Below ``time.dt_min`` the run fails with a :class:`StepFailure`.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from app import fem_utils
from app.solvers.minimizer import MinimizingNewton, energy_decreased
from app.solvers.newton import NewtonResult, NewtonSolver, SolverSettings
from app.solvers.step_control import TimeSettings
from app.solvers.stepped_problem import LostStability, Snapshot, StepFailure, SteppedProblem, StepRecord

ENERGY_INCREASED = -101  # a minimizer solve whose energy ended above its initial guess's (a rejection)


class TimeStepper:
    """Advances an :class:`SteppedProblem` in time.

    ``limits``: where a followed branch ends, a callable made once the stepper follows minimizers
    (:meth:`follow_minimizers`) and returning an object with new_step, failed_attempt, out_of_steps and
    accepted (:class:`app.onset.contact.ModelLimits`, raising :class:`ModelLimit`); None: a branch is followed
    without any check. ``check``: the diagnosis of two failed attempts in a row, ``check(dt)`` -> the
    (what, negative eigenvalues) of each stability test it ran (:class:`app.onset.criteria.LossOfStability`);
    None: failures are only cut back."""

    def __init__(self, system: SteppedProblem, time: TimeSettings, solver: SolverSettings, log=None, limits=None,
                 check=None):
        self.system = system
        self.end = time.end
        self.max_steps = time.max_steps
        self.control = time.step_control()
        self._solver_settings = solver
        self.solver = NewtonSolver(system.residual, system.hessian, system.bcs, system.w, solver,
                                   system.comm, fields={"u": system.u_dofs, "q": system.q_dofs},
                                   extra=system.extra)
        self.log = log or (lambda msg: None)
        self.kinks = sorted(k for k in system.kinks if 0 < k < self.end)

        nu, nq = len(system.u_dofs), len(system.q_dofs)
        self.rate_u = np.zeros(nu)
        self.dQ_prev = np.zeros(nq)
        self.dt_prev = time.dt_initial
        self.history_valid = False
        self.t = 0.0
        self.step = 0
        self.inflow = 0.0
        self.dt_next = time.dt_initial
        self.err_prev = float("nan")  # the error estimate of the accepted step before the last (the trend)
        self.rejected = 0
        self.failed_solves = 0
        self.equilibrium_threshold = time.stop_at_equilibrium
        self._volume = None  # (t, fluid volume) of the last record seen by at_equilibrium
        self._volume0 = None
        self.uptake_rate = float("nan")  # the last relative uptake rate at_equilibrium computed
        self.minimizing = False  # past an onset with stability.after_onset = "branch": follow_minimizers
        self.escape_length = None  # the minimizer's negative-curvature step [mm] (the branch's imperfection)
        self.energy_rejections = 0  # minimizer solves whose energy ended above the initial guess's
        self.inadmissible_predictions = 0  # minimizer steps whose extrapolated start lay outside the energy's domain
        self._limits_of = limits
        self.limits = None  # built once minimizing
        self.check = check

    def follow_minimizers(self) -> None:
        """From now on every step minimizes Pi^tau (app.solvers.minimizer.MinimizingNewton): the state past
        an onset. Newton's counters carry over; the run also checks for self-contact and inverted cells."""
        if self.minimizing:
            return

        s, old = self.system, self.solver
        self.solver = MinimizingNewton(s.energy, s.residual, s.hessian, s.bcs, s.w, self._solver_settings, s.comm,
                                       fields={"u": s.u_dofs, "q": s.q_dofs}, extra=s.extra)
        self.solver.escape_length = self.escape_length
        self.solver.set_counters(old.counters())
        old.destroy()
        self.minimizing = True
        if self.limits is None and self._limits_of is not None:  # built already if contact was checked before
            self.limits = self._limits_of()

    def relax(self) -> bool:
        """Minimize Pi at the current time from the current state, without advancing: a perturbed state settles
        onto the branch its perturbation points to, before any load increment (whose own residual would
        compete with the perturbation's). Only for problems without diffusion, where tau does not enter;
        False (state unchanged) if the solve fails."""
        s = self.system
        if s.diffusion:
            return False
        s.set_time(self.t, self.dt_prev)
        w = s.w.x.array
        w[:] = 0.0
        w[s.u_dofs] = s.state.x.array[s.u_dofs]
        res = self.solver.solve()
        if res.converged:
            s.state.x.array[s.u_dofs] = w[s.u_dofs]
        return res.converged

    # --- error estimate --------------------------------------------------------------------

    def _fluid_error(self, dQ_pred: np.ndarray) -> float:
        """Max over cells of |cell average of s - s_pred|."""
        s, change = self.system, self.system.content_change
        a = change.work.x.array
        a[:] = 0.0
        a[s.q_dofs] = s.w.x.array[s.q_dofs] - dQ_pred
        vec = fem_utils.assemble_vector(change.form)
        local = np.max(np.abs(vec.array / change.area)) if vec.array.size else 0.0
        vec.destroy()
        return s.comm.allreduce(float(local), op=MPI.MAX)

    # --- snapshots (for re-solving from an earlier state) ----------------------------------

    def snapshot(self) -> Snapshot:
        return Snapshot(self.system.state.x.array.copy(), self.rate_u.copy(), self.dQ_prev.copy(), self.dt_prev,
                        self.history_valid, self.t, self.step, self.inflow, self.dt_next, self.err_prev)

    @staticmethod
    def snapshot_of(state: np.ndarray, rate_u: np.ndarray, dQ_prev: np.ndarray, scalars: dict) -> Snapshot:
        """A snapshot from stored parts (a checkpoint's arrays on this layout and its scalars)."""
        return Snapshot.from_parts(state, rate_u, dQ_prev, scalars)

    def restore(self, snap: Snapshot) -> None:
        self.system.state.x.array[:] = snap.state
        self.rate_u[:] = snap.rate_u
        self.dQ_prev[:] = snap.dQ_prev
        self.dt_prev, self.history_valid = snap.dt_prev, snap.history_valid
        self.t, self.step, self.inflow, self.dt_next = snap.t, snap.step, snap.inflow, snap.dt_next
        self.err_prev = snap.err_prev

    def resume_from(self, snap: Snapshot, counters: dict) -> None:
        """Continue from a checkpoint's current snapshot and :meth:`counters`; the unknown holds the last
        step's (u, dQ), which only the flux output reads before the next step."""
        self.restore(snap)
        self.set_counters(counters)
        s = self.system
        w = s.w.x.array
        w[:] = 0.0
        w[s.u_dofs] = snap.state[s.u_dofs]
        w[s.q_dofs] = snap.dQ_prev

    def counters(self) -> dict:
        """What a checkpoint needs besides a :class:`Snapshot` to continue identically
        (:mod:`app.io.checkpoint`): the summary's counters, the equilibrium test's volumes, Newton's scale."""
        return {"rejected": self.rejected, "failed_solves": self.failed_solves, "volume": self._volume,
                "volume0": self._volume0, "uptake_rate": self.uptake_rate, "newton": self.solver.counters(),
                "minimizing": self.minimizing, "energy_rejections": self.energy_rejections,
                "inadmissible_predictions": self.inadmissible_predictions}

    def set_counters(self, c: dict) -> None:
        self.rejected, self.failed_solves = c["rejected"], c["failed_solves"]
        self._volume = tuple(c["volume"]) if c["volume"] is not None else None
        self._volume0, self.uptake_rate = c["volume0"], c["uptake_rate"]
        if c.get("minimizing"):
            self.follow_minimizers()
        self.energy_rejections = c.get("energy_rejections", 0)
        self.inadmissible_predictions = c.get("inadmissible_predictions", 0)
        self.solver.set_counters(c["newton"])

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

    def _predict(self, dt: float, extrapolate: bool = True) -> np.ndarray:
        """Set the unknown to the predictor (the displacement extrapolated from the last step unless not
        ``extrapolate``); return the predicted flux increment."""
        s = self.system
        r = dt / self.dt_prev if self.history_valid else 0.0
        u_n = s.state.x.array[s.u_dofs]
        dQ_pred = r * self.dQ_prev
        w = s.w.x.array
        w[:] = 0.0
        w[s.u_dofs] = u_n + (r if extrapolate else 0.0) * self.rate_u
        w[s.q_dofs] = dQ_pred
        return dQ_pred

    def attempt(self, dt: float):
        """Solve one step of size dt from the current state; returns (newton result, err)."""
        self.system.set_time(self.t + dt, dt)
        dQ_pred = self._predict(dt)
        if self.minimizing and not self.solver.admissible(self.system.state.x.array):
            # past a snap the last step's displacement rate, extrapolated, can invert cells (or carry a node
            # through the surface): the minimizer cannot start outside its energy's domain; the last state can
            self.inadmissible_predictions += 1
            dQ_pred = self._predict(dt, extrapolate=False)
        res = self.solver.solve()
        if res.converged and self.minimizing:
            if not energy_decreased(self.solver.last):
                self.energy_rejections += 1
                res = NewtonResult(False, res.iterations, ENERGY_INCREASED, res.residual_norm)
        err = float("nan")
        if res.converged and self.history_valid:
            err = dt / (2 * dt + self.dt_prev) * self._fluid_error(dQ_pred)
        return res, err

    def advance(self, until: float | None = None) -> StepRecord:
        """Take one accepted step (with rejections and cut-backs as needed), ending at ``until``
        at the latest."""
        if self.step >= self.max_steps:
            raise StepFailure(f"time.max_steps = {self.max_steps} reached at t = {self.t:.6g} s")
        control = self.control
        dt = control.first_try(self.dt_next)
        last_reason, diagnosed, failures = None, False, 0
        limits = self.limits if self.minimizing else None  # on a branch: where it ends (app.onset.contact)
        checks = limits or self._contact_checks()  # a converged state's checks: on a branch, or with contact
        if checks is not None:
            checks.new_step()
        while True:
            dt = self._clip(dt, until)
            res, err = self.attempt(dt)
            if not res.converged:
                self.failed_solves += 1
                failures += 1
                limit = (limits.failed_attempt(self.system.w.x.array, self.t + dt, self.t) if limits is not None
                         else None)
                if res.reason == last_reason and not diagnosed:
                    diagnosed = True
                    self._diagnose(dt, res.reason, failures)
                last_reason = res.reason
                new_dt = control.cut_back(dt)
                self.log(f"  Newton did not converge (reason {res.reason}) at t = {self.t + dt:.6g} s, "
                         f"dt = {dt:.3g} s: cutting back to {new_dt:.3g} s"
                         + (f" (its last iterate: {limit.status} near ("
                            + ", ".join(f"{v:.4g}" for v in limit.where) + ") mm)"
                            if limit is not None else ""))
                if new_dt < control.dt_min:
                    if limits is not None:
                        limits.out_of_steps(self.t + dt, self.t)
                    raise StepFailure(f"Newton failed to converge at t = {self.t:.6g} s even with "
                                      f"dt = {dt:.3g} s (time.dt_min = {control.dt_min:g} s); "
                                      f"last SNES reason {res.reason}")
                dt = new_dt
                continue
            if control.rejects(dt, err):
                self.rejected += 1
                dt = control.shrink(dt, err)
                continue
            if checks is not None:  # the checks read the displacement dofs: w's are the new ones
                new_dt = control.cut_back(dt)
                limit = checks.accepted(self.system.w.x.array, self.t + dt, retry=new_dt >= control.dt_min)
                if limit is not None and limit.retry == "same":  # the model changed (a stiffer contact): again
                    self.rejected += 1
                    self.log(f"  the step to t = {self.t + dt:.6g} s: {limit.detail}; solving it again")
                    continue
                if limit is not None:  # limit.retry == "shorter" (an overshoot): rejected, a shorter step tried
                    self.rejected += 1
                    self.log(f"  the step to t = {self.t + dt:.6g} s (dt = {dt:.3g} s) overshoots: {limit.detail}; "
                             f"cutting back to {new_dt:.3g} s")
                    dt = new_dt
                    continue
            break
        return self._accept(dt, res.iterations, err)

    def _contact_checks(self):
        """Before a branch, with self-contact on (a body whose surface touches itself while it swells, as a
        slit): the checks of every converged state (its penetration within the penalty's accuracy), not the
        rules for failed attempts, which belong to a followed branch. None without contact."""
        if self.system.extra is None or self._limits_of is None:
            return None
        if self.limits is None:
            self.limits = self._limits_of()
        return self.limits

    def _diagnose(self, dt: float, reason: int, failures: int) -> None:
        """After a step failed at 4 dt and again at dt for the same reason: is the last converged state
        still stable? ``check(dt)`` runs the stability tests (K with the failing step's tau = dt, what Newton
        sees, then the drained test: any growing perturbation, the fluid free to redistribute) until one has
        negative eigenvalues. Then the state has lost stability and no smaller step can follow the
        fundamental path: raise :class:`LostStability` instead of cutting back to dt_min. All positive
        definite let the cut-back go on."""
        if self.check is None:
            return
        found = []
        for what, nneg in self.check(dt):
            self.log(f"  two failures in a row (SNES reason {reason}): {what} at t = {self.t:.6g} s has {nneg} "
                     f"negative eigenvalue(s)")
            if nneg > 0:
                found.append(f"{what} has {nneg} negative eigenvalue(s)")
        if found and not self.minimizing:
            remedy = getattr(self.check, "remedy", "")
            raise LostStability(
                f"the state lost stability at t = {self.t:.6g} s ({found[0]}; Newton failed {failures} times on "
                f"this step, the last two with SNES reason {reason}): the fundamental path cannot be followed"
                + (f"; {remedy}" if remedy else ""))

    def at_equilibrium(self, rec: StepRecord) -> bool:
        """time.stop_at_equilibrium: whether the run has reached its equilibrium with the held loading.

        The relative uptake rate r = |dV/dt| t / |V - V(0)| (dV/dt over the last accepted step, V the
        SteppedProblem's ``uptake`` observable: the fluid volume; t the elapsed time) is below the threshold, after
        the last loading kink. For an exponential approach V_inf - V ~ exp(-t/T), the uptake still missing is
        r T/t, less than r of the uptake once t > T. Call it with every record of the run, the initial one
        first."""
        if self.system.uptake is None:
            return False
        volume = rec.values[self.system.uptake]
        if self._volume0 is None:
            self._volume0 = volume
        prev, self._volume = self._volume, (rec.time, volume)
        if self.equilibrium_threshold <= 0 or prev is None or rec.time <= prev[0]:
            return False
        if self.kinks and rec.time < self.kinks[-1] * (1 + 1e-12):
            return False
        uptake = abs(volume - self._volume0)
        if uptake == 0.0:
            return False
        rate = abs(volume - prev[1]) / (rec.time - prev[0]) * rec.time / uptake
        self.uptake_rate = rate
        return rate < self.equilibrium_threshold

    def _accept(self, dt: float, its: int, err: float) -> StepRecord:
        s = self.system
        influx = s.influx()
        w, state = s.w.x.array, s.state.x.array
        self.rate_u[:] = w[s.u_dofs] - state[s.u_dofs]
        self.dQ_prev[:] = w[s.q_dofs]
        s.accept()
        prev = (self.dt_prev, self.err_prev)
        self.dt_prev = dt
        self.t += dt
        self.step += 1
        self.inflow += influx
        crossed_kink = any(abs(self.t - k) <= 1e-12 * max(1.0, k) for k in self.kinks)
        self.history_valid = not crossed_kink
        if self.control.adaptive:
            self.dt_next = self.control.proposal(dt, err, prev)
        self.err_prev = err if not crossed_kink else float("nan")  # no trend across a kink
        return self.record(dt, its, err)

    def record(self, dt: float, its: int, err: float) -> StepRecord:
        return StepRecord(self.step, self.t, dt, its, self.inflow, err, self.system.observables(self.t))

    def initial_record(self) -> StepRecord:
        return self.record(0.0, 0, float("nan"))

    def done(self) -> bool:
        return self.t >= self.end - 1e-12 * max(1.0, self.end)

    # --- what the onset tracker needs ------------------------------------------------------

    def advance_to(self, t: float) -> int:
        """Step from the current state to time t exactly (re-solving a bracket); returns the steps taken."""
        steps = 0
        while self.t < t - 1e-14 * t:
            self.advance(until=t)
            steps += 1
        return steps

    def factor_inertia(self) -> tuple[int, int, int] | None:
        """Inertia of the last Newton factor (see :meth:`NewtonSolver.factor_inertia`)."""
        return self.solver.factor_inertia()

    def factor_counts(self) -> dict:
        """Newton's factorizations of K so far (the minimizer's shifted ones not included), and the solves
        repeated with plain Newton after a kept factor failed (:class:`NewtonSolver`)."""
        c = self.solver.counters()
        return {"factorizations": c["factorizations"], "reuse_retries": c["reuse_retries"]}

    @property
    def linear_iterations(self) -> int:
        return self.solver.linear_iterations

    def destroy(self) -> None:
        self.solver.destroy()
