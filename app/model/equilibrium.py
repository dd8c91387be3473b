"""Equilibrium states at a load, each with the energy that decides between them: what the trial crease
(:mod:`app.onset.creases`) compares, a flat state against a creased one at the same load.

- :class:`FrozenFluid`: a loading that moves no fluid (``compression``): the problem's own unknown (u, dQ)
  and forms with every flux dof held, so a state at load t has no history and its energy is the stored
  energy.
- :class:`DrainedEquilibrium`: a swelling gel in equilibrium with its bath. The fluid content is free
  wherever the bath reaches it, so at a bath potential mu_bar the equilibrium states are the stationary
  points of the grand potential in (u, c), u in Q1 and c the fluid content gained in each cell (DG0):

      G(u, c) = int psi(F, s0 + c) dV - mu_bar int c dV

  (the law's constraint part at its own one-point rule, as in the incremental potential). Its
  minimizer over c at fixed F is mu(F, s) = mu_bar in every cell, the drained state the incremental
  potential's time steps reach when diffusion is fast against the load; its minimizer over u is
  mechanical equilibrium. For an open system at fixed mu_bar, G is the energy whose difference decides
  between two states (a crease's Maxwell point). With ``fluid = "undrained"`` a state reached from the flat
  one keeps the flat state's content in every cell (c held): the crease then forms faster than fluid
  can follow, and the difference of G is the difference of the stored energy.

- :class:`HeldContent`: the body at the fluid content of a transient run's flat state, held in every cell at
  every load time (``content(t, Y)``: a laterally uniform content field, from the exact 1D transient,
  :class:`app.reduced.content.ContentProfile`). The energy is the grand potential at that content, whose
  difference between two states at one time is the difference of their stored energy: a crease that forms
  faster than the fluid moves (undrained) on the state the run has reached, wherever its diffusion stands.

With ``mirror = (line, stiffness)`` all three add the trial crease's contact with its mirror image: the surface may
touch the symmetry line x = line but not cross it,

    E_m = int_surface stiffness / 2 <line - x>_+^2 dA,   x = X + u_x,

(``stiffness`` per unit area: kappa mu / h, as the surface's self-contact). It is zero, with its gradient
and Hessian, on every state on the line's side, so the flat state is the same with it.

Both give the trial the same handles: ``w`` (the unknown), ``energy``, ``residual``, ``hessian`` (compiled
forms), ``bcs`` (the fixed displacements), ``displacement`` (the x and y sub-spaces the crease's
condition acts on), ``set_load(t)``, ``value()`` (the energy of ``w``), ``growth()``, and ``kept`` with
``keep(flat)``: the conditions a state reached from the flat one keeps besides those, set from the flat
state's array.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from app import compat, fem_utils
from app.model.kinematics import deformation_gradient
from app.model.operators import displacement_in_problem_space

MIRROR_QUADRATURE = 2  # quadrature degree of the mirror term on a surface facet (exact on a facet wholly past
# the line, where the penetration is linear; approximate on one that the line cuts)


def mirror_term(problem, u, mirror):
    """The mirror contact's energy (UFL) on the permeable surface; None for ``mirror = None``."""
    if mirror is None:
        return None
    line, stiffness = mirror
    x = ufl.SpatialCoordinate(problem.domain)[0] + u[0]
    ds = problem.ds_permeable(metadata={"quadrature_degree": MIRROR_QUADRATURE})
    return 0.5 * stiffness * ufl.max_value(line - x, 0.0) ** 2 * ds


