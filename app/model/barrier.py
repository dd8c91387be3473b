"""Self-contact as a smooth barrier (incremental potential contact), the same code in 2D and 3D.

The surface that can touch itself (:mod:`app.model.contact_surface`: segments in 2D, each hexahedron's
quadrilateral facet cut into four triangles about its centre in 3D) carries the barrier of the IPC Toolkit
(``ipctk``, pinned in scripts/requirements.txt) in its convergent form (Li et al.: each pair of surface
primitives weighted by its reference area, overlapping pairs corrected by the improved max approximator):

    E_c = kappa mu  sum_pairs  w_pair  b(d_pair) / d_hat,      b(d) = -(d - d_hat)^2 ln(d / d_hat)  (d < d_hat)

with d the distance between two primitives of the deformed surface (point-edge in 2D; point-triangle and
edge-edge in 3D), d_hat the barrier's reach (BARRIER_REACH of the shortest reference edge of the surface), mu
the largest shear modulus of the layers and kappa ``stability.contact_stiffness``. b and its first two
derivatives vanish at d_hat, so E_c is twice continuously differentiable in the positions where the distance
is; it grows without bound as d -> 0, so no state of finite energy has the surface through itself, and every
iterate of the minimizer stays so: its line search starts at the largest step that continuous collision
detection finds free of any crossing (:meth:`BarrierContact.step_fraction`, scaled by STEP_SAFETY). Nothing
has to be raised or can lock: the barrier holds the faces a distance below d_hat apart (at kappa 1000 and a
contact pressure of mu, 0.99 d_hat), a fraction of an element that vanishes with the mesh.

Two Hessians: the stability criteria and the minimizer's final plain-Newton polish take the exact one
(:meth:`BarrierContact.entry_blocks`, whose inertia the criteria read); Newton's matrix otherwise takes each
pair's Hessian projected to positive semi-definite (:meth:`BarrierContact.newton_blocks`).
What the fluid does in contact: nothing changes, as with the penalty (:mod:`app.model.penalty`).
"""

from __future__ import annotations

import math

import numpy as np

from app.model.contact_surface import ContactTerms, Facet, GatheredSurface, connected_groups

BARRIER_REACH = 0.05  # d_hat: this fraction of the shortest reference edge of the surface
STEP_SAFETY = 0.9  # a Newton step starts at this fraction of the largest collision-free step
CCD_ITERATIONS = 100_000  # conservative advancement's iterations per pair (it stops short, safely, beyond)


def _ipctk():
    try:
        import ipctk
    except ImportError as err:  # pragma: no cover - installed by scripts/install.sh
        raise RuntimeError("the barrier contact needs ipctk (pip install -r scripts/requirements.txt)") from err
    # one thread: its parallel broad phase orders the pairs, and so the sums' roundoff, differently from run to
    # run (measured: the same 2D run took 141 or 288 shifted factorizations); the ranks are the parallelism here
    ipctk.set_num_threads(1)
    return ipctk


def cyclic(quad: list[int], X: np.ndarray) -> list[int]:
    """A quadrilateral's nodes in order around it (from its first node in the reference numbering, toward the
    lower numbered of its two neighbours): by their angle about the centroid in the quadrilateral's own plane
    (its two principal directions), whatever order the nodes come in."""
    P = X[quad] - X[quad].mean(axis=0)
    if P.shape[1] == 3:
        _, _, vt = np.linalg.svd(P)
        P = P @ vt[:2].T
    around = [quad[k] for k in np.argsort(np.arctan2(P[:, 1], P[:, 0]))]
    start = around.index(min(around))
    around = around[start:] + around[:start]
    return around if around[1] < around[3] else [around[0], *around[:0:-1]]


def split(quads: list[list[int]], X: np.ndarray):
    """The surface's quadrilaterals as triangles: each cut into four about its centre, a vertex of its own (the
    mean of its four nodes, where the bilinear face is), so that no diagonal is preferred (a fold's two faces
    are mirror images). Returns the centres' nodes (q, 4) and the triangles (4 q, 3) in the numbering of the
    nodes followed by the centres."""
    n = len(X)
    centres, tris = [], []
    for k, quad in enumerate(quads):
        ring = cyclic(quad, X)
        centres.append(ring)
        tris += [[ring[i], ring[(i + 1) % 4], n + k] for i in range(4)]
    return np.asarray(centres, np.int64).reshape(-1, 4), np.asarray(tris, np.int64).reshape(-1, 3)


