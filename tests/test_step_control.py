"""The step-size controller (app/solvers/step_control.py) against hand values of the documented rules
(docs/model.md, "Time stepping"): dt_next = dt * clamp(0.9 sqrt(tol/err), 0.2, 2) within [dt_min, dt_max],
rejection retries, the cut-back by 4, and no estimate -> dt unchanged; the predictive rule (the factor
divided by sqrt(rho) while the error constant err/dt^2 grows by rho) against hand values and, on a model
error whose constant grows exponentially in time, against the rejections of the elementary rule. No mesh,
no solver."""

import math

import pytest

from app.solvers.step_control import StepControl

TOL = 1e-4
CTRL = StepControl(tolerance=TOL, dt_min=1e-6, dt_max=1.0)  # the default controller: predictive
ELEMENTARY = StepControl(tolerance=TOL, dt_min=1e-6, dt_max=1.0, controller="elementary")


@pytest.mark.parametrize("err, dt_next", [
    (1e-4, 0.09),  # err = tol: 0.9
    (4e-4, 0.045),  # 0.9 sqrt(1/4) = 0.45
    (0.81e-4 / 4, 0.2),  # 0.9 sqrt(4/0.81) = 2: the growth limit exactly
    (1e-8, 0.2),  # 0.9 sqrt(1e4) = 90 -> clamped to 2
    (1e-2, 0.02),  # 0.9 sqrt(1e-2) = 0.09 -> clamped to 0.2
    (0.0, 0.2),  # a zero estimate grows by the limit
])
def test_proposal_after_an_accepted_step(err, dt_next):
    assert CTRL.proposal(0.1, err) == pytest.approx(dt_next, rel=1e-14)


def test_no_estimate_leaves_the_step_unchanged():
    assert CTRL.proposal(0.1, float("nan")) == 0.1


def test_proposal_is_clamped_to_dt_min_and_dt_max():
    assert CTRL.proposal(0.7, 1e-8) == 1.0  # 1.4 -> dt_max
    assert CTRL.proposal(2e-6, 1.0) == 1e-6  # 4e-7 -> dt_min
    assert CTRL.proposal(5.0, float("nan")) == 1.0  # even without an estimate


def test_rejection_and_retry():
    assert not CTRL.rejects(0.1, TOL)  # err = tol is accepted
    assert CTRL.rejects(0.1, 4e-4)
    assert not CTRL.rejects(0.1, float("nan"))
    assert not CTRL.rejects(1e-6, 1.0)  # at dt_min nothing smaller is tried
    assert CTRL.shrink(0.1, 4e-4) == pytest.approx(0.045, rel=1e-14)
    assert CTRL.shrink(0.1, 1.0) == pytest.approx(0.02, rel=1e-14)  # 0.9 sqrt(1e-4) = 0.009 -> 0.2
    assert CTRL.shrink(2e-6, 1.0) == 1e-6  # not below dt_min


def test_cut_back_by_four():
    assert CTRL.cut_back(0.1) == 0.025
    assert CTRL.cut_back(CTRL.cut_back(0.1)) == 0.00625


def test_fixed_steps_try_dt_fixed_and_are_never_rejected():
    fixed = StepControl(tolerance=TOL, dt_min=1e-6, dt_max=0.5, adaptive=False, dt_fixed=0.3)
    assert fixed.first_try(0.01) == 0.3  # the adaptive proposal is ignored
    assert not fixed.rejects(0.3, 1.0)
    assert StepControl(TOL, 1e-6, 0.2, adaptive=False, dt_fixed=0.3).first_try(0.01) == 0.2  # dt_max
    assert CTRL.first_try(0.05) == 0.05 and CTRL.first_try(3.0) == 1.0


def test_documented_formula_over_a_range_of_estimates():
    for k in range(-12, 3):
        err = 10.0 ** k * TOL
        expected = 0.1 * min(2.0, max(0.2, 0.9 * math.sqrt(1 / 10.0 ** k)))
        assert CTRL.proposal(0.1, err) == pytest.approx(min(1.0, max(1e-6, expected)), rel=1e-14)


