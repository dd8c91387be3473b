"""The linear algebra of the stability tests: a Hessian's inertia on its free dofs and its smallest eigenpairs.
Which matrix counts is the criterion's choice (:mod:`app.onset.criteria`); its form is written in
:mod:`app.model.operators`; nothing here reads a problem.

- :class:`HessianOperator`: a compiled Hessian (K_tau) on the free dofs of its space, optionally only on a kept
  subset (the displacement block K_uu of the undrained test).
- :class:`DrainedOperator`: a Hessian in (u, c), c one content dof per cell, with c eliminated exactly: its
  block is diagonal, so the Schur complement S = K_uu - K_uc K_cc^-1 K_cu is an explicit sparse matrix on
  the displacement dofs, and In(K) = In(K_cc) + In(S) (Haynsworth).
- :class:`StabilityAnalyzer`: ``inertia()``, the exact counts of negative, zero and positive eigenvalues from an
  LDL^T (MUMPS Cholesky) factorization; ``eigenpairs(n)``, the n eigenpairs nearest zero (SLEPc
  Krylov-Schur, shift-invert, target 0, Hermitian), the eigenvectors embedded back into the problem's mixed
  space; ``lambda_min``, certified by the inertia.
- :func:`solve_with_held`: a Hessian's minimizer over some dofs with the others held (the branch's flux of a
  content change).

Dirichlet dofs are removed (free-dof submatrix), not kept with unit diagonal, which would add
spurious eigenvalues.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc
from slepc4py import SLEPc

from app import compat, fem_utils, timing
from app.solvers import mumps
from app.solvers.newton import add_blocks, allow_new_nonzeros, held_global


@dataclass
class Eigenpair:
    value: float
    vector: np.ndarray  # local array (owned + ghosts) in the mixed space W


class HessianOperator:
    """A Hessian (:class:`app.model.operators.OwnHessian`: its form, space, conditions and refresh) on its free
    dofs, optionally only those among ``keep`` (local indices of the space): K_tau for the criterion "rate" and
    the cut-back diagnosis, its displacement block K_uu for "undrained"."""

    def __init__(self, hessian, comm, keep: np.ndarray | None = None):
        self.k, self.comm, self.W, self.bcs = hessian, comm, hessian.space, hessian.bcs
        self.A = fem_petsc.create_matrix(self.k.form)
        self.contact = getattr(hessian, "contact", None)  # an extra term's Hessian (self-contact), added
        if self.contact is not None:
            allow_new_nonzeros(self.A)
            self._held = held_global(self.bcs, self.W, comm)
        free = ~self.fixed()
        if keep is not None:
            kept = np.zeros_like(free)
            kept[keep[keep < kept.size]] = True
            free &= kept
        self.is_free = fem_utils.owned_index_set(self.W, np.flatnonzero(free), self.comm)
        self.n_free = self.is_free.getSize()
        self.Kf = None
        self._full = self.A.createVecRight()

    def fixed(self) -> np.ndarray:
        """Owned dofs of the space under a Dirichlet condition."""
        fixed = np.zeros(fem_utils.owned_size(self.W), dtype=bool)
        fixed[fem_utils.owned_bc_dofs(self.bcs, self.W)] = True
        return fixed

    def matrix(self) -> PETSc.Mat:
        """The matrix at the current converged state (free dofs only); ``A`` holds it on the whole space."""
        self.k.refresh()
        fem_utils.assemble_matrix_into(self.A, self.k.form, self.bcs)
        if self.contact is not None:
            blocks = self.contact.entry_blocks(compat.function_vector(self.k.source).array)
            if add_blocks(self.A, blocks, self.contact.global_entries, self._held) and self.Kf is not None:
                self.Kf.destroy()  # the pattern may have grown: the free block is extracted anew
                self.Kf = None
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
        """Free-dof vector -> local array (owned + ghost) of the full space."""
        return free_to_local(x_free, self.is_free, self._full, self.W)

    def destroy(self) -> None:
        for obj in (self.Kf, self.A, self.is_free, self._full):
            if obj is not None:
                obj.destroy()


class DrainedOperator:
    """The drained test: a Hessian in (u, c) (:class:`app.model.operators.DrainedHessian`) with the content c
    of each cell eliminated, S = K_uu - K_uc K_cc^-1 K_cu on the free displacement dofs."""

    def __init__(self, hessian, comm):
        self.h, self.comm = hessian, comm
        space = hessian.space
        self.A = fem_petsc.create_matrix(hessian.form)
        self.contact = getattr(hessian, "contact", None)  # an extra term's Hessian (self-contact), added
        if self.contact is not None:
            allow_new_nonzeros(self.A)
            self._held = held_global(hessian.bcs, space, comm)
        n_owned = fem_utils.owned_size(space)
        fixed = np.zeros(n_owned, dtype=bool)
        fixed[fem_utils.owned_bc_dofs(hessian.bcs, space)] = True
        is_u = np.zeros(n_owned, dtype=bool)
        is_u[hessian.u_dofs[hessian.u_dofs < n_owned]] = True
        c_dofs = hessian.c_dofs
        self.is_free = fem_utils.owned_index_set(space, np.flatnonzero(is_u & ~fixed), self.comm)
        self.is_c = fem_utils.owned_index_set(space, c_dofs[c_dofs < n_owned], self.comm)
        self.n_free = self.is_free.getSize()
        self.S = None
        self._sub: dict = {}  # K_uu, K_uc, K_cc (kept: same patterns every assembly)
        self._negative_c = 0
        self._full = self.A.createVecRight()

    def matrix(self) -> PETSc.Mat:
        """S = K_uu - K_uc K_cc^-1 K_cu on the free displacement dofs."""
        self.h.refresh()
        fem_utils.assemble_matrix_into(self.A, self.h.form, self.h.bcs)
        if self.contact is not None:
            blocks = self.contact.entry_blocks(compat.function_vector(self.h.source).array)
            if add_blocks(self.A, blocks, self.h.contact_entries, self._held):
                for obj in (self.S, *self._sub.values()):  # the pattern may have grown: all blocks anew
                    if obj is not None:
                        obj.destroy()
                self.S, self._sub = None, {}
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
        return self.h.to_problem_space(free_to_local(x_free, self.is_free, self._full, self.h.space))

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
    f = fem.Function(space)
    f.x.array[:fem_utils.owned_size(space)] = full.array
    f.x.scatter_forward()
    return f.x.array.copy()


def solve_with_held(A: PETSc.Mat, free: PETSc.IS, held: PETSc.Vec, space, comm) -> np.ndarray:
    """The minimizer of 1/2 y^T A y over y = held + x with x on the ``free`` dofs only (A symmetric, positive
    definite there): A_ff x = -(A held)_f by an LDL^T (MUMPS). Returns x as a local array (owned + ghost) of
    ``space`` (A's space), zero off ``free``."""
    ksp = None
    options = mumps.PrefixedOptions("hbheld", mumps.direct("cholesky", {}))
    try:
        r = A.createVecLeft()
        A.mult(held, r)
        Aff = A.createSubMatrix(free, free)
        Aff.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        rhs = r.getSubVector(free)
        b = rhs.copy()
        r.restoreSubVector(free, rhs)
        b.scale(-1.0)
        x = b.duplicate()
        ksp = PETSc.KSP().create(comm)
        ksp.setOptionsPrefix(options.prefix)
        ksp.setFromOptions()
        ksp.setOperators(Aff)
        ksp.solve(b, x)
        full = A.createVecRight()
        out = free_to_local(x, free, full, space)
        for obj in (r, Aff, b, x, full):
            obj.destroy()
        return out
    finally:
        options.clear()
        if ksp is not None:
            ksp.destroy()


class StabilityAnalyzer:
    """Inertia and eigenpairs of a criterion's matrix (an operator above: ``matrix``, ``embed``,
    ``eliminated_negatives``, ``n_free``) at the converged state its form reads; a criterion builds it
    (:meth:`app.onset.criteria.Criterion.analyzer`)."""

    def __init__(self, operator, comm):
        self.op, self.comm = operator, comm
        self.n_free = operator.n_free
        self._ksp = None
        self._ksp_options = None
        self.tests = 0  # exact inertia tests (each one LDL^T factorization)

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
        if getattr(self.op, "contact", None) is None:  # with contact Kf may be a new matrix: a new factor
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
