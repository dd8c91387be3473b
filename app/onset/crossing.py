"""Locating a stability crossing in time: bisection between a stable and an unstable state.

Every accepted step gets a negative-eigenvalue count (:class:`CrossingDetector`: screened on the
Newton factor, or exact). On the first step whose count exceeds the previous one, confirmed exactly,
the crossing is bracketed by the last (exactly) stable and the first unstable accepted states. The
bracket is halved by re-solving from the stable end to the midpoint (with the same error-controlled
stepping) until its width is below ``stability.tolerance`` relative to the crossing time. At the two
final ends SLEPc gives lambda_min; the critical time and growth are linear interpolations in
lambda_min between them, and the eigenvector of the crossing eigenvalue at the unstable end is the buckling mode.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from app.onset.wrinkles import band_vertex, mode_wrinkle_count

BAND_MODES = 8  # eigenpairs sampled at the unstable end to locate the minimum of lambda(N)


@dataclass
class Crossing:
    time: float
    growth_mm: float
    applied_strain: float
    mu_bar: float
    wrinkle_count: float
    first_mode_wrinkle_count: float
    lambda_min_before: float
    lambda_min_after: float
    bracket: tuple[float, float]
    negative_eigenvalues: int
    modes: list[dict] = field(default_factory=list)
    bisection_solves: int = 0
    mode: np.ndarray | None = None  # mixed-space array of the buckling mode (local)
    state: np.ndarray | None = None  # mixed-space array of the state at the unstable end
    lo: object = None  # stepper snapshots at the bracket ends (for further crossings)
    hi: object = None
    hi_count: int = 0  # negative eigenvalues at the unstable end

    def as_dict(self) -> dict:
        return {"time": self.time, "growth_mm": self.growth_mm, "growth_um": 1e3 * self.growth_mm,
                "applied_strain": self.applied_strain, "mu_bar": self.mu_bar,
                "wrinkle_count": self.wrinkle_count, "first_mode_wrinkle_count": self.first_mode_wrinkle_count,
                "lambda_min_before": self.lambda_min_before,
                "lambda_min_after": self.lambda_min_after, "bracket": list(self.bracket),
                "negative_eigenvalues": self.negative_eigenvalues, "modes": self.modes,
                "bisection_solves": self.bisection_solves,
                "discretization_error": None}  # filled by stability.error_estimate / hydrobuckle converge


class CrossingDetector:
    """The per-step stability verdict, and a verified bracket when a new negative eigenvalue appears.

    ``screening = "exact"``: the inertia of K (converged state, zero increment, ``stability.tau``)
    after every step, one LDL^T factorization each.

    ``screening = "newton"``: every step reads the inertia of the Newton solver's last LDL^T factor,
    which that step computed anyway (K one Newton update short of the converged state, with the
    step's own tau): the stability test costs no factorization. It is a screen only: an increase is
    confirmed by the exact test at that step (a false alarm is logged and the run goes on), and the
    stable end of the bracket is verified by exact tests, walking back through the last ``keep``
    accepted states and, past them, to the last state verified exactly. The bracket that the
    bisection refines is therefore the same as with exact tests on every step, up to a screen that
    reports late (then the bracket is wider, never wrong).
    Steps without a factorization of their own (zero Newton iterations, or ``solver.factorization =
    "lu"``) are tested exactly."""

    def __init__(self, stepper, analyzer, screening: str = "newton", keep: int = 4, log=None):
        self.stepper, self.analyzer, self.screening = stepper, analyzer, screening
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
        """Exact negative-eigenvalue count of the initial state."""
        count = self._exact()
        self.verified = self.stepper.snapshot()
        self.recent.append(self.verified)
        return count

    def screen(self) -> int:
        """Negative-eigenvalue count of the state just accepted (screened or exact)."""
        if self.screening == "newton":
            inertia = self.stepper.solver.factor_inertia()
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


def locate_crossing(stepper, analyzer, snap_stable, snap_unstable, base_count: int, tol: float,
                    n_modes: int, log=None) -> Crossing:
    """Bisect the time bracket of a new negative eigenvalue; leaves the stepper at the unstable end."""
    log = log or (lambda msg: None)
    p = stepper.p
    lo, hi = snap_stable, snap_unstable
    solves = 0
    while hi.t - lo.t > tol * hi.t:
        mid_t = 0.5 * (lo.t + hi.t)
        stepper.restore(lo)
        while stepper.t < mid_t - 1e-14 * mid_t:
            stepper.advance(until=mid_t)
            solves += 1
        nneg = analyzer.inertia()[0]
        if nneg > base_count:
            hi = stepper.snapshot()
        else:
            lo = stepper.snapshot()
        log(f"  bisection: bracket [{lo.t:.6f}, {hi.t:.6f}] s")

    def end_data(snap, n):
        stepper.restore(snap)
        return p.growth(), analyzer.eigenpairs(n)

    g_lo, pairs_lo = end_data(lo, base_count + 1)
    g_hi, pairs_hi = end_data(hi, max(n_modes, base_count + BAND_MODES))
    hi_count = analyzer.inertia()[0]
    lam_lo = pairs_lo[base_count].value if len(pairs_lo) > base_count else float("nan")
    lam_hi = pairs_hi[base_count].value if len(pairs_hi) > base_count else float("nan")
    if np.isfinite(lam_lo) and np.isfinite(lam_hi) and lam_lo > 0 > lam_hi:
        frac = lam_lo / (lam_lo - lam_hi)
    else:
        frac = 0.5
    t_c = lo.t + frac * (hi.t - lo.t)
    g_c = g_lo + frac * (g_hi - g_lo)
    mode_pair = pairs_hi[min(base_count, len(pairs_hi) - 1)]
    counts = [mode_wrinkle_count(p, e.vector) for e in pairs_hi]
    modes = [{"eigenvalue": e.value, "wrinkle_count": n} for e, n in zip(pairs_hi, counts)][:n_modes]
    first = counts[min(base_count, len(counts) - 1)]
    step = 1.0 if p.geo.wrinkles == "around" else 0.5
    vertex = band_vertex(counts[base_count:], [e.value for e in pairs_hi[base_count:]], step=step)
    crossing = Crossing(
        time=t_c, growth_mm=g_c, applied_strain=p.loading.applied_strain(t_c), mu_bar=p.loading.mu_bar(t_c),
        wrinkle_count=vertex if vertex is not None else first, first_mode_wrinkle_count=first,
        lambda_min_before=lam_lo,
        lambda_min_after=lam_hi, bracket=(lo.t, hi.t), negative_eigenvalues=base_count + 1, modes=modes,
        bisection_solves=solves, mode=mode_pair.vector, state=p.state.x.array.copy(), lo=lo, hi=hi,
        hi_count=hi_count)
    return crossing
