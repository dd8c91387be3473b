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
    """(coordinates (N, 2), displacement (N, 2)) at the nodes on facet groups, gathered on every
    rank, one row per node. ``array`` is a mixed-space array (a state or a mode)."""
    p = problem
    V, dofs_in_W = p.V_u, p.u_dofs
    fdim = p.domain.topology.dim - 1
    facets = np.unique(np.concatenate([p.tm.facets(g) for g in groups])) if groups else np.empty(0, np.int32)
    blocks = compat.locate_dofs_on_facets(V, fdim, facets)
    n_owned = V.dofmap.index_map.size_local
    blocks = blocks[blocks < n_owned]
    coords = V.tabulate_dof_coordinates()[blocks, :2]
    values = np.stack([array[dofs_in_W[2 * blocks]], array[dofs_in_W[2 * blocks + 1]]], axis=-1)
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
    """How the permeable surface's shape is measured: an open, nearly straight surface (``along``, the bilayer)
    or a closed one (``around``, a tube's passage). A geometry kind names its shape
    (``GeometrySetup.wrinkles``); the counts, profiles, contact check, plots and bisection ask this object."""

    name = ""
    closed = False
    count_step = 0.5  # the resolution of a wrinkle count (half a wave along an open surface)
    position_label = "position along the surface [mm]"

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


def shape_of(problem) -> SurfaceShape:
    """The shape measure the problem's geometry kind named."""
    return SHAPES.get(problem.geo.wrinkles)


class GrowthMeasure:
    """What the run reports as the growth [mm] (``GeometrySetup.growth`` names it): ``bind(problem)`` returns
    the function of the converged state that measures it (collective)."""

    name = ""

    def bind(self, problem):
        raise NotImplementedError


class MeanNormal(GrowthMeasure):
    """The paper's growth: the mean displacement of the permeable surface along the body's outward normal."""

    name = "mean_normal"

    def bind(self, problem):
        import ufl

        u_n, _ = ufl.split(problem.state)
        form = compat.form(ufl.dot(u_n, ufl.FacetNormal(problem.domain)) * problem.ds_permeable)
        return lambda: compat.assemble_scalar(form, problem.comm) / problem.surface_length


class MeanRadial(GrowthMeasure):
    """A tube: the mean inward radial displacement of the passage's nodes about the axis (arc-length weighted)."""

    name = "mean_radial"

    def bind(self, problem):
        def growth() -> float:
            coords, disp = boundary_displacement(problem, problem.state.x.array,
                                                 problem.geo.facets_with_role("permeable"))
            _, radial, weights, _ = around_profile(coords, disp, centre=(0.0, 0.0))
            return float(-np.sum(weights * radial) / np.sum(weights))

        return growth


class AtVertex(GrowthMeasure):
    """The inward displacement of one node (``GeometrySetup.growth_point`` along ``growth_direction``): the
    elliptic passage's minor-axis vertex."""

    name = "vertex"

    def bind(self, problem):
        from mpi4py import MPI

        geo, comm = problem.geo, problem.comm
        X = problem.V_u.tabulate_dof_coordinates()[:, :2]
        n_owned = problem.V_u.dofmap.index_map.size_local
        d = np.linalg.norm(X[:n_owned] - np.asarray(geo.growth_point), axis=1)
        i = int(np.argmin(d)) if n_owned else -1
        best = comm.allreduce(float(d[i]) if n_owned else np.inf, op=MPI.MIN)
        if best > 1e-8:
            raise RuntimeError(f"no mesh node at the growth point {geo.growth_point} (nearest {best:.3g} mm away)")
        dofs = problem.u_dofs[[2 * i, 2 * i + 1]] if n_owned and d[i] == best else None  # (u_x, u_y) in W

        def growth() -> float:
            local = float(np.dot(problem.state.x.array[dofs], geo.growth_direction)) if dofs is not None else 0.0
            return comm.allreduce(local)

        return growth


GROWTH: Registry[GrowthMeasure] = Registry("growth measure")
for _measure in (MeanNormal(), MeanRadial(), AtVertex()):
    GROWTH.register(_measure)


def mode_wrinkle_count(problem, mode: np.ndarray) -> float:
    """Wrinkle count of a mode on the permeable surface: half-waves/2 along an open surface (bilayer),
    integer wavenumber around a closed one (tube)."""
    coords, disp = boundary_displacement(problem, mode, problem.geo.facets_with_role("permeable"))
    return shape_of(problem).mode_count(coords, disp)


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
