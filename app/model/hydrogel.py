"""The seed paper's hydrogel law (eqs. 3.1-3.6): neo-Hookean network, Flory-Rehner mixing, penalized
molecular incompressibility J J0 = 1 + s, and the quadratic dissipation of Fickian diffusion.

Free energy per unit preswollen reference volume, with the three-dimensional isotropic preswelling
F0 = J0^(1/3) 1; F is 3x3 on a 3D mesh, and in plane strain the 2x2 in-plane part (F:F(3D) = F:F(2D) + 1,
J = det F(2D)): one law for both, the 2D case being the 3D one with F33 = 1:

    psi = gamma/(2 J0) [J0^(2/3) F:F - 3 - 2 ln(J J0)] + alpha/J0 [s ln(s/(1+s)) + chi s/(1+s)]
          + eps/(2 J0) (J J0 - 1 - s)^2
"""

from __future__ import annotations

import ufl

from app.model.material import MaterialLaw
from app.schema import gt, in_closed, in_open, key


class HydrogelLaw(MaterialLaw):
    name = "hydrogel"
    material_name = "Hydrogel"
    params = {  # units: MPa, mm^4/(N s), dimensionless
        "shear_modulus": key(float, 0.1, gt(0), "gamma [MPa]; not given in the paper: an assumption", unit="MPa"),
        "mixing_modulus": key(float, 24.2, gt(0), "alpha [MPa]", unit="MPa"),
        "penalty": key(float, 10.0, gt(0), "epsilon [MPa]", unit="MPa"),
        "mobility": key(float, 1.0e-4, gt(0), "M [mm^4/(N s)]", unit="mm^4/(N s)"),
        "preswelling": key(float, 1.01, in_open(1.0, 100.0), "J0 [-], > 1"),
        "interaction": key(float, 0.1, in_closed(-1.0, 2.0), "chi [-]"),
    }
    stiffness = "shear_modulus"

    def free_energy(self, F, s, p):
        """(network + mixing, coupling): the coupling part is the penalty on J J0 = 1 + s, the volumetric
        constraint (eq. 3.4)."""
        g, a, e, J0, chi = p.shear_modulus, p.mixing_modulus, p.penalty, p.preswelling, p.interaction
        J = ufl.det(F)
        FF = ufl.inner(F, F) + (3 - ufl.shape(F)[0])  # plane strain: the out-of-plane stretch 1 adds 1
        psi_mech = g / (2 * J0) * (J0 ** (2.0 / 3.0) * FF - 3 - 2 * ufl.ln(J * J0))
        psi_chem = a / J0 * (s * ufl.ln(s / (1 + s)) + chi * s / (1 + s))
        psi_coup = e / (2 * J0) * (J * J0 - 1 - s) ** 2
        return psi_mech + psi_chem, psi_coup

    def dissipation(self, dQ, C_n, s_n, tau, p):
        """tau * phi(H = dQ/tau; C_n, s_n) of eq. 3.4 written in the flux increment dQ = tau H.

        phi = C_n:(H x H) / (2 J0^(1/3) M s_n); with H = dQ/tau this is C_n:(dQ x dQ)/(2 tau J0^(1/3) M s_n).
        ``C_n`` is the right Cauchy-Green tensor of the previous step (in plane strain its 2x2 in-plane
        part: the flux is in-plane, so the out-of-plane entry never enters)."""
        J0, M = p.preswelling, p.mobility
        return ufl.inner(C_n * dQ, dQ) / (2 * tau * J0 ** (1.0 / 3.0) * M * s_n)

    def reference_fluid(self, p) -> float:
        """Eq. 3.5: P(F = 1, s0) = 0."""
        g, e, J0 = p.shear_modulus, p.penalty, p.preswelling
        return g / e * (J0 ** (-1.0 / 3.0) - 1.0 / J0) + J0 - 1.0


HYDROGEL = HydrogelLaw()
Hydrogel = HYDROGEL.material_class  # one layer's parameters: Hydrogel(shear_modulus, mixing_modulus, ...)
