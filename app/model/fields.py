"""The fields a run writes to fields.xdmf: each a UFL expression of the converged state, registered once.

A :class:`Field` names itself, says what it means and where it lives (``"nodal vector"``: CG1 like the
displacement; ``"cell scalar"`` and ``"cell vector"``: one value a cell, DG0), and builds its expression from a
:class:`State`: the converged state's displacement, flux, deformation gradient, fluid content and the Cauchy stress
of the material law (sigma = P F^T / det F with P = d psi / d F by UFL differentiation). ``applies(dim)`` says
on which meshes it is written (the out-of-plane stresses only in 3D). The result writer
(:class:`app.io.output.ResultWriter`) compiles and writes every registered field that applies; it knows none of
them. A new field is one :class:`Field` and one ``FIELDS.register(...)`` line, here or in any module
(tests/test_xdmf.py registers one from test code).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import ufl

from app.model.kinematics import deformation_gradient, fluid_content
from app.model.material import chemical_potential, first_piola
from app.registry import Registry

SPACES = ("nodal vector", "cell scalar", "cell vector")


@dataclass(frozen=True)
class State:
    """What a field's expression may use of a problem's converged state (UFL)."""

    problem: Any
    u: Any  # displacement u_n
    Q: Any  # the accumulated flux Q_n
    dQ: Any  # the last step's flux increment (problem.w's)
    F: Any  # the deformation gradient (a ufl.variable)
    s: Any  # the fluid content
    J: Any  # det F
    sigma: Any  # the Cauchy stress of the material law
    dim: int  # the mesh's dimension


def state_of(problem) -> State:
    """The converged state's quantities (after a step is accepted, problem.state holds (u, Q) and problem.w
    the step's (u, dQ))."""
    u, Q = ufl.split(problem.state)
    _, dQ = ufl.split(problem.w)
    mat = problem.mat
    F = ufl.variable(deformation_gradient(u))
    s = fluid_content(mat.s0, Q)
    J = ufl.det(F)
    return State(problem, u, Q, dQ, F, s, J, first_piola(mat, F, s) * F.T / J, problem.domain.geometry.dim)


def _every_dimension(dim: int) -> bool:
    return True


@dataclass(frozen=True)
class Field:
    """One field of fields.xdmf: ``expression(state)`` -> UFL, in the space ``space`` (one of :data:`SPACES`),
    on meshes of a dimension where ``applies(dim)``."""

    name: str
    meaning: str
    space: str
    expression: Callable[[State], Any]
    applies: Callable[[int], bool] = _every_dimension


FIELDS: Registry[Field] = Registry("output field")


def fields_for(dim: int) -> list[Field]:
    """The registered fields a mesh of dimension ``dim`` gets, in registration order."""
    return [f for f in FIELDS if f.applies(dim)]


def smallest_principal(sigma):
    """The smallest eigenvalue of a symmetric 3 x 3 UFL tensor (the trigonometric closed form; an isotropic
    tensor, where the deviator vanishes, gives its mean stress)."""
    q = ufl.tr(sigma) / 3
    dev = sigma - q * ufl.Identity(3)
    p = ufl.sqrt(ufl.inner(dev, dev) / 6) + 1e-300
    r = ufl.det(dev / p) / 2
    r = ufl.max_value(ufl.min_value(r, 1.0), -1.0)
    return q + 2 * p * ufl.cos(ufl.acos(r) / 3 + 2 * ufl.pi / 3)


def _min_principal(st: State):
    """The film's compression: the smaller in-plane principal stress (2D), the smallest principal one (3D)."""
    sigma = st.sigma
    if st.dim == 3:
        return smallest_principal(sigma)
    mean = 0.5 * (sigma[0, 0] + sigma[1, 1])
    return mean - ufl.sqrt((0.5 * (sigma[0, 0] - sigma[1, 1])) ** 2 + sigma[0, 1] ** 2)


def _three_d(dim: int) -> bool:
    return dim == 3


for _field in (
    Field("displacement", "u [mm], nodal (CG1)", "nodal vector", lambda st: st.u),
    Field("fluid_content", "s, fluid volume per reference volume, per cell", "cell scalar", lambda st: st.s),
    Field("chemical_potential", "mu [MPa], per cell", "cell scalar",
          lambda st: chemical_potential(st.problem.mat, st.F, st.s)),
    Field("J", "det F, per cell", "cell scalar", lambda st: st.J),
    Field("flux", "H [mm/s] at the cell centre (the RTCF flux of the last step)", "cell vector",
          lambda st: st.dQ / st.problem.tau),
    Field("stress_xx", "Cauchy stress sigma_xx [MPa], per cell", "cell scalar", lambda st: st.sigma[0, 0]),
    Field("stress_yy", "Cauchy stress sigma_yy [MPa], per cell", "cell scalar", lambda st: st.sigma[1, 1]),
    Field("stress_xy", "Cauchy stress sigma_xy [MPa], per cell", "cell scalar", lambda st: st.sigma[0, 1]),
    Field("stress_min_principal", "smaller in-plane principal Cauchy stress [MPa] (the film's compression), per "
          "cell; 3D: the smallest principal stress", "cell scalar", _min_principal),
    # z: the plate's width, the tube's axis
    Field("stress_zz", "Cauchy stress sigma_zz [MPa], per cell (3D)", "cell scalar", lambda st: st.sigma[2, 2],
          _three_d),
    Field("stress_xz", "Cauchy stress sigma_xz [MPa], per cell (3D)", "cell scalar", lambda st: st.sigma[0, 2],
          _three_d),
    Field("stress_yz", "Cauchy stress sigma_yz [MPa], per cell (3D)", "cell scalar", lambda st: st.sigma[1, 2],
          _three_d),
):
    FIELDS.register(_field)
