"""The pattern of a 3D surface (app/model/patterns.py, docs/three-d.md "The pattern") on fields whose pattern is
known by construction:

- the spectral rules on textbook fields: one stripe shape, one cos x cos z, two orthogonal stripe sets, six
  shapes of equal weight, a stripe with a stronger cos x cos z of its own x-wave;
- herringbones built from their definition: crests that zigzag, the phase k cos(t) s + k sin(t) tri(n) with a
  triangle wave tri of slope +-1 across bands (so the wave vectors are exactly (cos t, +-sin t) k in
  alternating bands), at several angles t and band directions, and a smoothly zigzagging one; the two
  directions are found at +-t;
- bent stripes on small plates (Swift-Hohenberg, 4 and 6 wavelengths wide) are not herringbones;
- labyrinths grown by the Swift-Hohenberg equation (u_t = eps u - (k^2 + lap)^2 u / k^4 - u^3 from noise, with
  mirror sides as a rollered plate's, by cosine transforms): stripes of one wavelength meandering in every
  direction, the textbook labyrinth; and target rings (stripes in every direction by construction);
- what is not a herringbone although it has two stripe directions: one fold (two domains), two grains of
  orthogonal stripes side by side (their wall is not along a bisector), oblique stripes reflected by the
  rollered sides, a checkerboard.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.model.patterns import classify_pattern, surface_spectrum, surface_texture
from app.model.shapes3d import PlaneSurface

WAVELENGTH = 0.05


def _plate_grid(L: float = 0.3, W: float = 0.2, nx: int = 30, nz: int = 20):
    x, z = np.meshgrid(np.linspace(0, L, nx + 1), np.linspace(0, W, nz + 1), indexing="ij")
    return np.column_stack([x.ravel(), z.ravel()]), x.ravel(), z.ravel(), L, W


@pytest.mark.parametrize("field, pattern", [
    (lambda x, z, L, W: np.cos(4 * math.pi * x / L), "stripes"),
    (lambda x, z, L, W: np.cos(3 * math.pi * x / L) * np.cos(2 * math.pi * z / W), "checkerboard"),
    (lambda x, z, L, W: np.cos(3 * math.pi * x / L) + 0.9 * np.cos(2 * math.pi * z / W), "squares"),
    (lambda x, z, L, W: sum(np.cos(m * math.pi * x / L) * np.cos(n * math.pi * z / W)
                            for m, n in ((3, 1), (2, 2), (1, 3), (3, 2), (2, 3), (4, 1))), "labyrinth"),
    (lambda x, z, L, W: np.cos(3 * math.pi * x / L) + 1.5 * np.cos(3 * math.pi * x / L) * np.cos(2 * math.pi * z / W),
     "mixed"),
])
def test_the_pattern_of_an_analytic_surface(field, pattern):
    """Each spectral rule on its textbook field (plus a uniform swelling), with and without the texture: the
    texture does not overrule a spectrum that decides."""
    pos, x, z, L, W = _plate_grid()
    profile = 0.3 + field(x, z, L, W)
    spectrum = surface_spectrum(PlaneSurface(), pos, profile)
    assert classify_pattern(spectrum) == pattern
    assert classify_pattern(spectrum, surface_texture(PlaneSurface(), pos, profile, spectrum)) == pattern
    assert sum(f for _, _, f in spectrum) == pytest.approx(1.0, rel=1e-9)  # cos x cos shapes are a basis


def _square(L: float = 0.4, n: int = 161):
    x, z = np.meshgrid(np.linspace(0, L, n), np.linspace(0, L, n), indexing="ij")
    return np.column_stack([x.ravel(), z.ravel()]), x, z


def _triangle(s: np.ndarray, period: float) -> np.ndarray:
    """A triangle wave of slope +-1 and the given period (bands of half a period)."""
    u = np.mod(s, period)
    return np.where(u < period / 2, u, period - u)


def herringbone(x, z, angle_deg: float, bands_deg: float = 0.0, period: float = 4 * WAVELENGTH):
    """Crests zigzagging across bands along the direction ``bands_deg``: wave vectors at bands_deg +- angle_deg,
    each band two wavelengths wide."""
    t, b = math.radians(angle_deg), math.radians(bands_deg)
    along = x * math.cos(b) + z * math.sin(b)
    across = -x * math.sin(b) + z * math.cos(b)
    k = 2 * math.pi / WAVELENGTH
    return np.cos(k * math.cos(t) * along + k * math.sin(t) * _triangle(across, period))


def swift_hohenberg(L: float, n: int, seed: int, steps: int = 100, eps: float = 0.3) -> np.ndarray:
    """A labyrinth: the Swift-Hohenberg equation at wavelength WAVELENGTH from noise on a square of side L with
    mirror sides, semi-implicit in cosine space (time in units of the linear growth's)."""
    from scipy.fft import dctn, idctn

    u = 0.1 * np.random.default_rng(seed).standard_normal((n, n))
    q = np.pi * np.arange(n) / L * WAVELENGTH / (2 * math.pi)  # wavenumbers over the pattern's
    linear = eps - (1.0 - (q[:, None] ** 2 + q[None, :] ** 2)) ** 2
    for _ in range(steps):
        u = idctn((dctn(u, type=1) - 0.5 * dctn(u ** 3, type=1)) / (1.0 - 0.5 * linear), type=1)
    return u


def _classified(pos, field):
    profile = field.ravel()
    spectrum = surface_spectrum(PlaneSurface(), pos, profile)
    texture = surface_texture(PlaneSurface(), pos, profile, spectrum)
    return classify_pattern(spectrum, texture), texture


@pytest.mark.parametrize("angle, bands", [(35, 0), (50, 0), (65, 0), (40, 30), (50, 90)])
def test_a_herringbone_is_told_apart_and_its_two_wave_vectors_found(angle, bands):
    """A herringbone built from its definition, at several angles between its arms and the bands, on a plate 8
    wavelengths wide: classified herringbone, its two directions at bands +- angle (within 6 degrees: the
    window blurs each wall over a third of a wavelength; measured 5.7 at worst), each holding half the
    surface, its walls along the bands (measured within 1.7 degrees). Arms closer than about 20 degrees to the
    bands (35 degrees apart as measured) are read as wavy stripes (ARMS_APART), as bent stripes are."""
    pos, x, z = _square()
    pattern, texture = _classified(pos, herringbone(x, z, angle, bands))
    assert pattern == "herringbone", texture
    found = sorted(texture.directions)
    expected = sorted(((bands + s * angle + 90.0) % 180.0) - 90.0 for s in (1, -1))
    assert np.allclose(found, expected, atol=6.0), (found, expected)
    assert min(texture.shares) > 0.45  # measured 0.48 at least
    assert abs((texture.wall_angle - bands + 90.0) % 180.0 - 90.0) < 2.5, texture.wall_angle


def test_a_smoothly_zigzagging_stripe_is_a_herringbone():
    """cos(k x + A cos(q z)): crests x = -A cos(q z) / k zigzag smoothly; their wave vectors' angle,
    atan(A q sin(q z) / k), lingers near its extremes +-atan(A q / k) (here 45 degrees), which the two
    directions find within 15 degrees (the turning crests pull them in)."""
    pos, x, z = _square()
    k, q = 2 * math.pi / WAVELENGTH, 2 * math.pi / (4 * WAVELENGTH)
    pattern, texture = _classified(pos, np.cos(k * x + (k / q) * np.cos(q * z)))
    assert pattern == "herringbone", texture
    assert np.allclose(sorted(np.abs(texture.directions)), [45.0, 45.0], atol=15.0), texture.directions


@pytest.mark.parametrize("wavelengths", [4, 6])
def test_swift_hohenberg_stripes_on_small_plates_are_not_herringbones(wavelengths):
    """Swift-Hohenberg stripes on plates 4 and 6 wavelengths wide, 30 seeds each: bent stripes in a few domains
    whose directions are 20-40 degrees apart, some with walls near a bisector. None is a herringbone (before
    ARMS_APART and WALL_ALIGNED were set, 6 of 30 on the 4-wavelength plate were, measured)."""
    L = wavelengths * WAVELENGTH
    n = 16 * wavelengths + 1
    x, z = np.meshgrid(np.linspace(0, L, n), np.linspace(0, L, n), indexing="ij")
    pos = np.column_stack([x.ravel(), z.ravel()])
    found = [seed for seed in range(30) if _classified(pos, swift_hohenberg(L, n, seed))[0] == "herringbone"]
    assert not found, found


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_swift_hohenberg_labyrinth_is_a_labyrinth(seed):
    """Swift-Hohenberg stripes grown from noise on a plate 16 wavelengths wide: striped (coherence >= 0.5)
    with no preferred direction, and a labyrinth."""
    L, n = 16 * WAVELENGTH, 241
    x, z = np.meshgrid(np.linspace(0, L, n), np.linspace(0, L, n), indexing="ij")
    pos = np.column_stack([x.ravel(), z.ravel()])
    pattern, texture = _classified(pos, swift_hohenberg(L, n, seed))
    assert pattern == "labyrinth", texture
    assert texture.striped and texture.resultant < 0.5
    assert texture.wavelength_mm == pytest.approx(WAVELENGTH, rel=0.1)  # the window's wavelength is the pattern's


def test_target_rings_are_a_labyrinth_and_a_checkerboard_is_not_striped():
    """Concentric rings: striped with every direction equally (resultant 0 by symmetry): a labyrinth. An
    off-lattice checkerboard: its coherence ~0 (bumps)."""
    pos, x, z = _square()
    k = 2 * math.pi / WAVELENGTH
    pattern, texture = _classified(pos, np.cos(k * np.hypot(x - 0.2, z - 0.2)))
    assert pattern == "labyrinth" and texture.resultant < 0.05
    _, texture = _classified(pos, np.cos(k * x / math.sqrt(2)) * np.cos(k * z / math.sqrt(2)))
    assert texture.coherence < 0.1 and not texture.herringbone


@pytest.mark.parametrize("name, pattern", [("one fold", "mixed"), ("two grains", "mixed"),
                                           ("grain bands", "mixed"), ("oblique stripes", "mixed"),
                                           ("stripes", "stripes")])
def test_what_is_not_a_herringbone(name, pattern):
    """Two stripe directions are not enough: one fold has two domains; two grains of orthogonal stripes, and
    four alternating bands of them, have their walls across a bisector (45 degrees off); oblique stripes
    reflected at the rollered sides hold a second direction only in thin strips along the sides (one
    direction: resultant near 1, so not a labyrinth either)."""
    pos, x, z = _square()
    k = 2 * math.pi / WAVELENGTH
    field = {"one fold": np.cos(k * math.cos(0.7) * x + k * math.sin(0.7) * np.abs(z - 0.2)),
             "two grains": np.where(x < 0.2, np.cos(k * x), np.cos(k * z)),
             "grain bands": np.where(np.mod(x, 0.2) < 0.1, np.cos(k * x), np.cos(k * z)),
             "oblique stripes": np.cos(k * (x * math.cos(0.6) + z * math.sin(0.6))),
             "stripes": np.cos(k * x)}[name]
    found, texture = _classified(pos, field)
    assert found == pattern, texture
    if name in ("two grains", "grain bands"):
        assert texture.wall_offset == pytest.approx(45.0, abs=3.0)
        assert texture.domains == (2 if name == "two grains" else 4)
    if name == "one fold":
        assert texture.domains == 2 and texture.wall_offset < 3.0  # a herringbone's wall, but only one
    if name == "oblique stripes":
        assert texture.resultant > 0.9


def test_the_texture_of_a_passage_is_not_computed_and_a_graded_grid_is_resampled():
    """A passage's profile keeps its angle but not its radius: no texture (its pattern comes from the spectrum).
    A herringbone on a grid graded along z is the same herringbone."""
    from app.model.shapes3d import CylinderSurface

    th, z = np.meshgrid(np.linspace(0, 2 * np.pi, 24, endpoint=False), np.linspace(0, 1, 9), indexing="ij")
    pos = np.column_stack([th.ravel(), z.ravel()])
    assert surface_texture(CylinderSurface(), pos, np.cos(3 * th).ravel()) is None
    a = np.linspace(0, 0.4, 161)
    b = 0.4 * np.linspace(0, 1, 161) ** 1.2
    x, zz = np.meshgrid(a, b, indexing="ij")
    pattern, texture = _classified(np.column_stack([x.ravel(), zz.ravel()]), herringbone(x, zz, 50))
    assert pattern == "herringbone", texture


def _unequal_zigzag(z: np.ndarray, period: float, narrow: float) -> np.ndarray:
    """Slope +1 over the wide part of each period and -1 over the narrow one: crests zigzagging with unequal
    arms (continuous, drifting with z)."""
    u, n = np.mod(z, period), np.floor(z / period)
    wide = period - narrow
    return n * (wide - narrow) + np.where(u < wide, u, wide - (u - wide))


@pytest.mark.parametrize("narrow, pattern", [(1.0, "mixed"), (1.5, "herringbone")])
def test_a_zigzag_with_one_short_arm_is_a_herringbone_only_when_both_arms_hold_enough(narrow, pattern):
    """Crests at +-45 degrees in bands of unequal width (4 wavelengths a period, the narrow band ``narrow``
    wavelengths): with the narrow arm at 16% of the surface (measured) the stripes merely kink, below
    CLUSTER_SHARE; at 33% it is a herringbone with unequal arms."""
    pos, x, z = _square()
    k = 2 * math.pi / WAVELENGTH
    t = math.radians(45)
    field = np.cos(k * math.cos(t) * x + k * math.sin(t) * _unequal_zigzag(z, 4 * WAVELENGTH, narrow * WAVELENGTH))
    found, texture = _classified(pos, field)
    assert found == pattern, texture
    assert texture.wall_offset < 1.0 and texture.domains == 4  # the walls and domains of a zigzag either way
