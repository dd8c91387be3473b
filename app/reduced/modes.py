"""The stiffness of each Fourier mode about a laterally uniform (axisymmetric) state, and the short-wave
limit of the permeable surface.

A perturbation of the bilayer's uniform state is u_x = U(Y) sin kx, u_y = V(Y) cos kx, fluid flux
(A(Y) sin kx, B(Y) cos kx), so ds = -(k A + B') cos kx. Its gradient has the cos-part (kU, V') on the
diagonal and the sin-part (U', -kV) off it; at a diagonal F an isotropic law couples the two parts only
within each, so over one period the second variation is the same quadratic form of the reduced gradient

    dF = [[k U, U'], [-k V, V']]          (tube, polar axes, u_r = U cos n theta, u_theta = V sin n theta:
                                           dF = [[U', -(n U + V)/r], [V', (n V + U)/r]],
                                           ds = -(A' + A/r + n B/r))

in the law's own UFL: psi(F0 + dF, s0 + ds) [+ the dissipation of the flux (A, B) over tau] is differentiated
twice at zero perturbation, so nothing of the constitutive law is written twice. The form is a polynomial
of degree 2 in k: K(k) = K0 + k K1 + k^2 K2, assembled once per state from k = 0, 1, -1.

Criteria, as in 2D (app/solvers/stability.py): undrained (s frozen: psi_FF), drained (s eliminated
pointwise: psi_FF - psi_Fs psi_sF / psi_ss), rate (the zero-increment Hessian of the incremental potential
with step tau: E + D/tau in (U, V, A, B)).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from app import compat, fem_utils
from app.reduced.section import CRITERIA


def reduced_gradient(shape: str, k, U, V, r):
    if shape == "planar":
        return ufl.as_matrix([[k * U, U.dx(0)], [-k * V, V.dx(0)]])
    return ufl.as_matrix([[U.dx(0), -(k * U + V) / r], [V.dx(0), (k * V + U) / r]])


def reduced_content(shape: str, k, A, B, r):
    if shape == "planar":
        return -(k * A + B.dx(0))
    return -(A.dx(0) + A / r + k * B / r)


class ModeOperator:
    """K(k) of one criterion on a 1D mesh, about a base state (F0, s0) given as UFL expressions (Functions
    of a :class:`~app.reduced.transient.LayeredModel`, or constants for the half-space), banded in the
    dofs' coordinate order with the held dofs removed (LAPACK lower band storage, ab[i - j, j] = K[i, j])."""

    def __init__(self, domain, shape: str, degree: int, F0, s0, mat, criterion: str, *, tau=None, weight=1.0,
                 held: dict[int, float] | None = None, quadrature_degree: int | None = None):
        if criterion not in CRITERIA:
            raise ValueError(f"criterion {criterion!r}")
        self.criterion, self.shape = criterion, shape
        fields = 4 if criterion == "rate" else 2
        self.S = compat.mixed_lagrange_space(domain, degree, fields)
        self.k = fem.Constant(domain, PETSc.ScalarType(0.0))
        p = fem.Function(self.S)  # the perturbation, evaluated at zero
        parts = ufl.split(p)
        r = ufl.SpatialCoordinate(domain)[0]
        dF = reduced_gradient(shape, self.k, parts[0], parts[1], r)
        law = mat.law
        dx = ufl.Measure("dx", domain=domain, metadata={"quadrature_degree": quadrature_degree or 2 * degree + 2})
        v, dv = ufl.TestFunction(self.S), ufl.TrialFunction(self.S)

        def psi(F, s):
            bulk, constraint = law.free_energy(F, s, mat)
            return bulk + constraint

        if criterion == "rate":
            ds = reduced_content(shape, self.k, parts[2], parts[3], r)
            C0 = F0.T * F0
            e = psi(F0 + dF, s0 + ds) + law.dissipation(ufl.as_vector([parts[2], parts[3]]), C0, s0, tau, mat)
            a = ufl.derivative(ufl.derivative(e * weight * dx, p, v), p, dv)
        else:
            s = ufl.variable(s0)
            e = psi(F0 + dF, s)
            a = ufl.derivative(ufl.derivative(e * weight * dx, p, v), p, dv)
            if criterion == "drained":
                e_s = ufl.diff(e, s)
                e_ss = ufl.diff(e_s, s)
                a = a - ufl.derivative(e_s, p, v) * ufl.derivative(e_s, p, dv) / e_ss * weight * dx
        self.form = fem.form(a)
        self.p = p
        # coordinate order of the dofs (field index breaks ties): K is banded in it
        coords, field_of = np.zeros(0), np.zeros(0, dtype=int)
        index = np.zeros(0, dtype=np.int64)
        self.field_dofs = []
        for i in range(fields):
            Vi, dofs = fem_utils.collapse(self.S.sub(i))
            coords = np.concatenate([coords, fem_utils.dof_coordinates(Vi)])
            field_of = np.concatenate([field_of, np.full(len(dofs), i)])
            index = np.concatenate([index, dofs])
            self.field_dofs.append((dofs, fem_utils.dof_coordinates(Vi)))
        held = held or {}
        keep = np.ones(len(index), dtype=bool)
        for field, where in held.items():
            keep &= ~((field_of == field) & (np.abs(coords - where) < 1e-9 * max(1.0, abs(where))))
        order = np.lexsort((field_of[keep], coords[keep]))
        self.dofs = index[keep][order]  # row i of the reduced matrix = dof self.dofs[i]
        self.n = len(self.dofs)
        self.bandwidth = None
        self.assembler = BandAssembler(self.form, self.dofs)

    def polynomial(self) -> BandedPencil:
        """K0, K1, K2 at the current base state (the caller sets it)."""
        asm = self.assembler
        vals = []
        for k in (0.0, 1.0, -1.0):
            self.k.value = k
            vals.append(asm.values())
        v0, vp, vm = vals
        self.bandwidth = asm.bandwidth
        return BandedPencil([asm.band(v) for v in (v0, 0.5 * (vp - vm), 0.5 * (vp + vm) - v0)])


