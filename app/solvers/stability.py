"""Structural stability of a converged state: inertia of K on the free dofs, and its smallest eigenpairs.

A state is stable while the Hessian K of the incremental potential, restricted to the free dofs,
is positive definite (seed paper eq. 2.40). K is evaluated at the converged state (u, Q) for the
next increment at zero increment (dQ = 0), with the stability step ``stability.tau``: tau enters
the dissipation block only, as (1/tau) A with A positive semi-definite, so the verdict does not
depend on the step sizes the adaptive integrator happened to choose.

- ``inertia()``: the exact counts of negative, zero and positive eigenvalues from an LDL^T
  (MUMPS Cholesky) factorization, Sylvester's law of inertia. One factorization: with the default
  screening (:class:`app.onset.screening.StabilityScreen`) most steps read the Newton factor's inertia
  instead and this exact test only confirms the bracket of an onset.
- ``eigenpairs(n)``: the n eigenpairs nearest zero (SLEPc Krylov-Schur, shift-invert, target 0,
  Hermitian), with the eigenvectors embedded back into the full mixed space.

Dirichlet dofs are removed (free-dof submatrix), not kept with unit diagonal, which would add
spurious eigenvalues.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc
from slepc4py import SLEPc

from app import compat, timing
from app.model.potential import build
from app.solvers import mumps


@dataclass
class Eigenpair:
    value: float
    vector: np.ndarray  # local array (owned + ghosts) in the mixed space W


@dataclass
class OwnHessian:
    """A compiled Hessian form and the coefficients it is evaluated on, owned by its user."""

    form: object
    work: object  # (u, dQ): the increment K is evaluated at
    state: object  # (u_n, Q_n): the previous state
    tau: object  # Constant: the step in the dissipation block


def zero_increment_hessian(problem, tau: float) -> OwnHessian:
    """K of the problem's incremental potential on coefficients of its own.

    ``work`` is the (u, dQ) the Hessian is evaluated at and ``state`` the previous state (u_n, Q_n),
    both refreshed from the problem's converged state before each assembly; the material fields are
    copied once and ``tau`` is a Constant of its own. The coefficients are created in the order the
    problem creates its own (unknown, state, material fields, then the constants tau and mu_bar), so
    the form has the problem's form signature: the same compiled kernel (JIT cache hit) and a K
    identical to the one assembled from the problem's own coefficients, bit for bit."""
    p = problem
    work, state = compat.Function(p.W), compat.Function(p.W)
    fields = {}
    for f in dataclasses.fields(p.mat):  # whatever record of per-cell fields the material law has
        source = getattr(p.mat, f.name)
        fields[f.name] = compat.Function(source.function_space)
        fields[f.name].x.array[:] = source.x.array
    tau_c = compat.Constant(p.domain, compat.ScalarType(tau))
    mu_bar = compat.Constant(p.domain, compat.ScalarType(0.0))  # does not enter K (linear in dQ)
    pot = build(work, state, type(p.mat)(**fields), tau_c, mu_bar, p.dx, p.surface_measure, p.dx_coupling)
    return OwnHessian(compat.form(pot.hessian), work, state, tau_c)


class StabilityAnalyzer:
    """Inertia and eigenpairs of K at a state, from a Hessian form on the analyzer's own coefficients.

    Built from that form, the Dirichlet conditions and the state it reads (never writes); use
    :meth:`for_problem`."""

    def __init__(self, k: OwnHessian, tau: float, source_state, u_dofs, bcs, comm):
        self.k, self.tau = k, tau
        self.source = source_state  # the converged state the tests are about (read only)
        self.u_dofs, self.bcs, self.comm = u_dofs, bcs, comm
        self.W = k.work.function_space
        self.A = compat.create_matrix(k.form)
        self.is_free = self._free_index_set()
        self.Kf = None
        self._ksp = None
        self._ksp_options = None
        self._full = self.A.createVecRight()
        self.n_free = self.is_free.getSize()
        self.tests = 0  # exact inertia tests (each one LDL^T factorization)

    @classmethod
    def for_problem(cls, problem, tau: float) -> StabilityAnalyzer:
        """The analyzer of a problem's converged state (``problem.state``), with step ``tau`` in K."""
        return cls(zero_increment_hessian(problem, tau), tau, problem.state, problem.u_dofs, problem.bcs,
                   problem.comm)

    def _free_index_set(self) -> PETSc.IS:
        fixed = np.zeros(compat.owned_size(self.W), dtype=bool)
        fixed[compat.owned_bc_dofs(self.bcs, self.W)] = True
        return compat.owned_index_set(self.W, np.flatnonzero(~fixed), self.comm)

    # --- K on the free dofs ----------------------------------------------------------------

    def _set_zero_increment(self) -> None:
        """Own coefficients at the converged state: (u, dQ) = (u_n, 0), tau = stability.tau."""
        s = self.source.x.array
        self.k.state.x.array[:] = s
        w = self.k.work.x.array
        w[:] = 0.0
        w[self.u_dofs] = s[self.u_dofs]
        self.k.tau.value = self.tau

    def assemble(self) -> PETSc.Mat:
        """K at the current converged state, restricted to the free dofs."""
        self._set_zero_increment()
        compat.assemble_matrix_into(self.A, self.k.form, self.bcs)
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
            self._ksp_options = mumps.PrefixedOptions("hbinertia", mumps.direct("cholesky", mumps.INERTIA))
            ksp = PETSc.KSP().create(self.comm)
            ksp.setOptionsPrefix(self._ksp_options.prefix)
            ksp.setFromOptions()
            self._ksp = ksp
        self._ksp.setOperators(Kf)
        self._ksp.setUp()
        self._ksp_options.clear()  # read by the first factorization
        nneg, nzero, npos = self._ksp.getPC().getFactorMatrix().getInertia()
        return int(nneg), int(nzero), int(npos)

    def eigenpairs(self, n: int = 1) -> list[Eigenpair]:
        """The n eigenpairs of K (free dofs) nearest zero, sorted ascending by eigenvalue."""
        with timing.timed("eigen_solve"):
            return self._eigenpairs(n)

    def _eigenpairs(self, n: int) -> list[Eigenpair]:
        Kf = self.assemble()
        eps = SLEPc.EPS().create(self.comm)
        eps.setOperators(Kf)
        eps.setProblemType(SLEPc.EPS.ProblemType.HEP)
        eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
        eps.setDimensions(nev=n, ncv=max(2 * n + 10, 20))
        eps.setTarget(0.0)
        eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
        st = eps.getST()
        st.setType(SLEPc.ST.Type.SINVERT)
        st.setShift(0.0)
        # the shift-invert's LDL^T: MUMPS controls reach a factor that ST sets up only through options;
        # ICNTL(13) for a parallel factorization like the inertia test's (no null-pivot detection here)
        options = mumps.PrefixedOptions("hbeig", mumps.direct("cholesky", {13: 1}, scope="st_"))
        eps.setOptionsPrefix(options.prefix)
        eps.setFromOptions()
        eps.setTolerances(1e-10, 500)
        eps.solve()
        options.clear()
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
        f = compat.Function(self.W)
        n = compat.owned_size(self.W)
        f.x.array[:n] = full.array
        f.x.scatter_forward()
        return f.x.array.copy()

    def destroy(self) -> None:
        if self._ksp_options is not None:
            self._ksp_options.clear()
        for obj in (self._ksp, self.Kf, self.A, self.is_free, self._full):
            if obj is not None:
                obj.destroy()
