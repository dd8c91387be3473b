"""Structural stability of a converged state: inertia of a Hessian on the free dofs, and its smallest
eigenpairs, under one of three criteria (``stability.criterion``; docs/validation.md, "Which instabilities
count").

The incremental potential Pi^tau(u, dQ) is a stored energy plus a dissipation (1/tau) D(dQ, dQ) with D
positive semi-definite, so its Hessian is K_tau = K_inf + D/tau. Each criterion is a symmetric matrix
whose inertia (negative-eigenvalue count, Sylvester's law) decides stability:

- ``"drained"``: does any perturbation of the displacement and of the fluid distribution lower the stored
  energy? This is K_inf with the flux's divergence-free part (which K_inf does not see: the stored energy
  depends on dQ only through s = s_n - Div dQ) removed. The fluid content a flux can change is one number
  per cell (RTCF's divergence is c/det J on a cell), so the test takes the stored energy's Hessian in
  (u, c), u in Q1, c in DG0, and eliminates c exactly: its block is diagonal (one dof per cell), so the
  Schur complement S = K_uu - K_uc K_cc^-1 K_cu is an explicit sparse matrix on the displacement dofs, and
  In(K) = In(K_cc) + In(S) (Haynsworth). A gradient flow leaves a state exactly when this test fails: the
  default, and the limit tau -> infinity of K_tau.
- ``"undrained"``: the fluid frozen (tau -> 0): K_uu at fixed fluid content, the displacement block of
  K_tau (the dissipation does not touch it). Biot's surface instability of an incompressible solid.
- ``"rate"``: K_tau with ``stability.tau``: instabilities that grow faster than about 1/tau. The seed paper's
  choice when tau is the step.

Each Hessian is evaluated at the converged state (u_n, Q_n) at zero increment, on coefficients of its
own. Ordering: for every tau, negatives(undrained) <= negatives(K_tau) <= negatives(drained) (K_uu is a
principal block of K_tau; K_tau decreases with tau), so the drained onset comes first.

- ``inertia()``: the exact counts of negative, zero and positive eigenvalues from an LDL^T (MUMPS
  Cholesky) factorization. With ``screening = "newton"`` most steps may read the Newton factor's inertia
  instead where that is safe for the criterion (:mod:`app.onset.screening`).
- ``eigenpairs(n)``: the n eigenpairs nearest zero (SLEPc Krylov-Schur, shift-invert, target 0,
  Hermitian), with the eigenvectors embedded back into the full mixed space (drained, undrained: the
  displacement part; the flux part zero).

Dirichlet dofs are removed (free-dof submatrix), not kept with unit diagonal, which would add
spurious eigenvalues.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import ufl
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


CRITERIA = ("drained", "undrained", "rate")


class RateOperator:
    """K_tau on the free dofs of the mixed space W (criterion "rate"; the cut-back diagnosis)."""

    def __init__(self, problem, tau: float):
        self.k = zero_increment_hessian(problem, tau)
        self.tau = tau
        self.source, self.u_dofs, self.bcs, self.comm = problem.state, problem.u_dofs, problem.bcs, problem.comm
        self.W = problem.W
        self.A = compat.create_matrix(self.k.form)
        self.is_free = compat.owned_index_set(self.W, self._free_local(), self.comm)
        self.n_free = self.is_free.getSize()
        self.Kf = None
        self._full = self.A.createVecRight()

    def fixed(self) -> np.ndarray:
        """Owned dofs of W under a Dirichlet condition."""
        fixed = np.zeros(compat.owned_size(self.W), dtype=bool)
        fixed[compat.owned_bc_dofs(self.bcs, self.W)] = True
        return fixed

    def _free_local(self) -> np.ndarray:
        return np.flatnonzero(~self.fixed())

    def _set_zero_increment(self) -> None:
        """Own coefficients at the converged state: (u, dQ) = (u_n, 0)."""
        s = self.source.x.array
        self.k.state.x.array[:] = s
        w = self.k.work.x.array
        w[:] = 0.0
        w[self.u_dofs] = s[self.u_dofs]
        self.k.tau.value = self.tau

    def matrix(self) -> PETSc.Mat:
        """The criterion's matrix at the current converged state (free dofs only)."""
        self._set_zero_increment()
        compat.assemble_matrix_into(self.A, self.k.form, self.bcs)
        if self.Kf is None:
            self.Kf = self.A.createSubMatrix(self.is_free, self.is_free)
        else:
            self.A.createSubMatrix(self.is_free, self.is_free, submat=self.Kf)
        self.Kf.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        return self.Kf

    def eliminated_negatives(self) -> int:
        """Negative eigenvalues in the block eliminated from :meth:`matrix` (Haynsworth)."""
        return 0

    def embed(self, x_free: PETSc.Vec) -> np.ndarray:
        """Free-dof vector -> local array (owned + ghost) of the full mixed space W."""
        return free_to_local(x_free, self.is_free, self._full, self.W)

    def destroy(self) -> None:
        for obj in (self.Kf, self.A, self.is_free, self._full):
            if obj is not None:
                obj.destroy()


