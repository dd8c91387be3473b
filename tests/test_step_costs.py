"""summary.json's ``step_cost`` (app/workflows/step_costs.py): each accepted step's wall time sorted into the
run's parts, against hand sums of a made-up run, and in a real branch run against its history."""

from __future__ import annotations

import statistics

import pytest

from app.workflows.step_costs import SETTLING, StepCosts


def test_steps_are_sorted_into_before_branch_settling_and_contact():
    """Three steps before the onset (1 s each, and 0.5 s of stability test after each step), a switch, five branch steps (2, 2, 2, then 4 and 6 s in
    contact), a second switch and two more branch steps (3 s, 5 s in contact): the parts' counts and means by
    hand, the first SETTLING steps after each switch left out of the settled part."""
    costs = StepCosts()
    for _ in range(3):
        costs.add(1.0, 0.5, 4, False, False, 0)
    for wall, touch in ((2.0, False), (2.0, False), (2.0, False), (4.0, True), (6.0, True)):
        costs.add(wall, 0.5, 6, True, touch, 1)
    costs.add(3.0, 0.5, 8, True, False, 2)
    costs.add(5.0, 0.5, 8, True, True, 2)
    s = costs.summary()
    assert s["before_branch"] == {"steps": 3, "mean_s": 1.0, "median_s": 1.0, "mean_with_test_s": 1.5,
                                  "newton_its_mean": 4}
    assert s["branch"]["steps"] == 7 and s["branch"]["mean_s"] == pytest.approx(24 / 7)
    assert s["branch_settled"]["steps"] == 2 and s["branch_settled"]["mean_s"] == pytest.approx(5.0)  # 4 and 6 s
    assert SETTLING == 3
    assert s["branch_in_contact"]["mean_s"] == pytest.approx(5.0)
    assert s["branch_without_contact"]["mean_s"] == pytest.approx(9 / 4)
    assert s["branch_over_before"] == pytest.approx(24 / 7)
    assert s["contact_over_without"] == pytest.approx(5.0 / (9 / 4))
    assert s["branch"]["median_s"] == statistics.median([2, 2, 2, 4, 6, 3, 5])
    assert s["settled_in_contact"]["steps"] == 2 and "settled_without_contact" not in s  # 4 and 6 s only
    assert "settled_contact_over_without" not in s


def test_a_run_without_a_branch_reports_its_steps_only():
    costs = StepCosts()
    assert costs.summary() == {}
    costs.add(0.5, 0.0, 3, False, False, 0)
    s = costs.summary()
    assert set(s) == {"before_branch", "settling_steps"} and s["before_branch"]["steps"] == 1
