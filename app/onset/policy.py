"""What a run does after a stability crossing: an explicit policy instead of two loose flags.

``stability.after_onset`` names it: ``"stop"`` is :attr:`AfterCrossing.STOP`; ``"fundamental"`` is
:attr:`AfterCrossing.CONTINUE`: stay on the fundamental (unbuckled) path and record later crossings until
``stability.max_crossings``; ``"branch"`` is :attr:`AfterCrossing.BRANCH`: perturb the state along the
crossing's mode and follow the buckled branch with a minimizing step solver (:mod:`app.onset.branching`),
recording the crossings found on it. Unset, it follows the older ``stability.stop_at_onset`` (true: stop,
false: fundamental).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class AfterCrossing(enum.Enum):
    STOP = "stop"
    CONTINUE = "fundamental"  # on the fundamental path
    BRANCH = "branch"  # on the buckled branch


@dataclass(frozen=True)
class CrossingPolicy:
    after: AfterCrossing = AfterCrossing.STOP
    max_crossings: int = 20

    @classmethod
    def from_flags(cls, stop_at_onset: bool, max_crossings: int, after_onset: str | None = None) -> CrossingPolicy:
        if after_onset is None:
            after_onset = "stop" if stop_at_onset else "fundamental"
        return cls(AfterCrossing(after_onset), max_crossings)

    @property
    def branches(self) -> bool:
        return self.after is AfterCrossing.BRANCH

    def stops(self, crossings: int) -> bool:
        """Whether the run ends once ``crossings`` crossings are recorded."""
        return self.after is AfterCrossing.STOP or crossings >= self.max_crossings