class UndrainedOperator(RateOperator):
    """K_uu: the displacement block of K_tau on its free dofs (fluid frozen; tau does not enter)."""

    def __init__(self, problem):
        super().__init__(problem, 1.0)

    def _free_local(self) -> np.ndarray:
        is_u = np.zeros(compat.owned_size(self.W), dtype=bool)
        u = self.u_dofs[self.u_dofs < is_u.size]
        is_u[u] = True
        return np.flatnonzero(is_u & ~self.fixed())


class DrainedOperator:
    """The drained test: the stored energy's Hessian in (u, c) on Q1 x DG0 with the fluid content c of
    each cell eliminated (Schur complement on the free displacement dofs)."""

    def __init__(self, problem):
        p = problem
        self.problem, self.comm, self.source = p, p.comm, p.state
        self.Wd = compat.mixed_displacement_content_space(p.domain)
        self.work = compat.Function(self.Wd)  # (u, c): u = u_n, c = 0
        self.state = compat.Function(p.W)  # (u_n, Q_n)
        u, c = ufl.split(self.work)
        _, Q_n = ufl.split(self.state)
        F = ufl.Identity(2) + ufl.grad(u)
        # the content an RTCF flux changes in a cell: (div of the reference field, a constant) / det J
        s = p.mat.s0 - ufl.div(Q_n) - c / ufl.JacobianDeterminant(p.domain)
        bulk, constraint = p.mat.law.free_energy(F, s, p.mat)
        energy = bulk * p.dx + constraint * p.dx_coupling
        v, dv = ufl.TestFunction(self.Wd), ufl.TrialFunction(self.Wd)
        self.form = compat.form(ufl.derivative(ufl.derivative(energy, self.work, v), self.work, dv))
        self.bcs = p.fixed_displacement_conditions(self.Wd.sub(0))
        self.A = compat.create_matrix(self.form)
        self.Vd_u, self.ud_dofs = compat.collapse(self.Wd.sub(0))
        _, c_dofs = compat.collapse(self.Wd.sub(1))
        n_owned = compat.owned_size(self.Wd)
        fixed = np.zeros(n_owned, dtype=bool)
        fixed[compat.owned_bc_dofs(self.bcs, self.Wd)] = True
        is_u = np.zeros(n_owned, dtype=bool)
        is_u[self.ud_dofs[self.ud_dofs < n_owned]] = True
        self.is_free = compat.owned_index_set(self.Wd, np.flatnonzero(is_u & ~fixed), self.comm)
        self.is_c = compat.owned_index_set(self.Wd, c_dofs[c_dofs < n_owned], self.comm)
        self.n_free = self.is_free.getSize()
        self.S = None
        self._sub: dict = {}  # K_uu, K_uc, K_cc (kept: same patterns every assembly)
        self._negative_c = 0
        self._full = self.A.createVecRight()

    def _set_zero_increment(self) -> None:
        p = self.problem
        s = self.source.x.array
        self.state.x.array[:] = s
        u = compat.Function(p.V_u)
        u.x.array[:] = s[p.u_dofs]
        ud = compat.Function(self.Vd_u)
        compat.interpolate(ud, u)
        self.work.x.array[:] = 0.0
        self.work.x.array[self.ud_dofs] = ud.x.array

    def matrix(self) -> PETSc.Mat:
        """S = K_uu - K_uc K_cc^-1 K_cu on the free displacement dofs."""
        self._set_zero_increment()
        compat.assemble_matrix_into(self.A, self.form, self.bcs)
        sub = self._sub
        for name, rows, cols in (("uu", self.is_free, self.is_free), ("uc", self.is_free, self.is_c),
                                 ("cc", self.is_c, self.is_c)):
            sub[name] = self.A.createSubMatrix(rows, cols, submat=sub.get(name))
        d = sub["cc"].getDiagonal()
        self._negative_c = int(self.comm.allreduce(int(np.count_nonzero(d.array <= 0.0))))
        d.reciprocal()
        B = sub["uc"].copy()
        B.diagonalScale(R=d)  # K_uc K_cc^-1 (K_cc is diagonal: one content dof per cell)
        P = B.matTransposeMult(sub["uc"])
        SUBSET = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
        if self.S is None:  # the pattern of the union, kept: later factorizations are numeric only
            self.S = sub["uu"].copy()
            self.S.axpy(-1.0, P, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            self.S.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        else:
            self.S.zeroEntries()
            self.S.axpy(1.0, sub["uu"], structure=SUBSET)
            self.S.axpy(-1.0, P, structure=SUBSET)
        for obj in (d, B, P):
            obj.destroy()
        return self.S

    def eliminated_negatives(self) -> int:
        """Cells whose content block is not positive (a drained instability of the fluid alone)."""
        return self._negative_c

    def embed(self, x_free: PETSc.Vec) -> np.ndarray:
        """Free displacement vector -> local array of W (the mode's displacement; flux part zero)."""
        p = self.problem
        ud = compat.Function(self.Vd_u)
        ud.x.array[:] = free_to_local(x_free, self.is_free, self._full, self.Wd)[self.ud_dofs]
        u = compat.Function(p.V_u)
        compat.interpolate(u, ud)
        out = np.zeros_like(p.state.x.array)
        out[p.u_dofs] = u.x.array
        return out

    def destroy(self) -> None:
        for obj in (self.S, *self._sub.values(), self.A, self.is_free, self.is_c, self._full):
            if obj is not None:
                obj.destroy()


def free_to_local(x_free: PETSc.Vec, is_free: PETSc.IS, full: PETSc.Vec, space) -> np.ndarray:
    """A vector on the free dofs -> local array (owned + ghost) of ``space``, zero on the fixed dofs
    (``full``: a work vector of the space's global size)."""
    full.set(0.0)
    sub = full.getSubVector(is_free)
    x_free.copy(sub)
    full.restoreSubVector(is_free, sub)
    f = compat.Function(space)
    f.x.array[:compat.owned_size(space)] = full.array
    f.x.scatter_forward()
    return f.x.array.copy()


def criterion_operator(problem, criterion: str, tau: float | None = None):
    """The matrix whose inertia decides stability under ``criterion`` (see the module docstring)."""
    if criterion == "rate":
        return RateOperator(problem, tau)
    if criterion == "undrained" or not problem.diffusion:  # no fluid motion: drained = undrained
        return UndrainedOperator(problem)
    if criterion == "drained":
        if problem.permeable_facets() == 0:
            raise ValueError("stability.criterion = 'drained' needs a permeable boundary (the fluid content of a "
                             "closed body is conserved); use 'undrained' or 'rate'")
        return DrainedOperator(problem)
    raise ValueError(f"stability.criterion must be one of {', '.join(CRITERIA)}, got {criterion!r}")


class StabilityAnalyzer:
    """Inertia and eigenpairs of a criterion's matrix at a state (the problem's converged state, read
    only); use :meth:`for_problem`."""

    def __init__(self, operator, criterion: str, comm):
        self.op, self.criterion, self.comm = operator, criterion, comm
        self.tau = getattr(operator, "tau", None) if criterion == "rate" else None
        self.n_free = operator.n_free
        self._ksp = None
        self._ksp_options = None
        self.tests = 0  # exact inertia tests (each one LDL^T factorization)

    @classmethod
    def for_problem(cls, problem, tau: float | None = None, criterion: str = "rate") -> StabilityAnalyzer:
        """The analyzer of a problem's converged state (``problem.state``) under ``criterion`` (``tau``:
        the step in K_tau for "rate")."""
        return cls(criterion_operator(problem, criterion, tau), criterion, problem.comm)

    def assemble(self) -> PETSc.Mat:
        """The criterion's matrix at the current converged state, on the free dofs."""
        return self.op.matrix()

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
        return int(nneg) + self.op.eliminated_negatives(), int(nzero), int(npos)

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
            pairs.append(Eigenpair(float(np.real(lam)), self.op.embed(xr)))
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

    def destroy(self) -> None:
        if self._ksp_options is not None:
            self._ksp_options.clear()
        if self._ksp is not None:
            self._ksp.destroy()
        self.op.destroy()
