"""How a permeable surface's shape is measured, given its nodes' positions and displacement (numpy only): the
shape measures in a registry SHAPES (``GeometrySetup.wrinkles`` names one), and the 2D ones, along an open
surface (the bilayer) or around a closed one (a tube's passage). The 3D ones are :mod:`app.model.shapes3d`;
a problem's surface, state and mode are measured in :mod:`app.model.surface`.

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

import numpy as np

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


SHAPES: Registry[SurfaceShape] = Registry("surface shape")
SHAPES.register(OpenSurface())
SHAPES.register(ClosedSurface())