class BandAssembler:
    """A bilinear form assembled into LAPACK lower band storage (ab[i - j, j] = K[i, j]) in a fixed order
    of the dofs kept (``dofs[i]`` is row i); the matrix and the band pattern are built once."""

    def __init__(self, form, dofs: np.ndarray):
        self.form, self.dofs, self.n = form, dofs, len(dofs)
        self.bandwidth = None
        self._A = None
        self._pattern = None

    def values(self) -> np.ndarray:
        """The assembled matrix's CSR values (the pattern is the same every time)."""
        if self._A is None:
            self._A = fem_petsc.create_matrix(self.form)
        fem_utils.assemble_matrix_into(self._A, self.form, [])
        indptr, indices, values = self._A.getValuesCSR()
        if self._pattern is None:
            pos = np.full(len(indptr) - 1, -1, dtype=np.int64)
            pos[self.dofs] = np.arange(self.n)
            rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
            i, j = pos[rows], pos[indices]
            take = (i >= 0) & (j >= 0) & (i >= j)
            self.bandwidth = int(np.max(i[take] - j[take]))
            self._pattern = (np.flatnonzero(take), (i[take] - j[take]) * self.n + j[take])
        return values

    def band(self, values: np.ndarray) -> np.ndarray:
        take, flat = self._pattern
        ab = np.zeros((self.bandwidth + 1) * self.n)
        ab[flat] = values[take]  # each (i, j) is stored once
        return ab.reshape(self.bandwidth + 1, self.n)


class BandedPencil:
    """K(k) = K0 + k K1 + k^2 K2 in band storage: positive definiteness (banded Cholesky) and the smallest
    eigenvalue of the Jacobi-scaled K (zero exactly where K is singular; a margin that changes sign with it)."""

    def __init__(self, bands: list[np.ndarray]):
        self.bands = bands

    def at(self, k: float) -> np.ndarray:
        b0, b1, b2 = self.bands
        return b0 + k * b1 + (k * k) * b2

    def definite(self, k: float) -> bool:
        try:
            sla.cholesky_banded(self.at(k), lower=True, check_finite=False)
            return True
        except sla.LinAlgError:
            return False

    def margin(self, k: float) -> float:
        ab = self.at(k)
        d = np.sqrt(np.maximum(np.abs(ab[0]), 1e-300))
        scaled = ab.copy()
        for off in range(ab.shape[0]):
            scaled[off, :ab.shape[1] - off] /= d[off:] * d[:ab.shape[1] - off]
        w = sla.eig_banded(scaled, lower=True, eigvals_only=True, select="i", select_range=(0, 0),
                           check_finite=False)
        return float(w[0])
