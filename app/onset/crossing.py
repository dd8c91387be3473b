"""A located stability crossing: when, at what growth, with which mode (and its summary entry).

Produced by :class:`app.onset.bisection.Bisection`, recorded by :class:`app.onset.tracker.OnsetTracker`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np


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
    multiplicity: int = 1  # eigenvalues that crossed within the final bracket (equal |k| on a square plate)
    crossing_modes: list | None = None  # mixed-space arrays of the eigenpairs from the new one on (local; mode first)

    #: the arrays a crossing holds only while it is being located: never in a checkpoint
    TRANSIENT = ("mode", "state", "lo", "hi", "crossing_modes")

    def checkpoint_state(self) -> dict:
        """This crossing in a checkpoint's meta (JSON): every field but :attr:`TRANSIENT`."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in self.TRANSIENT}

    @classmethod
    def from_checkpoint(cls, state: dict) -> Crossing:
        return cls(**{**state, "bracket": tuple(state["bracket"])})

    def as_dict(self) -> dict:
        return {"time": self.time, "growth_mm": self.growth_mm, "growth_um": 1e3 * self.growth_mm,
                "applied_strain": self.applied_strain, "mu_bar": self.mu_bar,
                "wrinkle_count": self.wrinkle_count, "first_mode_wrinkle_count": self.first_mode_wrinkle_count,
                "lambda_min_before": self.lambda_min_before,
                "lambda_min_after": self.lambda_min_after, "bracket": list(self.bracket),
                "negative_eigenvalues": self.negative_eigenvalues, "multiplicity": self.multiplicity,
                "modes": self.modes,
                "bisection_solves": self.bisection_solves,
                "discretization_error": None}  # filled by stability.error_estimate / hydrobuckle converge
