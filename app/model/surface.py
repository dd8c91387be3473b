"""The permeable surface's shape: its nodes' displacement, profiles along or around it, the wrinkle amplitude and
count of a state or a mode (the observables of history.csv, wrinkles.png and the onset's N_c), and the branch's
recorded profiles.

Wrinkle count of a buckling mode from its surface displacement profile.

Definition (bilayer): N_c is the number of wavelengths of the mode's normal displacement along the
film surface, to half a wave (N = 0.5, 1, 1.5, ...), i.e. k/2 where k is the number of half-waves
that best explains the profile. k is found by a least-squares periodogram: for trial wavenumbers
q (in half-waves over the length, continuous, step 0.02), fit a + b cos(q pi x/L) + c sin(q pi x/L)
and keep the q with the largest explained variance; k = round(q*). Fitting both cos and sin with a
free phase makes the count independent of how the mode sits against the ends, and the continuous
scan tolerates end effects and noise that shift or blur a discrete spectrum.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app import compat
from app.registry import Registry


def dominant_half_waves(x: np.ndarray, y: np.ndarray, length: float, max_half_waves: int | None = None,
                        resolution: float = 0.02) -> float:
    """Best-fitting (continuous) number of half-waves q* of profile y(x) on [x0, x0 + length]."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    order = np.argsort(x)
    x, y = x[order], y[order]
    if max_half_waves is None:
        max_half_waves = max(2, len(x) // 3)  # at least ~3 samples per half-wave
    xi = (x - x[0]) / length
    yc = y - y.mean()
    total = float(np.dot(yc, yc))
    if total == 0.0:
        return 0.0
    # All trial wavenumbers at once, through the 3x3 normal equations of each fit:
    # explained variance = (coef . A^T y - n ybar^2) / total.
    q = np.arange(0.5, max_half_waves + resolution / 2, resolution)
    phase = np.pi * np.outer(q, xi)
    c, s = np.cos(phase), np.sin(phase)
    n = float(len(xi))
    gram = np.empty((len(q), 3, 3))
    gram[:, 0, 0] = n
    gram[:, 0, 1] = gram[:, 1, 0] = c.sum(axis=1)
    gram[:, 0, 2] = gram[:, 2, 0] = s.sum(axis=1)
    gram[:, 1, 1] = np.einsum("ij,ij->i", c, c)
    gram[:, 1, 2] = gram[:, 2, 1] = np.einsum("ij,ij->i", c, s)
    gram[:, 2, 2] = np.einsum("ij,ij->i", s, s)
    rhs = np.stack([np.full(len(q), y.sum()), c @ y, s @ y], axis=1)
    coef = np.einsum("qij,qj->qi", np.linalg.pinv(gram), rhs)
    score = (np.einsum("qi,qi->q", coef, rhs) - n * y.mean() ** 2) / total
    best = int(np.flatnonzero(score >= score.max() - 1e-12)[0])
    return float(q[best])


def wrinkle_count(x: np.ndarray, y: np.ndarray, length: float, **kw) -> float:
    """N = (number of half-waves)/2, to half a wave."""
    return 0.5 * round(dominant_half_waves(x, y, length, **kw))


def circumferential_wavenumber(theta: np.ndarray, r: np.ndarray, weights: np.ndarray | None = None) -> int:
    """Dominant integer wavenumber n >= 1 of a periodic profile r(theta): the largest Fourier amplitude,
    with quadrature weights for unevenly spaced samples (default: even spacing)."""
    theta = np.asarray(theta, float)
    r = np.asarray(r, float)
    wts = np.ones_like(r) if weights is None else np.asarray(weights, float)
    r = r - np.sum(wts * r) / np.sum(wts)
    n_max = max(2, len(theta) // 3)
    amps = [abs(np.sum(wts * r * np.exp(-1j * n * theta))) for n in range(1, n_max + 1)]
    return int(np.argmax(amps)) + 1


def boundary_displacement(problem, array: np.ndarray, groups: list[str]):
    """(coordinates (N, d), displacement (N, d)) at the nodes on facet groups, gathered on every
    rank, one row per node (d = 2 or 3, the mesh's dimension). ``array`` is a mixed-space array (a state or
    a mode)."""
    p = problem
    V, dofs_in_W = p.V_u, p.u_dofs
    fdim = p.domain.topology.dim - 1
    d = p.domain.geometry.dim
    facets = np.unique(np.concatenate([p.tm.facets(g) for g in groups])) if groups else np.empty(0, np.int32)
    blocks = compat.locate_dofs_on_facets(V, fdim, facets)
    n_owned = V.dofmap.index_map.size_local
    blocks = blocks[blocks < n_owned]
    coords = V.tabulate_dof_coordinates()[blocks, :d]
    values = np.stack([array[dofs_in_W[d * blocks + c]] for c in range(d)], axis=-1)
    data = p.comm.allgather((coords, values))
    return np.concatenate([d[0] for d in data]), np.concatenate([d[1] for d in data])


def surface_tangent(coords: np.ndarray):
    """(centre, unit tangent) of an open, nearly straight surface's nodes: the principal direction, with a
    sign independent of the node order (its largest component positive)."""
    centre = coords.mean(axis=0)
    _, _, vt = np.linalg.svd(coords - centre, full_matrices=False)
    return centre, (vt[0] if vt[0][np.argmax(np.abs(vt[0]))] > 0 else -vt[0])


def along_profile(coords: np.ndarray, disp: np.ndarray):
    """Position along an open, nearly straight surface, the displacement normal to it, and its length."""
    centre, tangent = surface_tangent(coords)
    normal = np.array([-tangent[1], tangent[0]])
    t = (coords - centre) @ tangent
    order = np.argsort(t)
    return t[order], (disp @ normal)[order], float(t.max() - t.min())


def around_profile(coords: np.ndarray, disp: np.ndarray, centre=None):
    """Arc-length phase (0..2 pi), radial displacement and quadrature weights along a closed surface."""
    c = coords.mean(axis=0) if centre is None else np.asarray(centre)
    rel = coords - c
    theta = np.arctan2(rel[:, 1], rel[:, 0])
    order = np.argsort(theta)
    rel, disp = rel[order], disp[order]
    radial = np.sum(disp * rel, axis=1) / np.linalg.norm(rel, axis=1)
    seg = np.linalg.norm(np.roll(rel, -1, axis=0) - rel, axis=1)  # closing segment included
    s = np.concatenate([[0.0], np.cumsum(seg[:-1])])
    total = seg.sum()
    weights = 0.5 * (seg + np.roll(seg, 1))
    return 2 * np.pi * s / total, radial, weights, theta[order]


class SurfaceShape:
    """How the permeable surface's shape is measured: an open, nearly straight surface (``along``, the bilayer),
    a closed one (``around``, a tube's passage), and in 3D a flat one (``plane``, the plate's top) or a
    cylinder (``cylinder``, the 3D tube's passage; these two also give a mode's wave vector, ``wave_vector``,
    described by ``wave_label``, and the axes of its map from above, ``map_axes``). A geometry kind names its shape
    (``GeometrySetup.wrinkles``); the counts, profiles, contact check, plots and bisection ask this object."""

    name = ""
    closed = False
    count_step = 0.5  # the resolution of a wrinkle count (half a wave along an open surface)
    position_label = "position along the surface [mm]"
    wave_label = ""  # 3D surfaces: what a wave vector's two numbers count
    surface_dim = 1  # the permeable surface is a curve (2D) or a surface (3D: plane, cylinder)
    map_axes = ("", "")  # 3D surfaces: the axes of the mode's map from above

    def order(self, coords: np.ndarray) -> np.ndarray:
        """The order of the surface's nodes along it."""
        centre, tangent = surface_tangent(coords)
        return np.argsort((coords - centre) @ tangent)

    def mode_count(self, coords: np.ndarray, disp: np.ndarray) -> float:
        t, un, length = along_profile(coords, disp)
        return wrinkle_count(t, un, length)

    def detrended(self, coords: np.ndarray, disp: np.ndarray, outward: bool):
        """(position, normal displacement, weights, basis of its rigid and uniform parts)."""
        phase, radial, _ = along_profile(coords, disp)
        if outward and radial.mean() < 0:
            radial = -radial
        return phase, radial, np.ones_like(phase), np.stack([np.ones_like(phase), phase], axis=1)

    def count(self, position: np.ndarray, profile: np.ndarray, weights: np.ndarray) -> float:
        return wrinkle_count(position, profile, float(position.max() - position.min()))

    def plotted(self, coords: np.ndarray, disp: np.ndarray):
        """(position, normal displacement) for the mode plot."""
        t, un, _ = along_profile(coords, disp)
        return t - t.min(), un


class ClosedSurface(SurfaceShape):
    name = "around"
    closed = True
    count_step = 1.0  # an integer wavenumber around a closed surface
    position_label = "angle around the passage [deg]"

    def order(self, coords: np.ndarray) -> np.ndarray:
        rel = coords - coords.mean(axis=0)
        return np.argsort(np.arctan2(rel[:, 1], rel[:, 0]))

    def mode_count(self, coords: np.ndarray, disp: np.ndarray) -> float:
        phase, radial, weights, _ = around_profile(coords, disp)
        return float(circumferential_wavenumber(phase, radial, weights))

    def detrended(self, coords: np.ndarray, disp: np.ndarray, outward: bool):
        phase, radial, weights, _ = around_profile(coords, disp)
        return phase, radial, weights, np.stack([np.ones_like(phase), np.cos(phase), np.sin(phase)], axis=1)

    def count(self, position: np.ndarray, profile: np.ndarray, weights: np.ndarray) -> float:
        return float(circumferential_wavenumber(position, profile, weights))

    def plotted(self, coords: np.ndarray, disp: np.ndarray):
        _, radial, _, theta = around_profile(coords, disp)
        return np.degrees(theta), radial


class OpenSurface(SurfaceShape):
    name = "along"


def plane_axes(coords: np.ndarray) -> tuple[int, tuple[int, int]]:
    """(normal axis, (first, second) in-plane axes) of a flat surface lying across coordinate axes: its
    normal is the axis along which it is thinnest (the plate's top: y, in-plane x and z)."""
    extent = np.ptp(coords, axis=0)
    normal = int(np.argmin(extent))
    return normal, tuple(a for a in range(coords.shape[1]) if a != normal)


def plane_modes(position: np.ndarray, profile: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The profile on a rectangle's tensor grid of nodes (``position``: (N, 2) in-plane coordinates)
    expanded in cos(m pi a / La) cos(n pi b / Lb), the shapes a rectangle with sides on rollers allows:
    (energy (M + 1, N + 1), the fraction of the profile's squared norm in each (m, n)), trapezoidal weights,
    m and n up to the grid's Nyquist number. ``ValueError`` if the nodes are not a tensor grid."""
    a, b, f = on_grid(position, profile)
    wa, wb = trapezoid_weights(a), trapezoid_weights(b)
    ca = np.cos(np.pi * np.outer(np.arange(len(a)), (a - a[0]) / (a[-1] - a[0])))  # (m, node)
    cb = np.cos(np.pi * np.outer(np.arange(len(b)), (b - b[0]) / (b[-1] - b[0]))) if len(b) > 1 else np.ones((1, 1))
    wb = wb if len(b) > 1 else np.ones(1)
    proj = (ca * wa) @ f @ (cb * wb).T  # <f, phi_mn>
    norm = np.outer((ca ** 2) @ wa, (cb ** 2) @ wb)  # <phi_mn, phi_mn>
    total = float(np.einsum("i,ij,j->", wa, f ** 2, wb))
    energy = proj ** 2 / norm / total if total > 0 else np.zeros_like(proj)
    return energy, np.array([a[-1] - a[0], b[-1] - b[0]])


def trapezoid_weights(x: np.ndarray) -> np.ndarray:
    if len(x) < 2:
        return np.ones(1)
    h = np.diff(x)
    return np.concatenate([[h[0] / 2], (h[:-1] + h[1:]) / 2, [h[-1] / 2]])


def plane_wave_vector(position: np.ndarray, profile: np.ndarray) -> tuple[int, int]:
    """(m, n): the half-waves along the first and second in-plane axes of the profile's strongest
    :func:`plane_modes` shape, the uniform (0, 0) excluded."""
    energy, _ = plane_modes(position, profile)
    energy[0, 0] = -1.0
    m, n = np.unravel_index(int(np.argmax(energy)), energy.shape)
    return int(m), int(n)


def plane_count(m: int, n: int, lengths) -> float:
    """The wrinkle count of half-waves (m, n) on a rectangle of sides ``lengths``: |k| L_a / (2 pi), the
    wavelengths along the first side at the mode's |k|, which is the 2D N_c (half-waves / 2) for n = 0."""
    if lengths[1] <= 0:
        return 0.5 * m
    ratio = round(float(lengths[0] / lengths[1]), 9)  # the sides' ratio, free of the node coordinates' roundoff
    return 0.5 * float(np.hypot(m, n * ratio))


class PlaneSurface(SurfaceShape):
    """A flat surface over a rectangle with its sides on rollers (the 3D plate's top): the normal
    displacement over the two in-plane axes, counted by its strongest cos x cos shape (:func:`plane_modes`)."""

    name = "plane"
    surface_dim = 2
    position_label = "position on the surface [mm]"
    map_axes = ("x [mm]", "z [mm]")
    wave_label = "half-waves (m along x, n along z)"
    count_step = 0.0  # a count is |k| L / (2 pi) of half-wave pairs: no fixed step

    @staticmethod
    def _project(coords: np.ndarray, disp: np.ndarray):
        normal, (a, b) = plane_axes(coords)
        position = coords[:, [a, b]] - coords[:, [a, b]].min(axis=0)
        return position, disp[:, normal]

    def order(self, coords: np.ndarray) -> np.ndarray:
        _, (a, b) = plane_axes(coords)
        return np.lexsort((coords[:, b], coords[:, a]))

    def mode_count(self, coords: np.ndarray, disp: np.ndarray) -> float:
        position, un = self._project(coords, disp)
        return self.count(position, un, np.ones_like(un))

    def wave_vector(self, coords: np.ndarray, disp: np.ndarray) -> tuple[int, int]:
        """(m, n) half-waves of a mode's normal displacement along the surface's two in-plane axes."""
        position, un = self._project(coords, disp)
        return plane_wave_vector(position, un)

    def detrended(self, coords: np.ndarray, disp: np.ndarray, outward: bool):
        position, un = self._project(coords, disp)
        if outward and un.mean() < 0:
            un = -un
        basis = np.stack([np.ones_like(un), position[:, 0], position[:, 1]], axis=1)
        return position, un, np.ones_like(un), basis

    def count(self, position: np.ndarray, profile: np.ndarray, weights: np.ndarray) -> float:
        m, n = plane_wave_vector(position, profile)
        return plane_count(m, n, np.ptp(position, axis=0))

    def plotted(self, coords: np.ndarray, disp: np.ndarray):
        return self._project(coords, disp)

    def overhang(self, coords: np.ndarray, disp: np.ndarray):
        """Where the deformed surface first overhangs (:func:`overhang`), else None."""
        _, (a, b) = plane_axes(coords)
        ia, ib, ua, ub = _grid_axes(coords[:, a], coords[:, b])
        return overhang(coords, disp, ia, ib, (len(ua), len(ub)))


def periodic_weights(theta: np.ndarray) -> np.ndarray:
    """Trapezoidal weights of sorted angles on a closed circle (they sum to 2 pi)."""
    gaps = np.diff(np.concatenate([theta, [theta[0] + 2 * np.pi]]))
    return 0.5 * (gaps + np.roll(gaps, 1))


def cylinder_modes(position: np.ndarray, profile: np.ndarray) -> np.ndarray:
    """A profile on a cylinder's tensor grid of nodes (``position``: (N, 2) angle around [rad] and z along
    the axis) expanded in cos / sin(n theta) cos(m pi z / L_z), the shapes a tube with its ends on rollers
    allows: the fraction of the profile's squared norm in each (n, m) (cos and sin of one n together),
    n up to the ring's Nyquist number, m to the axis'. ``ValueError`` if the nodes are not a tensor grid."""
    th, z, f = on_grid(position, profile, (9, 12))
    wt, wz = periodic_weights(th), trapezoid_weights(z)
    n = np.arange(len(th) // 2 + 1)
    e = np.exp(-1j * np.outer(n, th))  # (n, node around)
    cz = np.cos(np.pi * np.outer(np.arange(len(z)), (z - z[0]) / (z[-1] - z[0]))) if len(z) > 1 else np.ones((1, 1))
    proj = (e * wt) @ f @ (cz * wz).T  # (n, m)
    norm = np.outer(np.where(n == 0, 2 * np.pi, np.pi), (cz ** 2) @ wz)
    total = float(np.einsum("i,ij,j->", wt, f ** 2, wz))
    return np.abs(proj) ** 2 / norm / total if total > 0 else np.zeros(proj.shape)


def cylinder_wave_vector(position: np.ndarray, profile: np.ndarray) -> tuple[int, int]:
    """(n, m): the waves around and the half-waves along the axis of the profile's strongest
    :func:`cylinder_modes` shape, the uniform (0, 0) excluded."""
    energy = cylinder_modes(position, profile)
    energy[0, 0] = -1.0
    n, m = np.unravel_index(int(np.argmax(energy)), energy.shape)
    return int(n), int(m)


class CylinderSurface(SurfaceShape):
    """A tube's passage in 3D: the radial displacement over the angle around and z along the axis, counted by
    its strongest cos / sin(n theta) cos(m pi z / L_z) shape (:func:`cylinder_modes`); the count is n, the 2D
    tube's."""

    name = "cylinder"
    surface_dim = 2
    closed = True
    count_step = 1.0  # an integer wavenumber around, as the 2D tube's
    position_label = "position on the passage [mm]"
    map_axes = ("arc length around the passage [mm]", "z along the axis [mm]")
    wave_label = "(n around, m half-waves along the axis)"

    @staticmethod
    def _project(coords: np.ndarray, disp: np.ndarray):
        """(the nodes' (phase around, z), radial displacement, the section's perimeter / 2 pi). The phase is the
        arc length around the passage's section (the same on every ring) scaled to 2 pi, as the 2D tube's
        (:func:`around_profile`), from the angle of the first node: on a circle it is the angle itself, on an
        elliptic passage its waves are counted as in 2D."""
        rel = coords[:, :2]
        radius = np.linalg.norm(rel, axis=1)
        theta = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * np.pi)
        theta[theta > 2 * np.pi - 1e-9] = 0.0  # a node at theta = 0 one roundoff below the x axis
        _, first, inverse = np.unique(np.round(theta, 9), return_index=True, return_inverse=True)
        section = rel[first]  # one node per angle, in increasing angle
        seg = np.linalg.norm(np.roll(section, -1, axis=0) - section, axis=1)  # the closing chord included
        phase = theta[first[0]] + 2 * np.pi * np.concatenate([[0.0], np.cumsum(seg[:-1])]) / seg.sum()
        scale = np.full(len(coords), seg.sum() / (2 * np.pi))
        return np.column_stack([phase[inverse.ravel()], coords[:, 2]]), np.sum(disp[:, :2] * rel, axis=1) / radius, scale

    def order(self, coords: np.ndarray) -> np.ndarray:
        position, _, _ = self._project(coords, np.zeros_like(coords))
        return np.lexsort((position[:, 1], position[:, 0]))

    def mode_count(self, coords: np.ndarray, disp: np.ndarray) -> float:
        return float(self.wave_vector(coords, disp)[0])

    def wave_vector(self, coords: np.ndarray, disp: np.ndarray) -> tuple[int, int]:
        """(n, m): waves around the passage and half-waves along the axis of a mode's radial displacement."""
        position, radial, _ = self._project(coords, disp)
        return cylinder_wave_vector(position, radial)

    def detrended(self, coords: np.ndarray, disp: np.ndarray, outward: bool):
        position, radial, _ = self._project(coords, disp)
        return (position, radial, np.ones_like(radial),
                np.stack([np.ones_like(radial), np.cos(position[:, 0]), np.sin(position[:, 0])], axis=1))

    def count(self, position: np.ndarray, profile: np.ndarray, weights: np.ndarray) -> float:
        return float(cylinder_wave_vector(position, profile)[0])

    def plotted(self, coords: np.ndarray, disp: np.ndarray):
        position, radial, radius = self._project(coords, disp)
        return np.column_stack([radius.mean() * position[:, 0], position[:, 1]]), radial

    def overhang(self, coords: np.ndarray, disp: np.ndarray):
        """Where the deformed passage first overhangs (:func:`overhang`, periodic around), else None."""
        position, _, _ = self._project(coords, np.zeros_like(coords))
        it, iz, th, z = _grid_axes(position[:, 0], position[:, 1], (9, 12))
        return overhang(coords, disp, it, iz, (len(th), len(z)), periodic=True)


def _grid_axes(a: np.ndarray, b: np.ndarray, digits: tuple[int, int] = (12, 12)):
    """(index along a, index along b, the grid's a values, its b values) of nodes lying on a tensor grid of the
    values a and b (rounded to ``digits``); ``ValueError`` if they do not."""
    ua, ub = np.unique(np.round(a, digits[0])), np.unique(np.round(b, digits[1]))
    if len(ua) * len(ub) != len(a):
        raise ValueError("the surface's nodes are not a tensor grid")
    return np.searchsorted(ua, np.round(a, digits[0])), np.searchsorted(ub, np.round(b, digits[1])), ua, ub


def on_grid(position: np.ndarray, profile: np.ndarray, digits: tuple[int, int] = (12, 12)):
    """(the grid's first-axis values, its second-axis values, the profile as an array over them) of a profile
    on a tensor grid of nodes (``position``: (N, 2)); ``ValueError`` if the nodes are not one."""
    ia, ib, a, b = _grid_axes(position[:, 0], position[:, 1], digits)
    f = np.zeros((len(a), len(b)))
    f[ia, ib] = profile
    return a, b, f


def overhang(coords: np.ndarray, disp: np.ndarray, ia: np.ndarray, ib: np.ndarray, sizes, periodic: bool = False):
    """The reference centre of the first grid cell of a 3D surface whose deformed normal has turned by 90
    degrees or more from its reference normal (the surface overhangs: no longer a graph over its reference, the
    first stage of a fold, which a surface must pass before it can touch itself), else None. Each cell's normal
    is the cross product of its diagonals; ``periodic``: the first index wraps around (a passage)."""
    X = np.zeros((*sizes, 3))
    x = np.zeros((*sizes, 3))
    X[ia, ib] = coords
    x[ia, ib] = coords + disp
    if periodic:
        X, x = np.concatenate([X, X[:1]]), np.concatenate([x, x[:1]])

    def normals(P):
        return np.cross(P[1:, 1:] - P[:-1, :-1], P[:-1, 1:] - P[1:, :-1])

    N, n = normals(X), normals(x)
    turned = np.einsum("ijk,ijk->ij", N, n) <= 0.0
    if not turned.any():
        return None
    i, j = np.argwhere(turned)[0]
    return tuple(float(v) for v in 0.25 * (X[i, j] + X[i + 1, j] + X[i, j + 1] + X[i + 1, j + 1]))


SHAPES: Registry[SurfaceShape] = Registry("surface shape")
SHAPES.register(OpenSurface())
SHAPES.register(ClosedSurface())
SHAPES.register(PlaneSurface())
SHAPES.register(CylinderSurface())


def shape_of(problem) -> SurfaceShape:
    """The shape measure the problem's geometry kind named."""
    return SHAPES.get(problem.geo.wrinkles)


def mode_wrinkle_count(problem, mode: np.ndarray) -> float:
    """Wrinkle count of a mode on the permeable surface: half-waves/2 along an open surface (bilayer),
    integer wavenumber around a closed one (tube)."""
    coords, disp = boundary_displacement(problem, mode, problem.geo.facets_with_role("permeable"))
    return shape_of(problem).mode_count(coords, disp)


def mode_wave_vector(problem, mode: np.ndarray) -> tuple[int, int] | None:
    """A mode's half-waves (m, n) along the two in-plane axes of a plane surface (the 3D plate's top); None
    for a surface measured along or around a curve."""
    shape = shape_of(problem)
    if not hasattr(shape, "wave_vector"):
        return None
    coords, disp = boundary_displacement(problem, mode, problem.geo.facets_with_role("permeable"))
    return shape.wave_vector(coords, disp)


# --- the shape of a state's surface (history columns amplitude_mm and wrinkle_count) ------------------

SHAPE_FLOOR = 1e-9  # amplitudes below this fraction of the surface's length are roundoff: count 0


def surface_profile(problem, array: np.ndarray, outward: bool = True):
    """The permeable surface's normal displacement in ``array`` with its rigid and uniform parts removed:
    (position, profile, weights, closed). Open surfaces (bilayer): position along the surface [mm], the
    normal displacement minus its least-squares mean and linear trend (a uniform swelling and a tilt),
    signed so that the mean displacement is >= 0 (outwards for a swelling body; with ``outward = False`` the
    sign is that of a fixed normal, the tangent turned anticlockwise, for a mode whose mean means nothing). Closed surfaces (tubes):
    phase 0..2 pi, the radial displacement minus its weighted mean and its n = 1 Fourier part (a uniform
    swelling and a rigid translation), with the arc-length quadrature weights."""
    coords, disp = boundary_displacement(problem, array, problem.geo.facets_with_role("permeable"))
    shape = shape_of(problem)
    phase, radial, weights, basis = shape.detrended(coords, disp, outward)
    sw = np.sqrt(weights)[:, None]
    coef = np.linalg.lstsq(basis * sw, radial * sw[:, 0], rcond=None)[0]
    return phase, radial - basis @ coef, weights, shape.closed


def surface_shape(problem, array: np.ndarray) -> tuple[float, float]:
    """(amplitude [mm], wrinkle count) of the surface profile (:func:`surface_profile`): the amplitude is
    half its peak-to-trough, the count its dominant wrinkle count with the definition of N_c (half-waves / 2
    along an open surface, the integer wavenumber around a closed one); 0 for a profile at roundoff
    (amplitude below 1e-9 of the surface's length), e.g. on the unbuckled path of a flat film."""
    pos, prof, weights, closed = surface_profile(problem, array)
    if prof.size < 3:
        return 0.0, 0.0
    amplitude = 0.5 * float(prof.max() - prof.min())
    if amplitude <= SHAPE_FLOOR * problem.surface_length:
        return amplitude, 0.0
    return amplitude, shape_of(problem).count(pos, prof, weights)


@dataclass
class SurfaceProfiles:
    """The surface profile (:func:`surface_profile`) of every state on a followed branch, in step order:
    what profiles.npz and wrinkles.png show, kept in checkpoints so that a resumed run's files cover the
    whole branch. The arrays are the same on every rank."""

    growth_mm: list = field(default_factory=list)
    time: list = field(default_factory=list)
    position: list = field(default_factory=list)
    profile: list = field(default_factory=list)
    closed: bool = False

    def add(self, growth_mm: float, time: float, position: np.ndarray, profile: np.ndarray, closed: bool) -> None:
        self.growth_mm.append(float(growth_mm))
        self.time.append(float(time))
        self.position.append(np.asarray(position, float))
        self.profile.append(np.asarray(profile, float))
        self.closed = bool(closed)

    def __len__(self) -> int:
        return len(self.time)

    def tuples(self) -> list[tuple]:
        """(growth_mm, time, position, profile) per state."""
        return list(zip(self.growth_mm, self.time, self.position, self.profile))

    def arrays(self) -> dict:
        """One array per name: growth_mm and time (steps,), position and profile (steps, surface nodes)."""
        return {"growth_mm": np.array(self.growth_mm, float), "time": np.array(self.time, float),
                "position": np.stack(self.position), "profile": np.stack(self.profile)}

    @classmethod
    def from_arrays(cls, arrays: dict, closed: bool) -> SurfaceProfiles:
        return cls([float(g) for g in arrays["growth_mm"]], [float(t) for t in arrays["time"]],
                   [np.array(p, float) for p in arrays["position"]],
                   [np.array(p, float) for p in arrays["profile"]], bool(closed))
