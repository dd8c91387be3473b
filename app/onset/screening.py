"""The per-step stability verdict, and a verified bracket when a new negative eigenvalue appears.

``screening = "exact"``: the inertia of the criterion's matrix (converged state, zero increment;
:mod:`app.solvers.stability`) after every step, one LDL^T factorization each.

``screening = "newton"``: a step may instead read the inertia of the Newton solver's last LDL^T factor,
which that step computed anyway (K_dt: one Newton update short of the converged state, with the step's own
dt as tau), but only where that screen cannot miss a crossing of the criterion, i.e. where K_dt has at
least the criterion's negative eigenvalues (``newton_screen_valid``):

- ``undrained``: always (K_uu is a principal block of K_dt: interlacing);
- ``rate``: when dt >= 2 tau (K_dt = K_inf + D/dt <= K_tau; the factor 2 covers the change of the
  dissipation metric D between the previous and the converged state, small under the step control);
- ``drained``: never (K_dt is stiffer than the drained matrix for every dt): every step is exact.

A screened increase is confirmed by the exact test at that step (a false alarm is logged and the run goes
on), and the stable end of the bracket is verified by exact tests, walking back through the last ``keep``
accepted states and, past them, to the last state verified exactly. The bracket that the bisection
refines is therefore the same as with exact tests on every step, up to a screen that reports late (then
the bracket is wider, never wrong). Steps without a factorization of their own (zero Newton iterations,
or ``solver.factorization = "lu"``) are tested exactly.
"""

from __future__ import annotations

from collections import deque


class StabilityScreen:
    """Negative-eigenvalue counts of accepted states and the brackets of their increases.

    Needs from the stepper only ``snapshot``, ``restore`` and ``factor_inertia``; from the analyzer
    only ``inertia``."""

    def __init__(self, stepper, analyzer, screening: str = "newton", keep: int = 4, log=None,
                 newton_screen_valid=None):
        self.stepper, self.analyzer, self.screening = stepper, analyzer, screening
        # whether the Newton factor of a step of size dt may stand in for the exact test (default: always)
        self.newton_screen_valid = newton_screen_valid or (lambda dt: True)
        self.recent: deque = deque(maxlen=keep)  # accepted states before the current one
        self.verified = None  # the last state the exact test found with no new negative eigenvalue
        self.screened_steps = 0
        self._last_exact = True
        self.false_alarms = 0
        self.late_screens = 0  # states the walk-back found already unstable (the screen reported late)
        self.log = log or (lambda msg: None)

    def _exact(self) -> int:
        self._last_exact = True
        return self.analyzer.inertia()[0]

    def start(self) -> int:
        """Exact negative-eigenvalue count of the current state, which becomes the only remembered one (the
        initial state; a state just perturbed onto a branch)."""
        count = self._exact()
        self.verified = self.stepper.snapshot()
        self.recent.clear()
        self.recent.append(self.verified)
        return count

    def screen(self) -> int:
        """Negative-eigenvalue count of the state just accepted (screened or exact)."""
        if self.screening == "newton" and self.newton_screen_valid(self.stepper.dt_prev):
            inertia = self.stepper.factor_inertia()
            if inertia is not None:
                self.screened_steps += 1
                self._last_exact = False
                return inertia[0]
        return self._exact()

    def confirm(self, count: int, screened: int):
        """Exact check of a screened increase over ``count`` at the current state.

        Returns None for a false alarm, else (exact count, stable snapshot, unstable snapshot);
        the stepper is left at the current (unstable) state."""
        hi = self.stepper.snapshot()
        nneg = screened if self._last_exact else self._exact()
        if nneg <= count:
            self.false_alarms += 1
            self.log(f"  screened inertia reported {screened} negative eigenvalue(s); the exact test finds "
                     f"{nneg}: no crossing yet")
            self.verified = hi
            return None
        if self.screening != "newton":
            return nneg, self.recent[-1], hi  # the previous state passed the exact test
        lo = None
        for snap in reversed(self.recent):
            if snap is self.verified:
                lo = snap
                break
            self.stepper.restore(snap)
            if self._exact() <= count:
                lo = snap
                break
            self.late_screens += 1
            self.log(f"  the state at t = {snap.t:.6f} s is already unstable: widening the bracket")
        if lo is None:
            lo = self.verified
            self.log(f"  the bracket's stable end moved back to the last verified state, t = {lo.t:.6f} s")
        self.verified = lo
        self.stepper.restore(hi)
        return nneg, lo, hi

    def accepted(self, snap) -> None:
        """Remember an accepted state (a candidate stable end of a later bracket)."""
        self.recent.append(snap)

    def restart(self, snap) -> None:
        """After the crossings at ``snap`` are located: its exact count is the new reference."""
        self.recent.clear()
        self.recent.append(snap)
        self.verified = snap

    # --- checkpoints (app.io.checkpoint) -----------------------------------------------------

    def export_state(self) -> dict:
        """The remembered snapshots (``verified`` may be one of ``recent``: the same object) and counters."""
        return {"recent": list(self.recent), "verified": self.verified, "screened_steps": self.screened_steps,
                "last_exact": self._last_exact, "false_alarms": self.false_alarms, "late_screens": self.late_screens}

    def checkpoint_state(self, ref) -> dict:
        """This screen in a checkpoint's meta: the counters, and each remembered snapshot as ``ref(snapshot)``
        (the checkpoint stores each snapshot's arrays once)."""
        state = self.export_state()
        return {**{k: v for k, v in state.items() if k not in ("recent", "verified")},
                "recent": [ref(s) for s in state["recent"]],
                "verified": ref(state["verified"]) if state["verified"] is not None else None}

    @staticmethod
    def from_checkpoint(state: dict, snapshots: list) -> dict:
        """:meth:`checkpoint_state`'s dict with the snapshots in place of their references."""
        return {**state, "recent": [snapshots[i] for i in state["recent"]],
                "verified": snapshots[state["verified"]] if state["verified"] is not None else None}

    def import_state(self, state: dict) -> None:
        self.recent.clear()
        self.recent.extend(state["recent"])
        self.verified = state["verified"]
        self.screened_steps, self._last_exact = state["screened_steps"], state["last_exact"]
        self.false_alarms, self.late_screens = state["false_alarms"], state["late_screens"]
