"""Step-size control of the adaptive backward-Euler integrator, as plain arithmetic.

Kept apart from :mod:`app.solvers.stepping` (which solves) so the rules can be read and tested on
their own, with hand values and no mesh:

- after an accepted step with error estimate ``err``: dt_next = dt * clamp(0.9 sqrt(tol/err), 0.2, 2),
  clamped to [dt_min, dt_max]; err = 0 grows by 2; no estimate (first step, after a loading kink)
  leaves dt unchanged;
- a step with err > tol (and dt > dt_min) is rejected and retried with dt * max(0.2, 0.9 sqrt(tol/err)),
  not below dt_min;
- a step whose Newton iteration diverged is cut back by 4; below dt_min the run has failed.

With ``adaptive = False`` every step tries ``dt_fixed`` and only the cut-back applies.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SAFETY = 0.9
SHRINK_MIN = 0.2
GROW_MAX = 2.0
CUTBACK = 0.25


@dataclass(frozen=True)
class StepControl:
    tolerance: float
    dt_min: float
    dt_max: float
    adaptive: bool = True
    dt_fixed: float | None = None  # the step of a non-adaptive run

    def first_try(self, dt_next: float) -> float:
        """The step size a new step starts with (before clipping at kinks and the end)."""
        dt = dt_next if self.adaptive else self.dt_fixed
        return min(dt, self.dt_max)

    def rejects(self, dt: float, err: float) -> bool:
        """Whether an accepted Newton solve must be retried smaller for its error."""
        return self.adaptive and math.isfinite(err) and err > self.tolerance and dt > self.dt_min

    def shrink(self, dt: float, err: float) -> float:
        """The retry step after a rejection for ``err`` > tolerance."""
        return max(dt * max(SHRINK_MIN, SAFETY * math.sqrt(self.tolerance / err)), self.dt_min)

    def cut_back(self, dt: float) -> float:
        """The retry step after a Newton divergence (the caller fails the run below dt_min)."""
        return dt * CUTBACK

    def proposal(self, dt: float, err: float) -> float:
        """The next step after an accepted step of size dt with estimate err (NaN: none)."""
        if math.isfinite(err) and err > 0:
            factor = min(GROW_MAX, max(SHRINK_MIN, SAFETY * math.sqrt(self.tolerance / err)))
        elif math.isfinite(err):
            factor = GROW_MAX
        else:
            factor = 1.0  # no estimate yet (first step, or just after a kink)
        return min(self.dt_max, max(self.dt_min, dt * factor))
