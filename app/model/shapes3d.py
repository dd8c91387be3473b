"""How a 3D permeable surface's shape is measured (numpy only): a flat surface over a rectangle with its sides
on rollers (``plane``, the 3D plate's top) and a cylinder (``cylinder``, the 3D tube's passage), each by its
strongest shape of those the sides allow, with its wave vector; a surface's overhang on a tensor grid of nodes
(where a followed 3D branch ends). Both register in :data:`app.model.shapes.SHAPES`.
"""

from __future__ import annotations

import numpy as np

from app.model.shapes import SHAPES, SurfaceShape


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
        normal = np.sum(disp[:, :2] * rel, axis=1) / radius
        return np.column_stack([phase[inverse.ravel()], coords[:, 2]]), normal, scale

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


SHAPES.register(PlaneSurface())
SHAPES.register(CylinderSurface())
