"""What a run does after a stability crossing: an explicit policy instead of two loose flags.

``stability.stop_at_onset = true`` is :attr:`AfterCrossing.STOP`; ``false`` is
:attr:`AfterCrossing.CONTINUE`: stay on the fundamental (unbuckled) path and record later crossings
until ``stability.max_crossings``. Following the buckled branch (post-buckling) will be a third member.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class AfterCrossing(enum.Enum):
    STOP = "stop"
    CONTINUE = "continue"  # on the fundamental path


@dataclass(frozen=True)
class CrossingPolicy:
    after: AfterCrossing = AfterCrossing.STOP
    max_crossings: int = 20

    @classmethod
    def from_flags(cls, stop_at_onset: bool, max_crossings: int) -> CrossingPolicy:
        return cls(AfterCrossing.STOP if stop_at_onset else AfterCrossing.CONTINUE, max_crossings)

    def stops(self, crossings: int) -> bool:
        """Whether the run ends once ``crossings`` crossings are recorded."""
        return self.after is AfterCrossing.STOP or crossings >= self.max_crossings
