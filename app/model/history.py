"""What history.csv records of each converged state: groups of columns, each registered once.

A group (:class:`Observables`) names its columns and computes them together from a problem's converged state at
time t (one surface gather gives both the amplitude and the wrinkle count); ``applies`` says whether a problem
has them (the contact columns only with self-contact). :func:`record` is what the time stepper calls for each
accepted state (through :class:`app.solvers.stepping.SteppedProblem`'s ``observables`` hook), :func:`columns` what
the result writer lists. The time stepper adds its own columns (step, time, dt, Newton iterations, inflow,
error estimate) and the onset tracker its own (the inertia, lambda_min); neither knows these.

A new column is one :class:`Observables` and one ``HISTORY.register(...)`` line, in this file or any module
(tests/test_extensions.py registers one from test code).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from app.registry import Registry


def _always(problem) -> bool:
    return True


@dataclass(frozen=True)
class Observables:
    """Columns of history.csv computed together: ``values(problem, t)`` -> {column: float} of the converged
    state (``problem.state``) at time t, for every problem where ``applies(problem)``. Collective: called on
    every rank, it returns the same values on each."""

    name: str
    columns: tuple[str, ...]
    values: Callable[[object, float], dict]
    doc: str = ""
    applies: Callable[[object], bool] = _always


HISTORY: Registry[Observables] = Registry("history column group")


def columns(problem) -> tuple[str, ...]:
    """The model's history columns for ``problem``, in registration order."""
    return tuple(c for group in HISTORY if group.applies(problem) for c in group.columns)


def record(problem, t: float) -> dict:
    """The model's history columns of ``problem``'s converged state at time t."""
    out = {}
    for group in HISTORY:
        if group.applies(problem):
            values = group.values(problem, t)
            out.update({c: values[c] for c in group.columns})
    return out


def _state(p, t: float) -> dict:
    return {"growth_mm": p.growth(), "mu_bar": p.loading.mu_bar(t), "fluid_volume": p.fluid_volume(),
            "applied_strain": p.loading.applied_strain(t)}


def _surface(p, t: float) -> dict:
    amplitude, count = p.surface_shape()
    return {"amplitude_mm": amplitude, "wrinkle_count": count}


def _energy(p, t: float) -> dict:
    return {"energy": p.stored_energy()}


def _contact(p, t: float) -> dict:
    return p.contact.observables(p.state.x.array)


def _has_contact(p) -> bool:
    return getattr(p, "contact", None) is not None


HISTORY.register(Observables("state", ("growth_mm", "mu_bar", "fluid_volume", "applied_strain"), _state,
                             "the growth the geometry kind measures, the loading's mu_bar and applied strain, "
                             "the fluid volume (the integral of s over the reference)"))
HISTORY.register(Observables("surface", ("amplitude_mm", "wrinkle_count"), _surface,
                             "the permeable surface's wrinkle amplitude and dominant count (app.model.surface)"))
HISTORY.register(Observables("energy", ("energy",), _energy, "the stored energy of the state"))
HISTORY.register(Observables("contact", ("contact_length_mm", "creases", "contact_x_mm", "contact_y_mm",
                                         "penetration_mm"), _contact,
                             "self-contact's length (3D: area), zones, deepest place and penetration",
                             applies=_has_contact))
