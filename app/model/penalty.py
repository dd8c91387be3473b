"""The self-contact penalty as a term of a :class:`~app.model.problem.Problem`'s incremental potential, in 2D
(docs/creases.md): :class:`PenaltyContact` gathers the traction-free surface on every rank
(:class:`~app.model.contact_surface.GatheredSurface`) and evaluates the penalty of
:mod:`app.model.polyline_penalty` on it. The barrier (:mod:`app.model.barrier`) is the other contact energy,
with the same interface.
"""

from __future__ import annotations

import numpy as np

from app.model.contact_surface import ContactTerms, Facet, GatheredSurface
from app.model.polyline_penalty import ContactState, PolylinePenalty, deepest


class PenaltyContact(GatheredSurface):
    """The self-contact penalty of a :class:`~app.model.problem.Problem`'s traction-free surface.

    The surface's nodes (their reference positions and global displacement dofs) and its segments
    (oriented outward) are gathered once on every rank; each evaluation gathers the surface nodes'
    current displacement from their owners and computes the whole term on every rank (the surface is
    a polyline of a few hundred nodes). The solvers add it to the energy, the residual and the Hessian
    (:class:`app.solvers.newton.NewtonSolver`'s ``extra``)."""

    name = "penalty"

    def __init__(self, problem, kappa: float):
        super().__init__(problem, kappa)
        self.term = PolylinePenalty(self.X, np.asarray(self.facets, np.int64).reshape(-1, 2), self.kappa * self._mu)

    def order(self, facets: list[Facet]) -> list[Facet]:
        """Each segment's midpoint, then its first end (a slit's two coincident faces run opposite ways)."""
        return sorted(facets, key=lambda f: ((f.points[0][0] + f.points[1][0]) / 2,
                                             (f.points[0][1] + f.points[1][1]) / 2, *f.points[0]))

    def state(self, owned_values) -> ContactState:
        return self.term.pairs(self.displacement(owned_values))

    def objective(self, owned_values) -> float:
        """The term's energy, or inf outside its domain: where a node has tunnelled through the surface
        beyond the pairing's reach (:meth:`~app.model.polyline_penalty.PolylinePenalty.tunnelled_crossings`).
        The minimizer's line search
        then shortens the step; the penalty alone, which falls to zero beyond the reach, would let a step
        tunnel a node through the surface and call it a decrease of the energy."""
        return self.term.objective(self.displacement(owned_values))

    def tunnelled_crossing(self, owned_values) -> tuple[float, float] | None:
        """The reference midpoint of the first segment of a crossing with a tunnelled node, or None."""
        found = self.term.tunnelled_crossings(self.displacement(owned_values))
        if not len(found):
            return None
        pen = self.term
        mid = 0.5 * (pen.X[pen.segments[found[0, 0], 0]] + pen.X[pen.segments[found[0, 0], 1]])
        return float(mid[0]), float(mid[1])

    def traction(self, owned_values) -> np.ndarray:
        """The contact traction (n, 2) [MPa] on each surface node: the penalty's force on the node (minus its
        gradient, from the pairs the node is in, on either side) over the node's tributary length (0 off
        contact)."""
        _, grad, _ = self.term.derivatives(self.displacement(owned_values), hessian=False)
        return -grad / self.term.tributary[:, None]

    def entry_blocks(self, owned_values) -> list:
        """The Hessian's blocks at the state ``owned_values`` (owned part of a mixed-space array), as
        (surface entries, H): entry 2 i + c is node i's displacement component c."""
        return self.term.derivatives(self.displacement(owned_values))[2]

    def terms(self, owned_values) -> ContactTerms:
        """The energy and gradient at the state ``owned_values``, in the mixed space's global dofs."""
        energy, grad, _ = self.term.derivatives(self.displacement(owned_values), hessian=False)
        return ContactTerms(energy, self.global_entries, grad.reshape(-1))

    def observables(self, owned_values) -> dict:
        """history.csv's contact columns (app.model.history's "contact" group) at a state: the surface length in
        contact, the zones, the deepest contact's reference place and its penetration (the penalty's gap)."""
        state = self.state(owned_values)
        pen = self.term
        at = deepest(state.points, state.gaps, pen.Xp) if len(state.points) else None
        return {"contact_length_mm": pen.contact_length(state), "creases": len(pen.zones(state)),
                "contact_x_mm": float(pen.Xp[at, 0]) if at is not None else float("nan"),
                "contact_y_mm": float(pen.Xp[at, 1]) if at is not None else float("nan"),
                "penetration_mm": float(-state.gaps.min()) if len(state.gaps) else 0.0}

    def zone_summary(self, owned_values) -> list[dict]:
        """The contact zones of a state: each one's contact points' reference x and y range and its length."""
        state = self.state(owned_values)
        pen = self.term
        zones = []
        for points in pen.zones(state):
            X = pen.Xp[points]
            zones.append({"x_mm": [float(X[:, 0].min()), float(X[:, 0].max())],
                          "y_mm": [float(X[:, 1].min()), float(X[:, 1].max())],
                          "length_mm": float(np.sum(pen.share[points]))})
        return zones
