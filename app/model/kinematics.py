"""Kinematics of the (u, Q) description, in UFL: every form and field of hydrobuckle uses these.

Plane strain: F = I + Grad u is the 2x2 in-plane deformation gradient from the preswollen reference; the
fluid content per unit reference volume is s = s0 - Div Q for the accumulated fluid-volume flux Q (so s is
exact on non-affine cells when Q lives in RTCF)."""

from __future__ import annotations

import ufl


def deformation_gradient(u):
    """F = I + Grad u."""
    return ufl.Identity(2) + ufl.grad(u)


def fluid_content(s_reference, Q):
    """s = s_reference - Div Q: the content after the flux Q has left the reference content."""
    return s_reference - ufl.div(Q)