class Barrier:
    """The barrier on a surface of nodes at reference positions ``X`` (n, dim) with ``edges`` (m, 2) and, in
    3D, triangular ``faces`` (f, 3), numbered over the nodes followed by ``centres`` (rows of four nodes: a
    vertex at their mean each; :func:`split`); ``stiffness`` is kappa mu (MPa). Every function takes and gives
    the nodes' displacements: the centres follow their nodes."""

    def __init__(self, X: np.ndarray, edges: np.ndarray, faces: np.ndarray | None, stiffness: float,
                 reach: float | None = None, centres: np.ndarray | None = None):
        ipc = self.ipc = _ipctk()
        self.X = np.asarray(X, float)
        self.n, self.dim = self.X.shape
        self.centres = np.zeros((0, 4), np.int64) if centres is None else np.asarray(centres, np.int64)
        self.Xc = self._vertices(self.X)
        edges = np.asarray(edges, np.int32).reshape(-1, 2)
        faces = np.zeros((0, 3), np.int32) if faces is None else np.asarray(faces, np.int32).reshape(-1, 3)
        self.mesh = ipc.CollisionMesh(self.Xc, edges, faces)
        # sweep and prune: its memory follows the primitives, not the space a step sweeps (the default hash grid
        # allocated 24 GB for a far-reaching trial step of a shifted Newton direction, measured)
        self.broad = ipc.SweepAndPrune()
        # conservative advancement (additive CCD): bounded work per pair; Tight Inclusion (the default) took
        # minutes on one step of a fold whose faces rest a barrier's reach apart (measured)
        self.ccd = ipc.AdditiveCCD(CCD_ITERATIONS)
        # the reach from the surface's own edges (between nodes: a quadrilateral's sides and diagonals, not its
        # centre's spokes), so that a plate one element wide has the plane-strain layer's d_hat
        own = edges[(edges < self.n).all(axis=1)]
        lengths = np.linalg.norm(self.Xc[own[:, 1]] - self.Xc[own[:, 0]], axis=1)
        self.dhat = float(BARRIER_REACH * lengths.min()) if reach is None else float(reach)
        self.stiffness = float(stiffness)
        if ipc.has_intersections(self.mesh, self.Xc, self.broad) or \
                self._collisions(self.Xc).compute_minimum_distance(self.mesh, self.Xc) <= 0.0:
            raise ValueError("the contact surface touches itself in the reference (a slit: its two faces lie on "
                             "each other, where the barrier is infinite)")
        # the area each node stands for (half its segments in 2D; its share of the triangles in 3D, a centre's
        # shared equally by its four nodes): tractions
        self.area = self.to_nodes(np.asarray(self.mesh.vertex_areas, float).reshape(-1, 1))[:, 0]

    def _vertices(self, x: np.ndarray) -> np.ndarray:
        """The collision vertices at node positions (or displacements) ``x``: the nodes, then the centres."""
        return np.ascontiguousarray(np.concatenate([x, x[self.centres].mean(axis=1)]))

    def to_nodes(self, g: np.ndarray) -> np.ndarray:
        """A gradient (or any additive quantity) on the collision vertices (n + q, k) gathered on the nodes."""
        out = np.array(g[:self.n], float)
        np.add.at(out, self.centres.reshape(-1), np.repeat(0.25 * g[self.n:], 4, axis=0))
        return out

    def _collisions(self, x: np.ndarray):
        ipc = self.ipc
        c = ipc.NormalCollisions()
        c.use_area_weighting = True
        c.collision_set_type = ipc.NormalCollisions.CollisionSetType.IMPROVED_MAX_APPROX
        c.build(self.mesh, x, self.dhat, 0.0, self.broad)
        return c

    def _potential(self):
        return self.ipc.BarrierPotential(self.dhat, self.stiffness, True)

    def energy(self, u: np.ndarray) -> float:
        """E_c at displacement ``u`` (n, dim); inf where the surface passes through itself."""
        x = self._vertices(self.X + u)
        if self.ipc.has_intersections(self.mesh, x, self.broad):
            return math.inf
        return float(self._potential()(self._collisions(x), self.mesh, x))

    def _on_nodes(self, ids: np.ndarray):
        """The entries (dim k,) of the k distinct nodes that collision vertices ``ids`` are made of, and the map
        T (dim len(ids), dim k) from their displacements to the vertices'."""
        terms = [(int(v), i, 1.0) if v < self.n else (int(m), i, 0.25)
                 for i, v in enumerate(ids) for m in ([v] if v < self.n else self.centres[v - self.n])]
        nodes = sorted({t[0] for t in terms})
        where = {v: k for k, v in enumerate(nodes)}
        P = np.zeros((len(ids), len(nodes)))
        for node, i, c in terms:
            P[i, where[node]] += c
        entries = (self.dim * np.asarray(nodes)[:, None] + np.arange(self.dim)).reshape(-1)
        return entries, np.kron(P, np.eye(self.dim))

    def derivatives(self, u: np.ndarray, hessian: bool = True, project: bool = False):
        """(energy, gradient (n, dim), Hessian blocks [(entries, H)] over the pairs within reach: entry
        dim i + c is node i's component c; empty without ``hessian``; with ``project`` each pair's block
        projected to positive semi-definite (its negative eigenvalues clamped to 0))."""
        x = self._vertices(self.X + u)
        C = self._collisions(x)
        B = self._potential()
        energy = float(B(C, self.mesh, x))
        grad = self.to_nodes(np.asarray(B.gradient(C, self.mesh, x)).reshape(-1, self.dim))
        blocks = []
        if hessian:
            E, F = self.mesh.edges, self.mesh.faces
            for k in range(len(C)):
                c = C[k]
                ids = np.asarray(c.vertex_ids(E, F))
                entries, T = self._on_nodes(ids[ids >= 0])
                method = self.ipc.PSDProjectionMethod.CLAMP if project else self.ipc.PSDProjectionMethod.NONE
                blocks.append((entries, T.T @ np.asarray(B.hessian(c, c.dof(x, E, F), method)) @ T))
                del c
        return energy, grad, blocks

    def pairs(self, u: np.ndarray):
        """The nodes within the barrier's reach of another part of the surface at ``u`` (a centre's: its four
        nodes) and their least distance: (nodes, distances)."""
        x = self._vertices(self.X + u)
        C = self._collisions(x)
        E, F = self.mesh.edges, self.mesh.faces
        best = np.full(self.n, np.inf)
        for k in range(len(C)):
            c = C[k]
            ids = np.asarray(c.vertex_ids(E, F))
            d = math.sqrt(max(float(c.compute_distance(c.dof(x, E, F))), 0.0))
            for v in ids[ids >= 0]:
                for i in ([v] if v < self.n else self.centres[v - self.n]):
                    best[i] = min(best[i], d)
            del c
        nodes = np.flatnonzero(np.isfinite(best))
        return nodes, best[nodes]

    def step_fraction(self, u0: np.ndarray, u1: np.ndarray) -> float:
        """The largest fraction of the straight path from ``u0`` to ``u1`` free of any crossing (continuous
        collision detection; the centres move on straight paths too), 1 when the whole path is."""
        return float(self.ipc.compute_collision_free_stepsize(self.mesh, self._vertices(self.X + u0),
                                                              self._vertices(self.X + u1), 0.0, self.broad,
                                                              self.ccd))


