"""Step-size control of the adaptive backward-Euler integrator, as plain arithmetic.

Kept apart from :mod:`app.solvers.stepping` (which solves) so the rules can be read and tested on
their own, with hand values and no mesh:

- after an accepted step with error estimate ``err``: dt_next = dt * clamp(f, 0.2, 2), clamped to
  [dt_min, dt_max], with f = 0.9 sqrt(tol/err) (``controller = "elementary"``); err = 0 grows by 2; no
  estimate (first step, after a loading kink) leaves dt unchanged;
- ``controller = "predictive"`` (the default) also follows the error's trend. Backward Euler's local error
  is err ~ C dt^2; when the error constant C = err/dt^2 grew over the last two accepted steps by
  rho = C_n / C_(n-1) > 1, the next step expects it to grow by rho again, and f is divided by sqrt(rho).
  This is Gustafsson's predictive controller, dt_next = 0.9 dt (dt/dt_prev) (tol/err)^(1/2)
  (err_prev/err)^(1/2), used only while C grows: while it falls the elementary rule is kept, so a
  step never grows faster than it. Without a previous accepted step's estimate (the first steps, after a
  kink) it is the elementary rule;
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
    controller: str = "predictive"  # or "elementary" (the I controller alone)

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

    def proposal(self, dt: float, err: float, prev: tuple[float, float] | None = None) -> float:
        """The next step after an accepted step of size dt with estimate err (NaN: none); ``prev``: the
        (dt, err) of the accepted step before it, None or a NaN err where there is none."""
        if math.isfinite(err) and err > 0:
            factor = SAFETY * math.sqrt(self.tolerance / err)
            rho = self.trend(dt, err, prev)
            if rho > 1.0:
                factor /= math.sqrt(rho)
            factor = min(GROW_MAX, max(SHRINK_MIN, factor))
        elif math.isfinite(err):
            factor = GROW_MAX
        else:
            factor = 1.0  # no estimate yet (first step, or just after a kink)
        return min(self.dt_max, max(self.dt_min, dt * factor))

    def trend(self, dt: float, err: float, prev: tuple[float, float] | None) -> float:
        """rho = (err/dt^2) / (err_prev/dt_prev^2), the growth of the error constant over the last step; 1
        where the elementary rule applies (controller "elementary", no previous estimate)."""
        if self.controller != "predictive" or prev is None:
            return 1.0
        dt_prev, err_prev = prev
        if not (math.isfinite(err_prev) and err_prev > 0 and dt_prev > 0):
            return 1.0
        return (err / dt**2) / (err_prev / dt_prev**2)


@dataclass(frozen=True)
class TimeSettings:
    """The [time] table: end time, step-size limits and control."""

    end: float
    dt_initial: float
    dt_min: float
    dt_max: float
    tolerance: float
    adaptive: bool = True
    max_steps: int = 100000
    stop_at_equilibrium: float = 0.0  # threshold of the relative uptake rate (0 = off)
    controller: str = "predictive"  # the adaptive step's rule (app.solvers.step_control)

    def step_control(self) -> StepControl:
        return StepControl(self.tolerance, self.dt_min, self.dt_max, self.adaptive, self.dt_initial,
                           self.controller)
