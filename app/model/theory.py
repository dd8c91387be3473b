"""Closed-form references used to validate the model and the stability analysis, for the hydrogel law.

Written from the constitutive equations independently of the FE code path (tests check them against
the UFL derivatives of the law: :mod:`app.model.material`).

Constrained layer: a laterally constrained, traction-free layer (F = diag(1, l)) has P_yy = 0 in
closed form, s(l); its steady stretch in contact with mu_bar solves mu(l, s(l)) = mu_bar.

Stiff film on a compliant substrate in plane strain (Allen; Chen & Hutchinson): a film of
thickness h on a deep substrate wrinkles at the compressive strain

    eps_c = (1/4) (3 Es/Ef)^(2/3),   wavelength  l_c = 2 pi h (Ef / (3 Es))^(1/3),

with plane-strain moduli E = 2 mu/(1 - nu) of the linearized material. For the hydrogel with the
fluid content frozen (undrained, as in ``loading.kind = "compression"``) the plane-strain modulus
is obtained here directly from the constitutive model: uniaxial in-plane stress (P_yy = 0) at a
small strain, E = dP_xx/de. Biot: an incompressible neo-Hookean half-space under plane-strain
compression becomes unstable at the stretch 0.5437.
"""

from __future__ import annotations

import math

from scipy.optimize import brentq

from app.model.hydrogel import Hydrogel
from app.model.material import chemical_potential

HZS_CREASE_STRAIN = 0.354  # Hong, Zhao & Suo 2009: the crease onset of a neo-Hookean half-space in plane strain
CREASE_STRETCH_RATIO = 1.0 / (1.0 - HZS_CREASE_STRAIN) ** 2  # the same as a ratio of principal stretches: 2.396


def _undrained_pxx(mat: Hydrogel, e: float) -> float:
    """P_xx of F = diag(1 + e, l) with P_yy = 0 and s = s0 (plane strain); P written out for this F
    (tests/test_material.py checks it against the law's UFL P = dpsi/dF)."""
    g, eps, J0, s0 = mat.shear_modulus, mat.penalty, mat.preswelling, mat.s0
    a = 1.0 + e

    def p(a_, lam):
        J = a_ * lam
        return g / J0 * (J0 ** (2 / 3) * lam - 1 / lam) + eps * (J * J0 - 1 - s0) * a_

    lam = brentq(lambda l_: p(a, l_), 0.2, 5.0, xtol=1e-15, rtol=1e-15)
    J = a * lam
    return g / J0 * (J0 ** (2 / 3) * a - 1 / a) + eps * (J * J0 - 1 - s0) * lam


def plane_strain_modulus(mat: Hydrogel, strain: float = 1e-5) -> float:
    """E_bar = 2 mu/(1 - nu) of the linearized undrained material (central difference)."""
    return (_undrained_pxx(mat, strain) - _undrained_pxx(mat, -strain)) / (2 * strain)


def film_wrinkling_strain(film: Hydrogel, substrate: Hydrogel) -> float:
    Ef, Es = plane_strain_modulus(film), plane_strain_modulus(substrate)
    return 0.25 * (3 * Es / Ef) ** (2 / 3)


def film_wrinkling_wavelength(film: Hydrogel, substrate: Hydrogel, thickness: float) -> float:
    Ef, Es = plane_strain_modulus(film), plane_strain_modulus(substrate)
    return 2 * math.pi * thickness * (Ef / (3 * Es)) ** (1 / 3)


def constrained_layer_fluid(mat: Hydrogel, stretch: float) -> float:
    """Fluid content s of a laterally constrained, traction-free layer at thickness stretch l.

    With F = diag(1, l, 1), P_yy = 0 gives s(l) = l J0 - 1 + gamma/(eps J0) (J0^(2/3) l - 1/l)."""
    g, e, J0 = mat.shear_modulus, mat.penalty, mat.preswelling
    return stretch * J0 - 1 + g / (e * J0) * (J0 ** (2.0 / 3.0) * stretch - 1 / stretch)


def constrained_layer_stretch(mat: Hydrogel, mu_bar: float) -> float:
    """Steady thickness stretch of a laterally constrained layer in contact with mu_bar."""

    def residual(lam):
        return chemical_potential(mat, ((1.0, 0.0), (0.0, lam)), constrained_layer_fluid(mat, lam)) - mu_bar

    return brentq(residual, 1.0 + 1e-12, 1.0e3, xtol=1e-14, rtol=1e-14)


# --- surface instability of the swelling constrained layer (docs/theory/drained-onset.md) -------------------

BIOT_CUBIC_RATIO = 1.0 / brentq(lambda x: x**3 + x**2 + 3 * x - 1, 0.1, 0.5, xtol=1e-15)  # l2/l1 = 3.38298


def _mixing_f2(s: float, chi: float) -> float:
    """f''(s) of the mixing function f(s) = s ln(s/(1+s)) + chi s/(1+s)."""
    return 1 / (s * (1 + s) ** 2) - 2 * chi / (1 + s) ** 3


def layer_volumetric_stiffness(mat: Hydrogel, stretch: float, drained: bool) -> float:
    """G''(J) of the constrained layer's energy W = mu_n/2 F:F + G(J) at thickness stretch l (J = l):
    fluid frozen (undrained) gamma/(J0 l^2) + J0 eps, or with s minimized at fixed chemical potential
    (drained) gamma/(J0 l^2) + J0 alpha f'' eps/(alpha f'' + eps): the penalty in series with mixing."""
    g, a, e, J0 = mat.shear_modulus, mat.mixing_modulus, mat.penalty, mat.preswelling
    if not drained:
        return g / (J0 * stretch**2) + J0 * e
    af = a * _mixing_f2(constrained_layer_fluid(mat, stretch), mat.interaction)
    return g / (J0 * stretch**2) + J0 * af * e / (af + e)


def surface_stability_margin(stretch: float, kappa: float) -> float:
    """Biot's zero-speed surface-wave function of the traction-free half-space at F = diag(1, l), reduced
    for W = mu_n/2 F:F + G(J), kappa = G''/mu_n (positive: stable). Short waves decide a layer bonded
    to a rigid base, so this is the layer's onset condition."""
    l2 = stretch
    if 1 + kappa <= 0 or 1 + kappa * l2**2 <= 0:
        return -1.0  # strong ellipticity lost
    return (kappa * (1 + 3 * l2**2) + 1 - l2**2) / math.sqrt(1 + kappa) - (l2**2 - 1) * math.sqrt(1 + kappa * l2**2)


def surface_critical_stretch(mat: Hydrogel, drained: bool = True) -> float:
    """Thickness stretch (relative to the preswollen reference; times J0^(1/3) for the dry state) at which
    the homogeneously swollen, laterally constrained layer loses surface stability: Kang & Huang's
    critical swelling ratio for this free energy (drained), or the fluid-frozen (undrained) one. The first
    root of the margin below Biot's ratio 3.383, beyond which every layer is unstable."""
    mu_n = mat.shear_modulus * mat.preswelling ** (-1 / 3)

    def margin(lam):
        return surface_stability_margin(lam, layer_volumetric_stiffness(mat, lam, drained) / mu_n)

    grid = [1.0 + 1e-9 + (BIOT_CUBIC_RATIO - 1.0) * i / 4000 for i in range(4001)]
    prev = grid[0]
    for lam in grid[1:]:
        if margin(prev) > 0 >= margin(lam):
            return brentq(margin, prev, lam, xtol=1e-14, rtol=1e-14)
        prev = lam
    return BIOT_CUBIC_RATIO