class BarrierContact(GatheredSurface):
    """The barrier self-contact of a :class:`~app.model.problem.Problem`'s traction-free surface, 2D or 3D,
    with the interface of :class:`app.model.penalty.PenaltyContact` (the solvers' ``extra`` term) and the
    minimizer's step filter (:meth:`step_fraction`)."""

    name = "barrier"

    def __init__(self, problem, kappa: float):
        super().__init__(problem, kappa)
        centres = None
        if self.dim == 2:
            edges, faces = np.asarray(self.facets, np.int64).reshape(-1, 2), None
        else:
            centres, faces = split(self.facets, self.X)
            edges = _ipctk().edges(faces.astype(np.int32))
        try:
            self.term = Barrier(self.X, edges, faces, self.kappa * self._mu, centres=centres)
        except ValueError as err:
            raise ValueError(f"stability.contact_energy = 'barrier': {err}; allowed there: 'penalty' (2D)") from err

    def order(self, facets: list[Facet]) -> list[Facet]:
        """Each facet's nodes by their reference positions (lexicographic in x, y[, z]; the barrier needs no
        orientation, and a quadrilateral's ring is found from its geometry: :func:`cyclic`), the facets by
        their nodes: the nodes are numbered alike whatever vertex order a partition gives a facet."""
        ordered = [Facet(*map(list, zip(*sorted(zip(f.dofs, f.points), key=lambda dp: dp[1])))) for f in facets]
        return sorted(ordered, key=lambda f: f.points)

    def objective(self, owned_values) -> float:
        """The term's energy, inf where the surface passes through itself."""
        return self.energy(owned_values)

    def terms(self, owned_values) -> ContactTerms:
        energy, grad, _ = self.term.derivatives(self.displacement(owned_values), hessian=False)
        return ContactTerms(energy, self.global_entries, grad.reshape(-1))

    def entry_blocks(self, owned_values) -> list:
        """The exact Hessian's blocks (the stability criteria read its inertia)."""
        return self.term.derivatives(self.displacement(owned_values))[2]

    def newton_blocks(self, owned_values) -> list:
        """The blocks Newton's matrix takes: each pair's Hessian projected to positive semi-definite (incremental
        potential contact's practice). The exact blocks' negative curvature (the distance's own, between an
        edge pair or a point and a triangle) is no instability of the body, yet with it the minimizer shifted K
        at every iteration of a fold closing in 3D and did not converge (the creasing plate one element wide:
        2808 shifted factorizations and a failed step exact, 122 and the whole run projected, measured)."""
        return self.term.derivatives(self.displacement(owned_values), project=True)[2]

    def step_fraction(self, owned_start, owned_step) -> float:
        """The fraction of the step ``owned_step`` (owned part of a mixed-space array, the iterate moving to
        ``owned_start - owned_step`` as in PETSc's line search) that is free of crossings, times
        STEP_SAFETY, capped at 1."""
        u0 = self.displacement(owned_start)
        du = self.displacement(owned_step)
        free = self.term.step_fraction(u0, u0 - du)
        return 1.0 if free >= 1.0 else STEP_SAFETY * free

    def crossing(self, owned_values) -> tuple | None:
        """None, or the reference place of a node of a surface that passes through itself (the first
        node)."""
        if not math.isinf(self.energy(owned_values)):
            return None
        return tuple(float(v) for v in self.X[0])

    def traction(self, owned_values) -> np.ndarray:
        """The contact traction (n, dim) [MPa] on each surface node: the barrier's force on it over the
        reference area (2D: length) it stands for."""
        _, grad, _ = self.term.derivatives(self.displacement(owned_values), hessian=False)
        return -grad / self.term.area[:, None]

    def observables(self, owned_values) -> dict:
        """history.csv's contact columns: the reference surface within the barrier's reach of another part
        (its nodes' areas), the zones (connected groups of such nodes along the surface), the place of the
        closest approach and, as "penetration", 0 (the barrier admits none)."""
        nodes, dist = self.term.pairs(self.displacement(owned_values))
        zones = self._zones(nodes)
        k = int(nodes[np.lexsort((*self.X[nodes].T[::-1], dist))[0]]) if len(nodes) else None
        return {"contact_length_mm": float(self.term.area[nodes].sum()), "creases": len(zones),
                "contact_x_mm": float(self.X[k, 0]) if k is not None else float("nan"),
                "contact_y_mm": float(self.X[k, 1]) if k is not None else float("nan"),
                "penetration_mm": 0.0}

    def _zones(self, nodes: np.ndarray) -> list[list[int]]:
        return connected_groups(set(int(i) for i in nodes), self.facets)

    def zone_summary(self, owned_values) -> list[dict]:
        """The contact zones of a state: each one's nodes' reference ranges (x, y[, z]) and area (2D: length)."""
        nodes, _ = self.term.pairs(self.displacement(owned_values))
        out = []
        for zone in self._zones(nodes):
            X = self.X[zone]
            z = {f"{a}_mm": [float(X[:, i].min()), float(X[:, i].max())] for i, a in enumerate("xyz"[:self.dim])}
            z["length_mm" if self.dim == 2 else "area_mm2"] = float(self.term.area[zone].sum())
            out.append(z)
        return out
