"""Self-contact as a smooth barrier (incremental potential contact), the same code in 2D and 3D.

The surface that can touch itself (:mod:`app.model.contact_surface`: segments in 2D, each hexahedron's
quadrilateral facet split into two triangles in 3D) carries the barrier of the IPC Toolkit (``ipctk``, pinned
in scripts/requirements.txt) in its convergent form (Li et al.: each pair of surface primitives weighted by
its reference area, overlapping pairs corrected by the improved max approximator):

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

The Hessian is exact (no projection to positive semi-definite): the stability criteria read its inertia.
What the fluid does in contact: nothing changes, as with the penalty (:mod:`app.model.contact`).
"""

from __future__ import annotations

import math

import numpy as np

from app.model.contact_surface import ContactTerms, Facet, GatheredSurface

BARRIER_REACH = 0.05  # d_hat: this fraction of the shortest reference edge of the surface
STEP_SAFETY = 0.9  # a Newton step starts at this fraction of the largest collision-free step


def _ipctk():
    try:
        import ipctk
    except ImportError as err:  # pragma: no cover - installed by scripts/install.sh
        raise RuntimeError("the barrier contact needs ipctk (pip install -r scripts/requirements.txt)") from err
    # one thread: its parallel broad phase orders the pairs, and so the sums' roundoff, differently from run to
    # run (measured: the same 2D run took 141 or 288 shifted factorizations); the ranks are the parallelism here
    ipctk.set_num_threads(1)
    return ipctk


def triangles(quad: list[int], X: np.ndarray) -> list[list[int]]:
    """A quadrilateral facet's two triangles, split along the diagonal from its first node in the reference
    numbering (the surface's node order, the same on any number of ranks): the node opposite it is the
    farthest of the other three."""
    q = sorted(quad)
    first, rest = q[0], q[1:]
    opposite = max(rest, key=lambda k: float(np.linalg.norm(X[k] - X[first])))
    a, b = (k for k in rest if k != opposite)
    return [[first, a, opposite], [first, opposite, b]]


class Barrier:
    """The barrier on a surface of nodes at reference positions ``X`` (n, dim) with ``edges`` (m, 2) and, in
    3D, triangular ``faces`` (f, 3); ``stiffness`` is kappa mu (MPa)."""

    def __init__(self, X: np.ndarray, edges: np.ndarray, faces: np.ndarray | None, stiffness: float,
                 reach: float | None = None):
        ipc = self.ipc = _ipctk()
        self.X = np.asarray(X, float)
        self.dim = self.X.shape[1]
        edges = np.asarray(edges, np.int32).reshape(-1, 2)
        faces = np.zeros((0, 3), np.int32) if faces is None else np.asarray(faces, np.int32).reshape(-1, 3)
        self.mesh = ipc.CollisionMesh(self.X, edges, faces)
        lengths = np.linalg.norm(self.X[edges[:, 1]] - self.X[edges[:, 0]], axis=1)
        self.dhat = float(BARRIER_REACH * lengths.min()) if reach is None else float(reach)
        self.stiffness = float(stiffness)
        if ipc.has_intersections(self.mesh, self.X) or \
                self._collisions(self.X).compute_minimum_distance(self.mesh, self.X) <= 0.0:
            raise ValueError("the contact surface touches itself in the reference (a slit: its two faces lie on "
                             "each other, where the barrier is infinite)")
        # the area each node stands for (half its segments in 2D; a third of its triangles in 3D): tractions
        self.area = np.asarray(self.mesh.vertex_areas, float).reshape(-1)

    def _collisions(self, x: np.ndarray):
        ipc = self.ipc
        c = ipc.NormalCollisions()
        c.use_area_weighting = True
        c.collision_set_type = ipc.NormalCollisions.CollisionSetType.IMPROVED_MAX_APPROX
        c.build(self.mesh, np.ascontiguousarray(x), self.dhat)
        return c

    def _potential(self):
        return self.ipc.BarrierPotential(self.dhat, self.stiffness, True)

    def energy(self, u: np.ndarray) -> float:
        """E_c at displacement ``u`` (n, dim); inf where the surface passes through itself."""
        x = self.X + u
        if self.ipc.has_intersections(self.mesh, x):
            return math.inf
        return float(self._potential()(self._collisions(x), self.mesh, x))

    def derivatives(self, u: np.ndarray, hessian: bool = True):
        """(energy, gradient (n, dim), Hessian blocks [(entries, H)] over the pairs within reach: entry
        dim i + c is node i's component c; empty without ``hessian``)."""
        x = self.X + u
        C = self._collisions(x)
        B = self._potential()
        energy = float(B(C, self.mesh, x))
        grad = np.asarray(B.gradient(C, self.mesh, x)).reshape(-1, self.dim)
        blocks = []
        if hessian:
            E, F = self.mesh.edges, self.mesh.faces
            for k in range(len(C)):
                c = C[k]
                ids = np.asarray(c.vertex_ids(E, F))
                ids = ids[ids >= 0]
                entries = (self.dim * ids[:, None] + np.arange(self.dim)).reshape(-1)
                blocks.append((entries, np.asarray(B.hessian(c, c.dof(x, E, F)))))
                del c
        return energy, grad, blocks

    def pairs(self, u: np.ndarray):
        """The nodes within the barrier's reach of another part of the surface at ``u`` and their least
        distance: (nodes, distances)."""
        x = self.X + u
        C = self._collisions(x)
        E, F = self.mesh.edges, self.mesh.faces
        best = np.full(len(self.X), np.inf)
        for k in range(len(C)):
            c = C[k]
            ids = np.asarray(c.vertex_ids(E, F))
            d = math.sqrt(max(float(c.compute_distance(c.dof(x, E, F))), 0.0))
            for i in ids[ids >= 0]:
                best[i] = min(best[i], d)
            del c
        nodes = np.flatnonzero(np.isfinite(best))
        return nodes, best[nodes]

    def step_fraction(self, u0: np.ndarray, u1: np.ndarray) -> float:
        """The largest fraction of the straight path from ``u0`` to ``u1`` free of any crossing (continuous
        collision detection), 1 when the whole path is."""
        return float(self.ipc.compute_collision_free_stepsize(self.mesh, self.X + u0, self.X + u1))


