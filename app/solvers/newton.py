"""PETSc SNES Newton solver for one incremental minimization step, with a direct (MUMPS) solve.

dolfinx 0.5's own NewtonSolver is not SNES; here the residual and Hessian callbacks assemble
compiled forms into PETSc objects that SNES drives. The solver is built from those forms, their
Dirichlet conditions and the unknown function ``w`` they are written in, and owns its work
vectors; it writes only ``w`` (the solution). Options live under a per-instance prefix
(:mod:`app.solvers.mumps`) so that several solvers can coexist in one process.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, fem_utils, timing
from app.solvers import mumps


@dataclass(frozen=True)
class SolverSettings:
    """The [solver] table: Newton tolerances and the linear solver of each Newton step."""

    rtol: float
    atol: float
    max_it: int
    factorization: str = "cholesky"  # MUMPS LDL^T or LU (direct)
    linear: str = "direct"  # or "iterative": MINRES + block AMG
    ksp_rtol: float = 1e-10
    ksp_max_it: int = 2000
    line_search: str = "basic"
    reuse: bool = False  # modified Newton: keep the factor while |R| falls by reuse_rate per iteration
    reuse_rate: float = 0.03


def allow_new_nonzeros(A: PETSc.Mat) -> None:
    """Let ``A`` take entries outside the pattern of its form (an extra term's couplings)."""
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATION_ERR, False)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATIONS, True)


def held_global(bcs, space, comm) -> np.ndarray:
    """Global dofs of ``space`` under any of the Dirichlet conditions ``bcs`` (all ranks)."""
    held = fem_utils.global_indices(space, fem_utils.owned_bc_dofs(bcs, space))
    return np.unique(np.concatenate(comm.allgather(held)))


def free_rows(dofs: np.ndarray, rows: tuple[int, int], held: np.ndarray) -> np.ndarray:
    """Global dofs in this rank's row range ``rows`` that no condition holds; -1 (PETSc skips it) elsewhere."""
    lo, hi = rows
    keep = (dofs >= lo) & (dofs < hi) & ~np.isin(dofs, held)
    return np.where(keep, dofs, -1).astype(PETSc.IntType)


def add_blocks(A: PETSc.Mat, blocks: list, to_global: np.ndarray, held: np.ndarray) -> bool:
    """Add an extra term's Hessian blocks (entries (6,), H (6, 6)) to the assembled ``A``: entry e is the
    global dof ``to_global[e]``; this rank adds its own rows, no row or column of a held dof. Whether any
    block was added (``A`` is then assembled again: the same on every rank, the blocks being so)."""
    rows = A.getOwnershipRange()
    for entries, H in blocks:
        dofs = to_global[entries]
        cols = np.where(np.isin(dofs, held) | (dofs < 0), -1, dofs).astype(PETSc.IntType)
        A.setValues(free_rows(np.where(dofs < 0, -1, dofs), rows, held), cols, H, addv=PETSc.InsertMode.ADD_VALUES)
    if blocks:
        A.assemble()
    return bool(blocks)


ROUNDOFF_UPDATE = 1e3 * np.finfo(float).eps  # a Newton update below this times |x| is at roundoff
STAGNATION = 0.5  # a residual that falls by less than this factor in one iteration has stagnated
DIVTOL = 1e4  # PETSc's default divergence tolerance (SNESConvergedDefault's DIVERGED_DTOL)


@dataclass
class NewtonResult:
    converged: bool
    iterations: int
    reason: int
    residual_norm: float


