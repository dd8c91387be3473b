"""The surface that can touch itself, gathered on every rank: what both contact energies share (the penalty,
:mod:`app.model.penalty`, and the barrier, :mod:`app.model.barrier`), in 2D and 3D.

Every boundary facet whose role holds no displacement component (permeable, impermeable, free) is part of it:
a segment between two P1 nodes in 2D, a quadrilateral of four Q1 nodes in 3D. The facets of every rank are
gathered once, with their nodes' reference positions and global displacement dofs; each evaluation gathers the
surface nodes' current displacement from their owners and every rank computes the whole term (a surface is a
few hundred to a few thousand nodes). The subclass orders the facets by the reference geometry alone, so that
the nodes come in the same order on any number of ranks and partitions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import fem

from app import fem_utils

# roles of the surface that can touch itself: every boundary that holds no displacement component
CONTACT_ROLES = ("permeable", "impermeable", "free")
# a followed branch whose accepted state the term cannot hold raises its stiffness by STIFFEN and solves the
# step again, up to KAPPA_MAX (the top of stability.contact_stiffness's range)
STIFFEN = 10.0
KAPPA_MAX = 1.0e6


def connected_groups(inside, chains, bridges=()) -> list[list[int]]:
    """The groups of the members ``inside`` joined by ``chains`` (each joins those of its elements that are
    members) and then by ``bridges`` (each joins all its elements, adding those that are not members as links
    only), each group sorted, the groups by their first member."""
    parent = {int(i): int(i) for i in inside}

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(elements):
        elements = [int(e) for e in elements]
        for e in elements[1:]:
            parent[find(e)] = find(elements[0])

    for chain in chains:
        join([e for e in chain if int(e) in parent])
    for bridge in bridges:
        for e in bridge:
            parent.setdefault(int(e), int(e))
        join(bridge)
    groups: dict[int, list[int]] = {}
    for i in inside:
        groups.setdefault(find(int(i)), []).append(int(i))
    return sorted((sorted(g) for g in groups.values()), key=lambda g: g[0])


@dataclass
class ContactTerms:
    """A contact energy at one iterate, in the global numbering of the mixed space (the same on every rank):
    its energy and its gradient at ``grad_dofs``."""

    energy: float
    grad_dofs: np.ndarray  # (dim n,) global dofs (the displacement components of each surface node)
    grad: np.ndarray  # (dim n,)


@dataclass
class Facet:
    """One gathered facet: its nodes' global displacement dofs (one tuple of dim per node) and reference
    positions, in the facet's vertex order (2D: oriented so that the right-hand normal points out of the
    body)."""

    dofs: list
    points: list


class GatheredSurface:
    """The contact surface of a :class:`~app.model.problem.Problem` on every rank (see the module docstring).
    After construction: ``X`` (n, dim) the nodes' reference positions, ``dofs`` (n, dim) their global
    displacement dofs in the problem's mixed space, ``facets`` the node indices of each facet in the order of
    :meth:`order`. Entry dim i + c of every array of surface entries is node i's displacement component c."""

    #: the subclass's energy of the gathered nodes' displacement (its ``stiffness``, ``energy(u)``, derivatives):
    #: the penalty's :class:`~app.model.polyline_penalty.PolylinePenalty` or the barrier's ``Barrier``
    term = None

    def __init__(self, problem, kappa: float):
        p = self.p = problem
        self.kappa = float(kappa)
        self.raised: list[tuple[float, float]] = []  # (time, kappa) of each raise on a followed branch
        self._mu = max(float(getattr(m, m.law.stiffness)) for m in p.materials.values())
        dim = self.dim = p.domain.geometry.dim
        self.facets_gathered = self.order([f for part in p.comm.allgather(self._owned_facets()) for f in part])
        nodes: dict[int, int] = {}
        X, dofs, facets = [], [], []
        for f in self.facets_gathered:
            ij = []
            for d, x in zip(f.dofs, f.points):
                if d[0] not in nodes:
                    nodes[d[0]] = len(X)
                    X.append(x)
                    dofs.append(d)
                ij.append(nodes[d[0]])
            facets.append(ij)
        self.X = np.asarray(X, float).reshape(-1, dim)
        self.dofs = np.asarray(dofs, np.int64).reshape(-1, dim)
        self.facets = facets
        # the owned surface dofs of this rank: where the current displacement is read
        n_owned = fem_utils.owned_size(p.W)
        gdofs = fem_utils.global_indices(p.W, p.u_dofs)
        local = {int(g): int(i) for i, g in zip(p.u_dofs, gdofs) if i < n_owned}
        flat = self.dofs.reshape(-1)
        self._mine = np.array([k for k, g in enumerate(flat) if int(g) in local], np.int64)
        self._mine_local = np.array([local[int(flat[k])] for k in self._mine], np.int64)
        # where this rank's owned surface entries sit in the displacement space (fields for ParaView)
        in_u = {int(w): i for i, w in enumerate(p.u_dofs)}
        self._mine_in_u = np.array([in_u[int(w)] for w in self._mine_local], np.int64)

    def _owned_facets(self) -> list[Facet]:
        """This rank's owned facets of the contact roles (2D segments oriented outward)."""
        p = self.p
        dim = self.dim
        groups = [g for g in p.geo.boundaries if p.geo.boundaries[g] in CONTACT_ROLES]
        domain, V, fdim = p.domain, p.V_u, p.domain.topology.dim - 1
        facets = p.facets_of(groups)
        facets = facets[facets < domain.topology.index_map(fdim).size_local]
        domain.topology.create_connectivity(fdim, fdim + 1)
        domain.topology.create_connectivity(fdim, 0)
        domain.topology.create_connectivity(fdim + 1, 0)
        f2c = domain.topology.connectivity(fdim, fdim + 1)
        f2v, c2v = domain.topology.connectivity(fdim, 0), domain.topology.connectivity(fdim + 1, 0)
        points = V.tabulate_dof_coordinates()[:, :dim]
        gdofs = fem_utils.global_indices(p.W, p.u_dofs)  # global W dof of each u dof (dim blk + c)
        cells = np.array([f2c.links(f)[0] for f in facets], np.int32)
        if dim == 2:
            mids = fem_utils.facet_midpoints(domain, facets) if len(facets) else np.empty((0, 2))
            cmids = fem_utils.cell_midpoints(domain, cells) if len(cells) else np.empty((0, 2))
        mine = []
        for k, (f, c) in enumerate(zip(facets, cells)):
            # a P1/Q1 cell's dofs follow its vertices: the facet's vertices' places in the cell give its dofs
            corners = list(c2v.links(c))
            cell_dofs = V.dofmap.cell_dofs(c)
            blk = np.array([cell_dofs[corners.index(v)] for v in f2v.links(f)])
            if dim == 2:
                t = points[blk[1]] - points[blk[0]]
                if (mids[k] - cmids[k]) @ np.array([t[1], -t[0]]) < 0:  # the right-hand normal points out
                    blk = blk[::-1]
            mine.append(Facet([tuple(int(gdofs[dim * b + c]) for c in range(dim)) for b in blk],
                              [tuple(float(v) for v in points[b]) for b in blk]))
        return mine

    def order(self, facets: list[Facet]) -> list[Facet]:
        """The gathered facets in an order of the reference geometry alone (the subclass's rule)."""
        raise NotImplementedError

    @property
    def size(self) -> int:
        return len(self.X)

    @property
    def global_entries(self) -> np.ndarray:
        """Global dof in the problem's mixed space of each surface entry (dim n,)."""
        return self.dofs.reshape(-1)

    def displacement(self, owned_values) -> np.ndarray:
        """The surface nodes' displacement (n, dim) from each rank's owned part of a mixed-space array (a
        PETSc vector's ``array`` or a Function's owned entries)."""
        flat = np.zeros(self.dofs.size)
        parts = self.p.comm.allgather((self._mine, np.asarray(owned_values)[self._mine_local]))
        for k, v in parts:
            flat[k] = v
        return flat.reshape(-1, self.dim)

    def stiffen(self, t: float) -> bool:
        """Raise kappa by STIFFEN (at the time ``t`` of the step that needs it); False, unchanged, when that
        would pass KAPPA_MAX."""
        if self.kappa * STIFFEN > KAPPA_MAX * (1 + 1e-12):
            return False
        self.set_kappa(self.kappa * STIFFEN)
        self.raised.append((float(t), self.kappa))
        return True

    def set_kappa(self, kappa: float) -> None:
        self.kappa = float(kappa)
        if self.term is not None:
            self.term.stiffness = self.kappa * self._mu

    def energy(self, owned_values) -> float:
        """The contact energy at the state ``owned_values`` (owned part of a mixed-space array)."""
        return self.term.energy(self.displacement(owned_values))

    def traction_into(self, f, owned_values) -> None:
        """Write the subclass's ``traction`` (n, dim) into a Function ``f`` of the problem's displacement
        space."""
        f.x.array[:] = 0.0
        f.x.array[self._mine_in_u] = self.traction(owned_values).reshape(-1)[self._mine]
        f.x.scatter_forward()

    def entries_in(self, space, V, u_dofs) -> np.ndarray:
        """Global dof in ``space`` of each surface entry (dim n,), for a mixed space whose displacement part,
        collapsed, is ``V`` (P1 like the problem's; ``u_dofs``: V's index -> space's local dof), as the
        stability criteria's own spaces: the numbering is carried over by interpolating entry numbers (P1
        to P1 on one mesh: node to node, slits included)."""
        p = self.p
        number = fem.Function(p.V_u)
        number.x.array[:] = -1.0
        number.x.array[self._mine_in_u] = self._mine.astype(float)
        number.x.scatter_forward()
        there = fem.Function(V)
        there.interpolate(number)
        values = np.rint(there.x.array[:fem_utils.owned_size(V)]).astype(np.int64)
        local = np.flatnonzero(values >= 0)
        glob = fem_utils.global_indices(space, np.asarray(u_dofs)[local])
        out = np.full(self.dim * self.size, -1, np.int64)
        for k, g in p.comm.allgather((values[local], glob)):
            out[k] = g
        return out
