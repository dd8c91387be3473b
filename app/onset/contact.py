"""Where the model ends on a buckled branch: the surface folding onto itself, or an element inverting.

Without self-contact (``stability.contact = false``, the default) the potential has no contact energy: once
wrinkles fold into a crease, the permeable surface passes through itself and the states that follow mean
nothing. With it (a penalty, :mod:`app.model.penalty`, or a barrier, :mod:`app.model.barrier`) the surface
holds, and a penalty that cannot hold a state is an overrun. In either case a cell with det F <= 0 cannot be
represented (the energy's ln J is undefined there). A run that follows the branch checks every accepted
state and ends with status "contact" (a crossing, or the penalty overrun) or "inverted", saying when and where,
instead of a Newton
failure (docs/postbuckling.md, docs/creases.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from app import compat, fem_utils
from app.model.kinematics import deformation_gradient
from app.model.polyline_penalty import GAP_LIMIT, crossing_segments
from app.model.surface import boundary_displacement, shape_of
from app.solvers.stepped_problem import ModelLimit

NO_CONTACT = ("without stability.contact the surface may pass through itself and no element may invert, the "
              "branch cannot be followed further")


@dataclass
class Limit:
    """A state the model cannot represent: which ("contact" / "inverted"), where, and a sentence."""

    status: str
    where: tuple[float, ...]  # (x, y) or (x, y, z)
    detail: str
    consequence: str = NO_CONTACT
    overshoot: bool = False  # a converged state that a shorter step may avoid (the stepper retries it)
    depth: float = 0.0  # a penetration that a stiffer penalty may hold, in elements (0: none)
    retry: str | None = None  # a converged state the stepper retries: "same" (the penalty was raised: the same
    # step again) or "shorter" (an overshoot a shorter step may avoid)


INVERTED = "the model has no inverted elements, the branch cannot be followed further"
OVERRUN = "the contact penalty cannot hold this state, the branch cannot be followed further"
# an overrun that a tenfold stiffer penalty reduced by less than this factor is not the penalty's softness
LOCKED = 0.5


def _segments_cross(p: np.ndarray, closed: bool) -> tuple[int, int] | None:
    """The first pair (i, j) of non-adjacent segments of the polyline p (N, 2) that intersect or touch, else
    None (:func:`app.model.polyline_penalty.crossing_segments` on the polyline's segments)."""
    n = len(p) if closed else len(p) - 1
    if n < 4:
        return None
    i = np.arange(n)
    pairs = crossing_segments(p, np.stack([i, (i + 1) % len(p)], axis=1), touching=True)
    if not len(pairs):
        return None
    first = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))[0]]
    return int(first[0]), int(first[1])


def surface_contact(problem, array: np.ndarray) -> Limit | None:
    """Whether the deformed permeable surface of ``array`` intersects itself (same verdict on every rank)."""
    coords, disp = boundary_displacement(problem, array, problem.geo.facets_with_role("permeable"))
    shape = shape_of(problem)
    if shape.surface_dim == 2:  # 3D: no self-contact test of a surface; the branch ends where a fold begins
        where = shape.overhang(coords, disp)
        if where is None:
            return None
        return Limit("contact", where, "the surface overhangs (its normal has turned past 90 degrees: a fold "
                                       "begins) near the reference point (" + ", ".join(f"{v:.4g}" for v in where)
                     + ") mm", "3D self-contact is not modelled, the branch is not followed into the fold")
    order = shape.order(coords)
    x = (coords + disp)[order]
    pair = _segments_cross(x, shape.closed)
    if pair is None:
        return None
    where = tuple(float(v) for v in coords[order][pair[0]])
    return Limit("contact", where, f"the surface folds onto itself (self-contact, a crease) near the reference "
                                   f"point ({where[0]:.4g}, {where[1]:.4g}) mm")