class NewtonSolver:
    """SNES (newtonls) on R(w) = 0 with Jacobian K, in place on the function ``w``.

    ``fields`` ({"u": dofs, "q": dofs}, local indices in w's space) are the blocks of the iterative
    solver's field-split preconditioner; the direct solver does not need them.

    ``extra`` is a term of the energy that is not a form (the surface's self-contact,
    :class:`app.model.penalty.PenaltyContact`): ``extra.terms(owned_values)`` gives its energy and gradient
    in global dof numbers, ``extra.entry_blocks(owned_values)`` its Hessian as blocks on its entries,
    ``extra.global_entries`` their global dofs, ``extra.energy(owned_values)`` its energy and
    ``extra.objective(owned_values)`` the same or inf outside its domain (the minimizer's line search,
    :mod:`app.solvers.minimizer`); the same on every rank. Each rank adds the rows it owns,
    outside the Dirichlet dofs (whose rows and columns stay those of the conditions; :func:`add_blocks`).
    Its Hessian couples surface dofs that no cell couples: the matrix takes new nonzeros where contact
    begins.

    **Factor reuse** (``settings.reuse``, direct solves without an extra term): each solve factorizes K at
    its initial guess, and that factor serves the later iterations of the solve as long as each iteration
    reduces the residual by at least ``settings.reuse_rate``; an iteration that does worse makes the next
    one assemble and factorize K at its iterate (modified Newton with an adaptive refresh). The converged
    state is the same to Newton's tolerance: only the path to it changes. A solve that fails after an update
    with a kept factor is repeated from the same initial guess with a fresh factor every iteration (plain
    Newton), so reuse never turns a step that Newton solves into a failure. A factor is never carried from
    one solve to the next: a solve then depends only on its initial guess and the problem's state, so a run
    resumed from a checkpoint takes the same iterations as the run never stopped (carrying it over saved
    another 18% of the factorizations, 8% of the run, on the default bilayer; docs/performance.md)."""

    def __init__(self, residual, hessian, bcs, w, settings: SolverSettings, comm, fields: dict | None = None,
                 extra=None):
        self.residual_form, self.hessian_form = residual, hessian
        self.bcs, self.w, self.comm = bcs, w, comm
        self.A = fem_petsc.create_matrix(hessian)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.b = fem_petsc.create_vector(residual)
        self.x = self.b.duplicate()
        self._g = self.b.duplicate()  # Dirichlet values at the constrained dofs, 0 elsewhere
        self._x_prev, self._dx = self.b.duplicate(), self.b.duplicate()  # the last iterate, the update taken
        self._bc_dofs = fem_utils.owned_bc_dofs(bcs, w.function_space)
        self._lifting = True
        self.extra = extra
        self.reuse = settings.reuse and settings.linear == "direct" and extra is None
        self.reuse_rate = settings.reuse_rate
        self._refresh = True  # the next Jacobian call assembles and factorizes K
        self._kept = False  # the last solve took an update with a factor it did not make at that iterate
        self._plain = False  # this solve factorizes every iteration (the repeat of a failed reuse)
        self.factorizations = 0  # of K, by this solver
        self.reuse_retries = 0  # solves repeated with plain Newton after a failure with a kept factor
        if extra is not None:
            allow_new_nonzeros(self.A)
            self._held = held_global(bcs, w.function_space, comm)
            self._rows = self.A.getOwnershipRange()
        linear = settings.linear
        options = {
            "snes_type": "newtonls",
            # with a contact term the pairing can flip between iterates where a node just touches: a plain
            # Newton step may then cycle between two active sets; backtracking (on |R|^2, or on the energy in
            # the minimizer) breaks the cycle
            "snes_linesearch_type": "bt" if extra is not None else settings.line_search,
            "snes_rtol": settings.rtol,
            "snes_atol": settings.atol,
            "snes_stol": 0.0,
            "snes_max_it": settings.max_it,
            "snes_max_funcs": 100 * settings.max_it,
        }
        # K is symmetric (a Hessian): MUMPS LDL^T, valid also where K is indefinite (past an onset), with
        # the controls that make its inertia exact (the stability screen reads it)
        options.update(mumps.direct(settings.factorization) if linear == "direct"
                       else self._iterative_options(settings.ksp_rtol, settings.ksp_max_it))
        self._options = mumps.PrefixedOptions("hb", options)
        self.prefix = self._options.prefix
        self.factorization = settings.factorization if linear == "direct" else None
        self.linear = linear
        self.last_iterations = 0
        self.linear_iterations = 0  # Krylov iterations of all solves (iterative mode)
        self._tol = (settings.rtol, settings.atol, 100 * settings.max_it)
        self.residual_scale = None  # the initial residual norm of the first solve: the problem's scale
        self.floor_accepted = 0  # solves accepted by the roundoff-floor rule (see _converged)
        self.keep_tolerance = False  # the next solve keeps the last one's tolerance (MinimizingNewton._resumed)
        self._ttol = self._rnorm0 = None  # this solve's convergence tolerance and initial residual (_converged)
        self.snes = PETSc.SNES().create(comm)
        self.snes.setOptionsPrefix(self.prefix)
        self.snes.setFunction(self._residual, self.b)
        self.snes.setJacobian(self._jacobian, self.A)
        self.snes.setFromOptions()
        self.snes.setConvergenceTest(self._converged)
        ksp = self.snes.getKSP()
        ksp.setFromOptions()
        if linear == "iterative":
            u_is, q_is = self._field_index_sets(fields)
            ksp.getPC().setFieldSplitIS(("u", u_is), ("q", q_is))
        ksp.getPC().setFromOptions()
        self.exact_blocks = False  # the extra term's exact Hessian even where it offers Newton blocks of its own
        if getattr(extra, "step_fraction", None) is not None:  # a barrier: every iterate stays free of crossings
            self.snes.setLineSearchPreCheck(self._step_filter)

    def collision_free(self, start, step) -> float:
        """The fraction of the update ``step`` from ``start`` (owned arrays; the iterate moves to start - step)
        that crosses no part of the surface: the extra term's ``step_fraction`` (a barrier's continuous
        collision detection), 1 without one."""
        if getattr(self.extra, "step_fraction", None) is None:
            return 1.0
        return self.extra.step_fraction(start, step)

    def _step_filter(self, x, y, *args) -> None:
        """The line search's precheck with a barrier term: the update y (the iterate moves to x - lambda y,
        lambda <= 1) is shortened to the part of it free of crossings (:meth:`collision_free`), so that no
        trial point of the line search lies beyond the barrier, where its energy is not defined."""
        fraction = self.collision_free(x.array_r, y.array_r)
        if fraction < 1.0:
            y.scale(fraction)

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

    def _field_index_sets(self, fields: dict):
        """Global indices of the owned displacement and flux dofs of the mixed space."""
        W = self.w.function_space
        n_owned = fem_utils.owned_size(W)
        return [fem_utils.owned_index_set(W, dofs[dofs < n_owned], self.comm) for dofs in (fields["u"], fields["q"])]

    def _sync_solution(self, x: PETSc.Vec) -> None:
        w = self.w
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(compat.function_vector(w))
        compat.function_vector(w).ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def _residual(self, snes, x, b):
        with timing.timed("assembly"):
            self._sync_solution(x)
            compat.assemble_residual_into(b, self.residual_form, self.hessian_form, self.bcs, x,
                                          lifting=self._lifting)
            if self.extra is not None:
                terms = self.extra.terms(x.array_r)
                rows = free_rows(terms.grad_dofs, self._rows, self._held)
                keep = rows >= 0
                b.array[rows[keep] - self._rows[0]] += terms.grad[keep]

    def _needs_lifting(self, x: PETSc.Vec) -> bool:
        """Whether the initial guess misses the Dirichlet values (then the residual needs the lifting
        term K (g - x); once every iterate meets them, that term is zero and skipped)."""
        g = self._g
        g.set(0.0)
        fem_petsc.set_bc(g, self.bcs)
        idx = self._bc_dofs
        local = float(np.max(np.abs(x.array[idx] - g.array[idx]))) if idx.size else 0.0
        scale = float(np.max(np.abs(g.array[idx]))) if idx.size else 0.0
        comm = self.comm
        return comm.allreduce(local, op=MPI.MAX) > 1e-13 * max(1.0, comm.allreduce(scale, op=MPI.MAX))

    def _converged(self, snes, it, norms):
        """PETSc's default test (SNESConvergedDefault with stol = 0), in the same order, plus one
        acceptance it lacks: a residual at its roundoff floor is converged.

        Default: converged if |R| < atol or (it > 0 and) |R| <= rtol |R_0| (R_0: this step's initial
        residual); diverged on NaN, too many function evaluations or |R| > 1e4 |R_0|. Near equilibrium
        |R_0| is tiny and rtol |R_0| can lie below roundoff; then a converged state would iterate to
        max_it and be cut back. So (it > 0) the iterate is also converged if the Newton update is at
        roundoff (|dx| <= 1e3 eps |x|), or if the residual stagnated (fell by less than 2 in the last
        iteration) at a level below rtol times the problem's scale (the initial residual norm of the
        solver's first solve, the run's first step). Normal steps converge by the default rules first,
        with their iteration counts unchanged.

        |dx| is the update actually taken, measured here from the iterates: the norm PETSc reports after
        a backtracking line search is the scaled step in PETSc 3.18 but the full Newton direction in
        3.22, which would make the roundoff rule fire on one stack and not on the other."""
        xnorm, _, fnorm = norms
        ynorm = self._update_norm(it)
        rtol, atol, max_funcs = self._tol
        if it == 0 and not (self.keep_tolerance and self._ttol is not None):  # a solve resumed from a failed one
            self._ttol, self._rnorm0 = fnorm * rtol, fnorm
            if self.residual_scale is None and np.isfinite(fnorm) and fnorm > 0:
                self.residual_scale = float(fnorm)
        reason = PETSc.SNES.ConvergedReason
        out = reason.CONVERGED_ITERATING
        if not np.isfinite(fnorm):
            out = reason.DIVERGED_FNORM_NAN
        elif fnorm < atol:
            out = reason.CONVERGED_FNORM_ABS
        elif snes.getFunctionEvaluations() >= max_funcs:
            out = reason.DIVERGED_FUNCTION_COUNT
        if it and out == reason.CONVERGED_ITERATING:
            scale = self.residual_scale or 0.0
            if fnorm <= self._ttol:
                out = reason.CONVERGED_FNORM_RELATIVE
            elif ynorm <= ROUNDOFF_UPDATE * xnorm or (fnorm <= rtol * scale and fnorm > STAGNATION * self._fprev):
                out = reason.CONVERGED_SNORM_RELATIVE
                self.floor_accepted += 1
            elif fnorm > DIVTOL * self._rnorm0:
                out = reason.DIVERGED_DTOL
        if it and self.reuse and fnorm > self.reuse_rate * self._fprev:
            self._refresh = True  # too slow for the kept factor: a fresh one at the next iteration
        self._fprev = fnorm
        return out

    def _update_norm(self, it: int) -> float:
        """|x_it - x_(it-1)| of the iterates of this solve (0 at it = 0)."""
        x = self.x
        if it == 0:
            x.copy(self._x_prev)
            return 0.0
        self._dx.waxpy(-1.0, self._x_prev, x)
        x.copy(self._x_prev)
        return self._dx.norm()

    def _jacobian(self, snes, x, J, P):
        ksp = snes.getKSP()
        if self.reuse and not (self._refresh or self._plain):
            ksp.getPC().setReusePreconditioner(True)  # J untouched and its factor kept (no PCSetUp)
            self._kept = True
            return
        if self.reuse:
            ksp.getPC().setReusePreconditioner(False)
            self._refresh = False
        self.factorizations += 1
        self._assemble_jacobian(x, J)

    def _assemble_jacobian(self, x, J):
        with timing.timed("assembly"):
            fem_utils.assemble_matrix_into(J, self.hessian_form, self.bcs)
            if self.extra is not None:
                # the term's Newton blocks where it has its own (the barrier's, projected to positive
                # semi-definite pair by pair) until Newton is near the solution (``exact_blocks``), else its Hessian
                blocks = self.extra.entry_blocks if self.exact_blocks else \
                    getattr(self.extra, "newton_blocks", self.extra.entry_blocks)
                add_blocks(J, blocks(x.array_r), self.extra.global_entries, self._held)

    def solve(self) -> NewtonResult:
        """Solve from the current ``w`` as initial guess; ``w`` holds the result."""
        w_vec = compat.function_vector(self.w)
        w_vec.copy(self.x)
        self._lifting = self._needs_lifting(self.x)
        if not self._lifting:
            fem_petsc.set_bc(self.x, self.bcs)  # exact, not just to round-off
        self._kept = self._plain = False
        self._refresh = True  # every solve starts with a factor of its own
        start = self.x.copy() if self.reuse else None
        reason, its = self._snes_solve()
        if reason <= 0 and self._kept:  # the kept factor may be what failed: again, plain Newton
            self.reuse_retries += 1
            start.copy(self.x)
            self._plain = True
            reason, more = self._snes_solve()
            its += more
        if start is not None:
            start.destroy()
        self.last_iterations = its
        if its >= 1 and self.extra is None:
            # every option has been read once the linear solver was set up (MUMPS reads its controls at
            # the first factorization, field-split its blocks' at the first PCSetUp). With an extra term the
            # matrix gains nonzeros where contact begins, and PETSc then makes a new factor, which reads
            # them again: they stay until destroy()
            self._options.clear()
        self.linear_iterations += self.snes.getLinearSolveIterations()
        if reason > 0:
            self._sync_solution(self.x)
        fnorm = self.snes.getFunctionNorm() if reason != -100 else float("nan")
        converged = reason > 0 and np.isfinite(fnorm)
        return NewtonResult(converged, its, reason, float(fnorm))

    def _snes_solve(self) -> tuple[int, int]:
        """One SNES solve from ``self.x``: (converged reason, -100 for a PETSc error; iterations)."""
        try:
            with timing.timed("newton"):
                self.snes.solve(None, self.x)
            reason = self.snes.getConvergedReason()
        except PETSc.Error:
            reason = -100
        return reason, self.snes.getIterationNumber()

    def factor_inertia(self) -> tuple[int, int, int] | None:
        """(negative, zero, positive) pivot counts of the last LDL^T factorization of the last solve.

        That factor is K at the last Newton iterate (one update short of the converged state) with
        the step's tau, Dirichlet rows and columns replaced by a unit diagonal (which adds only
        positive eigenvalues). With factor reuse it may be K at an earlier iterate of that solve (its initial
        guess at the earliest). None if the last solve factorized nothing or used LU."""
        if self.factorization != "cholesky" or self.last_iterations < 1:
            return None
        F = self.snes.getKSP().getPC().getFactorMatrix()
        nneg, nzero, npos = F.getInertia()
        return int(nneg), int(nzero), int(npos)

    def counters(self) -> dict:
        """The state that outlives one solve (for checkpoints): the problem's residual scale (the
        roundoff-floor rule reads it) and the counters reported in the summary."""
        return {"residual_scale": self.residual_scale, "floor_accepted": self.floor_accepted,
                "linear_iterations": self.linear_iterations, "factorizations": self.factorizations,
                "reuse_retries": self.reuse_retries}

    def set_counters(self, c: dict) -> None:
        self.residual_scale, self.floor_accepted = c["residual_scale"], c["floor_accepted"]
        self.linear_iterations = c["linear_iterations"]
        self.factorizations, self.reuse_retries = c.get("factorizations", 0), c.get("reuse_retries", 0)

    def destroy(self) -> None:
        self._options.clear()
        for obj in (self.snes, self.A, self.b, self.x, self._g, self._x_prev, self._dx):
            obj.destroy()
