"""Structural stability of a converged state: inertia of K on the free dofs, and its smallest eigenpairs.

A state is stable while the Hessian K of the incremental potential, restricted to the free dofs,
is positive definite (seed paper eq. 2.40). K is evaluated at the converged state (u, Q) for the
next increment at zero increment (dQ = 0), with the stability step ``stability.tau``: tau enters
the dissipation block only, as (1/tau) A with A positive semi-definite, so the verdict does not
depend on the step sizes the adaptive integrator happened to choose.

- ``inertia()``: the exact counts of negative, zero and positive eigenvalues from an LDL^T
  (MUMPS Cholesky) factorization, Sylvester's law of inertia. One factorization: with the default
  screening (:class:`app.onset.crossing.CrossingDetector`) most steps read the Newton factor's inertia
  instead and this exact test only confirms the bracket of an onset.
- ``eigenpairs(n)``: the n eigenpairs nearest zero (SLEPc Krylov-Schur, shift-invert, target 0,
  Hermitian), with the eigenvectors embedded back into the full mixed space.

Dirichlet dofs are removed (free-dof submatrix), not kept with unit diagonal, which would add
spurious eigenvalues.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from app import compat, timing


@dataclass
class Eigenpair:
    value: float
    vector: np.ndarray  # local array (owned + ghosts) in the mixed space W


class StabilityAnalyzer:
    def __init__(self, problem, tau: float):
        self.p = problem
        self.tau = tau
        self.A = compat.create_matrix(problem.forms.hessian)
        self.is_free = self._free_index_set()
        self.Kf = None
        self._ksp = None
        self._full = compat.create_vector(problem.forms.residual)
        self.n_free = self.is_free.getSize()
        self.tests = 0  # exact inertia tests (each one LDL^T factorization)

    def _free_index_set(self) -> PETSc.IS:
        W = self.p.W
        fixed = np.zeros(compat.owned_size(W), dtype=bool)
        fixed[compat.owned_bc_dofs(self.p.bcs, W)] = True
        return compat.owned_index_set(W, np.flatnonzero(~fixed), self.p.comm)

    # --- K on the free dofs ----------------------------------------------------------------

    def _set_zero_increment(self) -> None:
        p = self.p
        w, s = p.w.x.array, p.state.x.array
        w[:] = 0.0
        w[p.u_dofs] = s[p.u_dofs]
        p.tau.value = self.tau

    def assemble(self) -> PETSc.Mat:
        """K at the current converged state (problem.state), restricted to the free dofs."""
        self._set_zero_increment()
        compat.assemble_matrix_into(self.A, self.p.forms.hessian, self.p.bcs)
        if self.Kf is None:
            self.Kf = self.A.createSubMatrix(self.is_free, self.is_free)
        else:
            self.A.createSubMatrix(self.is_free, self.is_free, submat=self.Kf)
        self.Kf.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        return self.Kf

    def inertia(self) -> tuple[int, int, int]:
        """(negative, zero, positive) eigenvalue counts of K on the free dofs."""
        self.tests += 1
        with timing.timed("stability_test"):
            return self._inertia()

    def _inertia(self) -> tuple[int, int, int]:
        Kf = self.assemble()
        if self._ksp is None:
            ksp = PETSc.KSP().create(self.p.comm)
            ksp.setType("preonly")
            pc = ksp.getPC()
            pc.setType("cholesky")
            pc.setFactorSolverType("mumps")
            ksp.setOperators(Kf)
            pc.setFactorSetUpSolverType()
            F = pc.getFactorMatrix()
            F.setMumpsIcntl(24, 1)  # detect null pivots
            F.setMumpsIcntl(13, 1)  # no ScaLAPACK on the root node: exact inertia in parallel
            self._ksp = ksp
        else:
            self._ksp.setOperators(Kf)
        self._ksp.setUp()
        nneg, nzero, npos = self._ksp.getPC().getFactorMatrix().getInertia()
        return int(nneg), int(nzero), int(npos)

    def eigenpairs(self, n: int = 1) -> list[Eigenpair]:
        """The n eigenpairs of K (free dofs) nearest zero, sorted ascending by eigenvalue."""
        with timing.timed("eigen_solve"):
            return self._eigenpairs(n)

    def _eigenpairs(self, n: int) -> list[Eigenpair]:
        Kf = self.assemble()
        eps = SLEPc.EPS().create(self.p.comm)
        eps.setOperators(Kf)
        eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
        eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
        eps.setDimensions(nev=n, ncv=max(2 * n + 10, 20))
        eps.setTarget(0.0)
        eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
        st = eps.getST()
        st.setType(SLEPc.ST.Type.SINVERT)
        st.setShift(0.0)
        ksp = st.getKSP()
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        # MUMPS controls can only reach the factor through options before ST sets it up.
        prefix = f"hbeig{id(self)}_"
        PETSc.Options()[prefix + "st_mat_mumps_icntl_13"] = 1
        eps.setOptionsPrefix(prefix)
        eps.setFromOptions()
        eps.setTolerances(1e-10, 500)
        eps.solve()
        PETSc.Options().delValue(prefix + "st_mat_mumps_icntl_13")
        pairs = []
        xr = Kf.createVecRight()
        for i in range(min(eps.getConverged(), n)):
            lam = eps.getEigenpair(i, xr)
            pairs.append(Eigenpair(float(np.real(lam)), self._embed(xr)))
        eps.destroy()
        xr.destroy()
        pairs.sort(key=lambda e: e.value)
        return pairs

    def lambda_min(self, negative_count: int) -> float:
        """The smallest eigenvalue of K (free dofs), certified by the inertia.

        Shift-invert at 0 finds the eigenvalues nearest zero; once more than the inertia's
        ``negative_count`` of them are found, all negative ones are among them and the smallest
        returned is lambda_min. Otherwise the request grows (up to 64 pairs)."""
        n = negative_count + 1
        while True:
            values = [e.value for e in self.eigenpairs(n)]
            found_negative = sum(v < 0 for v in values)
            if found_negative >= negative_count and (len(values) > negative_count or n >= 64):
                return min(values) if values else float("nan")
            if n >= 64:
                return float("nan")
            n = min(2 * n + 2, 64)

    def _embed(self, x_free: PETSc.Vec) -> np.ndarray:
        """Free-dof vector -> local array (owned + ghost) of the full mixed space."""
        full = self._full
        full.set(0.0)
        sub = full.getSubVector(self.is_free)
        x_free.copy(sub)
        full.restoreSubVector(self.is_free, sub)
        f = compat.Function(self.p.W)
        n = compat.owned_size(self.p.W)
        f.x.array[:n] = full.array
        f.x.scatter_forward()
        return f.x.array.copy()

    def destroy(self) -> None:
        for obj in (self._ksp, self.Kf, self.A, self.is_free, self._full):
            if obj is not None:
                obj.destroy()
