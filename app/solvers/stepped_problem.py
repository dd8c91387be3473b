"""What goes into the time stepper and what comes out of it: :class:`SteppedProblem`, an evolution as forms,
conditions, index sets and the model's hooks (accept a converged step, its observables, its uptake);
:class:`StepRecord`, one accepted state's history row; :class:`Snapshot`, what resumes the stepping; and how a
step fails (:class:`StepFailure`, :class:`ModelLimit`, :class:`LostStability`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np


@dataclass
class StepRecord:
    """One accepted state: the stepper's own columns, the model's (``values``: the SteppedProblem's
    ``observables`` at that time, :mod:`app.model.history`) and what others add (``extra``: the onset
    tracker's). A model column reads as an attribute too (``rec.growth_mm``)."""

    step: int
    time: float
    dt: float
    newton_its: int
    inflow: float  # the fluid volume that entered since t = 0 (the SteppedProblem's influx, step by step)
    error_estimate: float = float("nan")
    values: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    COLUMNS = ("step", "time", "dt", "newton_its", "inflow", "error_estimate")  # the stepper's own

    def __getattr__(self, name: str):
        if name.startswith("__") or name in ("values", "extra"):  # copies and pickles look before __init__
            raise AttributeError(name)
        try:
            return self.values[name]
        except KeyError:
            raise AttributeError(f"StepRecord has no column {name!r}") from None

    def row(self) -> dict:
        """The history row: every column by name."""
        return {**{c: getattr(self, c) for c in self.COLUMNS}, **self.values, **self.extra}


@dataclass
class Snapshot:
    """Everything needed to resume time stepping from an accepted state."""

    state: np.ndarray
    rate_u: np.ndarray
    dQ_prev: np.ndarray
    dt_prev: float
    history_valid: bool
    t: float
    step: int
    inflow: float
    dt_next: float
    err_prev: float = float("nan")  # the last accepted step's error estimate (NaN: none since a kink)

    #: the scalars a checkpoint stores with the arrays (in this order)
    SCALARS: ClassVar[tuple[str, ...]] = ("dt_prev", "history_valid", "t", "step", "inflow", "dt_next",
                                          "err_prev")

    def scalars(self) -> dict:
        return {k: getattr(self, k) for k in self.SCALARS}

    @classmethod
    def from_parts(cls, state: np.ndarray, rate_u: np.ndarray, dQ_prev: np.ndarray, scalars: dict) -> Snapshot:
        """``scalars`` of a checkpoint written before err_prev was stored resume without it (NaN: the next
        step's proposal follows the elementary rule once)."""
        values = {k: scalars[k] for k in cls.SCALARS if k in scalars}
        return cls(state, rate_u, dQ_prev, **values)


@dataclass(frozen=True)
class SteppedProblem:
    """What the stepper advances, as forms, conditions, index sets and the model's hooks (the stepper reads
    nothing else; :func:`app.factory.time_stepper` fills it from a problem)."""

    energy: Any  # compiled forms of the incremental potential Pi_tau(u, dQ), its residual and Hessian
    residual: Any
    hessian: Any
    bcs: list  # Dirichlet conditions on the unknown
    w: Any  # the unknown (u, dQ) of the current step (a Function of the mixed space)
    state: Any  # the converged state (u_n, Q_n), same space
    u_dofs: np.ndarray  # the mixed space's displacement and flux dofs (local indices)
    q_dofs: np.ndarray
    comm: Any
    content_change: Any  # app.model.operators.CellContentChange: the error estimate's cell averages
    kinks: tuple  # times where the loading's rate jumps
    diffusion: bool  # whether fluid moves (tau enters the potential)
    set_time: Callable[[float, float], None]  # (t, tau): the loading at t for a step of size tau
    influx: Callable[[], float]  # fluid volume entering through the permeable surface in the current step
    observables: Callable[[float], dict]  # the converged state's history columns at time t (StepRecord.values)
    # the converged step (in ``w``) becomes the state (the model's update: u_n = u, Q_n += dQ)
    accept: Callable[[], None]
    extra: Any = None  # an energy term that is not a form (self-contact; NewtonSolver's ``extra``), or None
    uptake: str | None = None  # the observable whose relative rate time.stop_at_equilibrium tests (None: never)


class StepFailure(RuntimeError):
    """The step could not be completed even at the smallest allowed step size."""


class ModelLimit(StepFailure):
    """The branch reached a state the model cannot represent (:mod:`app.onset.contact`): the run ends with
    the limit's status ("contact" or "inverted")."""

    def __init__(self, limit, t: float, accepted: float | None = None):
        """``t``: the state's time; ``accepted``: for the iterates of a step that failed, the time of the last
        accepted state (which passed the checks)."""
        self.limit, self.t = limit, t
        when = (f"at t = {t:.6g} s" if accepted is None else
                f"in the Newton iterates of two attempts of the step after t = {accepted:.6g} s (the last one to "
                f"t = {t:.6g} s; the accepted state at {accepted:.6g} s passed the checks)")
        super().__init__(f"{limit.detail} {when}: {limit.consequence}")


class LostStability(StepFailure):
    """Newton failed twice in a row for the same reason and K at the last converged state is
    indefinite: the fundamental path cannot be followed (see :meth:`app.solvers.stepping.TimeStepper.advance`)."""