def test_predictive_rule_against_hand_values():
    # the error constant err/dt^2 grew by 4 over the last step: the factor 0.9 is halved
    assert CTRL.proposal(0.1, 1e-4, prev=(0.1, 0.25e-4)) == pytest.approx(0.045, rel=1e-14)
    # the same growth with different step sizes: rho = (1e-4/0.1^2) / (0.25e-4/0.05^2) = 1
    assert CTRL.proposal(0.1, 1e-4, prev=(0.05, 0.25e-4)) == pytest.approx(0.09, rel=1e-14)
    # rho = (1e-4/0.01) / (1e-4/0.04) = 4 with the previous step twice as long
    assert CTRL.proposal(0.1, 1e-4, prev=(0.2, 1e-4)) == pytest.approx(0.045, rel=1e-14)
    # a falling error constant keeps the elementary rule (it never grows a step faster)
    assert CTRL.proposal(0.1, 1e-4, prev=(0.1, 4e-4)) == pytest.approx(0.09, rel=1e-14)
    # the clamps apply after the trend: rho = 1e4 would give 0.009
    assert CTRL.proposal(0.1, 1e-4, prev=(0.1, 1e-8)) == pytest.approx(0.02, rel=1e-14)
    # no usable previous estimate: the elementary rule
    for prev in (None, (0.1, float("nan")), (0.1, 0.0)):
        assert CTRL.proposal(0.1, 4e-4, prev=prev) == pytest.approx(0.045, rel=1e-14)
    # the elementary controller ignores the trend
    assert ELEMENTARY.proposal(0.1, 1e-4, prev=(0.1, 0.25e-4)) == pytest.approx(0.09, rel=1e-14)
    assert CTRL.trend(0.1, 1e-4, (0.1, 0.25e-4)) == pytest.approx(4.0, rel=1e-14)
    assert ELEMENTARY.trend(0.1, 1e-4, (0.1, 0.25e-4)) == 1.0


def march(ctrl: StepControl, growth_time: float, t_end: float, dt0: float = 1e-3) -> tuple[int, int]:
    """Step a model whose local error is err = C(t) dt^2, C(t) = exp(t / growth_time) (the constant taken
    at the step's end), with ``ctrl``'s accept/reject/proposal exactly as the stepper does; returns the
    (accepted, rejected) steps to t_end."""
    t, dt, prev, accepted, rejected = 0.0, dt0, None, 0, 0
    while t < t_end:
        dt = min(dt, t_end - t)
        err = math.exp((t + dt) / growth_time) * dt**2
        if ctrl.rejects(dt, err):
            rejected += 1
            dt = ctrl.shrink(dt, err)
            continue
        accepted += 1
        t += dt
        dt, prev = ctrl.proposal(dt, err, prev), (dt, err)
    return accepted, rejected


def test_predictive_rule_removes_the_rejections_of_a_growing_error():
    """With C growing by exp(dt/T) per step, the elementary rule's step (chosen for the last C with the
    margin 0.81 of the safety factor) is rejected whenever exp(dt/T) > 1/0.81; the predictive rule expects
    the growth and is never rejected, for at most a few more steps."""
    ctrl = StepControl(tolerance=TOL, dt_min=1e-9, dt_max=1.0)
    elem = StepControl(tolerance=TOL, dt_min=1e-9, dt_max=1.0, controller="elementary")
    growth = 0.01  # T: with tol 1e-4 the steps are about 0.01 exp(-t/2T), so exp(dt/T) reaches e early on
    acc_e, rej_e = march(elem, growth, 0.1)
    acc_p, rej_p = march(ctrl, growth, 0.1)
    assert rej_e >= 5 and rej_p == 0
    assert acc_p + rej_p < acc_e + rej_e  # fewer solves in all
    # a constant error constant: both rules take the same steps
    assert march(ctrl, 1e12, 0.1) == march(elem, 1e12, 0.1)
