"""PETSc SNES Newton solver for one incremental minimization step, with a direct (MUMPS) solve.

dolfinx 0.5's own NewtonSolver is not SNES; here the residual and Hessian callbacks assemble
the compiled forms of :mod:`app.potential` into PETSc objects that SNES drives. Options are set
under a per-instance prefix so that several problems can coexist in one process.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
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
                 factorization: str = "cholesky"):
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
        for key, value in {
            "snes_type": "newtonls",
            "snes_linesearch_type": line_search,
            "snes_rtol": rtol,
            "snes_atol": atol,
            "snes_stol": 0.0,
            "snes_max_it": max_it,
            "snes_max_funcs": 100 * max_it,
            "ksp_type": "preonly",
            # K is symmetric (a Hessian): MUMPS LDL^T, valid also where K is indefinite (past an onset)
            "pc_type": factorization,
            "pc_factor_mat_solver_type": "mumps",
            # inertia of the factor (stability screening): null-pivot detection, and no ScaLAPACK
            # on the root node, without which MUMPS cannot count negative pivots in parallel
            "mat_mumps_icntl_24": 1,
            "mat_mumps_icntl_13": 1,
        }.items():
            opts[self.prefix + key] = value
        self.factorization = factorization
        self.last_iterations = 0
        self.snes = PETSc.SNES().create(problem.comm)
        self.snes.setOptionsPrefix(self.prefix)
        self.snes.setFunction(self._residual, self.b)
        self.snes.setJacobian(self._jacobian, self.A)
        self.snes.setFromOptions()
        self.snes.getKSP().setFromOptions()
        self.snes.getKSP().getPC().setFromOptions()

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
        return comm.allreduce(local, op=_mpi_max()) > 1e-13 * max(1.0, comm.allreduce(scale, op=_mpi_max()))

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

    def destroy(self) -> None:
        for obj in (self.snes, self.A, self.b, self.x):
            obj.destroy()


def _mpi_max():
    from mpi4py import MPI

    return MPI.MAX
