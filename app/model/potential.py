"""The incremental potential Pi^tau of eq. 2.17 on the mixed Q1 x RTCF space, and its derivatives.

The flux unknown is the fluid-volume increment of the step, dQ = tau * H (the same minimizer as
eq. 2.17, rewritten), so that

    Pi(u, dQ) = int psi(F, s) dV + int C_n:(dQ x dQ) / (2 tau J0^(1/3) M s_n) dV + int mu_bar dQ.n dA,
    s   = s_n - Div dQ,      s_n = s0 - Div Q_n,

where Q_n is the accumulated flux (kept in the RTCF space, so s_n is exact on non-affine cells).
The step size tau enters the dissipation term only. The residual is dPi and the Hessian K = d^2 Pi
is symmetric by construction (both from ``ufl.derivative``).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import ufl
from dolfinx import fem

from app.model.kinematics import deformation_gradient, fluid_content
from app.model.material import chemical_potential


@functools.cache
def fields_class(law) -> type:
    """The record of per-cell (DG0) material fields under ``law``: one field per declared parameter, then
    ``s0`` (the reference fluid content), in that order; ``law`` is a class attribute. With them any
    number of layers shares one set of forms, and the law's psi reads ``fields.<parameter>``."""
    cls = dataclasses.make_dataclass("MaterialFields", [(name, object) for name in (*law.params, "s0")],
                                     namespace={"law": law})
    cls.__module__ = __name__
    return cls


@dataclass
class Potential:
    """UFL expressions of one time step; compiled forms live in :class:`CompiledForms`."""

    energy: object  # Pi^tau (UFL scalar form)
    residual: object  # dPi/dw
    hessian: object  # d^2 Pi/dw^2
    F: object
    s: object
    s_n: object
    mu: object


def kinematics(w, state):
    """Deformation gradient, fluid content of the step and of the previous state."""
    u, dQ = ufl.split(w)
    u_n, Q_n = ufl.split(state)
    F = deformation_gradient(u)
    F_n = deformation_gradient(u_n)
    return u, dQ, F, F_n, Q_n


def build(w, state, mat, tau, mu_bar, dx, ds_permeable, dx_coupling=None) -> Potential:
    """Assemble Pi^tau symbolically and differentiate it.

    ``ds_permeable`` is the measure of the boundary where the chemical potential is prescribed
    (None for none); elsewhere the normal flux is fixed by Dirichlet conditions on dQ.
    ``dx_coupling`` integrates the law's constraint part (the hydrogel's volumetric penalty
    (J J0 - 1 - s)^2): with one point per cell
    it enforces the constraint against the cell's (constant) fluid content once per cell, as a
    Q1/P0 pair does, instead of at every Gauss point, which locks Q1 elements in bending."""
    u, dQ, F, F_n, Q_n = kinematics(w, state)
    s_n = fluid_content(mat.s0, Q_n)
    s = fluid_content(s_n, dQ)
    C_n = F_n.T * F_n
    bulk, constraint = mat.law.free_energy(F, s, mat)
    energy = bulk * dx + constraint * (dx_coupling or dx) + mat.law.dissipation(dQ, C_n, s_n, tau, mat) * dx
    if ds_permeable is not None:
        n = ufl.FacetNormal(w.function_space.mesh)
        energy += mu_bar * ufl.dot(dQ, n) * ds_permeable
    W = w.function_space
    residual = ufl.derivative(energy, w, ufl.TestFunction(W))
    hessian = ufl.derivative(residual, w, ufl.TrialFunction(W))
    mu = chemical_potential(mat, F, s)
    return Potential(energy, residual, hessian, F, s, s_n, mu)


class CompiledForms:
    """JIT-compiled residual and Hessian (compiled once per problem, reused every step)."""

    def __init__(self, pot: Potential):
        self.residual = fem.form(pot.residual)
        self.hessian = fem.form(pot.hessian)
        self.energy = fem.form(pot.energy)
