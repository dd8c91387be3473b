"""The step solver past an onset: Newton that finds a local *minimizer* of the incremental potential.

Past a stability crossing K is indefinite along the buckling mode, and plain Newton converges to
whatever stationary point is nearest, the unbuckled saddle included. This solver is the same SNES
(:class:`app.solvers.newton.NewtonSolver`, MUMPS LDL^T) with three changes (docs/postbuckling.md):

- **objective**: SNES's objective is Pi^tau itself (``CompiledForms.energy``), and the line search is
  backtracking on it (``bt``): every accepted iterate lowers the energy;
- **inertia-corrected direction**: after assembling K the solver factorizes it and reads the
  inertia of the LDL^T factor; while it shows negative pivots, K is shifted by sigma |diag K| (a
  Jacobi-scaled shift, the same for every unit system) and refactorized, sigma growing tenfold. The
  direction K_sigma^-1 R is then a descent direction of Pi. The factor SNES then solves with is the one
  computed here (PETSc does not refactorize an unchanged matrix), so an unshifted iteration costs one
  factorization, as before;
- **verdicts**: the unshifted negative-pivot count of the last factorization tells whether the
  converged state is a minimizer (none) or a saddle (some), and the energy at the initial guess and at
  the solution are kept: :attr:`last` reports both.

Near a minimizer energy differences fall below the roundoff of the assembled energy; a line search
that then fails, or shrinks the step to roundoff (which the base test would accept as converged short of
the tolerance), at a residual already below ``sqrt(rtol)`` times the problem's scale is finished with
plain Newton steps (K is positive definite there), not reported as a failure.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from app import compat, fem_utils, timing
from app.solvers.newton import NewtonResult, NewtonSolver, SolverSettings

SHIFT_START = 1e-6  # first trial shift (times |diag K|) of a factorization with negative pivots
SHIFT_MAX = 1e6  # beyond this the direction is a scaled gradient step already
# the objective outside Pi's domain (see MinimizingNewton._objective): far above any energy of a step, and far
# below overflow: PETSc's backtracking (bt) fits a cubic through two such values divided by squares of step
# lengths down to 1e-12. At 1e300 (until 2026-12-05) that fit overflows: its formula, replayed with two trials
# outside, gives a NaN step length after three cuts, and a NaN never compares below the minimum step
OUTSIDE = 1e20
ITERATION_FACTOR = 4  # escaping a saddle may take more iterations than an ordinary step
SNAP_ROUNDS = 4  # a solve that left a saddle and ran out of iterations still descending goes on, up to this x
ESCAPES = 3  # negative-curvature steps per solve (MinimizingNewton._escape)
INVERSE_ITERATIONS = 30  # inverse iterations with the shifted factor for a direction of negative curvature


@dataclass
class MinimizerVerdict:
    """What the last solve found besides convergence."""

    negatives: int = 0  # negative pivots of the unshifted K at the last Newton iterate (0: a minimizer)
    energy_start: float = float("nan")  # Pi at the initial guess (with the Dirichlet values)
    energy_end: float = float("nan")  # Pi at the solution
    shifted: int = 0  # factorizations with a shift in this solve
    polished: bool = False  # the energy line search gave way to plain Newton near the minimizer
    escapes: int = 0  # negative-curvature steps taken in this solve


class MinimizingNewton(NewtonSolver):
    """Energy-decreasing, inertia-corrected Newton on Pi^tau (see the module docstring)."""

    def __init__(self, energy, residual, hessian, bcs, w, settings: SolverSettings, comm, fields=None, extra=None):
        settings = dataclasses.replace(settings, line_search="bt", max_it=ITERATION_FACTOR * settings.max_it,
                                       factorization="cholesky", linear="direct", reuse=False)
        super().__init__(residual, hessian, bcs, w, settings, comm, fields, extra)
        self.energy_form = energy
        self.snes.setObjective(self._objective)
        self.rtol = settings.rtol
        self.last = MinimizerVerdict()
        self.sigma = 0.0  # the last shift that gave no negative pivots (a start for the next one)
        self.shifted_factorizations = 0
        self.saddles = 0  # solves that converged with negative pivots left
        self.polishes = 0
        self.escapes = 0  # negative-curvature steps (all solves)
        self.snap_rounds = 0  # solves continued past their iteration limit while descending from a saddle
        # how far a negative-curvature step moves the farthest node [mm]: the branch's imperfection (set by
        # the stepper); None: no such steps
        self.escape_length: float | None = None
        self.u_dofs = np.asarray(fields["u"]) if fields else None
        self._shift = (0.0, None)  # (sigma, D) of the last factorization: its matrix is K + sigma D

    # --- SNES callbacks ------------------------------------------------------------------------

    def _objective(self, snes, x):
        """Pi at the iterate. With a contact term, outside Pi's domain a value far above any energy of the
        step, so that the backtracking line search shortens the step: where a cell has det F <= 0 (ln J is
        not defined: NaN) and where the surface has passed through itself beyond the penalty's reach
        (``extra.objective``: inf). Without contact PETSc's line search gives up at once on a NaN objective,
        and the step is cut back: that behaviour is kept as it was."""
        with timing.timed("assembly"):
            self._sync_solution(x)
            if self.extra is None:
                return self.energy(x.array_r)
            value = fem_utils.assemble_scalar(self.energy_form, self.comm) + self.extra.objective(x.array_r)
            return value if math.isfinite(value) else OUTSIDE

    def admissible(self, start=None) -> bool:
        """Whether ``w`` (its Dirichlet values set) lies in Pi's domain: the objective there is finite (no
        inverted cell; with contact, no node tunnelled through the surface) and, with a barrier and the array
        of the state it starts from (``start``), the straight path from there to ``w`` crosses no part of the
        surface (a prediction can carry a whole fold through the other face, to a state without a crossing).
        Same answer on every rank."""
        x = compat.function_vector(self.w)
        fem_petsc.set_bc(x, self.bcs)
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        value = self._objective(self.snes, x)  # NaN (no contact term) or OUTSIDE outside the domain
        if not (math.isfinite(value) and value < OUTSIDE):
            return False
        if start is None:
            return True
        start = np.asarray(start)[:len(x.array_r)]
        return self.collision_free(start, start - x.array_r) >= 1.0

    def energy(self, owned_values=None) -> float:
        """Pi at ``w`` (or at the owned values given, already in ``w``): the energy form plus the extra
        term (self-contact)."""
        value = fem_utils.assemble_scalar(self.energy_form, self.comm)
        if self.extra is not None:
            value += self.extra.energy(compat.function_vector(self.w).array if owned_values is None
                                       else owned_values)
        return value

    def _factor_negatives(self, ksp) -> int:
        ksp.getPC().setUp()
        nneg, _, _ = ksp.getPC().getFactorMatrix().getInertia()
        return int(nneg)

    def _jacobian(self, snes, x, J, P):
        super()._jacobian(snes, x, J, P)
        ksp = snes.getKSP()
        ksp.setOperators(J, P)
        nneg = self._factor_negatives(ksp)
        self.last.negatives = nneg
        if self._shift[1] is not None:
            self._shift[1].destroy()
        self._shift = (0.0, None)
        if nneg == 0:
            self.sigma = 0.0
            return
        d = J.getDiagonal()
        d.abs()
        floor = d.max()[1] * 1e-12
        d.array[d.array < floor] = floor
        sigma, applied = max(SHIFT_START, self.sigma / 10.0), 0.0
        step = d.duplicate()
        try:
            while True:
                d.copy(step)
                step.scale(sigma - applied)
                J.setDiagonal(step, addv=PETSc.InsertMode.ADD_VALUES)
                J.assemble()
                applied = sigma
                self.shifted_factorizations += 1
                self.last.shifted += 1
                if self._factor_negatives(ksp) == 0 or sigma >= SHIFT_MAX:
                    break
                sigma *= 10.0
        finally:
            step.destroy()
        self._shift = (applied, d)
        self.sigma = sigma

    def _converged(self, snes, it, norms):
        """The default test of :class:`NewtonSolver` without its divergence rule: leaving a saddle the
        residual grows by orders of magnitude while the energy falls."""
        out = super()._converged(snes, it, norms)
        if out == PETSc.SNES.ConvergedReason.DIVERGED_DTOL:
            return PETSc.SNES.ConvergedReason.CONVERGED_ITERATING
        return out

    # --- one solve -----------------------------------------------------------------------------

    def solve(self) -> NewtonResult:
        """Minimize Pi from the current ``w`` (its Dirichlet values set first, so that every iterate is
        admissible and the energies compare); ``w`` holds the result, :attr:`last` the verdict."""
        self.last = MinimizerVerdict()
        self._ttol = None  # set by this solve's first Newton iteration; a resumed round keeps it
        x = compat.function_vector(self.w)
        fem_petsc.set_bc(x, self.bcs)
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        self.last.energy_start = self.energy(x.array)
        if not self.admissible():
            # a start outside Pi's domain: every trial of the line search is OUTSIDE there too, and the
            # backtracking's test (not above the start) takes the first one: the iterates would wander
            # outside. No iteration: the caller starts from elsewhere or cuts the step
            self.last_iterations = 0
            return NewtonResult(False, 0, int(PETSc.SNES.ConvergedReason.DIVERGED_FUNCTION_DOMAIN), float("nan"))
        res = super().solve()
        reason = PETSc.SNES.ConvergedReason
        rounds, round_start = 1, self.last.energy_start
        while (not res.converged and res.reason == reason.DIVERGED_MAX_IT and self.last.shifted
               and rounds < SNAP_ROUNDS):
            # a snap: the solve left a saddle (it shifted K) and its iterations ran out while the round still
            # lowered the energy. A shorter time step does not help (the state it starts from is the same
            # saddle, and the way down to the next minimizer as long): the descent goes on from its last iterate
            end = self._objective(self.snes, self.x)
            if not (math.isfinite(end) and end < OUTSIDE and end < round_start - 1e-12 * max(1.0, abs(round_start))):
                break
            rounds, round_start = rounds + 1, end
            self.snap_rounds += 1
            res = self._resumed(res)
        if not res.converged and res.reason == reason.DIVERGED_LINE_SEARCH:
            res = self._polish(res)
        elif res.converged and res.reason == reason.CONVERGED_SNORM_RELATIVE and res.residual_norm > self._ttol:
            # the roundoff-update rule fired on a step the line search had shrunk (the energy's roundoff
            # hides the decrease near the minimizer): the iterate is short of the tolerance, finish it
            res = self._polish(res)
        while (not res.converged and res.reason == reason.DIVERGED_LINE_SEARCH and self.last.negatives
               and self.last.escapes < ESCAPES and self._escape()):
            # a saddle the line search cannot leave: its residual is mostly in stiff directions and the
            # energy along K_sigma^-1 R falls below roundoff, while K is indefinite. A step along a direction
            # of negative curvature leaves it; then Newton again from there
            res = self._resumed(res)
            if not res.converged and res.reason == reason.DIVERGED_LINE_SEARCH:
                res = self._polish(res)
        if res.converged:
            self.last.energy_end = self.energy()
            if self.last.negatives:
                self.saddles += 1
        return res

    def _resumed(self, res: NewtonResult) -> NewtonResult:
        """Newton again from the last iterate (after an escape step, or for another round of a snap), converged
        by the first round's tolerance (rtol times the step's initial residual, not the larger residual met on
        the way down); the iterations add up."""
        its = res.iterations
        self._sync_solution(self.x)
        self.keep_tolerance = True
        try:
            res = super().solve()
        finally:
            self.keep_tolerance = False
        res = dataclasses.replace(res, iterations=res.iterations + its)
        self.last_iterations = res.iterations
        return res

    def _escape(self) -> bool:
        """One step from the last iterate along a direction of negative curvature of K, downhill: x += a v
        with the farthest node moved by ``escape_length``, halved (at most 4 times) until the energy falls by
        more than its roundoff. v comes from inverse iteration with the shifted factor (K + sigma D is
        positive definite, its smallest eigenvalue in the D metric is K's most negative one plus sigma), from
        a fixed random start; any v with v' K v < 0 will do. False (x unchanged) if there is no such step."""
        if self.escape_length is None or self.u_dofs is None:
            return False
        snes, x, A = self.snes, self.x, self.A
        ksp = snes.getKSP()
        self._sync_solution(x)  # the forms read w: the line search may have left a trial point there
        self._jacobian(snes, x, A, A)  # K at this iterate, shifted until positive definite
        sigma, D = self._shift
        if not self.last.negatives or D is None:
            return False
        n_owned = x.getLocalSize()
        u_owned = self.u_dofs[self.u_dofs < n_owned]
        v, w, Av = x.duplicate(), x.duplicate(), x.duplicate()
        trial = x.duplicate()
        try:
            rng = PETSc.Random().create(self.comm)
            rng.setSeed(20261204)
            v.setRandom(rng)
            rng.destroy()
            v.array[self._bc_dofs] = 0.0
            for _ in range(INVERSE_ITERATIONS):
                w.pointwiseMult(D, v)
                ksp.solve(w, v)
                v.array[self._bc_dofs] = 0.0
                v.scale(1.0 / v.norm())
            A.mult(v, Av)
            w.pointwiseMult(D, v)
            curvature = v.dot(Av) - sigma * v.dot(w)  # v' K v
            if not curvature < 0.0:
                return False
            self._residual(snes, x, w)
            if w.dot(v) > 0.0:
                v.scale(-1.0)  # downhill (the energy's gradient is the residual)
            local = float(np.max(np.abs(v.array[u_owned]))) if u_owned.size else 0.0
            vmax = self.comm.allreduce(local, op=MPI.MAX)
            if not vmax > 0.0:
                return False
            e0 = self._objective(snes, x)
            step = self.escape_length / vmax
            w.set(0.0)  # a barrier: no step through the surface
            w.axpy(-step, v)
            step *= self.collision_free(x.array_r, w.array_r)
            for _ in range(5):
                trial.waxpy(step, v, x)
                e = self._objective(snes, trial)
                if e < e0 - 1e-12 * max(1.0, abs(e0)):
                    trial.copy(x)
                    self.last.escapes += 1
                    self.escapes += 1
                    return True
                step /= 2.0
            self._sync_solution(x)
            return False
        finally:
            for vec in (v, w, Av, trial):
                vec.destroy()

    def _polish(self, failed: NewtonResult) -> NewtonResult:
        """A line search that failed or stalled close to a minimizer (residual below sqrt(rtol) x the
        problem's scale, K without negative pivots): finish with plain Newton steps from the last iterate,
        converged by the same test (:meth:`NewtonSolver._converged`), whose roundoff-update rule means
        what it says only for full Newton steps. Otherwise ``failed`` is returned as it is."""
        scale = self.residual_scale or 0.0
        if not (math.isfinite(failed.residual_norm) and failed.residual_norm <= math.sqrt(self.rtol) * scale
                and self.last.negatives == 0):
            return failed
        snes, x, b, A = self.snes, self.x, self.b, self.A
        ksp = snes.getKSP()
        dx = x.duplicate()
        reason, its, fnorm = failed.reason, 0, failed.residual_norm
        self.exact_blocks = True  # near the minimizer: the exact Hessian, for Newton's quadratic convergence
        try:
            self._residual(snes, x, b)
            fnorm = b.norm()
            self._converged(snes, 0, (x.norm(), 0.0, fnorm))
            self._ttol = failed.residual_norm * self.rtol
            for its in range(1, 6):
                self._jacobian(snes, x, A, A)
                if self.last.negatives:  # not a minimizer's neighbourhood after all: the result as it was
                    its -= 1
                    break
                ksp.solve(b, dx)
                x.axpy(-self.collision_free(x.array_r, dx.array_r), dx)  # a barrier: not through the surface
                self._residual(snes, x, b)
                fnorm = b.norm()
                reason = self._converged(snes, its, (x.norm(), dx.norm(), fnorm))
                if reason != PETSc.SNES.ConvergedReason.CONVERGED_ITERATING:
                    break
        finally:
            dx.destroy()
            self.exact_blocks = False
        if its == 0:
            return failed
        converged = reason > 0 and math.isfinite(fnorm)
        if converged:
            self._sync_solution(x)
            self.polishes += 1
            self.last.polished = True
        self.last_iterations = failed.iterations + its
        return NewtonResult(converged, failed.iterations + its, int(reason), float(fnorm))

    def destroy(self) -> None:
        if self._shift[1] is not None:
            self._shift[1].destroy()
        super().destroy()

    def counters(self) -> dict:
        return {**super().counters(), "sigma": self.sigma, "shifted_factorizations": self.shifted_factorizations,
                "saddles": self.saddles, "polishes": self.polishes, "escapes": self.escapes,
                "snap_rounds": self.snap_rounds}

    def set_counters(self, c: dict) -> None:
        super().set_counters(c)
        self.sigma = c.get("sigma", 0.0)
        self.shifted_factorizations = c.get("shifted_factorizations", 0)
        self.saddles, self.polishes = c.get("saddles", 0), c.get("polishes", 0)
        self.escapes = c.get("escapes", 0)
        self.snap_rounds = c.get("snap_rounds", 0)


def energy_decreased(verdict: MinimizerVerdict) -> bool:
    """The step's energy test: Pi at the solution not above Pi at the initial guess (up to roundoff)."""
    a, b = verdict.energy_start, verdict.energy_end
    return bool(np.isfinite(a) and np.isfinite(b) and b <= a + 1e-12 * max(1.0, abs(a)))
