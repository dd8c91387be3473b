"""Locating one stability crossing in time: bisection between a stable and an unstable state.

The bracket (the last exactly stable and the first unstable accepted state, from
:class:`app.onset.screening.StabilityScreen`) is halved by re-solving from the stable end to the
midpoint (with the same error-controlled stepping) until its width is below ``tolerance`` relative
to the crossing time. At the two final ends SLEPc gives lambda_min; the critical time and growth are
linear interpolations in lambda_min between them, and the eigenvector of the crossing eigenvalue at
the unstable end is the buckling mode. The wrinkle count N_c is the vertex of lambda(N) over the
eigenpairs nearest zero there (:func:`band_vertex`).
"""

from __future__ import annotations

import math

import numpy as np

from app.model.surface import mode_wave_vector, mode_wrinkle_count, shape_of
from app.onset.crossing import Crossing

BAND_MODES = 8  # eigenpairs sampled at the unstable end to locate the minimum of lambda(N)


class Bisection:
    """Bisects crossing brackets of ``problem`` advanced by ``stepper``, tested by ``analyzer``.

    The problem is only read (growth, loading, state, wrinkle counts); the stepper is moved with
    ``restore``/``advance_to`` and left at the unstable end."""

    def __init__(self, problem, stepper, analyzer, *, tolerance: float, n_modes: int, log=None):
        self.problem, self.stepper, self.analyzer = problem, stepper, analyzer
        self.tolerance, self.n_modes = tolerance, n_modes
        self.log = log or (lambda msg: None)

    def locate(self, stable, unstable, *, base_count: int) -> Crossing:
        """The crossing of eigenvalue number ``base_count`` (0-based) between two snapshots."""
        stepper, analyzer = self.stepper, self.analyzer
        lo, hi = stable, unstable
        solves = 0
        while hi.t - lo.t > self.tolerance * hi.t:
            stepper.restore(lo)
            solves += stepper.advance_to(0.5 * (lo.t + hi.t))
            if analyzer.inertia()[0] > base_count:
                hi = stepper.snapshot()
            else:
                lo = stepper.snapshot()
            self.log(f"  bisection: bracket [{lo.t:.6f}, {hi.t:.6f}] s")
        return self._crossing(lo, hi, base_count, solves)

    def _end(self, snap, n: int):
        self.stepper.restore(snap)
        return self.problem.growth(), self.analyzer.eigenpairs(n)

    def _crossing(self, lo, hi, base_count: int, solves: int) -> Crossing:
        p, n_modes = self.problem, self.n_modes
        g_lo, pairs_lo = self._end(lo, base_count + 1)
        g_hi, pairs_hi = self._end(hi, max(n_modes, base_count + BAND_MODES))
        hi_count = self.analyzer.inertia()[0]
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
        for entry, e in zip(modes, pairs_hi):  # 3D: each mode's wave vector, half-waves along x and z
            wave = mode_wave_vector(p, e.vector)
            if wave is not None:
                entry["wave_vector"] = list(wave)
        first = counts[min(base_count, len(counts) - 1)]
        vertex = band_vertex(counts[base_count:], [e.value for e in pairs_hi[base_count:]],
                             step=shape_of(p).count_step)
        return Crossing(
            time=t_c, growth_mm=g_c, applied_strain=p.loading.applied_strain(t_c), mu_bar=p.loading.mu_bar(t_c),
            wrinkle_count=vertex if vertex is not None else first, first_mode_wrinkle_count=first,
            lambda_min_before=lam_lo, lambda_min_after=lam_hi, bracket=(lo.t, hi.t),
            negative_eigenvalues=base_count + 1, modes=modes, bisection_solves=solves, mode=mode_pair.vector,
            state=p.state.x.array.copy(), lo=lo, hi=hi, hi_count=hi_count,
            multiplicity=max(1, hi_count - base_count),
            crossing_modes=[e.vector for e in pairs_hi[base_count:]])


def band_vertex(counts, eigenvalues, step: float = 0.5) -> float | None:
    """Wrinkle count at the minimum of the dispersion curve lambda(N) sampled by several modes.

    Near a wrinkling onset the eigenvalues of neighbouring wrinkle counts are nearly equal, so which
    of them crosses zero first is decided by tiny details. Around the count n0 with the lowest
    eigenvalue (equal lowest eigenvalues: the smaller count), a parabola through the lowest
    eigenvalue of each count within n0 +- 2 steps (at least one on each side) locates the minimum of
    lambda(N). The result is the count (a multiple of ``step``) nearest to the parabola's vertex,
    with the vertex kept within one step of n0, so the answer is n0 or one of its neighbours. A
    vertex halfway between two counts (to 1e-9 of a step, e.g. data mirrored about that point)
    goes to the one nearer n0, i.e. to n0 itself, whatever the parity of n0 / step. Far-away counts
    (global modes, the other branch of the dispersion curve) are left out of the fit.
    None if no such fit exists."""
    lowest: dict[float, float] = {}
    for n, lam in zip(counts, eigenvalues):
        if n is None or not np.isfinite(lam) or n <= 0:
            continue
        lowest[n] = min(lam, lowest.get(n, np.inf))
    if not lowest:
        return None
    n0 = min(lowest, key=lambda n: (lowest[n], n))
    near = sorted(n for n in lowest if abs(n - n0) <= 2 * step + 1e-9)
    if len(near) < 3 or min(near) >= n0 or max(near) <= n0:
        return None
    a, b, _ = np.polyfit(near, [lowest[n] for n in near], 2)
    if a <= 0:
        return None
    offset = min(max(-b / (2 * a) - n0, -step), step) / step  # vertex - n0 in steps, in [-1, 1]
    k = math.floor(abs(offset) + 0.5 - 1e-9)  # nearest whole step; a tie rounds towards n0
    return n0 + math.copysign(k * step, offset)
