"""The energetic crease onset (docs/creases.md): the load at which a creased surface has less energy than the
flat one, by the trial crease of Hong, Zhao & Suo (2009), held at its size or growing from it.

A crease is subcritical: the flat state stays linearly stable past it (the Hessian's inertia cannot see it),
but a state folded into self-contact has lower energy. The trial crease sits on a symmetry line of the body
(the bilayer's left edge, held in x): the permeable surface's points within the reference length ``c`` of
that line are moved onto it, x = 0, and are free to slide along it (frictionless contact with their mirror
image: the crease's two walls). Between those points and the rest of the surface the body folds into a
crease of depth about c, its tip at the surface point on the symmetry line. Every other condition and the
load are those of the flat state. The energy difference

    dPi(t) = Pi(creased state at load t) - Pi(flat state at load t)

scales as mu c^2 f(load) while c is small against the layer; it is positive at no load and changes sign at
the crease onset, independently of c (Hong, Zhao & Suo: nominal strain 0.354 for an incompressible
neo-Hookean half-space in plane-strain compression; the linear, Biot onset is 0.456).

A growing crease (``mirror_stiffness``: :func:`app.model.equilibrium.mirror_term`) lets the rest of the free
surface fold onto the line too, in frictionless contact with its mirror image: the trial crease is then the
smallest crease, and the body takes the size of least energy (a bilayer's is about twice its film). Once
a load has a creased state below the flat one, a trial at a lower load follows that crease down in load
instead of closing a new one from the flat state, so that the onset is the sign change along the branch of
the crease of least energy, not of the small trial crease that coexists with it.

The creased state is reached from the flat one by moving the crease's points to the symmetry line in
sub-steps, each solved by the minimizing Newton (energy line search, inertia correction: the fold passes
through states where K is indefinite); a sub-step that fails is halved. The load enters through the
problem's loading, and the test needs a flat state at every load without a history:

- a loading without fluid motion (``compression``: the fluid frozen, the energy path independent): the
  energy is the stored energy;
- a swelling loading: the body in equilibrium with its bath at mu_bar(t) (quasi-static swelling, the
  drained limit), the energy the grand potential G = Psi - mu_bar (fluid volume); the creased state's fluid
  is free to follow (drained: both states in equilibrium with the bath) or held at the flat state's
  (undrained);
- a swelling run's own transient (``fluid = "transient"``, ``content``): the flat state at load time t holds
  the content the run's uniform transient has reached at t in every cell (from the exact 1D reduction), and
  so does the creased state (undrained: the crease forms faster than the fluid moves).
:mod:`app.model.equilibrium` writes the energies.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from app import fem_utils
from app.model.equilibrium import equilibrium
from app.solvers.minimizer import MinimizingNewton
from app.solvers.newton import NewtonSolver, SolverSettings


class CreaseFailed(RuntimeError):
    """The creased state could not be reached (one line: where and why)."""


class FlatFailed(CreaseFailed):
    """The flat state could not be solved: nothing is known about the crease at that load. ``reached``: the
    last load the flat state was solved at on the way."""

    def __init__(self, message: str, reached: float = 0.0):
        super().__init__(message)
        self.reached = reached


@dataclass
class Trial:
    """One trial at load time t: the energies of the flat and creased states and the creased state's shape."""

    time: float
    applied_strain: float
    flat_energy: float
    creased_energy: float
    penetration: float  # the deepest crossing of the symmetry line by the free surface [mm] (0: none)
    depth: float  # the crease tip's depth below the flat surface [mm]
    substeps: int
    mu_bar: float = 0.0  # the bath's chemical potential at t [MPa]
    growth: float = 0.0  # the flat state's growth [mm]
    followed: bool = False  # the creased state was followed down in load from a grown crease (not closed)

    @property
    def difference(self) -> float:
        return self.creased_energy - self.flat_energy


FLAT_STRAIN_STEP = 0.02  # the flat state is followed in load steps of at most this applied strain
FLAT_HALVINGS = 10  # a flat-state load step that fails is halved at most this often
MIN_SUBSTEP = 1.0e-3  # the smallest fraction of the crease's motion one sub-step may take