class InversionCheck:
    """The smallest det F over the cells (at each cell's midpoint) of a mixed-space array."""

    def __init__(self, problem):
        self.p = problem
        self.V0 = compat.scalar_space(problem.domain, "DG", 0)
        self._u = fem.Function(problem.V_u)
        self._J = fem.Function(self.V0)
        self._expr = compat.expression(ufl.det(deformation_gradient(self._u)), self.V0)
        self._mid = None

    def __call__(self, array: np.ndarray) -> Limit | None:
        p = self.p
        self._u.x.array[:] = array[p.u_dofs]
        self._J.interpolate(self._expr)
        n_owned = fem_utils.num_owned_cells(p.domain)
        J = self._J.x.array[:n_owned]
        i = int(np.argmin(J)) if n_owned else -1
        local = float(J[i]) if n_owned else np.inf
        jmin = p.comm.allreduce(local, op=MPI.MIN)
        if jmin > 0:
            return None
        if self._mid is None:
            self._mid = self.V0.tabulate_dof_coordinates()[:, :p.domain.geometry.dim]
        mine = tuple(float(v) for v in self._mid[i]) if n_owned and local == jmin else None
        where = next(w for w in p.comm.allgather(mine) if w is not None)
        # with self-contact on, only the inversion is beyond the model
        return Limit("inverted", where, f"an element inverts (det F = {jmin:.3g}) at ("
                     + ", ".join(f"{v:.4g}" for v in where) + ") mm",
                     INVERTED if p.contact is not None else NO_CONTACT)


def contact_summary(problem, rows: list[dict]) -> dict:
    """summary.json's ``creases`` block of a run with self-contact: the first state in contact (time, growth,
    applied strain, the deepest contact's reference place), the largest penetration of any recorded
    state, and the zones of the last state (each: its contact points' reference x and y range and its length)."""
    c = problem.contact
    touching = [r for r in rows if float(r.get("contact_length_mm") or 0.0) > 0.0]
    first = None
    if touching:
        r = touching[0]
        first = {"time": r["time"], "growth_mm": r["growth_mm"], "applied_strain": r["applied_strain"],
                 "position_mm": [r["contact_x_mm"], r["contact_y_mm"]]}
    zones = c.zone_summary(problem.state.x.array)
    raised = [{"time": t, "contact_stiffness": k} for t, k in c.raised]
    return {"contact": c.name, "contact_stiffness": c.kappa, "stiffened": raised, "first_contact": first,
            "max_penetration_mm": max((float(r.get("penetration_mm") or 0.0) for r in rows), default=0.0),
            "zones": zones}


def penalty_overrun(problem, array: np.ndarray) -> Limit | None:
    """With self-contact on: a state whose surface crosses itself where a node was pushed through beyond the
    pairing's reach (the same rule as the minimizer's objective,
    :meth:`app.model.penalty.PenaltyContact.objective`), or penetrates deeper than GAP_LIMIT of its
    element."""
    c = problem.contact
    if c.name == "barrier":  # no penetration to overrun; only a crossing the step filter missed
        where = c.crossing(array)
        if where is None:
            return None
        return Limit("contact", where[:2], "the surface passes through itself (a step the barrier's collision "
                     "filter did not stop: a shorter step)", OVERRUN, overshoot=True)
    state = c.state(array)
    pen = c.term
    if len(state.points):
        depth = -state.gaps / pen.element[state.points]
        k = int(np.argmax(depth))
        if depth[k] > GAP_LIMIT:
            where = tuple(float(v) for v in pen.Xp[state.points[k]])
            return Limit("contact", where, f"the contact penalty is overrun near ({where[0]:.4g}, {where[1]:.4g}) mm:"
                                           f" penetration {depth[k]:.3g} of the element (limit {GAP_LIMIT:g})",
                         OVERRUN, depth=float(depth[k]))
    where = c.tunnelled_crossing(array)  # the penalty's own overlaps in contact, within its reach, are not
    if where is None:
        return None
    return Limit("contact", where, f"the surface passes through itself near the reference point "
                                   f"({where[0]:.4g}, {where[1]:.4g}) mm, beyond the contact penalty's reach (a "
                                   "node tunnelled in one step: a shorter step or a stiffer penalty)", OVERRUN,
                 overshoot=True)


