"""The laterally uniform swelling transient of a :class:`~app.reduced.section.Section` in 1D.

The same incremental potential as the 2D model (:mod:`app.model.potential`, eq. 2.17 with the law's free
energy and dissipation), restricted to the uniform state: the unknowns are the displacement along the
section's coordinate (v(Y), or u(r)) and the fluid-volume increment of the step along it (dQ), both
continuous Lagrange fields of one degree, so s = s_n - Div dQ is discontinuous of one degree less, as
Div maps RT onto DG in 2D. Per unit length of the bilayer (per radian of the tube):

    planar:        F = diag(lambda_x, 1 + v'),      Div dQ = dQ',               dV = dY
    axisymmetric:  F = diag(1 + u', 1 + u/r),       Div dQ = (r dQ)'/r,         dV = r dr

(polar axes: an isotropic law's psi does not depend on the basis). lambda_x is 1, or 1 - strain(t) under
``loading.kind = "compression"`` (diffusion off). Backward Euler; Newton with the exact Hessian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, fem_utils
from app.model.material import chemical_potential
from app.model.potential import fields_class
from app.reduced.section import Section
from app.solvers.local import LocalSystem


class TransientFailed(RuntimeError):
    pass


@dataclass(frozen=True)
class Resolution:
    """The 1D discretization: element degree, cells through the film, cell growth away from it and through
    the film away from the permeable surface, and the step control (the largest relative change of the
    displacement per step, the largest and the first step)."""

    degree: int = 3
    film_cells: int = 12
    grading: float = 1.25
    surface_grading: float = 1.35
    step_change: float = 0.01
    dt_max: float = 0.05
    dt_first: float = 1.0e-3

    def refined(self, level: int) -> Resolution:
        """Level ``level`` of the mesh sequence: cells halved ``level`` times (film cells doubled, the
        grading's root)."""
        f = 2 ** level
        return Resolution(self.degree, self.film_cells * f, self.grading ** (1.0 / f),
                          self.surface_grading ** (1.0 / f), self.step_change, self.dt_max, self.dt_first)


class LayeredModel:
    """Mesh, spaces, per-cell material fields and the compiled forms of one section and resolution."""

    def __init__(self, section: Section, res: Resolution, comm=MPI.COMM_SELF):
        self.section, self.res = section, res
        self.nodes = section.nodes(res.film_cells, res.grading, res.surface_grading)
        self.domain = fem_utils.interval_mesh(comm, self.nodes)
        self.W = compat.mixed_lagrange_space(self.domain, res.degree, 2)
        self.w = fem.Function(self.W)  # (displacement, dQ of the step)
        self.state = fem.Function(self.W)  # (displacement, Q accumulated)
        self.V0, self.v_dofs = fem_utils.collapse(self.W.sub(0))
        self.V1, self.q_dofs = fem_utils.collapse(self.W.sub(1))
        self.x_v = fem_utils.dof_coordinates(self.V0)
        self.x_q = fem_utils.dof_coordinates(self.V1)
        self.mat = self._fields()
        d = self.domain
        self.tau = fem.Constant(d, PETSc.ScalarType(res.dt_first))
        self.mu_bar = fem.Constant(d, PETSc.ScalarType(section.loading.mu_bar(0.0)))
        self.lam_x = fem.Constant(d, PETSc.ScalarType(1.0))
        self.dx = ufl.Measure("dx", domain=d, metadata={"quadrature_degree": 2 * res.degree + 2})
        self.r = ufl.SpatialCoordinate(d)[0]
        self.weight = self.r if section.shape == "axisymmetric" else 1.0
        self._flat = None
        self._system = None  # the residual and Hessian assembled for SciPy (created at the first assembly)
        self._forms()
        self.fixed = self._fixed_dofs()
        self.surface_v = self._dof_at(self.v_dofs, self.x_v, section.surface)

    # --- setup --------------------------------------------------------------------------------

    def _fields(self):
        """The law's parameters and s0 per cell (DG0), as in the 2D problem: one set of forms for both layers."""
        mats = self.section.materials
        law = next(iter(mats.values())).law
        V0 = compat.scalar_space(self.domain, "DG", 0)
        mid = fem_utils.dof_coordinates(V0)
        values = {}
        for name in (*law.params, "s0"):
            f = fem.Function(V0)
            for lay in self.section.layers:
                inside = (mid >= lay.start) & (mid <= lay.end)
                f.x.array[inside] = getattr(mats[lay.material], name)
            values[name] = f
        return fields_class(law)(**values)

    def kinematics(self, fn, increment: bool):
        """(F, s, C_n-free pieces) of a function of W: F and the fluid content of its second field taken as
        an increment of ``state`` (``increment``) or as the accumulated flux itself."""
        u, q = ufl.split(fn)
        un, Qn = ufl.split(self.state)
        s_n = self.mat.s0 - self.div(Qn)
        s = s_n - self.div(q) if increment else self.mat.s0 - self.div(q)
        return self.deformation(u), s, self.deformation(un), s_n

    def deformation(self, u):
        if self.section.shape == "planar":
            return ufl.as_matrix([[self.lam_x, 0.0], [0.0, 1.0 + u.dx(0)]])
        return ufl.as_matrix([[1.0 + u.dx(0), 0.0], [0.0, 1.0 + u / self.r]])

    def div(self, q):
        if self.section.shape == "planar":
            return q.dx(0)
        return q.dx(0) + q / self.r

    def flux_vector(self, q):
        """The flux along the section's coordinate as the 2D law sees it: (0, q) along Y, (q, 0) along r."""
        return ufl.as_vector([0.0, q]) if self.section.shape == "planar" else ufl.as_vector([q, 0.0])

    def _forms(self):
        law = self.mat.law
        F, s, F_n, s_n = self.kinematics(self.w, increment=True)
        bulk, constraint = law.free_energy(F, s, self.mat)
        _, dQ = ufl.split(self.w)
        diss = law.dissipation(self.flux_vector(dQ), F_n.T * F_n, s_n, self.tau, self.mat)
        energy = (bulk + constraint + diss) * self.weight * self.dx
        if self.section.loading.surface_term:
            n = ufl.FacetNormal(self.domain)[0]
            base, surf = self.section.base, self.section.surface
            at_surface = (self.r - base) / (surf - base)  # 1 on the permeable surface, 0 on the held end
            energy += self.mu_bar * dQ * n * at_surface * self.weight * ufl.ds
        W = self.W
        self.residual_form = ufl.derivative(energy, self.w, ufl.TestFunction(W))
        self.hessian_form = ufl.derivative(self.residual_form, self.w, ufl.TrialFunction(W))
        self.residual = fem.form(self.residual_form)
        self.hessian = fem.form(self.hessian_form)
        self.energy = fem.form(energy)
        self.mu = chemical_potential(self.mat, F, s)

    def _dof_at(self, dofs, x, where) -> int:
        i = int(np.argmin(np.abs(x - where)))
        if abs(x[i] - where) > 1e-9 * max(1.0, abs(where)):
            raise RuntimeError(f"no dof at x = {where}")
        return int(dofs[i])

    def _fixed_dofs(self) -> np.ndarray:
        base = self.section.base
        fixed = [self._dof_at(self.v_dofs, self.x_v, base), self._dof_at(self.q_dofs, self.x_q, base)]
        if not self.section.loading.surface_term:  # diffusion off: every flux dof held at zero
            fixed.extend(int(i) for i in self.q_dofs)
        return np.unique(np.array(fixed, dtype=np.int64))

    # --- algebra --------------------------------------------------------------------------------

    def assemble(self):
        """(residual, Hessian in LAPACK general band storage in coordinate order :attr:`order`) at the
        current w: a 1D system is banded."""
        if self._system is None:
            self._system = LocalSystem(self.residual, self.hessian)
        r, (indptr, indices, values) = self._system.assemble()
        if self._flat is None:
            self._band_pattern(indptr, indices)
        ab = np.zeros((2 * self.bandwidth + 1) * len(r))
        ab[self._flat] = values
        return r, ab.reshape(2 * self.bandwidth + 1, len(r))

    def _band_pattern(self, indptr, indices) -> None:
        n = len(indptr) - 1
        coords = np.zeros(n)
        field = np.zeros(n, dtype=int)
        coords[self.v_dofs], coords[self.q_dofs] = self.x_v, self.x_q
        field[self.q_dofs] = 1
        self.order = np.lexsort((field, coords))  # position p holds dof order[p]
        pos = np.empty(n, dtype=np.int64)
        pos[self.order] = np.arange(n)
        rows = np.repeat(np.arange(n), np.diff(indptr))
        i, j = pos[rows], pos[indices]
        self.bandwidth = int(np.max(np.abs(i - j)))
        self._flat = (self.bandwidth + i - j) * n + j  # ab[u + i - j, j] = K[i, j]
        self._pos = pos


@dataclass
class Snapshot:
    """One accepted step: time, the state (displacement, accumulated flux) and observables."""

    t: float
    state: np.ndarray
    growth: float  # mean normal displacement of the permeable surface (into the passage for the tube) [mm]
    mu_bar: float
    lam_x: float


class Transient:
    """Backward Euler in time with Newton per step; steps adapt to the change of the surface fluid
    content and never cross a loading kink. :meth:`run` keeps every accepted step (a 1D state is small)."""

    def __init__(self, model: LayeredModel, rtol: float = 1e-10, atol: float = 1e-13, max_it: int = 30):
        self.m = model
        self.rtol, self.atol, self.max_it = rtol, atol, max_it
        self.t = 0.0
        self.steps: list[Snapshot] = [self._snapshot()]
        self.newton_its = 0

    def _snapshot(self) -> Snapshot:
        m = self.m
        st = m.state.x.array.copy()
        g = st[m.surface_v]
        growth = float(g if m.section.shape == "planar" else -g)
        return Snapshot(self.t, st, growth, float(m.mu_bar.value), float(m.lam_x.value))

    def _set_load(self, t: float) -> None:
        lo = self.m.section.loading
        self.m.mu_bar.value = lo.mu_bar(t)
        self.m.lam_x.value = 1.0 - lo.applied_strain(t)

    def step(self, dt: float) -> bool:
        """One backward Euler step of size dt from the current state; False (state unchanged) if Newton fails."""
        m = self.m
        self._set_load(self.t + dt)
        m.tau.value = dt
        w = m.w.x.array
        w[:] = 0.0
        w[m.v_dofs] = m.state.x.array[m.v_dofs]
        free = np.ones(len(w), dtype=bool)
        free[m.fixed] = False
        r0 = None
        for _ in range(self.max_it):
            r, K = m.assemble()
            r[~free] = 0.0
            norm = float(np.linalg.norm(r))
            if not np.isfinite(norm):
                return False
            if r0 is None:
                r0 = norm
            if norm <= max(self.rtol * r0, self.atol):
                break
            dw = self._solve(K, r, free)
            if dw is None:
                return False
            if not np.all(np.isfinite(dw)):
                return False
            w += dw
            self.newton_its += 1
            if np.max(np.abs(dw)) <= 1e-13 * (np.max(np.abs(w)) + m.section.film_thickness):
                break  # the update is at roundoff: the residual cannot fall further
        else:
            return False
        st = m.state.x.array
        st[m.v_dofs] = w[m.v_dofs]
        st[m.q_dofs] += w[m.q_dofs]
        self.t += dt
        return True

    def _solve(self, ab: np.ndarray, r: np.ndarray, free: np.ndarray):
        """K dw = -r on the free dofs, held dofs unchanged (banded LU)."""
        m = self.m
        n, u = len(r), m.bandwidth
        held = m._pos[~free]
        ab = ab.copy()
        for p in held:  # zero row and column p (ab[u + i - j, j] = K[i, j]), unit diagonal
            ab[:, p] = 0.0
            j = np.arange(max(0, p - u), min(n, p + u + 1))
            ab[u + p - j, j] = 0.0
            ab[u, p] = 1.0
        rhs = -r[m.order]
        rhs[held] = 0.0
        try:
            x = sla.solve_banded((u, u), ab, rhs, check_finite=False)
        except (sla.LinAlgError, ValueError):
            return None
        dw = np.empty(n)
        dw[m.order] = x
        return dw

    def run(self, t_end: float, stop=None, scale: int = 1, schedule: list[float] | None = None) -> list[Snapshot]:
        """Advance to ``t_end`` (or until ``stop(snapshot, index)`` is true). Without ``schedule`` the steps adapt;
        with it (the step sizes of another run) each is taken as ``scale`` equal sub-steps, so two runs
        differ only in their step size (Richardson)."""
        res = self.m.res
        kinks = sorted(k for k in self.m.section.loading.kinks() if 0 < k < t_end) + [t_end]
        if schedule is not None:
            for dt in schedule:
                for _ in range(scale):
                    if not self.step(dt / scale):
                        raise TransientFailed(f"Newton failed at t = {self.t:.6g} s (step {dt / scale:.3g} s)")
                    self.steps.append(self._snapshot())
                    if stop is not None and stop(self.steps[-1], len(self.steps) - 1):
                        return self.steps
            return self.steps
        dt = res.dt_first
        while self.t < t_end - 1e-12:
            nxt = next(k for k in kinks if k > self.t + 1e-12)
            dt_try = min(dt, res.dt_max, nxt - self.t)
            if nxt - self.t - dt_try < 1e-3 * dt_try:
                dt_try = nxt - self.t
            before = self.m.state.x.array.copy()
            if not self.step(dt_try):
                dt *= 0.25
                if dt < 1e-9:
                    raise TransientFailed(f"Newton failed at t = {self.t:.6g} s with steps down to 1e-9 s")
                continue
            after = self.m.state.x.array[self.m.v_dofs]
            scale_u = float(np.max(np.abs(after))) + 1e-3 * self.m.section.film_thickness
            change = float(np.max(np.abs(after - before[self.m.v_dofs]))) / scale_u
            if change > 2 * res.step_change and dt_try > 1e-6:
                self.m.state.x.array[:] = before
                self.t -= dt_try
                dt = dt_try * 0.5
                continue
            self.steps.append(self._snapshot())
            dt = dt_try * min(2.0, max(0.5, 0.9 * res.step_change / max(change, 1e-12)))
            if stop is not None and stop(self.steps[-1], len(self.steps) - 1):
                break
        return self.steps


def schedule(steps: list[Snapshot]) -> list[float]:
    """The step sizes of a run's stored steps (to replay it with :meth:`Transient.run`'s ``schedule``)."""
    return [b.t - a.t for a, b in zip(steps, steps[1:])]
