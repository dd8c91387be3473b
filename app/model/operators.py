"""The matrices of the stability criteria as compiled forms on coefficients of their own (docs/validation.md,
"Which instabilities count"). The solvers (:mod:`app.solvers.stability`) take these records, assemble,
factor and solve; the physics of each matrix is written here, once.

- :func:`zero_increment_hessian`: K_tau, the Hessian of the incremental potential at the converged state
  with a zero increment (the "rate" and "undrained" criteria, the cut-back diagnosis, the branch's content
  flux). Its form has the problem's own form signature: the same compiled kernel and a K identical to the
  problem's bit for bit (``tests/test_solver_independence.py``).
- :class:`DrainedHessian`: the stored energy's Hessian in (u, c), u in Q1, c the fluid content of each cell
  (DG0): what the "drained" criterion's Schur complement is built from.

Each record's :meth:`refresh` sets its coefficients from the problem's converged state (read only) before an
assembly; ``space`` and ``bcs`` say where the matrix lives and which dofs are fixed (their rows and columns
are removed by the solvers).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from app import compat, fem_utils
from app.model.kinematics import deformation_gradient, fluid_content
from app.model.potential import build


@dataclass
class OwnHessian:
    """K_tau of a problem on coefficients of its own: ``work`` the (u, dQ) it is evaluated at, ``state`` the
    previous state (u_n, Q_n), ``tau`` a Constant."""

    form: object
    work: object
    state: object
    tau: object
    space: object  # the mixed space W
    bcs: list  # the problem's Dirichlet conditions (which dofs are fixed)
    u_dofs: np.ndarray  # W's displacement dofs (local)
    source: object  # the problem's converged state (u_n, Q_n), read only
    step: float  # the tau every refresh sets
    contact: object = None  # the problem's self-contact term (its Hessian is added at the source state)

    def refresh(self) -> None:
        """Own coefficients at the converged state with a zero increment: (u, dQ) = (u_n, 0)."""
        s = self.source.x.array
        self.state.x.array[:] = s
        w = self.work.x.array
        w[:] = 0.0
        w[self.u_dofs] = s[self.u_dofs]
        self.tau.value = self.step


def zero_increment_hessian(problem, tau: float) -> OwnHessian:
    """K_tau of the problem's incremental potential on coefficients of its own.

    The material fields are copied once and ``tau`` is a Constant of its own. The coefficients are created in
    the order the problem creates its own (unknown, state, material fields, then the constants tau and
    mu_bar), so the form has the problem's form signature: the same compiled kernel (JIT cache hit) and a K
    identical to the one assembled from the problem's own coefficients, bit for bit."""
    p = problem
    work, state = fem.Function(p.W), fem.Function(p.W)
    fields = {}
    for f in dataclasses.fields(p.mat):  # whatever record of per-cell fields the material law has
        source = getattr(p.mat, f.name)
        fields[f.name] = fem.Function(source.function_space)
        fields[f.name].x.array[:] = source.x.array
    tau_c = fem.Constant(p.domain, PETSc.ScalarType(tau))
    mu_bar = fem.Constant(p.domain, PETSc.ScalarType(0.0))  # does not enter K (linear in dQ)
    pot = build(work, state, type(p.mat)(**fields), tau_c, mu_bar, p.dx, p.surface_measure, p.dx_coupling)
    return OwnHessian(fem.form(pot.hessian), work, state, tau_c, p.W, p.bcs, p.u_dofs, p.state, tau,
                      getattr(p, "contact", None))


class DrainedHessian:
    """The stored energy's Hessian in (u, c) on Q1 x DG0: c is the fluid content an RTCF flux changes in a
    cell ((div of the reference field, a constant) / det J), so eliminating it cell by cell leaves the
    drained test's Schur complement on the displacement (:class:`app.solvers.stability.DrainedOperator`)."""

    def __init__(self, problem):
        p = self.problem = problem
        self.space = compat.mixed_displacement_content_space(p.domain)
        self.work = fem.Function(self.space)  # (u, c): u = u_n, c = 0
        self.state = fem.Function(p.W)  # (u_n, Q_n)
        u, c = ufl.split(self.work)
        _, Q_n = ufl.split(self.state)
        F = deformation_gradient(u)
        s = fluid_content(p.mat.s0, Q_n) - c / ufl.JacobianDeterminant(p.domain)
        bulk, constraint = p.mat.law.free_energy(F, s, p.mat)
        energy = bulk * p.dx + constraint * p.dx_coupling
        v, dv = ufl.TestFunction(self.space), ufl.TrialFunction(self.space)
        self.form = fem.form(ufl.derivative(ufl.derivative(energy, self.work, v), self.work, dv))
        self.bcs = p.fixed_displacement_conditions(self.space.sub(0))
        self._V_u, self.u_dofs = fem_utils.collapse(self.space.sub(0))
        _, self.c_dofs = fem_utils.collapse(self.space.sub(1))
        self.contact = getattr(p, "contact", None)  # the self-contact term: its Hessian at the state is added
        self.source = p.state
        # each surface entry's global dof in this space (the contact's Hessian lands there)
        self.contact_entries = (self.contact.entries_in(self.space, self._V_u, self.u_dofs)
                                if self.contact is not None else None)

    def refresh(self) -> None:
        """Own coefficients at the converged state: u = u_n (carried over from the problem's displacement
        space), c = 0."""
        p = self.problem
        s = p.state.x.array
        self.state.x.array[:] = s
        u = fem.Function(p.V_u)
        u.x.array[:] = s[p.u_dofs]
        ud = fem.Function(self._V_u)
        ud.interpolate(u)
        self.work.x.array[:] = 0.0
        self.work.x.array[self.u_dofs] = ud.x.array

    def to_problem_space(self, values: np.ndarray) -> np.ndarray:
        """A local array of this space -> the problem's local array of W with its displacement part (the
        flux part zero)."""
        return displacement_in_problem_space(self.problem, self._V_u, self.u_dofs, values)


def displacement_in_problem_space(problem, V_u, u_dofs: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The displacement of a (u, c) array (``V_u`` its collapsed Q1 space, ``u_dofs`` their places in it) as
    the problem's local array of W: Q1 to Q1 on one mesh, node for node; the flux part zero."""
    ud = fem.Function(V_u)
    ud.x.array[:] = values[u_dofs]
    u = fem.Function(problem.V_u)
    u.interpolate(ud)
    out = np.zeros_like(problem.state.x.array)
    out[problem.u_dofs] = u.x.array
    return out


@dataclass
class CellContentChange:
    """The fluid content a flux increment adds to each cell, as a cell average: ``form`` assembles, against
    the DG0 test function, the integral of div(dQ) over each cell for the dQ held in ``work`` (a function in
    the mixed space, its displacement part zero); dividing by ``area`` (each cell's reference area) gives the
    cell average. The time stepper's error estimate measures its predictor's error with it."""

    form: object
    work: object
    area: np.ndarray


def cell_content_change(problem) -> CellContentChange:
    V0 = compat.scalar_space(problem.domain, "DG", 0)
    v0 = ufl.TestFunction(V0)
    work = fem.Function(problem.W)
    _, dQ = ufl.split(work)
    form = fem.form(ufl.div(dQ) * v0 * ufl.dx)
    area = fem_utils.assemble_vector(fem.form(v0 * ufl.dx))
    cells = area.array.copy()
    area.destroy()
    return CellContentChange(form, work, cells)
