"""Hydrogel constitutive model of the seed paper (eqs. 3.1-3.6), as plain UFL functions.

Free energy per unit preswollen reference volume (neo-Hookean network, Flory-Rehner mixing,
penalized molecular incompressibility J J0 = 1 + s), and the quadratic dissipation potential of
Fickian diffusion. Plane strain: ``F`` is the 2x2 in-plane deformation gradient and the
out-of-plane stretch is 1, so F:F(3D) = F:F(2D) + 1 and J = det F(2D). The preswelling
F0 = J0^(1/3) 1 is three-dimensional and isotropic.

Nothing here knows about meshes: the same functions give UFL expressions (for forms) and
floats (for the reference values in tests and the analytic solutions).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import ufl


@dataclass(frozen=True)
class Hydrogel:
    """Material parameters of one layer (units: MPa, mm^4/(N s), dimensionless)."""

    shear_modulus: float  # gamma
    mixing_modulus: float  # alpha
    penalty: float  # epsilon
    mobility: float  # M
    preswelling: float  # J0
    interaction: float  # chi

    @classmethod
    def from_dict(cls, d: dict) -> Hydrogel:
        return cls(**{k: float(d[k]) for k in cls.__dataclass_fields__})

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def s0(self) -> float:
        """Fluid content of the stress-free preswollen reference state, eq. 3.5."""
        g, e, J0 = self.shear_modulus, self.penalty, self.preswelling
        return g / e * (J0 ** (-1.0 / 3.0) - 1.0 / J0) + J0 - 1.0

    @property
    def mu0(self) -> float:
        """Chemical potential of the reference state, eq. 3.6 (= dpsi/ds at F = 1, s = s0)."""
        return chemical_potential_value(self, 1.0, self.s0)


def _log(x):
    return ufl.ln(x) if isinstance(x, ufl.core.expr.Expr) else math.log(x)


def free_energy_parts(mat, F, s):
    """(network, mixing, coupling) parts of psi(F, s) of eq. 3.4 in plane strain.

    F is 2x2 (UFL), s the fluid content; ``mat`` may hold floats or UFL coefficients (per-cell
    parameter fields). The coupling part is the penalty on J J0 = 1 + s, the volumetric constraint."""
    g, a, e, J0, chi = mat.shear_modulus, mat.mixing_modulus, mat.penalty, mat.preswelling, mat.interaction
    J = ufl.det(F)
    FF = ufl.inner(F, F) + 1.0  # out-of-plane stretch 1
    psi_mech = g / (2 * J0) * (J0 ** (2.0 / 3.0) * FF - 3 - 2 * ufl.ln(J * J0))
    psi_chem = a / J0 * (s * ufl.ln(s / (1 + s)) + chi * s / (1 + s))
    psi_coup = e / (2 * J0) * (J * J0 - 1 - s) ** 2
    return psi_mech, psi_chem, psi_coup


def free_energy(mat, F, s):
    """psi(F, s) of eq. 3.4 in plane strain."""
    return sum(free_energy_parts(mat, F, s))


def chemical_potential(mat, J, s):
    """mu = dpsi/ds at fixed F (eq. 2.6), written out; works for UFL and floats."""
    a, e, J0, chi = mat.mixing_modulus, mat.penalty, mat.preswelling, mat.interaction
    return a / J0 * (_log(s / (1 + s)) + 1 / (1 + s) + chi / (1 + s) ** 2) - e / J0 * (J * J0 - 1 - s)


def chemical_potential_value(mat: Hydrogel, J: float, s: float) -> float:
    return float(chemical_potential(mat, J, s))


def dissipation_increment(mat, dQ, C_n, s_n, tau):
    """tau * phi(H = dQ/tau; C_n, s_n) of eq. 3.4 written in the flux increment dQ = tau H.

    phi = C_n:(H x H) / (2 J0^(1/3) M s_n); with H = dQ/tau this is C_n:(dQ x dQ)/(2 tau J0^(1/3) M s_n).
    ``C_n`` is the 2x2 in-plane right Cauchy-Green tensor of the previous step (the flux is
    in-plane, so the out-of-plane entry never enters)."""
    J0, M = mat.preswelling, mat.mobility
    return ufl.inner(C_n * dQ, dQ) / (2 * tau * J0 ** (1.0 / 3.0) * M * s_n)


def first_piola(mat: Hydrogel, F, s):
    """P = dpsi/dF (2x2, plane strain), for post-processing and tests."""
    g, e, J0 = mat.shear_modulus, mat.penalty, mat.preswelling
    J = ufl.det(F)
    Finv_T = ufl.inv(F).T
    return g / J0 * (J0 ** (2.0 / 3.0) * F - Finv_T) + e * (J * J0 - 1 - s) * J * Finv_T


# --- closed-form reference solutions (floats) ------------------------------------------------


def constrained_layer_fluid(mat: Hydrogel, stretch: float) -> float:
    """Fluid content s of a laterally constrained, traction-free layer at thickness stretch l.

    With F = diag(1, l, 1), P_yy = 0 gives s(l) = l J0 - 1 + gamma/(eps J0) (J0^(2/3) l - 1/l)."""
    g, e, J0 = mat.shear_modulus, mat.penalty, mat.preswelling
    return stretch * J0 - 1 + g / (e * J0) * (J0 ** (2.0 / 3.0) * stretch - 1 / stretch)


def constrained_layer_stretch(mat: Hydrogel, mu_bar: float) -> float:
    """Steady thickness stretch of a laterally constrained layer in contact with mu_bar."""
    from scipy.optimize import brentq

    def residual(lam):
        return chemical_potential_value(mat, lam, constrained_layer_fluid(mat, lam)) - mu_bar

    return brentq(residual, 1.0 + 1e-12, 1.0e3, xtol=1e-14, rtol=1e-14)