class CreaseTrial:
    """The trial crease of length ``length`` [mm, reference] at the symmetry line x = ``line`` of a problem:
    under a loading that moves no fluid the states' energy is the stored energy; under swelling the states
    are in equilibrium with the bath and the energy is the grand potential, with the creased state's fluid
    free (``fluid = "drained"``) or held at the flat state's (``"undrained"``), or both hold a transient run's
    content at t (``"transient"``, ``content(t, Y)``): :mod:`app.model.equilibrium`."""

    def __init__(self, problem, length: float, settings: SolverSettings, substeps: int = 20, line: float = 0.0,
                 fluid: str = "drained", mirror_stiffness: float | None = None, content=None):
        p = self.problem = problem
        self.grows = mirror_stiffness is not None
        sys = self.system = equilibrium(p, fluid, (line, mirror_stiffness) if self.grows else None, content)
        self.length, self.line, self.substeps = length, line, substeps
        self._creased = {}  # growing: the creased states with less energy than the flat one, by load time
        fdim = p.domain.topology.dim - 1
        surface = p.facets_of(p.geo.facets_with_role("permeable"))
        mid = fem_utils.facet_midpoints(p.domain, surface.astype(np.int32))
        facets = surface[np.abs(mid[:, 0] - line) < length].astype(np.int32)
        if p.comm.allreduce(len(facets)) == 0:
            raise ValueError(f"no surface facet within {length:g} mm of the symmetry line x = {line:g}")
        self.bc, self.target = fem_utils.dirichlet_zero_on_facets(sys.displacement.sub(0), facets, fdim)
        V0, self._x_dofs = fem_utils.collapse(sys.displacement.sub(0))
        _, self._y_dofs = fem_utils.collapse(sys.displacement.sub(1))  # the same nodes in the same order
        self._points = fem_utils.dof_points(V0)
        self._X = self._points[:, 0]
        # the surface's nodes: the body's top (a flat surface, as the bilayer's)
        top = p.comm.allreduce(float(self._points[:, 1].max()) if len(self._points) else -np.inf, op=_max())
        self._on_surface = np.isclose(self._points[:, 1], top, rtol=0.0, atol=1e-9 * max(1.0, abs(top)))
        # plain Newton (no factor reuse): its last quadratic iteration leaves the flat state far below the
        # tolerance (the closed form to 3e-11; 1.2e-9 with reuse), and a trial's cost is its minimizer's
        self.flat_solver = NewtonSolver(sys.residual, sys.hessian, sys.bcs, sys.w,
                                        dataclasses.replace(settings, reuse=False), p.comm)
        self.crease_solver = MinimizingNewton(sys.energy, sys.residual, sys.hessian,
                                              sys.bcs + [self.bc] + sys.kept, sys.w, settings, p.comm)
        self._flat = sys.w.x.array.copy()  # the last flat state
        self._solved = {0.0: self._flat}  # every flat state solved, by load time
        self._last = 0.0  # the load time of the last one
        self._growth = 0.0

    def flat_state(self, t: float) -> float:
        """Solve the flat state at load time t, followed in small load steps (a step that fails is halved):
        with frozen fluid from the last flat state, as the load goes; in equilibrium with a bath from the
        solved one at the nearest load at or below t, so always forwards in the load (a swelling gel's flat
        state is not reliably followed back down). Its energy."""
        sys = self.system
        # frozen fluid or a transient run's content held: from the last flat state, up or down in the load (a
        # path-independent elastic state); in equilibrium with a bath: forwards only
        start = self._last if sys.fluid in ("frozen", "transient") else max(tk for tk in self._solved if tk <= t)
        sys.w.x.array[:] = self._solved[start]
        failed, _ = self._step_load(self.flat_solver, start, t, FLAT_HALVINGS)
        if failed is not None:
            tk, reason, done = failed
            self._last = done  # the flat state in w is at that load (path independent states)
            self._solved[done] = sys.w.x.array.copy()
            raise FlatFailed(f"the flat state did not converge at t = {tk:.6g} s (SNES reason {reason}, "
                             f"load steps halved {FLAT_HALVINGS} times from t = {done:.6g} s)", done)
        sys.set_load(t)  # the load of the state in w (also when it was solved before)
        self._flat = self._solved[t] = sys.w.x.array.copy()
        self._last = t
        self._growth = sys.growth()
        return sys.value()

    def flat_growth(self, t: float) -> float:
        """The flat state's growth at load time t [mm]."""
        self.flat_state(t)
        return self._growth

    def trial(self, t: float) -> Trial:
        """The flat and creased states at load time t and their energies. A growing crease is followed down
        in load from the nearest load above t whose creased state had less energy than the flat one, if there
        is one (:meth:`_follow`); otherwise, and if that fails, it is closed from the flat state."""
        p, sys = self.problem, self.system
        flat = self.flat_state(t)
        strain = p.loading.applied_strain(t)
        sys.keep(self._flat)
        above = [tk for tk in self._creased if tk > t]
        taken = self._follow(min(above), t) if above else None
        followed = taken is not None
        if taken is None:
            taken = self._close(t)
        w = sys.w.x.array
        creased = sys.value()
        penetration, depth = self._shape(w, self._flat)
        if self.grows and creased < flat:
            self._creased[t] = w.copy()
        w[:] = self._flat
        return Trial(t, strain, flat, creased, penetration, depth, taken, p.loading.mu_bar(t), self._growth,
                     followed)

    def _follow(self, start: float, t: float) -> int | None:
        """The creased state at load t followed from the one at load ``start`` (the crease's points held on
        the line, the load stepped like the flat state's, a step that fails halved): the number of load
        steps, or None if it failed (the flat state left in ``w``)."""
        sys = self.system
        w = sys.w.x.array
        w[:] = self._creased[start]
        self.target.x.array[:] = self.line - self._X  # the crease's points on the line
        # undrained, the content is held at the flat state's at t (kept by trial()) from the first step on:
        # smaller load steps change nothing then
        halvings = 0 if sys.fluid == "undrained" else FLAT_HALVINGS
        failed, taken = self._step_load(self.crease_solver, start, t, halvings)
        sys.set_load(t)
        if failed is not None:
            w[:] = self._flat
            return None
        return taken

    def _steps(self, start: float, t: float) -> int:
        """Load steps from ``start`` to t: at most FLAT_STRAIN_STEP of applied strain each, or the system's own
        count (a transient's content: :meth:`app.model.equilibrium.HeldContent.load_steps`)."""
        own = getattr(self.system, "load_steps", None)
        if own is not None:
            return own(start, t)
        lo = self.problem.loading
        return max(1, int(np.ceil(abs(lo.applied_strain(t) - lo.applied_strain(start)) / FLAT_STRAIN_STEP)))

    def _step_load(self, solver, start: float, t: float, max_halvings: int):
        """Take the state in ``w`` (at load ``start``) to load t in :meth:`_steps` steps, each solved by
        ``solver``; a step that fails is undone and halved, at most ``max_halvings`` times in all. Returns
        (None when done, else (the load that failed, its SNES reason, the last load reached) with ``w`` at
        that load; the number of steps that converged)."""
        w = self.system.w.x.array
        steps = self._steps(start, t)
        targets = list(np.linspace(start, t, steps + 1)[1:]) if t != start else []
        done, halvings, taken = start, 0, 0
        while targets:
            tk = float(targets[0])
            before = w.copy()
            self.system.set_load(tk)
            res = solver.solve()
            if res.converged:
                done = targets.pop(0)
                taken += 1
                continue
            w[:] = before
            halvings += 1
            if halvings > max_halvings:
                return (tk, res.reason, done), taken
            targets.insert(0, 0.5 * (done + tk))
        return None, taken

    def _close(self, t: float) -> int:
        """Close the trial crease from the flat state in ``w`` in sub-steps: the number taken."""
        sys = self.system
        X = self._X
        w = sys.w.x.array
        flat_x = w[self._x_dofs]  # the flat state's u_x (the crease's points start from it)
        s, ds, taken = 0.0, 1.0 / self.substeps, 0
        while s < 1.0:
            step = min(ds, 1.0 - s)
            before = w.copy()
            # the crease's points move from the flat state's position to the symmetry line: u_x = line - X
            self.target.x.array[:] = (1 - (s + step)) * flat_x + (s + step) * (self.line - X)
            res = self.crease_solver.solve()
            if res.converged:
                s += step
                taken += 1
                continue
            w[:] = before
            ds = step / 2
            if ds < MIN_SUBSTEP:
                w[:] = self._flat
                raise CreaseFailed(f"the trial crease did not close at t = {t:.6g} s ({self._load(t)}): "
                                   f"{s:.3f} of its motion done, the minimizing Newton failed with sub-steps of "
                                   f"{2 * ds:.2g} (SNES reason {res.reason})")
        return taken

    def _load(self, t: float) -> str:
        lo = self.problem.loading
        if self.system.fluid == "frozen":
            return f"applied strain {lo.applied_strain(t):.4g}"
        if self.system.fluid == "transient":
            return f"the run's content at that time, growth {self._growth:.4g} mm"
        return f"bath potential {lo.mu_bar(t):.4g} MPa, growth {self._growth:.4g} mm"

    def _shape(self, creased: np.ndarray, flat: np.ndarray) -> tuple[float, float]:
        """(the deepest crossing of the symmetry line by the surface, the depth of the crease's tip below the
        flat state's surface) [mm]."""
        comm, on = self.problem.comm, self._on_surface
        x = self._X[on] + creased[self._x_dofs][on]
        y = self._points[on, 1] + creased[self._y_dofs][on]
        y_flat = self._points[on, 1] + flat[self._y_dofs][on]
        crossing = comm.allreduce(float(np.max(self.line - x)) if x.size else -np.inf, op=_max())
        lowest = -comm.allreduce(float(-np.min(y)) if y.size else -np.inf, op=_max())
        flat_top = comm.allreduce(float(np.max(y_flat)) if y.size else -np.inf, op=_max())
        return max(crossing, 0.0), flat_top - lowest

    def destroy(self) -> None:
        self.flat_solver.destroy()
        self.crease_solver.destroy()


def _max():
    from mpi4py import MPI

    return MPI.MAX
