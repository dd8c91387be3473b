"""Kinematics of the (u, Q) description, in UFL: every form and field of hydrobuckle uses these.

F = I + Grad u is the deformation gradient from the preswollen reference: 3x3 on a 3D mesh, and on a 2D mesh
the 2x2 in-plane part of the plane-strain F (its out-of-plane stretch is 1, which the law adds). The
fluid content per unit reference volume is s = s0 - Div Q for the accumulated fluid-volume flux Q (so s is
exact on non-affine cells when Q lives in RTCF)."""

from __future__ import annotations

import ufl


def deformation_gradient(u):
    """F = I + Grad u (as many dimensions as u has components)."""
    return ufl.Identity(ufl.shape(u)[0]) + ufl.grad(u)


def fluid_content(s_reference, Q):
    """s = s_reference - Div Q: the content after the flux Q has left the reference content."""
    return s_reference - ufl.div(Q)
