"""The pattern on a followed 3D branch: a surface's spectrum in the shapes its sides allow, its local texture
(where it is striped and along which wave vector), and the pattern they name (docs/three-d.md, "The pattern").

Two views, because neither alone tells the patterns apart:

- the **spectrum** (:func:`surface_spectrum`): the whole surface's squared norm in cos x cos shapes. One shape
  or an orthogonal pair of them names stripes, a checkerboard or squares;
- the **texture** (:func:`surface_texture`): the structure tensor of the surface's slope, averaged over a window
  of a third of the pattern's wavelength, gives at each point how striped the surface is there (the coherence, 1 for
  stripes, 0 for a checkerboard's bumps) and the local wave vector's direction. A herringbone is striped
  everywhere with its wave vectors in two directions, in domains whose walls run along a bisector of the two
  (the crests pass the wall unbroken); a labyrinth is striped everywhere with its wave vectors in every
  direction. On a rectangle with rollered sides each of a herringbone's oblique wave pairs is itself one
  cos x cos z shape, so the spectrum alone cannot tell it from a checkerboard or a mix: where its domains lie
  does.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from app.model.shapes import SurfaceShape
from app.model.shapes3d import cylinder_modes, on_grid, periodic_weights, plane_modes, trapezoid_weights
from app.model.surface import SurfaceProfiles

PATTERN_MULTIPLES = (1.1, 1.25, 1.5, 2.0)  # growth / g_c of the states a 3D branch's pattern is reported at
DOMINANT = 0.6  # a single shape (or an orthogonal pair) holding this fraction of the surface's squared norm
STRIPED = 0.5  # a surface whose slope-weighted mean coherence reaches this is striped (locally one wave vector)
TIGHT = 0.9  # a direction cluster whose doubled-angle resultant reaches this is one wave vector (about +-13 deg)
CLUSTER_SHARE = 0.2  # each of a herringbone's two directions holds at least this share of the striped surface
SPREAD = 0.5  # a striped surface whose doubled-angle resultant is below this has no preferred direction
WALL_ALIGNED = 5.0  # degrees: a herringbone's domain walls lie within this of a bisector of its wave vectors
ARMS_APART = 35.0  # degrees: a herringbone's two wave vectors at least this far apart (closer: wavy or bent stripes)
FLAT = 1e-12  # a surface whose non-uniform part holds less than this fraction of its squared norm is flat
WINDOW = 1.0 / 3.0  # the structure tensor's Gaussian window: this fraction of the pattern's wavelength


def surface_spectrum(shape: SurfaceShape, position: np.ndarray, profile: np.ndarray) -> list[tuple[int, int, float]]:
    """A 3D surface profile's shapes (i, j, fraction of its squared norm), strongest first: (m, n) half-waves
    along x and z on a plate (:func:`app.model.shapes3d.plane_modes`), (n around, m along the axis) on a passage
    (:func:`app.model.shapes3d.cylinder_modes`)."""
    if shape.name == "cylinder":
        energy = cylinder_modes(position, profile)
    else:
        energy, _ = plane_modes(position, profile)
    uniform, energy[0, 0] = energy[0, 0], 0.0
    if not np.all(np.isfinite(energy)) or uniform >= 1.0 - FLAT:
        energy[:] = 0.0  # a flat surface (or one at roundoff about its mean): no shape at all
    else:  # fractions of the profile's non-uniform part
        energy /= 1.0 - uniform
    order = np.argsort(energy, axis=None)[::-1]
    i, j = np.unravel_index(order, energy.shape)
    return [(int(a), int(b), float(energy[a, b])) for a, b in zip(i, j)]


def shape_coefficient(shape: SurfaceShape, position: np.ndarray, profile: np.ndarray, i: int, j: int) -> float:
    """The signed projection of a 3D surface profile on one of its shapes: cos(i pi x / L) cos(j pi z / W) on a
    plate, cos(i theta) cos(j pi z / L_z) on a passage (the profile's inner product with it over the shape's
    own, trapezoidal weights)."""
    if shape.name == "cylinder":
        a, b, f = on_grid(position, profile, (9, 12))
        wa = periodic_weights(a)
        phi_a = np.cos(i * a)
    else:
        a, b, f = on_grid(position, profile)
        wa = trapezoid_weights(a)
        phi_a = np.cos(np.pi * i * (a - a[0]) / (a[-1] - a[0]))
    wb = trapezoid_weights(b)
    phi_b = np.cos(np.pi * j * (b - b[0]) / (b[-1] - b[0])) if len(b) > 1 else np.ones(1)
    return float((wa * phi_a) @ f @ (wb * phi_b) / (((phi_a ** 2) @ wa) * ((phi_b ** 2) @ wb)))


# --- the texture: where the surface is striped, and along which wave vector ---------------------------------

@dataclass
class Texture:
    """A plate surface's local texture (:func:`surface_texture`). Directions are the local wave vector's angle
    from the first in-plane axis (x) in degrees, in (-90, 90]; a stripe's wave vector is across its crests.

    coherence: the slope-weighted mean coherence (1 striped everywhere, 0 bumps and dimples);
    resultant: how much the striped surface's wave vectors share one direction (1 one direction, 0 none);
    directions, shares, tightness: the two direction clusters that best describe the wave vectors, the share of
    the striped surface each holds and how tight each is (the doubled-angle resultant within it);
    domains: the connected regions of one cluster or the other at least a wavelength across;
    wall_angle: the direction of the walls between them (None without walls), and wall_offset its angle to the
    nearer bisector of the two directions; wavelength_mm: the window's wavelength (from the spectrum)."""

    coherence: float
    resultant: float
    directions: tuple[float, float]
    shares: tuple[float, float]
    tightness: tuple[float, float]
    domains: int
    wall_angle: float | None
    wall_offset: float | None
    wavelength_mm: float

    @property
    def striped(self) -> bool:
        return self.coherence >= STRIPED

    @property
    def herringbone(self) -> bool:
        """Striped, two tight directions (each holding CLUSTER_SHARE) at least ARMS_APART apart (closer ones are
        wavy or bent stripes), three or more domains, walls within WALL_ALIGNED of a bisector of the two
        directions (the crests cross them unbroken)."""
        between = abs(self.directions[0] - self.directions[1]) % 180.0
        between = min(between, 180.0 - between)
        return (self.striped and min(self.shares) >= CLUSTER_SHARE and min(self.tightness) >= TIGHT
                and between >= ARMS_APART and self.domains >= 3
                and self.wall_offset is not None and self.wall_offset <= WALL_ALIGNED)

    @property
    def labyrinth(self) -> bool:
        """Striped, with no preferred direction and not two tight ones: stripes meandering in every direction."""
        two = min(self.shares) >= CLUSTER_SHARE and min(self.tightness) >= TIGHT
        return self.striped and self.resultant < SPREAD and not two

    def summary(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


def _uniform(axis: np.ndarray) -> np.ndarray:
    return np.linspace(axis[0], axis[-1], len(axis))


def _resampled(a: np.ndarray, b: np.ndarray, f: np.ndarray):
    """The grid's profile on uniformly spaced axes with as many nodes (linear interpolation; a structured
    plate's top is uniform already and comes back unchanged)."""
    ua, ub = _uniform(a), _uniform(b)
    if np.allclose(ua, a, rtol=0, atol=1e-9 * np.ptp(a)) and np.allclose(ub, b, rtol=0, atol=1e-9 * np.ptp(b)):
        return a, b, f
    f = np.array([np.interp(ua, a, f[:, j]) for j in range(f.shape[1])]).T
    f = np.array([np.interp(ub, b, f[i]) for i in range(f.shape[0])])
    return ua, ub, f


def pattern_wavelength(spectrum: list[tuple[int, int, float]], lengths) -> float:
    """The pattern's wavelength [mm] on a plate of sides ``lengths``: 2 pi over the spectrum's mean |k|, each
    shape (m, n) at |k| = pi sqrt((m / La)^2 + (n / Lb)^2), weighted by its fraction."""
    along = 1.0 / lengths[1] if lengths[1] > 0 else 0.0
    ks = [(np.pi * np.hypot(m / lengths[0], n * along), f) for m, n, f in spectrum if f > 0]
    total = sum(f for _, f in ks)
    if not total:
        return float(max(lengths))
    return float(2 * np.pi / (sum(k * f for k, f in ks) / total))


def _two_clusters(z: np.ndarray, q: np.ndarray):
    """The two clusters of doubled-angle unit vectors ``z`` (weights ``q``, summing to 1) that explain them best
    (k-means on the circle from 12 starts): (labels, centres, shares, tightness)."""
    best = None
    for start in np.linspace(0.0, np.pi, 12, endpoint=False):
        centre = np.array([np.exp(1j * start), -np.exp(1j * start)])
        for _ in range(50):
            label = np.argmax(np.real(z[:, None] * np.conj(centre[None, :])), axis=1)
            sums = np.array([(q * z)[label == i].sum() for i in (0, 1)])
            new = np.where(np.abs(sums) > 0, sums / np.maximum(np.abs(sums), 1e-300), centre)
            if np.allclose(new, centre):
                break
            centre = new
        share = np.array([q[label == i].sum() for i in (0, 1)])
        tight = np.array([abs((q * z)[label == i].sum()) / share[i] if share[i] > 0 else 0.0 for i in (0, 1)])
        score = float(share @ tight)
        if best is None or score > best[0] + 1e-12:
            best = (score, label, centre, share, tight)
    return best[1:]


def surface_texture(shape: SurfaceShape, position: np.ndarray, profile: np.ndarray,
                    spectrum: list[tuple[int, int, float]] | None = None) -> Texture | None:
    """The local texture of a plate's surface profile (a tensor grid of nodes; None on a passage, whose
    profile keeps the angle around but not the radius, and on a surface a single node wide).

    The profile is extended evenly across each side (a rollered side is a mirror: the shapes it allows are even
    about it) and its slope g taken by central differences; the structure tensor J = <g g^T> is its Gaussian
    average with a standard deviation of a third of the pattern's wavelength (:func:`pattern_wavelength`), long
    enough to average a checkerboard's two slopes into an isotropic J and short enough to keep a herringbone's
    domains apart. At each node the coherence is (l1 - l2) / (l1 + l2) of J's eigenvalues and the wave vector
    J's leading eigenvector; the means are weighted by the slope (tr J), the directions by slope x coherence."""
    if shape.name == "cylinder":
        return None
    a, b, f = on_grid(position, profile)
    if len(a) < 3 or len(b) < 3:
        return None
    from scipy import ndimage

    spectrum = spectrum if spectrum is not None else surface_spectrum(shape, position, profile)
    if not spectrum or spectrum[0][2] <= 0.0 or not np.all(np.isfinite(f)):
        return None  # flat: no texture
    lengths = (a[-1] - a[0], b[-1] - b[0])
    wavelength = pattern_wavelength(spectrum, lengths)
    a, b, f = _resampled(a, b, f)
    ha, hb = a[1] - a[0], b[1] - b[0]
    mirror = np.concatenate([f, f[-2:0:-1]], axis=0)
    mirror = np.concatenate([mirror, mirror[:, -2:0:-1]], axis=1)  # periodic with period 2 L: the even extension
    ga = (np.roll(mirror, -1, 0) - np.roll(mirror, 1, 0)) / (2 * ha)
    gb = (np.roll(mirror, -1, 1) - np.roll(mirror, 1, 1)) / (2 * hb)
    sigma = (WINDOW * wavelength / ha, WINDOW * wavelength / hb)
    na, nb = f.shape

    def mean(v):
        return ndimage.gaussian_filter(v, sigma, mode="wrap")[:na, :nb]

    jaa, jbb, jab = mean(ga * ga), mean(gb * gb), mean(ga * gb)
    trace = jaa + jbb
    if trace.max() <= 0.0:
        return None
    coherence = np.hypot(jaa - jbb, 2 * jab) / np.where(trace > 0, trace, 1.0)
    doubled = np.exp(1j * np.arctan2(2 * jab, jaa - jbb))  # the wave vector's direction, doubled (sign-free)
    mean_coherence = float((coherence * trace).sum() / trace.sum())
    q = (coherence * trace).ravel()
    q = q / q.sum() if q.sum() > 0 else np.full(q.size, 1.0 / q.size)
    resultant = float(abs((q * doubled.ravel()).sum()))
    label, centre, share, tight = _two_clusters(doubled.ravel(), q)
    directions = tuple(float(np.degrees(np.angle(c)) / 2) for c in centre)
    # the domains: connected regions of one cluster, a wavelength's square or more, where the surface is striped
    striped = coherence.ravel() >= STRIPED
    min_cells = (wavelength / ha) * (wavelength / hb)
    domains = 0
    member = np.zeros(f.shape, int)
    for i in (0, 1):
        region = ((label == i) & striped).reshape(f.shape)
        labelled, count = ndimage.label(region)
        sizes = np.bincount(labelled.ravel())[1:]
        domains += int((sizes >= min_cells).sum())
        member[region] = 1 if i == 0 else -1
    wall_angle = wall_offset = None
    if domains >= 2:
        step = ndimage.gaussian_filter(member.astype(float), sigma, mode="nearest")
        wa, wb = np.gradient(step, ha, hb)
        w2 = complex(((wa ** 2 - wb ** 2) + 2j * wa * wb).sum())  # the walls' normal, doubled
        if abs(w2) > 0:
            wall_angle = float(np.degrees(np.angle(w2)) / 2 + 90.0)  # the walls run across their normal
            wall_angle = (wall_angle + 90.0) % 180.0 - 90.0
            bisector = 0.5 * (directions[0] + directions[1])
            offset = min(abs((wall_angle - bisector - s + 90.0) % 180.0 - 90.0) for s in (0.0, 90.0))
            wall_offset = float(offset)
    return Texture(mean_coherence, resultant, directions, (float(share[0]), float(share[1])),
                   (float(tight[0]), float(tight[1])), domains, wall_angle, wall_offset, wavelength)


def classify_pattern(spectrum: list[tuple[int, int, float]], texture: Texture | None = None) -> str:
    """The pattern a 3D surface's spectrum and texture describe (docs/three-d.md, "The pattern"), in this order:

    - ``stripes``: one shape with a zero index holds >= DOMINANT of the profile (crests parallel to a side;
      on a passage, n > 0, m = 0: crests along the axis; n = 0: rings);
    - ``checkerboard``: one shape with both indices non-zero holds >= DOMINANT (cos x cos z: bumps and dimples
      alternating);
    - ``squares``: two orthogonal stripe shapes (i, 0) and (0, j), each at least half the other, hold >=
      DOMINANT together (cos x + cos z);
    - ``herringbone``: the texture is striped in two directions, in three or more domains whose walls lie along
      a bisector of the two (:attr:`Texture.herringbone`);
    - ``labyrinth``: the texture is striped with no preferred direction (:attr:`Texture.labyrinth`), or, without
      a texture or where it is not striped, four or more shapes are needed to reach DOMINANT;
    - ``mixed``: anything else (e.g. stripes with a transverse modulation, two grains of stripes)."""
    if not spectrum or spectrum[0][2] <= 0.0:
        return "flat"
    (i1, j1, f1) = spectrum[0]
    if f1 >= DOMINANT:
        return "stripes" if i1 == 0 or j1 == 0 else "checkerboard"
    (i2, j2, f2) = spectrum[1] if len(spectrum) > 1 else (0, 0, 0.0)
    pair = ({(i1 == 0), (j1 == 0)} == {True, False} and {(i2 == 0), (j2 == 0)} == {True, False}
            and (i1 == 0) != (i2 == 0))
    if pair and f1 + f2 >= DOMINANT and f2 >= 0.5 * f1:
        return "squares"
    if texture is not None and texture.herringbone:
        return "herringbone"
    if texture is not None and texture.labyrinth:
        return "labyrinth"
    cumulative = np.cumsum([f for _, _, f in spectrum])
    needed = int(np.searchsorted(cumulative, DOMINANT)) + 1
    return "labyrinth" if needed >= 4 and not (texture is not None and texture.striped) else "mixed"


def branch_patterns(profiles: SurfaceProfiles, shape: SurfaceShape, g_c_mm: float | None) -> list[dict]:
    """The pattern of a followed 3D branch at the first states past PATTERN_MULTIPLES x g_c and at its last
    state: growth, time, pattern (:func:`classify_pattern`), amplitude (half the peak-to-trough of the detrended
    profile), the four strongest shapes with their fractions and, on a plate, the texture
    (:meth:`Texture.summary`)."""
    if not len(profiles) or shape.surface_dim != 2:
        return []
    picks = []
    if g_c_mm:
        for k in PATTERN_MULTIPLES:
            i = next((i for i, g in enumerate(profiles.growth_mm) if g >= k * g_c_mm), None)
            if i is not None and i not in picks:
                picks.append(i)
    last = len(profiles) - 1
    if last not in picks:
        picks.append(last)
    out = []
    for i in picks:
        prof = profiles.profile[i]
        spectrum = surface_spectrum(shape, profiles.position[i], prof)
        texture = surface_texture(shape, profiles.position[i], prof, spectrum)
        entry = {"growth_mm": profiles.growth_mm[i], "time": profiles.time[i],
                 "growth_over_g_c": profiles.growth_mm[i] / g_c_mm if g_c_mm else None,
                 "pattern": classify_pattern(spectrum, texture), "amplitude_mm": 0.5 * float(np.ptp(prof)),
                 "shapes": [[a, b, f] for a, b, f in spectrum[:4]]}
        if texture is not None:
            entry["texture"] = texture.summary()
        out.append(entry)
    return out