class BarrierContact(GatheredSurface):
    """The barrier self-contact of a :class:`~app.model.problem.Problem`'s traction-free surface, 2D or 3D,
    with the interface of :class:`app.model.contact.SurfaceContact` (the solvers' ``extra`` term) and the
    minimizer's step filter (:meth:`step_fraction`)."""

    name = "barrier"

    def __init__(self, problem, kappa: float):
        super().__init__(problem, kappa)
        if self.dim == 2:
            edges, faces = np.asarray(self.facets, np.int64).reshape(-1, 2), None
        else:
            faces = np.array([t for quad in self.facets for t in triangles(quad, self.X)], np.int64).reshape(-1, 3)
            edges = _ipctk().edges(faces.astype(np.int32))
        try:
            self.barrier = Barrier(self.X, edges, faces, self.kappa * self._mu)
        except ValueError as err:
            raise ValueError(f"stability.contact_energy = 'barrier': {err}; allowed there: 'penalty' (2D)") from err

    def order(self, facets: list[Facet]) -> list[Facet]:
        """By the facet's reference nodes, sorted (lexicographic in x, y[, z])."""
        return sorted(facets, key=lambda f: sorted(f.points))

    def set_kappa(self, kappa: float) -> None:
        self.kappa = float(kappa)
        self.barrier.stiffness = self.kappa * self._mu

    def energy(self, owned_values) -> float:
        return self.barrier.energy(self.displacement(owned_values))

    def objective(self, owned_values) -> float:
        """The term's energy, inf where the surface passes through itself."""
        return self.energy(owned_values)

    def terms(self, owned_values) -> ContactTerms:
        energy, grad, _ = self.barrier.derivatives(self.displacement(owned_values), hessian=False)
        return ContactTerms(energy, self.global_entries, grad.reshape(-1))

    def entry_blocks(self, owned_values) -> list:
        return self.barrier.derivatives(self.displacement(owned_values))[2]

    def step_fraction(self, owned_start, owned_step) -> float:
        """The fraction of the step ``owned_step`` (owned part of a mixed-space array, the iterate moving to
        ``owned_start - owned_step`` as in PETSc's line search) that is free of crossings, times
        STEP_SAFETY, capped at 1."""
        u0 = self.displacement(owned_start)
        du = self.displacement(owned_step)
        free = self.barrier.step_fraction(u0, u0 - du)
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
        _, grad, _ = self.barrier.derivatives(self.displacement(owned_values), hessian=False)
        return -grad / self.barrier.area[:, None]

    def observables(self, owned_values) -> dict:
        """history.csv's contact columns: the reference surface within the barrier's reach of another part
        (its nodes' areas), the zones (connected groups of such nodes along the surface), the place of the
        closest approach and, as "penetration", 0 (the barrier admits none)."""
        nodes, dist = self.barrier.pairs(self.displacement(owned_values))
        zones = self._zones(nodes)
        k = int(nodes[np.lexsort((*self.X[nodes].T[::-1], dist))[0]]) if len(nodes) else None
        return {"contact_length_mm": float(self.barrier.area[nodes].sum()), "creases": len(zones),
                "contact_x_mm": float(self.X[k, 0]) if k is not None else float("nan"),
                "contact_y_mm": float(self.X[k, 1]) if k is not None else float("nan"),
                "penetration_mm": 0.0}

    def _zones(self, nodes: np.ndarray) -> list[list[int]]:
        inside = set(int(i) for i in nodes)
        parent = {i: i for i in inside}

        def find(i):
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        for f in self.facets:
            here = [int(i) for i in f if int(i) in inside]
            for i in here[1:]:
                parent[find(i)] = find(here[0])
        groups: dict[int, list[int]] = {}
        for i in inside:
            groups.setdefault(find(i), []).append(i)
        return sorted((sorted(g) for g in groups.values()), key=lambda g: g[0])

    def zone_summary(self, owned_values) -> list[dict]:
        """The contact zones of a state: each one's nodes' reference ranges (x, y[, z]) and area (2D: length)."""
        nodes, _ = self.barrier.pairs(self.displacement(owned_values))
        out = []
        for zone in self._zones(nodes):
            X = self.X[zone]
            z = {f"{a}_mm": [float(X[:, i].min()), float(X[:, i].max())] for i, a in enumerate("xyz"[:self.dim])}
            z["length_mm" if self.dim == 2 else "area_mm2"] = float(self.barrier.area[zone].sum())
            out.append(z)
        return out