class ModelLimits:
    """Where a followed branch ends: both checks of an array (a converged state or a failed step's last
    iterate), and the rule for failed attempts. The :class:`~app.solvers.stepping.TimeStepper` builds one
    when it starts to follow minimizers and tells it of every step (``new_step``), failed attempt
    (``failed_attempt``), cut-back below dt_min (``out_of_steps``) and accepted state (``accepted``); it
    raises :class:`~app.solvers.stepped_problem.ModelLimit`, which ends the run with the limit's status.

    One failed attempt whose last iterate folds or inverts may be an overshoot that a shorter step avoids;
    when a second attempt of the same step does too, the branch itself runs into the limit."""

    def __init__(self, problem):
        self.p = problem
        self.inversion = InversionCheck(problem)
        self._folded: Limit | None = None  # the limit a failed attempt of the current step reached
        self._overrun: float | None = None  # the penetration of this step's last overrun, before a raise
        self._locked = False  # this step met a crossing that a stiffer penalty did not undo: no more raises

    def __call__(self, array: np.ndarray) -> Limit | None:
        if self.p.contact is not None:  # with self-contact the surface may touch itself, not pass through
            return self.inversion(array) or penalty_overrun(self.p, array)
        return self.inversion(array) or surface_contact(self.p, array)

    def _of(self, array: np.ndarray, iterate: bool = False) -> Limit | None:
        if not np.all(np.isfinite(array[self.p.u_dofs])):
            return None
        if iterate and self.p.contact is not None:  # an iterate may overrun the penalty; a state may not
            return self.inversion(array)
        return self(array)

    def new_step(self) -> None:
        self._folded = self._overrun = None
        self._locked = False

    def failed_attempt(self, array: np.ndarray, t_try: float, t: float) -> Limit | None:
        """The limit a failed attempt's last iterate reaches (for the log line), or None; ModelLimit when an
        earlier attempt of this step reached one too."""
        limit = self._of(array, iterate=True)
        if limit is not None:
            if self._folded is not None:
                raise ModelLimit(limit, t_try, accepted=t)
            self._folded = limit
        return limit

    def out_of_steps(self, t_try: float, t: float) -> None:
        """No smaller step is left: the limit a failed attempt reached ends the run (else the caller's
        failure)."""
        if self._folded is not None:
            raise ModelLimit(self._folded, t_try, accepted=t)

    def accepted(self, array: np.ndarray, t: float, retry: bool = False) -> Limit | None:
        """The checks of a converged step's state ``array`` (its displacement dofs): None, it is accepted;
        ModelLimit if it reaches a limit. With self-contact, a surface through which a node tunnelled beyond the
        penalty's reach is the step's overshoot, not yet the branch's end: the pairing follows every Newton
        iterate but reaches only ``REACH`` segment lengths through the surface, and a node that one iterate
        carries farther is missed. With ``retry`` (a shorter step is left) that limit is returned and the
        stepper cuts the step back; without, it ends the run. A state that penetrates deeper than GAP_LIMIT of
        its element raises the penalty (:meth:`app.model.penalty.PenaltyContact.stiffen`) and is returned with
        ``retry = "same"``: the stepper solves the same step again; past KAPPA_MAX it ends the run. A limit returned
        for a shorter step has ``retry = "shorter"``."""
        limit = self._of(array)
        if limit is None:
            return None
        if limit.overshoot and retry:
            limit.retry = "shorter"
            return limit
        if limit.depth:  # the penalty's own accuracy: raised until it holds the state, up to KAPPA_MAX
            before, self._overrun = self._overrun, limit.depth
            old = self.p.contact.kappa
            if self._locked or (before is not None and limit.depth > LOCKED * before):
                # a stiffer penalty did not push the node out: the faces crossed where the pairing holds both
                # sides (a node of each through the other), a state no penalty undoes; a shorter step may not
                # drive them through (and no further raise is tried in this step)
                self._locked = True
                limit.detail += (f", not reduced by raising the penalty to {old:g}: the surface is locked "
                                 "through itself")
                if retry:
                    limit.overshoot, limit.retry = True, "shorter"
                    return limit
            elif self.p.contact.stiffen(t):
                limit.retry = "same"
                limit.detail += f": the penalty is raised from {old:g} to {self.p.contact.kappa:g}"
                return limit
            else:
                limit.detail += f" with stability.contact_stiffness = {old:g}, the largest allowed"
        raise ModelLimit(limit, t)
