"""The permeable surface of a problem: its nodes' displacement gathered on every rank, and measured by the shape
its geometry kind names (:mod:`app.model.shapes`, :mod:`app.model.shapes3d`): the wrinkle count and wave vector
of a mode (the onset's N_c), the amplitude and count of a state (history.csv's columns, wrinkles.png), and the
branch's recorded profiles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem

from app.model import shapes3d  # noqa: F401  (registers the 3D shape measures)
from app.model.shapes import SHAPES, SurfaceShape


def boundary_displacement(problem, array: np.ndarray, groups: list[str]):
    """(coordinates (N, d), displacement (N, d)) at the nodes on facet groups, gathered on every
    rank, one row per node (d = 2 or 3, the mesh's dimension). ``array`` is a mixed-space array (a state or
    a mode)."""
    p = problem
    V, dofs_in_W = p.V_u, p.u_dofs
    fdim = p.domain.topology.dim - 1
    d = p.domain.geometry.dim
    facets = np.unique(np.concatenate([p.tm.facets(g) for g in groups])) if groups else np.empty(0, np.int32)
    blocks = np.asarray(fem.locate_dofs_topological(V, fdim, facets), dtype=np.int32)
    n_owned = V.dofmap.index_map.size_local
    blocks = blocks[blocks < n_owned]
    coords = V.tabulate_dof_coordinates()[blocks, :d]
    values = np.stack([array[dofs_in_W[d * blocks + c]] for c in range(d)], axis=-1)
    data = p.comm.allgather((coords, values))
    return np.concatenate([d[0] for d in data]), np.concatenate([d[1] for d in data])


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
    sign is that of a fixed normal, the tangent turned anticlockwise, for a mode whose mean means nothing).
    Closed surfaces (tubes):
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
