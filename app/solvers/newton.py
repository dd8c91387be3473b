"""PETSc SNES Newton solver for one incremental minimization step, with a direct (MUMPS) solve.

dolfinx 0.5's own NewtonSolver is not SNES; here the residual and Hessian callbacks assemble
the compiled forms of :mod:`app.model.potential` into PETSc objects that SNES drives. Options are set
under a per-instance prefix so that several problems can coexist in one process.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, timing

_ids = itertools.count()


@dataclass
class NewtonResult:
    converged: bool
    iterations: int
    reason: int
    residual_norm: float


class NewtonSolver:
    """SNES (newtonls) on R(w) = 0 with Jacobian K; w is ``problem.w``."""

    def __init__(self, problem, rtol: float, atol: float, max_it: int, line_search: str = "basic",
                 factorization: str = "cholesky", linear: str = "direct", ksp_rtol: float = 1e-10,
                 ksp_max_it: int = 2000):
        self.problem = problem
        forms = problem.forms
        self.A = compat.create_matrix(forms.hessian)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.b = compat.create_vector(forms.residual)
        self.x = self.b.duplicate()
        self._g = self.b.duplicate()  # Dirichlet values at the constrained dofs, 0 elsewhere
        self._bc_dofs = compat.owned_bc_dofs(problem.bcs, problem.W)
        self._lifting = True
        self.prefix = f"hb{next(_ids)}_"
        opts = PETSc.Options()
        settings = {
            "snes_type": "newtonls",
            "snes_linesearch_type": line_search,
            "snes_rtol": rtol,
            "snes_atol": atol,
            "snes_stol": 0.0,
            "snes_max_it": max_it,
            "snes_max_funcs": 100 * max_it,
        }
        settings.update(self._direct_options(factorization) if linear == "direct"
                        else self._iterative_options(ksp_rtol, ksp_max_it))
        for key, value in settings.items():
            opts[self.prefix + key] = value
        self._option_keys = [self.prefix + key for key in settings]
        self.factorization = factorization if linear == "direct" else None
        self.linear = linear
        self.last_iterations = 0
        self.linear_iterations = 0  # Krylov iterations of all solves (iterative mode)
        self.snes = PETSc.SNES().create(problem.comm)
        self.snes.setOptionsPrefix(self.prefix)
        self.snes.setFunction(self._residual, self.b)
        self.snes.setJacobian(self._jacobian, self.A)
        self.snes.setFromOptions()
        ksp = self.snes.getKSP()
        ksp.setFromOptions()
        if linear == "iterative":
            u_is, q_is = self._field_index_sets()
            ksp.getPC().setFieldSplitIS(("u", u_is), ("q", q_is))
        ksp.getPC().setFromOptions()

    @staticmethod
    def _direct_options(factorization: str) -> dict:
        return {
            "ksp_type": "preonly",
            # K is symmetric (a Hessian): MUMPS LDL^T, valid also where K is indefinite (past an onset)
            "pc_type": factorization,
            "pc_factor_mat_solver_type": "mumps",
            # inertia of the factor (stability screening): null-pivot detection, and no ScaLAPACK
            # on the root node, without which MUMPS cannot count negative pivots in parallel
            "mat_mumps_icntl_24": 1,
            "mat_mumps_icntl_13": 1,
        }

    @staticmethod
    def _iterative_options(rtol: float, max_it: int) -> dict:
        """MINRES (K is symmetric, indefinite past an onset) with a block-diagonal (additive field-split)
        preconditioner, BoomerAMG on the displacement and on the flux block: symmetric positive
        definite where K is. Measured against MUMPS in docs/performance.md (far slower near an onset,
        where K is nearly singular: a memory-saving fallback, not the default)."""
        return {
            "ksp_type": "minres",
            "ksp_rtol": rtol,
            "ksp_atol": 0.0,
            "ksp_max_it": max_it,
            "pc_type": "fieldsplit",
            "pc_fieldsplit_type": "additive",
            "fieldsplit_u_ksp_type": "preonly",
            "fieldsplit_u_pc_type": "hypre",
            "fieldsplit_u_pc_hypre_type": "boomeramg",
            "fieldsplit_q_ksp_type": "preonly",
            "fieldsplit_q_pc_type": "hypre",
            "fieldsplit_q_pc_hypre_type": "boomeramg",
        }

    def _field_index_sets(self):
        """Global indices of the owned displacement and flux dofs of the mixed space."""
        p = self.problem
        n_owned = compat.owned_size(p.W)
        return [compat.owned_index_set(p.W, dofs[dofs < n_owned], p.comm) for dofs in (p.u_dofs, p.q_dofs)]

    def _sync_solution(self, x: PETSc.Vec) -> None:
        w = self.problem.w
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(compat.function_vector(w))
        compat.function_vector(w).ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def _residual(self, snes, x, b):
        with timing.timed("assembly"):
            self._sync_solution(x)
            compat.assemble_residual_into(b, self.problem.forms.residual, self.problem.forms.hessian,
                                          self.problem.bcs, x, lifting=self._lifting)

    def _needs_lifting(self, x: PETSc.Vec) -> bool:
        """Whether the initial guess misses the Dirichlet values (then the residual needs the lifting
        term K (g - x); once every iterate meets them, that term is zero and skipped)."""
        g = self._g
        g.set(0.0)
        compat.set_dirichlet_values(g, self.problem.bcs)
        idx = self._bc_dofs
        local = float(np.max(np.abs(x.array[idx] - g.array[idx]))) if idx.size else 0.0
        scale = float(np.max(np.abs(g.array[idx]))) if idx.size else 0.0
        comm = self.problem.comm
        return comm.allreduce(local, op=MPI.MAX) > 1e-13 * max(1.0, comm.allreduce(scale, op=MPI.MAX))

    def _jacobian(self, snes, x, J, P):
        with timing.timed("assembly"):
            compat.assemble_matrix_into(J, self.problem.forms.hessian, self.problem.bcs)

    def solve(self) -> NewtonResult:
        """Solve from the current ``problem.w`` as initial guess; ``problem.w`` holds the result."""
        w_vec = compat.function_vector(self.problem.w)
        w_vec.copy(self.x)
        self._lifting = self._needs_lifting(self.x)
        if not self._lifting:
            compat.set_dirichlet_values(self.x, self.problem.bcs)  # exact, not just to round-off
        try:
            with timing.timed("newton"):
                self.snes.solve(None, self.x)
            reason = self.snes.getConvergedReason()
        except PETSc.Error:
            reason = -100
        its = self.snes.getIterationNumber()
        self.last_iterations = its
        if its >= 1:
            # every option has been read once the linear solver was set up (MUMPS reads its controls at
            # the first factorization, field-split its blocks' at the first PCSetUp): free PETSc's
            # options table (512 entries per process), which many solvers in one process would fill
            self._clear_options()
        self.linear_iterations += self.snes.getLinearSolveIterations()
        if reason > 0:
            self._sync_solution(self.x)
        fnorm = self.snes.getFunctionNorm() if reason != -100 else float("nan")
        converged = reason > 0 and np.isfinite(fnorm)
        return NewtonResult(converged, its, reason, float(fnorm))

    def factor_inertia(self) -> tuple[int, int, int] | None:
        """(negative, zero, positive) pivot counts of the last LDL^T factorization of the last solve.

        That factor is K at the last Newton iterate (one update short of the converged state) with
        the step's tau, Dirichlet rows and columns replaced by a unit diagonal (which adds only
        positive eigenvalues). None if the last solve factorized nothing or used LU."""
        if self.factorization != "cholesky" or self.last_iterations < 1:
            return None
        F = self.snes.getKSP().getPC().getFactorMatrix()
        nneg, nzero, npos = F.getInertia()
        return int(nneg), int(nzero), int(npos)

    def _clear_options(self) -> None:
        opts = PETSc.Options()
        for key in self._option_keys:
            if opts.hasName(key):
                opts.delValue(key)
        self._option_keys = []

    def destroy(self) -> None:
        self._clear_options()
        for obj in (self.snes, self.A, self.b, self.x, self._g):
            obj.destroy()
