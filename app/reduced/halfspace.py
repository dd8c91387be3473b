"""The short-wave limit of a traction-free surface: a homogeneous half-space in the surface's local state.

A perturbation of wavenumber k along the surface lives in a layer of depth ~1/k under it, where the state
is the surface's; as k -> infinity the stability of every such mode is that of a homogeneous half-space
in that state. In depth units of 1/k one operator stands for every wavenumber: the mode
u = (U1 cos x + U2 sin x, V1 cos x + V2 sin x) on Y in [-depth, 0] (the surface at Y = 0, outward normal +Y),
clamped at -depth where it has decayed. Its gradient is dF_c cos x + dF_s sin x with

    dF_c = [[U2, U1'], [V2, V1']],     dF_s = [[-U1, U2'], [-V1, V2']],

and over one period the second variation is (q(dF_c) + q(dF_s)) / 2 for the law's quadratic form q at the
state (F, s): no symmetry of F is assumed, so the same operator serves a 1D section's diagonal state and any
2D surface state written in the surface's frame (tangent, outward normal). Criteria: undrained (s frozen),
drained (s eliminated pointwise from each part); the rate criterion's short-wave limit is the drained one
(its dissipation does not grow with k).

In 3D (``dim = 3``) the frame is (t1, t2, n): the wave runs along t1, the mode has a third component
W1 cos x + W2 sin x along t2, and the gradient's middle column (along t2) is zero:

    dF_c = [[U2, 0, U1'], [W2, 0, W1'], [V2, 0, V1']],     dF_s = [[-U1, 0, U2'], [-W1, 0, W2'], [-V1, 0, V2']].

A surface state F (3x3 in the frame) is stable at short waves when this operator is definite for every
direction of the wave in the surface: each direction phi is the state seen in a frame turned by phi about the
normal, F Q(phi). :meth:`HalfSpace.directions` samples phi from the principal directions of the surface's
stretch (where the extremes of a state that is uniform in the plane lie) in steps of pi / 8; a state with
F_2D in its (t1, n) block and 1 at t2 (F t2 = t2), with the wave along t1, is the plane-strain half-space
exactly.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import scipy.linalg as sla
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, fem_utils
from app.reduced.modes import BandAssembler, BandedPencil


class HalfSpace:
    """The half-space operator of one material law under one criterion; :meth:`margin` / :meth:`definite` at
    a state (F in the surface frame, 2x2; s) of the material last given to :meth:`use`. The law's
    parameters are constants of the form, so one compiled form serves every material."""

    def __init__(self, mat, criterion: str, degree: int = 3, depth: float = 40.0, cells: int = 96, dim: int = 2):
        crit = "drained" if criterion == "rate" else criterion
        self.dim = dim
        if crit not in ("drained", "undrained"):
            raise ValueError(f"criterion {criterion!r}")
        nodes = -depth * (np.linspace(1.0, 0.0, cells + 1) ** 2)
        d = fem_utils.interval_mesh(MPI.COMM_SELF, nodes)
        self.domain = d
        self.F = fem.Constant(d, np.eye(dim, dtype=PETSc.ScalarType))
        self.s = fem.Constant(d, PETSc.ScalarType(mat.s0))
        law = mat.law
        self.params = {name: fem.Constant(d, PETSc.ScalarType(getattr(mat, name))) for name in law.params}
        S = compat.mixed_lagrange_space(d, degree, 2 * dim)
        p = fem.Function(S)
        if dim == 2:
            U1, U2, V1, V2 = ufl.split(p)
            parts = (ufl.as_matrix([[U2, U1.dx(0)], [V2, V1.dx(0)]]),
                     ufl.as_matrix([[-U1, U2.dx(0)], [-V1, V2.dx(0)]]))
        else:
            U1, U2, W1, W2, V1, V2 = ufl.split(p)
            parts = (ufl.as_matrix([[U2, 0, U1.dx(0)], [W2, 0, W1.dx(0)], [V2, 0, V1.dx(0)]]),
                     ufl.as_matrix([[-U1, 0, U2.dx(0)], [-W1, 0, W2.dx(0)], [-V1, 0, V2.dx(0)]]))
        p_ufl = SimpleNamespace(**self.params)
        dx = ufl.Measure("dx", domain=d, metadata={"quadrature_degree": 2 * degree + 2})
        v, dv = ufl.TestFunction(S), ufl.TrialFunction(S)
        s = ufl.variable(self.s)
        a = 0
        for dF in parts:
            bulk, constraint = law.free_energy(self.F + dF, s, p_ufl)
            e = bulk + constraint
            a = a + ufl.derivative(ufl.derivative(e * dx, p, v), p, dv)
            if crit == "drained":
                e_s = ufl.diff(e, s)
                e_ss = ufl.diff(e_s, s)
                a = a - ufl.derivative(e_s, p, v) * ufl.derivative(e_s, p, dv) / e_ss * dx
        self.form = fem.form(a)
        coords, index, field = [], [], []
        for i in range(2 * dim):
            Vi, dofs = fem_utils.collapse(S.sub(i))
            coords.append(fem_utils.dof_coordinates(Vi))
            index.append(dofs)
            field.append(np.full(len(dofs), i))
        coords, index, field = np.concatenate(coords), np.concatenate(index), np.concatenate(field)
        keep = np.abs(coords + depth) > 1e-9 * depth  # clamped at -depth
        order = np.lexsort((field[keep], coords[keep]))
        self.dofs = index[keep][order]
        self.n = len(self.dofs)

        self._assembler = BandAssembler(self.form, self.dofs)

    def use(self, mat) -> HalfSpace:
        """Evaluate with ``mat``'s parameters from now on (a record of the same law)."""
        for name, c in self.params.items():
            c.value = getattr(mat, name)
        return self

    @staticmethod
    def directions(F) -> list[np.ndarray]:
        """The state seen by waves in 8 directions phi in the surface (3D): F Q(phi), phi from the principal
        direction of the tangential stretch (the 2x2 block of F^T F) in steps of pi / 8. In 2D: [F]."""
        F = np.asarray(F, dtype=float)
        if F.shape == (2, 2):
            return [F]
        C = F[:, :2].T @ F[:, :2]
        phi0 = 0.5 * np.arctan2(2 * C[0, 1], C[0, 0] - C[1, 1])
        out = []
        for j in range(8):
            c, s = np.cos(phi0 + j * np.pi / 8), np.sin(phi0 + j * np.pi / 8)
            out.append(F @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))
        return out

    def band(self, F, s: float) -> np.ndarray:
        """K in LAPACK lower band storage at the state (F in the surface frame, the wave along its first axis;
        2x2 or 3x3; s)."""
        self.F.value[:] = np.asarray(F, dtype=float)
        self.s.value = s
        return self._assembler.band(self._assembler.values())

    def definite(self, F, s: float) -> bool:
        """Definite for a wave in every direction (:meth:`directions`)."""
        for G in self.directions(F):
            try:
                sla.cholesky_banded(self.band(G, s), lower=True, check_finite=False)
            except sla.LinAlgError:
                return False
        return True

    def margin_along(self, F, s: float) -> float:
        """The margin for a wave along the frame's first axis only."""
        return BandedPencil([self.band(F, s), 0.0, 0.0]).margin(0.0)

    def margin(self, F, s: float) -> float:
        """The smallest eigenvalue of the Jacobi-scaled operator (over the directions in 3D): negative exactly
        where it is indefinite."""
        return min(self.margin_along(G, s) for G in self.directions(F))