class FrozenFluid:
    """The problem's own unknown and forms; the energy is the stored energy of the state in ``w``."""

    fluid = "frozen"

    def __init__(self, problem, mirror=None):
        if problem.diffusion:
            raise ValueError("a frozen-fluid state needs a loading without fluid motion (loading.kind = compression)")
        p = self.problem = problem
        self.w, self.bcs = p.w, p.bcs
        self.displacement = p.W.sub(0)
        self._mirror = None
        if mirror is None:
            self.energy, self.residual, self.hessian = p.forms.energy, p.forms.residual, p.forms.hessian
            return
        term = mirror_term(p, ufl.split(p.w)[0], mirror)
        residual = p.pot.residual + ufl.derivative(term, p.w, ufl.TestFunction(p.W))
        hessian = ufl.derivative(residual, p.w, ufl.TrialFunction(p.W))
        self.energy, self.residual, self.hessian = (fem.form(p.pot.energy + term), fem.form(residual),
                                                    fem.form(hessian))
        self._mirror = fem.form(term)

    def set_load(self, t: float) -> None:
        self.problem.set_time(t, 1.0)

    def value(self) -> float:
        p = self.problem
        p.state.x.array[:] = p.w.x.array  # no fluid moves: Q stays 0, the state is w
        mirror = 0.0 if self._mirror is None else fem_utils.assemble_scalar(self._mirror, p.comm)
        return p.stored_energy() + mirror

    def growth(self) -> float:
        p = self.problem
        p.state.x.array[:] = p.w.x.array
        return p.growth()

    kept: list = []

    def keep(self, flat: np.ndarray) -> None:
        pass


class DrainedEquilibrium:
    """The grand potential G(u, c) of a problem's body at the bath potential of its loading (module docstring);
    ``fluid``: "drained" (c free in every state) or "undrained" (a state reached from the flat one keeps its
    content)."""

    def __init__(self, problem, fluid: str = "drained", mirror=None):
        if not problem.diffusion or problem.surface_measure is None:
            raise ValueError("a drained equilibrium needs a loading whose bath reaches the body through a "
                             "permeable surface (loading.kind = swelling)")
        if fluid not in ("drained", "undrained"):
            raise ValueError(f"fluid = {fluid!r}: allowed 'drained' or 'undrained'")
        p = self.problem = problem
        self.fluid = fluid
        self.space = compat.mixed_displacement_content_space(p.domain)
        self.w = fem.Function(self.space)  # (u, c): the stress-free reference state at c = 0
        self.mu_bar = fem.Constant(p.domain, PETSc.ScalarType(p.loading.mu_bar(0.0)))
        u, c = ufl.split(self.w)
        bulk, constraint = p.mat.law.free_energy(deformation_gradient(u), p.mat.s0 + c, p.mat)
        G = (bulk - self.mu_bar * c) * p.dx + constraint * p.dx_coupling
        if mirror is not None:
            G = G + mirror_term(p, u, mirror)
        v, dv = ufl.TestFunction(self.space), ufl.TrialFunction(self.space)
        residual = ufl.derivative(G, self.w, v)
        self.energy, self.residual = fem.form(G), fem.form(residual)
        self.hessian = fem.form(ufl.derivative(residual, self.w, dv))
        self.bcs = p.fixed_displacement_conditions(self.space.sub(0))
        self.displacement = self.space.sub(0)
        self._V_u, self._u_dofs = fem_utils.collapse(self.space.sub(0))
        self.kept, self._content = [], None
        if fluid == "undrained":  # every cell's content held at the flat state's
            bc, self._content = fem_utils.dirichlet_function_on_cells(self.space.sub(1), p.domain)
            self.kept = [bc]
            _, self._c_dofs = fem_utils.collapse(self.space.sub(1))

    def set_load(self, t: float) -> None:
        self.mu_bar.value = self.problem.loading.mu_bar(t)

    def value(self) -> float:
        return fem_utils.assemble_scalar(self.energy, self.problem.comm)

    def growth(self) -> float:
        """The problem's growth measure of the displacement in ``w``."""
        p = self.problem
        p.state.x.array[:] = displacement_in_problem_space(p, self._V_u, self._u_dofs, self.w.x.array)
        return p.growth()

    def keep(self, flat: np.ndarray) -> None:
        """Hold every cell's content at the flat state's (undrained; nothing held when drained)."""
        if self._content is not None:
            self._content.x.array[:] = flat[self._c_dofs]


