"""Self-contact of the traction-free surface as a term of the incremental potential (docs/creases.md).

The surface (every boundary facet whose role holds no displacement: permeable, impermeable, free) is a
polyline of segments between P1 nodes. Its contact points are its nodes and its segments' midpoints
(Simpson's rule on every segment). A point that has passed through the surface is penalized by

    E_c = sum_p  w_p kappa mu / 2  g_p^2,    g_p = -(distance from x_p to the face it has passed)

with x the deformed positions, mu the largest shear modulus of the layers (out-of-plane depth 1 mm, like
every 2D energy here) and w_p Simpson's weights (1/6 at each end of a segment, 2/3 at its midpoint: a
segment's weights sum to 1). The distance is to the nearest place of the faces the point faced in the
reference: to a segment it projects onto (projection in [0, 1], g the signed distance from the segment's
line) or, in the wedge behind a concave joint where it projects onto neither of the joint's segments, to
the joint's node. So E_c is a continuous function of the positions (a point sliding over a joint changes its
energy continuously, as the minimizer's line search needs), continuously differentiable but at the kinks
where the nearest place changes. A uniform gap g along a segment of length l costs kappa mu g^2 / 2 per
segment: an interface of stiffness kappa mu / l. The contact pressure is p = kappa mu |g| / l, so the
penetration |g| = p l / (kappa mu) is a fraction p / (kappa mu) of an element, and it vanishes with the mesh.
Every point is checked against every segment (each side of a contact is both slave and master), so the term
is symmetric between the two faces. The midpoints hold corners: a node-only pairing lets two convex
corners that press on each other (a slit's mouth) slide past each other at the cost of a sliver's
penetration (their nodes barely inside the other face), while the segments behind them pass through each
other; their midpoints see that.

The term is a function of the surface nodes' displacements only; :class:`PolylinePenalty` evaluates its
value, gradient and exact Hessian (the Gauss-Newton part plus g times the curvature of g; behind a concave
joint the identity in x_p - x_v) on the gathered surface. What the fluid does in contact: nothing changes.
The permeable surface stays at the bath's chemical potential where it touches itself: the walls of a crease
or fold still bound a film of the bath (a gel's surface is never sealed by a touching gel surface: both are
the same solvent), and the contact zones are short against the diffusion length, so the flux boundary
condition is left as it is.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from app.model.contact_surface import connected_groups

REACH = 0.5  # a point is paired with a segment it has passed by at most this times the segment's length
OVERLAP = 1e-3  # the tunnel check: a segment's projection range [0, 1] widened by this at each end

# the rotation of the plane by +90 degrees
_R = np.array([[0.0, -1.0], [1.0, 0.0]])


@dataclass
class ContactState:
    """What the penalty sees at one state: its energy, the active pairs and their gaps."""

    energy: float
    points: np.ndarray  # (P,) contact point of each active pair (a node, or n + j: segment j's midpoint)
    segments: np.ndarray  # (P,) master segment of each pair (behind a concave joint: the segment ending there)
    gaps: np.ndarray  # (P,) g < 0 [mm]
    at_joint: np.ndarray  # (P,) bool: the gap is the distance to the end node of the segment (a concave joint)


def _gap_derivatives(p: np.ndarray, a: np.ndarray, b: np.ndarray):
    """g = (p - a) . n(a, b) (n: right-hand unit normal of b - a), its gradient (6,) and Hessian (6, 6) in
    z = (p, a, b), for one pair."""
    t, d = b - a, p - a
    L2 = t @ t
    L = np.sqrt(L2)
    c = t[0] * d[1] - t[1] * d[0]
    g = -c / L
    Rt, Rd = _R @ t, _R @ d
    g_t = Rd / L + c * t / L**3  # dg/dt
    g_d = -Rt / L  # dg/dd
    H_tt = (-(np.outer(Rd, t) + np.outer(t, Rd)) + c * np.eye(2)) / L**3 - 3.0 * c * np.outer(t, t) / L**5
    H_dt = -_R / L + np.outer(Rt, t) / L**3  # rows d, columns t
    # z -> (t, d): t = b - a, d = p - a
    M = np.zeros((4, 6))
    M[0:2, 4:6], M[0:2, 2:4] = np.eye(2), -np.eye(2)
    M[2:4, 0:2], M[2:4, 2:4] = np.eye(2), -np.eye(2)
    H = np.zeros((4, 4))
    H[0:2, 0:2], H[2:4, 0:2], H[0:2, 2:4] = H_tt, H_dt, H_dt.T
    grad = M.T @ np.concatenate([g_t, g_d])
    return g, grad, M.T @ H @ M


def _on_nodes(terms: list[tuple[int, int, float]], n_geo: int):
    """The surface entries (2 k,) and the map T (2 k, 2 n_geo) from derivatives in n_geo geometric points to
    derivatives in the k distinct nodes they are made of: ``terms`` lists (node, point, coefficient) with
    point = sum of coefficient x node (a midpoint is half of each end; a node may enter twice, as a
    midpoint's end and as the master segment's end)."""
    nodes = sorted({t[0] for t in terms})
    where = {v: k for k, v in enumerate(nodes)}
    P = np.zeros((len(nodes), n_geo))
    for node, point, c in terms:
        P[where[node], point] += c
    entries = np.stack([2 * np.array(nodes), 2 * np.array(nodes) + 1], axis=1).reshape(-1)
    return entries, np.kron(P, np.eye(2))


def crossing_segments(x: np.ndarray, segments: np.ndarray, touching: bool = False) -> np.ndarray:
    """The pairs (A, B), A < B, of segments (m, 2) of node indices, with no node in common, that cross at
    node positions ``x`` (n, 2): inside both (a node touching a segment is in contact, not through it;
    ``touching``: that counts too; collinear overlaps never count: a slit's two faces lie on each other in
    the reference). Candidates by
    their bounding boxes (sorted along x, each segment against those whose x range starts within its own),
    then the exact test: O(m log m) for a surface of short segments."""
    m = len(segments)
    p, q = x[segments[:, 0]], x[segments[:, 1]]
    lo, hi = np.minimum(p, q), np.maximum(p, q)
    order = np.argsort(lo[:, 0], kind="stable")
    end = np.searchsorted(lo[order, 0], hi[order, 0], side="right")
    start = np.arange(1, m + 1)
    counts = np.maximum(end - start, 0)
    first = np.repeat(np.arange(m), counts)
    offset = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    A, B = order[first], order[start[first] + offset]
    ea, eb = segments[A], segments[B]
    ok = (lo[A, 1] <= hi[B, 1]) & (lo[B, 1] <= hi[A, 1]) & (ea[:, 0] != eb[:, 0]) & (ea[:, 0] != eb[:, 1]) \
        & (ea[:, 1] != eb[:, 0]) & (ea[:, 1] != eb[:, 1])
    A, B = A[ok], B[ok]
    da, db, r = q[A] - p[A], q[B] - p[B], p[B] - p[A]

    def cross(v, w):
        return v[:, 0] * w[:, 1] - v[:, 1] * w[:, 0]

    den = cross(da, db)
    with np.errstate(divide="ignore", invalid="ignore"):
        s, t = cross(r, db) / den, cross(r, da) / den  # along A, along B
    if touching:
        hit = (den != 0) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    else:
        hit = (den != 0) & (s > 0) & (s < 1) & (t > 0) & (t < 1)
    return np.sort(np.stack([A[hit], B[hit]], axis=1), axis=1)


class PolylinePenalty:
    """The penalty on a surface of ``n`` nodes with reference positions ``X`` (n, 2) and segments
    ``segments`` (m, 2) of node indices, each ordered so that its right-hand normal points out of the
    body. ``stiffness`` is kappa mu (MPa). Its contact points are the nodes (point i: node i) and the
    segments' midpoints (point n + j: segment j's), each the mean of its two ``ends`` (a node's are itself)."""

    def __init__(self, X: np.ndarray, segments: np.ndarray, stiffness: float, reach: float = REACH):
        self.X = np.asarray(X, float)
        self.segments = np.asarray(segments, np.int64)
        self.stiffness = float(stiffness)
        self.reach = reach
        n, m = len(self.X), len(self.segments)
        a, b = self.X[self.segments[:, 0]], self.X[self.segments[:, 1]]
        L = self.seg_length = np.linalg.norm(b - a, axis=1)
        # a node's tributary reference length (half its segments'): its element size
        tributary = np.zeros(n)
        np.add.at(tributary, self.segments.reshape(-1), np.repeat(L / 2, 2))
        self.tributary = tributary
        # the contact points, Simpson's weights and each point's share of the surface length
        self.ends = np.concatenate([np.repeat(np.arange(n)[:, None], 2, axis=1), self.segments])
        self.Xp = 0.5 * (self.X[self.ends[:, 0]] + self.X[self.ends[:, 1]])
        count = np.bincount(self.segments.reshape(-1), minlength=n)
        self.weight = np.concatenate([count / 6.0, np.full(m, 2.0 / 3.0)])
        share = np.zeros(n)
        np.add.at(share, self.segments.reshape(-1), np.repeat(L / 6, 2))
        self.share = np.concatenate([share, 2.0 * L / 3.0])
        self.element = np.concatenate([tributary, L])  # the element length at each point
        # a point can only touch a segment it faces in the reference (on its outer side or on its line):
        # what lies behind a segment there is the body's own far side (a corner's other face), not contact
        t = b - a
        normal = np.stack([t[:, 1], -t[:, 0]], axis=1) / L[:, None]
        facing = np.einsum("ijk,jk->ij", self.Xp[:, None, :] - a[None, :, :], normal)
        # a point's partners: the segments it faced but its own (a node's two, a midpoint's one)
        own = np.zeros(facing.shape, bool)
        own[self.segments[:, 0], np.arange(m)] = True
        own[self.segments[:, 1], np.arange(m)] = True
        own[n + np.arange(m), np.arange(m)] = True
        self.partners = ~own & (facing >= -1e-9 * L[None, :])
        # the joints: each pair (J, K) of segments where K starts at the node where J ends; a point behind a
        # joint pairs with its node when it faced both segments in the reference
        starts = {int(s): k for k, (s, _) in enumerate(self.segments)}
        self.joints = np.array([(j, starts[int(e)]) for j, (_, e) in enumerate(self.segments) if int(e) in starts],
                               np.int64).reshape(-1, 2)
        J, K = self.joints.T
        self.joint_partners = self.partners[:, J] & self.partners[:, K]
        self.joint_depth = reach * np.minimum(L[J], L[K])

    @property
    def point_stiffness(self) -> np.ndarray:
        """Each point's stiffness: kappa mu times its weight."""
        return self.stiffness * self.weight

    def points(self, u: np.ndarray) -> np.ndarray:
        """The contact points' positions at displacement ``u`` (n, 2)."""
        x = self.X + u
        return 0.5 * (x[self.ends[:, 0]] + x[self.ends[:, 1]])

    def pairs(self, u: np.ndarray) -> ContactState:
        """The active pairs of displacement ``u`` (n, 2): each point with the segment or concave joint it has
        passed through least deeply (none if it is behind none within the reach)."""
        x = self.X + u
        xp = self.points(u)
        a, b = x[self.segments[:, 0]], x[self.segments[:, 1]]
        t = b - a
        L = np.linalg.norm(t, axis=1)
        n = np.stack([t[:, 1], -t[:, 0]], axis=1) / L[:, None]
        s, g = self._projections(xp, a, t, L, n)
        depth = self.reach * self.seg_length[None, :]
        active = (s >= 0.0) & (s <= 1.0) & (g < 0.0) & (g > -depth)
        # behind a concave joint: past the end of the first segment and before the start of the next, behind
        # both (at a convex joint that region lies in front of the face)
        J, K = self.joints.T
        wedge = self.joint_partners & (s[:, J] > 1.0) & (s[:, K] < 0.0) & (g[:, J] < 0.0) & (g[:, K] < 0.0)
        dist = np.full(wedge.shape, np.inf)
        wi, wq = np.nonzero(wedge)
        dist[wi, wq] = np.linalg.norm(xp[wi] - x[self.segments[J[wq], 1]], axis=1)
        wedge &= dist < self.joint_depth[None, :]
        points, segs, gaps, at_joint = [], [], [], []
        for i in np.flatnonzero(active.any(axis=1) | wedge.any(axis=1)):
            cand = np.flatnonzero(active[i])
            corners = np.flatnonzero(wedge[i])
            best_seg = g[i, cand].max() if len(cand) else -np.inf
            best_joint = -dist[i, corners].min() if len(corners) else -np.inf
            if best_joint > best_seg:  # the nearest place of the face is a concave joint's node
                q = corners[np.argmin(dist[i, corners])]
                points.append(i)
                segs.append(J[q])
                gaps.append(best_joint)
                at_joint.append(True)
                continue
            j = cand[np.argmax(g[i, cand])]  # the shallowest penetration: the nearest face
            # a point exactly over the joint of two segments of a straight face is as near to both: always the
            # later along the surface's direction (the one that starts where the other ends), a rule of the
            # geometry, not of the segments' numbering, so that it picks alike on any number of ranks
            tie = 1e-12 * self.seg_length[j]
            after = [k for k in cand if self.segments[k, 0] == self.segments[j, 1] and g[i, k] >= g[i, j] - tie]
            j = after[0] if after else j
            points.append(i)
            segs.append(j)
            gaps.append(g[i, j])
            at_joint.append(False)
        gaps = np.asarray(gaps, float)
        points = np.asarray(points, np.int64)
        energy = float(0.5 * np.sum(self.point_stiffness[points] * gaps**2)) if len(points) else 0.0
        return ContactState(energy, points, np.asarray(segs, np.int64), gaps, np.asarray(at_joint, bool))

    def _projections(self, xp, a, t, L, n):
        """s (projection along the segment, 0 to 1 on it) and g (signed distance from its line) of the
        partner pairs near enough to touch, as (points, segments) arrays, NaN elsewhere: the candidates are
        the points within reach of a segment's midpoint (a k-d tree: every pair that can touch lies within
        half the segment's length plus the reach of it), an O(n log m) search instead of every point against
        every segment (measured 1.3 against 6.3 ms on a folded face of 320 nodes, the size of the paper's
        bilayer's surface at element 0.008 mm; each Newton iteration evaluates the term several times)."""
        mid = a + 0.5 * t
        radius = float(np.max(0.5 * L + self.reach * self.seg_length)) * (1.0 + 1e-9)
        near = cKDTree(mid).query_ball_point(xp, radius)
        Ip = np.repeat(np.arange(len(xp)), [len(c) for c in near])
        Jc = np.fromiter((j for c in near for j in c), np.int64, count=len(Ip))
        keep = self.partners[Ip, Jc]
        Ip, Jc = Ip[keep], Jc[keep]
        rel = xp[Ip] - a[Jc]
        s = np.full(self.partners.shape, np.nan)
        g = np.full(self.partners.shape, np.nan)
        s[Ip, Jc] = np.einsum("ij,ij->i", rel, t[Jc]) / L[Jc] ** 2
        g[Ip, Jc] = np.einsum("ij,ij->i", rel, n[Jc])
        return s, g

    def energy(self, u: np.ndarray) -> float:
        return self.pairs(u).energy

    def objective(self, u: np.ndarray) -> float:
        """The energy at ``u``, or inf where a node has tunnelled through the surface
        (:meth:`tunnelled_crossings`)."""
        return math.inf if len(self.tunnelled_crossings(u)) else self.energy(u)

    def tunnelled_crossings(self, u: np.ndarray) -> np.ndarray:
        """The pairs (A, B) (k, 2) of surface segments that cross each other at displacement ``u`` where a node
        has tunnelled: an end node of A that faced B in the reference and now lies in B's projection range
        (widened by OVERLAP at each end) at least the pairing's reach (``reach`` x B's length) behind it, or the
        same with A and B exchanged. There the node's penalty has dropped to zero at once (kappa mu / 2
        (reach L)^2), although the surface has passed through itself: such a state is outside the domain of the
        term. The penalty's own small overlaps, within the reach, are not (the rule reads positions only, no
        pairing)."""
        x = self.X + u
        found = crossing_segments(x, self.segments)
        if not len(found):
            return found

        def tunnelled(A: int, B: int) -> bool:
            """Whether an end node of A lies in B's range, the reach or more behind it."""
            a, b = x[self.segments[B]]
            t = b - a
            L = float(np.linalg.norm(t))
            for i in self.segments[A]:
                d = x[i] - a
                s, g = (d @ t) / L**2, (t[1] * d[0] - t[0] * d[1]) / L  # g: along B's outward normal
                if self.partners[i, B] and -OVERLAP <= s <= 1.0 + OVERLAP and g <= -self.reach * self.seg_length[B]:
                    return True
            return False

        keep = [k for k, (A, B) in enumerate(found) if tunnelled(A, B) or tunnelled(B, A)]
        return found[keep]

    def derivatives(self, u: np.ndarray, hessian: bool = True):
        """(energy, gradient (n, 2), Hessian blocks [(entries, H)]: entry 2 i + c is node i's displacement
        component c; empty without ``hessian``) at displacement ``u``."""
        state = self.pairs(u)
        x = self.X + u
        xp = self.points(u)
        grad = np.zeros(2 * len(self.X))
        blocks = []
        k = self.point_stiffness
        for p, j, corner in zip(state.points, state.segments, state.at_joint):
            ia, ib = self.segments[j]
            c, d = self.ends[p]
            if corner:  # k / 2 |x_p - x_b|^2: the joint's node b pulls the point like a spring
                r = xp[p] - x[ib]
                dE, d2E = k[p] * np.concatenate([r, -r]), k[p] * np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]),
                                                                         np.eye(2))
                entries, T = _on_nodes([(c, 0, 0.5), (d, 0, 0.5), (ib, 1, 1.0)], 2)
            else:
                g, dg, d2g = _gap_derivatives(xp[p], x[ia], x[ib])
                dE, d2E = k[p] * g * dg, k[p] * (np.outer(dg, dg) + g * d2g)
                entries, T = _on_nodes([(c, 0, 0.5), (d, 0, 0.5), (ia, 1, 1.0), (ib, 2, 1.0)], 3)
            np.add.at(grad, entries, T @ dE)
            if hessian:
                blocks.append((entries, T @ d2E @ T.T))
        return state.energy, grad.reshape(-1, 2), blocks

    def contact_length(self, state: ContactState) -> float:
        """Reference surface length in contact: the shares of the points in contact [mm]."""
        return float(np.sum(self.share[state.points])) if len(state.points) else 0.0

    def zones(self, state: ContactState) -> list[list[int]]:
        """The contact zones: groups of points in contact joined along the surface (a midpoint and its
        segment's ends, both in contact, on either face) and across it (a point and the segment it touches)."""
        n = len(self.X)
        chains = ((int(a), int(b), n + j) for j, (a, b) in enumerate(self.segments))
        bridges = ((int(p), *(int(e) for e in self.segments[j]), n + int(j))
                   for p, j in zip(state.points, state.segments))
        return connected_groups(set(int(i) for i in state.points), chains, bridges)


# the gap a state may show: a penetration beyond this fraction of the node's tributary length means the
# penalty was overrun (a crossing the pairing no longer sees): the state is a model limit, not contact
GAP_LIMIT = 0.1


DEEPEST_TIE = 1e-6  # gaps within this fraction of the deepest are equally deep (a symmetric crease's two faces)


def deepest(nodes: np.ndarray, gaps: np.ndarray, X: np.ndarray) -> int:
    """The contact point (node or segment midpoint, reference positions ``X``) of the deepest contact: the least
    gap, and among gaps equal to it within DEEPEST_TIE (a crease's two faces penetrate each other equally by
    symmetry, and roundoff would pick either) the first in reference x, then y, so that the history's contact
    place does not flip between runs that differ by roundoff."""
    g = gaps.min()
    near = nodes[gaps <= g + DEEPEST_TIE * abs(g)]
    return int(near[np.lexsort((X[near, 1], X[near, 0]))[0]])
