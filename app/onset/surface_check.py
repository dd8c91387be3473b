"""The short-wave limit of the permeable surface, checked every step from the 2D run's local state.

A 2D mesh resolves no wave shorter than a few elements, so a surface that becomes unstable at short
wavelengths (a swelling gel's free surface passing Kang & Huang's condition, docs/theory/drained-onset.md)
is invisible to K, or shows up as a wave at the mesh's scale. The check evaluates, after every accepted
step, the half-space operator of app/reduced/halfspace.py at every permeable facet, under the run's
criterion (its short-wave limit: rate counts as drained).

The state it needs is that of the surface itself, which no mesh resolves: under the permeable surface the
fluid content has a diffusion boundary layer of well under a micrometre (docs/reduction.md section 6), so a
surface cell's own state lags far behind. At the surface the gel is in equilibrium with the bath and free of
traction, so its state follows locally from what the mesh does resolve, the stretch along the surface:
with the tangential column of F (the facet's deformed length and turn, in the facet's frame of tangent and
outward normal) given, the normal column and s solve P n = 0 and mu(F, s) = mu_bar(t) (:class:`SurfaceState`,
the law's own UFL on one cell per facet). The first step at which any facet's half-space is indefinite gives
the surface onset, located between the steps by bisection in time (that facet's tangential column
interpolated linearly, the bath's mu_bar(t) from the loading); it is reported as its own kind of result
(time, growth, where), not as a wrinkle count (summary.json
``surface_onset``).
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, fem_utils
from app.geometry import dofmaps
from app.model.material import chemical_potential, first_piola
from app.model.potential import fields_class
from app.reduced.halfspace import HalfSpace
from app.solvers.local import LocalSystem


class SurfaceCheck:
    """The per-step short-wave check of one problem's permeable surface (collective)."""

    def __init__(self, problem, criterion):
        """``criterion``: the run's :class:`app.onset.criteria.Criterion`; the check uses its short-wave
        counterpart (``criterion.surface``: drained or undrained)."""
        p = problem
        self.problem, self.comm, self.criterion = p, p.comm, criterion.surface
        self._label = criterion.surface_label()
        domain = p.domain
        tdim = domain.topology.dim
        domain.topology.create_connectivity(tdim - 1, tdim)
        domain.topology.create_connectivity(tdim - 1, 0)
        f2c = domain.topology.connectivity(tdim - 1, tdim)
        f2v = domain.topology.connectivity(tdim - 1, 0)
        n_owned_facets = domain.topology.index_map(tdim - 1).size_local
        facets = [f for g in p.geo.facets_with_role("permeable") for f in p.tm.facets(g) if f < n_owned_facets]
        self.facets = np.array(sorted(set(int(f) for f in facets)), dtype=np.int64)
        v2g = fem_utils.vertex_to_geometry(domain)
        x = fem_utils.node_coordinates(domain)
        gdim = self.dim = domain.geometry.dim
        cell_nodes = fem_utils.cell_geometry_nodes(domain)
        self.cells = np.array([f2c.links(f)[0] for f in self.facets], dtype=np.int64)
        corners = 2 ** (tdim - 1)  # a facet's vertices: 2 (a segment) or 4 (a quadrilateral, tensor-product order)
        self.vertex_nodes = np.array([v2g[f2v.links(f)] for f in self.facets], dtype=np.int64).reshape(-1, corners)
        X = x[self.vertex_nodes][..., :gdim] if len(self.facets) else np.zeros((0, corners, gdim))
        self.where = X.mean(axis=1)  # facet midpoints (reference)
        J = self._tangents(X)  # (n, gdim, tdim - 1): the facet's derivatives at its midpoint
        centre = (np.array([x[cell_nodes[c]][:, :gdim].mean(axis=0) for c in self.cells]) if len(self.cells)
                  else np.zeros((0, gdim)))
        t1 = J[:, :, 0] / np.linalg.norm(J[:, :, 0], axis=1)[:, None]
        if gdim == 2:
            n = np.stack([t1[:, 1], -t1[:, 0]], axis=1)
        else:
            n = np.cross(J[:, :, 0], J[:, :, 1])
            n /= np.linalg.norm(n, axis=1)[:, None]
        flip = np.einsum("ij,ij->i", n, self.where - centre) < 0
        n[flip] *= -1.0
        if gdim == 2:
            self.R = np.stack([np.stack([n[:, 1], -n[:, 0]], axis=1), n], axis=1)  # rows: tangent, normal
        else:
            self.R = np.stack([t1, np.cross(n, t1), n], axis=1)  # rows: t1, t2, outward normal (right-handed)
        # F t_b = j (J^T J)^-1 J^T t_b for the current derivatives j: the map from (dxi) to the frame's tangents
        tang = self.R[:, :gdim - 1, :]  # (n, tdim - 1, gdim)
        self.to_tangents = np.einsum("nab,nbg,nkg->nak", np.linalg.inv(np.einsum("nga,ngb->nab", J, J)),
                                     np.transpose(J, (0, 2, 1)), tang) if len(J) else np.zeros((0, gdim - 1, gdim - 1))
        # the material of each facet's cell
        group_of_cell = {}
        for group in p.geo.layers:
            for c in p.tm.cells(group):
                group_of_cell[int(c)] = group
        self.material = [p.geo.layers.get(group_of_cell.get(int(c)), None) for c in self.cells]
        # the surface state in equilibrium with the bath, one cell per facet
        self.node_dofs = dofmaps.lagrange1_dof_nodes(p.V_u)  # geometry node of each displacement dof block
        first = next(iter(p.materials.values()))
        point_materials = [p.materials.get(name) if name else first for name in self.material]
        # the 1D forms are compiled on rank 0 first, then loaded from the cache by the others (no two
        # processes compile one form at once)
        self.equilibrium = self.halfspace = None
        for turn in (0, 1):
            if (self.comm.rank == 0) == (turn == 0):
                self.halfspace = HalfSpace(first, self.criterion, dim=gdim)
                self.equilibrium = SurfaceState(point_materials or [first], dim=gdim)
            self.comm.barrier()
        if not len(self.facets):
            self.equilibrium = None
        self.mats = {name: p.materials[name] for name in set(self.material) if name is not None}
        self.history: list[tuple] = []  # the last step tested: (time, growth_mm, margin, tangential columns)

    @staticmethod
    def _tangents(P: np.ndarray) -> np.ndarray:
        """The derivatives of facets' maps at their midpoints, (n, gdim, tdim - 1), from their vertices ``P``
        (n, corners, gdim): a segment's P1 - P0; a quadrilateral's (vertices in dolfinx's tensor-product order
        (0, 0), (1, 0), (0, 1), (1, 1)) d/dxi and d/deta of its bilinear map."""
        if P.shape[1] == 2:
            return (P[:, 1] - P[:, 0])[:, :, None]
        dxi = 0.5 * ((P[:, 1] - P[:, 0]) + (P[:, 3] - P[:, 2]))
        deta = 0.5 * ((P[:, 2] - P[:, 0]) + (P[:, 3] - P[:, 1]))
        return np.stack([dxi, deta], axis=2)

    def columns(self) -> np.ndarray:
        """The tangential columns F t of every permeable facet of this rank in the facet's frame: (n, 2) in 2D
        (the facet's deformed length and turn), (n, 3, 2) in 3D (F t1 and F t2): what the mesh resolves of the
        surface."""
        p = self.problem
        d = self.dim
        u = p.state.x.array[p.u_dofs].reshape(-1, d)
        x = fem_utils.node_coordinates(p.domain)
        node_u = np.zeros((x.shape[0], d))
        node_u[self.node_dofs] = u
        j = self._tangents(x[self.vertex_nodes][..., :d] + node_u[self.vertex_nodes])  # current derivatives
        Ft = np.einsum("nga,nak->ngk", j, self.to_tangents)  # F t_k, (n, gdim, tdim - 1)
        cols = np.einsum("nij,njk->nik", self.R, Ft)
        return cols[:, :, 0] if d == 2 else cols

    def margins(self, columns: np.ndarray, mu_bar: float, only: int | None = None, exact: bool = False) -> np.ndarray:
        """Each facet's verdict on its surface state: +1 / -1 (stable / not: a banded Cholesky), or with
        ``exact`` the half-space margin itself; equal states are evaluated once. ``only``: that facet alone
        (the others inf)."""
        out = np.full(len(self.facets), np.inf)
        if self.equilibrium is None:
            return out
        F, s = self.equilibrium.solve(columns, mu_bar)
        F, s = np.round(F, 7), np.round(s, 7)  # states equal to 1e-7: one evaluation
        seen: dict = {}
        for i in range(len(self.facets)) if only is None else (only,):
            name = self.material[i]
            if name is None:
                continue
            key = (name, *F[i].ravel(), float(s[i]))
            if key not in seen:
                hs = self.halfspace.use(self.mats[name])
                seen[key] = hs.margin(F[i], float(s[i])) if exact else (1.0 if hs.definite(F[i], float(s[i])) else -1.0)
            out[i] = seen[key]
        return out

    def test(self, time: float, growth_mm: float) -> dict | None:
        """After an accepted step (collective): the surface onset record if the surface became unstable in
        this step. The crossing is located by bisection in time between the two steps: the tangential
        columns interpolated linearly, the bath's mu_bar(t) from the loading."""
        cols = self.columns()
        mu = float(self.problem.mu_bar.value)
        m = self.margins(cols, mu)
        i = int(np.argmin(m)) if len(m) else -1
        mine = (float(m[i]), self.comm.rank, i) if len(m) else (np.inf, self.comm.rank, -1)
        best = min(self.comm.allgather(mine))
        prev, self.history = (self.history[-1] if self.history else None), [(time, growth_mm, best[0], cols)]
        if best[0] > 0:
            return None
        owner, i = best[1], best[2]
        where = self.comm.bcast(tuple(float(v) for v in self.where[i]) if self.comm.rank == owner else None,
                                root=owner)
        if prev is None:  # unstable in the first state tested
            return {"kind": "surface", "time": time, "growth_mm": growth_mm, "growth_um": 1e3 * growth_mm,
                    "where": list(where), "criterion": self._label, "bracket": [time, time]}
        t0, g0, _, cols0 = prev
        lo, hi = t0, time
        loading = self.problem.loading
        if self.comm.rank == owner:
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                f = (mid - t0) / (time - t0)
                c = (1 - f) * cols0 + f * cols
                if self.margins(c, loading.mu_bar(mid), only=i)[i] > 0:
                    lo = mid
                else:
                    hi = mid
                if hi - lo <= 1e-10 * max(1.0, hi):
                    break
        t = self.comm.bcast(0.5 * (lo + hi), root=owner)
        f = (t - t0) / (time - t0)
        g = (1 - f) * g0 + f * growth_mm
        return {"kind": "surface", "time": t, "growth_mm": g, "growth_um": 1e3 * g, "where": list(where),
                "criterion": self._label, "bracket": [t0, time]}