class HeldContent(DrainedEquilibrium):
    """The grand potential's states at a transient run's content, held in every cell (module docstring): each
    cell's content is the cell's mean of ``content(t, Y)`` (a 4 x 4 Gauss rule on the cell's bilinear map),
    set by :meth:`set_load`. Its states at one load time are elastic ones: path independent."""

    GAUSS = 4

    def __init__(self, problem, content, mirror=None):
        super().__init__(problem, "undrained", mirror)
        self.fluid = "transient"
        self.bcs, self.kept = self.bcs + self.kept, []  # the flat state holds its content too
        self.content = content
        V_c, _ = fem_utils.collapse(self.space.sub(1))
        self._y, self._w = _cell_quadrature(problem.domain, V_c, self.GAUSS)

    def set_load(self, t: float) -> None:
        super().set_load(t)
        self._content.x.array[:] = (self.content(t, self._y) * self._w).sum(axis=1)

    def keep(self, flat: np.ndarray) -> None:
        pass

    def load_steps(self, start: float, t: float) -> int:
        """Steps from load ``start`` to t: one per STEPS_PER_LOAD_STEP of the content's stored steps between them
        (the 1D transient's own steps each change its state by about 1%)."""
        lo, hi = min(start, t), max(start, t)
        times = getattr(self.content, "times", None)
        between = 0 if times is None else int(np.count_nonzero((times > lo) & (times <= hi)))
        return max(1, -(-between // self.STEPS_PER_LOAD_STEP))

    STEPS_PER_LOAD_STEP = 10


def _cell_quadrature(domain, V0, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For each local dof of a cell-wise constant space on a quadrilateral mesh: the y of an n x n Gauss rule's
    points on its cell and their weights over the cell's area (summing to 1), shape (dofs, n * n)."""
    g, gw = np.polynomial.legendre.leggauss(n)
    xi, eta = np.meshgrid(0.5 * (g + 1.0), 0.5 * (g + 1.0), indexing="ij")
    xi, eta, wts = xi.ravel(), eta.ravel(), np.outer(gw, gw).ravel() / 4.0
    nodes = fem_utils.node_coordinates(domain)[fem_utils.cell_geometry_nodes(domain)[:, :4]]  # (cells, 4, 2)
    # dolfinx's quadrilateral: vertices at (0, 0), (1, 0), (0, 1), (1, 1) of the reference square
    shape = np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), (1 - xi) * eta, xi * eta])  # (4, points)
    d_xi = np.stack([-(1 - eta), 1 - eta, -eta, eta])
    d_eta = np.stack([-(1 - xi), -xi, 1 - xi, xi])
    jx = np.einsum("vp,cvk->cpk", d_xi, nodes)
    je = np.einsum("vp,cvk->cpk", d_eta, nodes)
    det = np.abs(jx[..., 0] * je[..., 1] - jx[..., 1] * je[..., 0]) * wts
    y = np.einsum("vp,cv->cp", shape, nodes[..., 1])
    dofs = fem_utils.cell_dofs(V0)[:, 0]  # the dof of each cell, in the order of the geometry's cells
    imap = V0.dofmap.index_map
    out_y = np.empty((imap.size_local + imap.num_ghosts, len(wts)))
    out_w = np.empty_like(out_y)
    out_y[dofs] = y
    out_w[dofs] = det / det.sum(axis=1, keepdims=True)
    return out_y, out_w


def equilibrium(problem, fluid: str = "drained", mirror=None, content=None):
    """The equilibrium states of a problem's loading: frozen fluid when no fluid moves, else the bath's, or with
    ``fluid = "transient"`` a transient run's content held (``content(t, Y)``, :class:`HeldContent`);
    ``mirror``: (line, stiffness) of the trial crease's contact with its mirror image, or None."""
    if not problem.diffusion:
        return FrozenFluid(problem, mirror)
    if fluid == "transient":
        if content is None:
            raise ValueError("fluid = 'transient' needs the run's content field")
        return HeldContent(problem, content, mirror)
    return DrainedEquilibrium(problem, fluid, mirror)
