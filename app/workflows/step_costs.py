"""What a step costs on each part of a run (docs/performance.md): the wall time of every accepted step (its
attempts, cut-backs and solves) and of the stability test of its state that follows (not the location of a
crossing: bisection, the switch), sorted into the steps before a branch switch and those on a followed branch,
and on the branch into the steps whose state touches itself and those that touch nowhere. summary.json's
``step_cost`` block: the count, mean and median of
each part with their Newton iterations, and the ratios a user compares (a branch step against a step before
the onset; a step in contact against a branch step without contact). The first SETTLING steps after each
switch leave a saddle and are reported apart.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

SETTLING = 3  # steps after a branch switch that still leave its saddle (reported apart)


@dataclass
class StepCosts:
    """The accepted steps' wall times, as the run loop tells them (:meth:`add`)."""

    #: (solve s, test s, Newton its, on a branch, in contact, steps since the last switch or -1)
    steps: list[tuple[float, float, int, bool, bool, int]] = field(default_factory=list)
    _switches: int = 0
    _since: int | None = None  # steps since the last switch (None: no switch yet)

    def add(self, seconds: float, test_seconds: float, newton_its: int, on_branch: bool, in_contact: bool,
            switches: int) -> None:
        """One accepted step: its wall time, its stability test's, its Newton iterations, whether it was a branch
        step (the stepper minimizing), whether its state touches itself, and the branch switches made before
        it."""
        if switches != self._switches:
            self._switches, self._since = switches, 0
        since = self._since if on_branch and self._since is not None else -1
        self.steps.append((float(seconds), float(test_seconds), int(newton_its), bool(on_branch), bool(in_contact),
                           since))
        if self._since is not None and on_branch:
            self._since += 1

    @staticmethod
    def _part(steps) -> dict | None:
        if not steps:
            return None
        walls = [s[0] for s in steps]
        return {"steps": len(steps), "mean_s": statistics.mean(walls), "median_s": statistics.median(walls),
                "mean_with_test_s": statistics.mean(s[0] + s[1] for s in steps),
                "newton_its_mean": statistics.mean(s[2] for s in steps)}

    def summary(self) -> dict:
        """summary.json's ``step_cost``: each part's count, mean and median wall time of the step [s], the mean
        with its stability test, the mean Newton iterations (a part without steps is left out), and the ratios
        of the steps' means."""
        before = [s for s in self.steps if not s[3]]
        branch = [s for s in self.steps if s[3]]
        parts = {"before_branch": before, "branch": branch,
                 "branch_settled": [s for s in branch if s[5] >= SETTLING],
                 "branch_without_contact": [s for s in branch if not s[4]],
                 "branch_in_contact": [s for s in branch if s[4]],
                 "settled_without_contact": [s for s in branch if s[5] >= SETTLING and not s[4]],
                 "settled_in_contact": [s for s in branch if s[5] >= SETTLING and s[4]]}
        out = {name: p for name, steps in parts.items() if (p := self._part(steps)) is not None}
        ratios = {"branch_over_before": ("branch", "before_branch"),
                  "settled_branch_over_before": ("branch_settled", "before_branch"),
                  "contact_over_without": ("branch_in_contact", "branch_without_contact"),
                  "settled_contact_over_without": ("settled_in_contact", "settled_without_contact")}
        for name, (a, b) in ratios.items():
            if a in out and b in out and out[b]["mean_s"] > 0:
                out[name] = out[a]["mean_s"] / out[b]["mean_s"]
        return {**out, "settling_steps": SETTLING} if out else {}