class SurfaceState:
    """The state of N surface points in equilibrium with the bath: given the tangential columns of F in the
    surface frame (one in 2D, two in 3D), the normal column a and s with P(F, s) e_n = 0 and mu(F, s) = mu_bar,
    F = [c | a] (2D: [[c0, a0], [c1, a1]]; 3D: the frame (t1, t2, n), F = [c1 c2 a]). One DG0 cell per point
    on a 1D mesh (the law's parameters per cell), Newton on the cell-local (dim + 1) systems, warm-started from
    the last solution."""

    def __init__(self, materials: list, dim: int = 2):
        n = len(materials)
        self.dim = dim
        law = materials[0].law
        d = fem_utils.interval_mesh(MPI.COMM_SELF, np.arange(n + 1, dtype=float))
        V0 = compat.scalar_space(d, "DG", 0)
        at = np.argsort(fem_utils.dof_coordinates(V0))  # dof of point k (cell k spans [k, k + 1])
        fields = {}
        for name in (*law.params, "s0"):
            f = fem.Function(V0)
            f.x.array[at] = [getattr(m, name) for m in materials]
            fields[name] = f
        mat = fields_class(law)(**fields)
        tangents = dim - 1
        self.c = [[fem.Function(V0) for _ in range(tangents)] for _ in range(dim)]  # c[row][column]
        self.at = at
        self.mu_bar = fem.Constant(d, PETSc.ScalarType(0.0))
        W = compat.mixed_dg0_space(d, dim + 1)
        self.w = fem.Function(W)
        parts = ufl.split(self.w)
        a, s = parts[:dim], parts[dim]
        F = ufl.as_matrix([[*self.c[i], a[i]] for i in range(dim)])
        P = first_piola(mat, F, s)
        mu = chemical_potential(mat, F, s)
        v = ufl.TestFunction(W)
        dx = ufl.Measure("dx", domain=d, metadata={"quadrature_degree": 1})
        res = (sum(P[i, dim - 1] * v[i] for i in range(dim)) + (mu - self.mu_bar) * v[dim]) * dx
        self.system = LocalSystem(fem.form(res), fem.form(ufl.derivative(res, self.w, ufl.TrialFunction(W))))
        self.dofs = []
        for i in range(dim + 1):
            Vi, dofs = fem_utils.collapse(W.sub(i))
            self.dofs.append(dofs[np.argsort(fem_utils.dof_coordinates(Vi))])  # parent dof of point k
        x = self.w.x.array
        x[self.dofs[dim - 1]] = 1.0
        x[self.dofs[dim]] = [m.s0 for m in materials]

    def solve(self, column: np.ndarray, mu_bar: float, tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
        """(F (N, dim, dim), s (N,)) at the tangential columns ``column`` ((N, 2) in 2D, (N, 3, 2) in 3D) and
        the bath's mu_bar."""
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        dim = self.dim
        cols = np.asarray(column, dtype=float).reshape(len(column), dim, dim - 1)
        for i in range(dim):
            for j in range(dim - 1):
                self.c[i][j].x.array[self.at] = cols[:, i, j]
        self.mu_bar.value = mu_bar
        x = self.w.x.array
        js = self.dofs[dim]

        def full(y):
            return np.concatenate([cols, np.stack([y[self.dofs[i]] for i in range(dim)], axis=1)[:, :, None]], axis=2)

        def admissible(y):  # the law's logarithms: s > 0, det F > 0
            return y[js].min() > 0 and np.linalg.det(full(y)).min() > 0

        for _ in range(60):
            r, (indptr, indices, values) = self.system.assemble()
            K = sp.csr_matrix((values, indices, indptr), shape=self.system.shape)
            dx = spla.spsolve(K.tocsc(), -r)
            step = 1.0
            while step > 1e-8 and not admissible(x + step * dx):
                step *= 0.5
            x += step * dx
            if step == 1.0 and np.max(np.abs(dx)) < tol * (1.0 + np.max(np.abs(x))):
                break
        else:
            raise RuntimeError("the surface's equilibrium state did not converge")
        return full(x), x[js].copy()
