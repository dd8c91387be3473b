"""Stability screening with the Newton factor's inertia: same onset as exact tests every step, and the
bracket logic when the screen is late or early (against a scripted eigenvalue history)."""

from dataclasses import dataclass

import pytest
from cases import swelling_case

from app.onset.screening import StabilityScreen
from app.workflows.run import simulate


def test_screened_onset_equals_exact_onset(shared_tmp, comm):
    """Screening changes which factorizations are made, not the answer: identical bracket and g_c."""
    runs = {}
    for mode in ("exact", "newton"):
        cfg = swelling_case(f"stability.screening={mode}")
        runs[mode] = simulate(cfg, shared_tmp / mode, comm)
    exact, screened = runs["exact"], runs["newton"]
    assert exact["status"] == screened["status"] == "buckled"
    assert screened["critical"]["bracket"] == pytest.approx(exact["critical"]["bracket"], rel=1e-12)
    assert screened["critical"]["growth_mm"] == pytest.approx(exact["critical"]["growth_mm"], rel=1e-9)
    assert screened["critical"]["wrinkle_count"] == exact["critical"]["wrinkle_count"]
    steps = screened["steps"]
    assert exact["stability_tests"]["exact_tests"] >= steps + 1
    assert screened["stability_tests"]["screened_steps"] >= steps - 1
    # exact tests left: the initial state, the confirmation, the bracket's stable end, the bisection
    assert screened["stability_tests"]["exact_tests"] <= exact["stability_tests"]["exact_tests"] - steps + 4


@pytest.mark.parametrize("tau, counter", [(10.0, "late_screens"), (1e-5, "false_alarms")])
def test_screen_late_or_early_still_gives_the_exact_onset(shared_tmp, comm, tau, counter):
    """A homogeneous gel (Biot-type surface instability) whose exact test uses a stability.tau far from
    the steps' own: with tau = 10 s the exact K is softer and crosses before the screen (the bracket is
    widened back to an exactly stable state), with 1e-5 s after it (false alarms). Either way g_c is
    the exact-test g_c within the onset tolerance."""
    base = ("material.film.modulus_ratio=1.0", "time.end=3", f"stability.tau={tau}")
    runs = {mode: simulate(swelling_case(*base, f"stability.screening={mode}"), shared_tmp / mode, comm)
            for mode in ("exact", "newton")}
    exact, screened = runs["exact"], runs["newton"]
    assert exact["status"] == screened["status"] == "buckled"
    assert screened["stability_tests"][counter] >= 1  # the case exercises the mechanism it is named for
    tol = exact["config"]["stability"]["tolerance"]
    assert screened["critical"]["growth_mm"] == pytest.approx(exact["critical"]["growth_mm"], rel=tol)
    assert screened["critical"]["time"] == pytest.approx(exact["critical"]["time"], rel=tol)


# --- the bracket logic against a scripted history --------------------------------------------


@dataclass
class Snap:
    t: float


class ScriptedStepper:
    """Integer times 0, 1, 2, ...; the Newton factor's inertia follows ``screen(t)``."""

    def __init__(self, screen):
        self.t = 0.0
        self.solver = self
        self._screen = screen

    def snapshot(self):
        return Snap(self.t)

    def restore(self, snap):
        self.t = snap.t

    def factor_inertia(self):
        return (self._screen(self.t), 0, 1)


class ScriptedAnalyzer:
    def __init__(self, stepper, exact):
        self.stepper, self.exact, self.tested = stepper, exact, []

    def inertia(self):
        self.tested.append(self.stepper.t)
        return (self.exact(self.stepper.t), 0, 1)


def _drive(screen, exact, steps=10, keep=4):
    """Step until the detector confirms a crossing; return (detector, analyzer, bracket)."""
    stepper = ScriptedStepper(screen)
    analyzer = ScriptedAnalyzer(stepper, exact)
    det = StabilityScreen(stepper, analyzer, "newton", keep=keep)
    count = det.start()
    for k in range(1, steps + 1):
        stepper.t = float(k)
        nneg = det.screen()
        if nneg > count:
            bracket = det.confirm(count, nneg)
            if bracket is not None:
                assert stepper.t == k  # left at the unstable end
                return det, analyzer, bracket
        det.accepted(stepper.snapshot())
    return det, analyzer, None


def test_late_screen_widens_the_bracket_back_to_an_exactly_stable_state():
    """Exact crossing at t = 2.5, screen only at 4.5: the bracket is [2, 5], verified exactly."""
    det, analyzer, bracket = _drive(screen=lambda t: int(t > 4.5), exact=lambda t: int(t > 2.5))
    nneg, lo, hi = bracket
    assert (nneg, lo.t, hi.t) == (1, 2.0, 5.0)
    assert analyzer.tested == [0.0, 5.0, 4.0, 3.0, 2.0]


def test_screen_late_beyond_the_kept_states_falls_back_to_the_last_verified_state():
    det, analyzer, bracket = _drive(screen=lambda t: int(t > 7.5), exact=lambda t: int(t > 0.5), keep=3)
    nneg, lo, hi = bracket
    assert (lo.t, hi.t) == (0.0, 8.0)


def test_early_screen_is_a_false_alarm_confirmed_later():
    """Screen at 1.5, exact at 3.5: step 2 and 3 are false alarms; the bracket is [3, 4]."""
    det, analyzer, bracket = _drive(screen=lambda t: int(t > 1.5), exact=lambda t: int(t > 3.5))
    nneg, lo, hi = bracket
    assert (lo.t, hi.t) == (3.0, 4.0)
    assert det.false_alarms == 2
