"""Wrinkle count of a buckling mode from its surface displacement profile.

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
    best_q, best_score = 0.0, -1.0
    for q in np.arange(0.5, max_half_waves + resolution / 2, resolution):
        A = np.column_stack([np.ones_like(xi), np.cos(q * np.pi * xi), np.sin(q * np.pi * xi)])
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        resid = y - A @ coef
        score = 1.0 - float(np.dot(resid, resid)) / total
        if score > best_score + 1e-12:
            best_q, best_score = float(q), score
    return best_q


def wrinkle_count(x: np.ndarray, y: np.ndarray, length: float, **kw) -> float:
    """N = (number of half-waves)/2, to half a wave."""
    return 0.5 * round(dominant_half_waves(x, y, length, **kw))


def band_vertex(counts, eigenvalues, step: float = 0.5) -> float | None:
    """Wrinkle count at the minimum of the dispersion curve lambda(N) sampled by several modes.

    Near a wrinkling onset the eigenvalues of neighbouring wrinkle counts are nearly equal, so which
    of them crosses zero first is decided by tiny details. Around the count n0 with the lowest
    eigenvalue, a parabola through the lowest eigenvalue of each count within n0 +- 2 steps (at
    least one on each side) locates the minimum; its vertex, kept within half a step of n0 and
    rounded to ``step``, is the count of the first crossing for a continuous spectrum. Far-away
    counts (global modes, the other branch of the dispersion curve) are left out of the fit.
    None if no such fit exists."""
    lowest: dict[float, float] = {}
    for n, lam in zip(counts, eigenvalues):
        if n is None or not np.isfinite(lam) or n <= 0:
            continue
        lowest[n] = min(lam, lowest.get(n, np.inf))
    if not lowest:
        return None
    n0 = min(lowest, key=lowest.get)
    near = sorted(n for n in lowest if abs(n - n0) <= 2 * step + 1e-9)
    if len(near) < 3 or min(near) >= n0 or max(near) <= n0:
        return None
    a, b, _ = np.polyfit(near, [lowest[n] for n in near], 2)
    if a <= 0:
        return None
    vertex = min(max(-b / (2 * a), n0 - step / 2), n0 + step / 2)
    return step * round(vertex / step)


def circumferential_wavenumber(theta: np.ndarray, r: np.ndarray) -> int:
    """Dominant integer wavenumber n of a periodic profile r(theta) (tubes): largest |DFT| for n >= 1."""
    theta = np.asarray(theta, float)
    r = np.asarray(r, float) - np.mean(r)
    n_max = max(2, len(theta) // 3)
    amps = [abs(np.sum(r * np.exp(-1j * n * theta))) for n in range(1, n_max + 1)]
    return int(np.argmax(amps)) + 1


def surface_profile(problem, mode_array: np.ndarray, facet_name: str = "top", component: int = 1):
    """Gather (x, value) of one displacement component of a mixed-space array along a boundary.

    Returns sorted numpy arrays on every rank (the boundary is small)."""
    from app import compat

    p = problem
    sub = p.W.sub(0).sub(component)
    V, dofs_in_W = compat.collapse(sub)
    fdim = p.domain.topology.dim - 1
    facets = p.tm.facets(facet_name)
    local = compat.locate_dofs_on_facets(V, fdim, facets)
    n_owned = V.dofmap.index_map.size_local
    local = local[local < n_owned]
    coords = V.tabulate_dof_coordinates()[local]
    values = mode_array[dofs_in_W[local]]
    data = p.comm.allgather((coords[:, 0].copy(), coords[:, 1].copy(), values.copy()))
    x = np.concatenate([d[0] for d in data])
    yc = np.concatenate([d[1] for d in data])
    v = np.concatenate([d[2] for d in data])
    order = np.argsort(x)
    return x[order], yc[order], v[order]
