"""Switching onto the buckled branch at a located crossing (``stability.after_onset = "branch"``).

At the crossing's unstable end the state is perturbed along the crossing's mode, scaled so that the
mode's surface amplitude (:func:`app.model.surface.surface_shape`) is ``stability.imperfection`` times the
film thickness, and the stepper switches to the minimizing step solver
(:class:`app.solvers.minimizer.MinimizingNewton`), which from then on cannot settle on the unbuckled saddle.

What the perturbation must contain depends on the criterion (docs/postbuckling.md). A mode that moves
fluid (the drained one) is a displacement *and* a change of each cell's fluid content; a displacement alone
would be undone by the next step, whose potential does not depend on the previous displacement. The drained
mode's content change c = -K_cc^-1 K_cu u (the eliminated block of :class:`~app.model.operators.DrainedHessian`)
is carried by a flux increment dQ added to the accumulated flux Q_n: dQ minimizes the quadratic of K_tau
with the displacement held at the mode, for a tau far beyond the run's time, which makes Div dQ = c up to
(cell diffusion time / tau) and picks the least-dissipative such flux. The fluid it brings in through the
permeable surface is added to the run's inflow, so the history's balance holds. Undrained modes (fluid
frozen) and problems without diffusion need the displacement only; "rate" modes carry their flux already.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from app import fem_utils
from app.model.operators import zero_increment_hessian
from app.model.patterns import shape_coefficient, surface_spectrum
from app.model.surface import shape_of, surface_profile, surface_shape
from app.solvers.stability import HessianOperator, solve_with_held

TAU_FACTOR = 1e8  # the flux of a content change: tau = this x (elapsed time + ramp scale), see the docstring


@dataclass
class Switch:
    """One switch onto a branch: where, with which mode, how large."""

    time: float
    growth_mm: float
    wrinkle_count: float
    imperfection_mm: float
    with_flux: bool
    inflow: float  # fluid volume the perturbation brought in

    def as_dict(self) -> dict:
        return {"time": self.time, "growth_mm": self.growth_mm, "wrinkle_count": self.wrinkle_count,
                "imperfection_mm": self.imperfection_mm, "with_flux": self.with_flux, "inflow": self.inflow}


def typical_cell_size(problem) -> float:
    """sqrt(area / cells) of the mesh as its file has it: a .msh mesh split by mesh.refinements keeps the
    file's cell size, so the imperfection is the same on every level of a refinement study."""
    one = fem.Constant(problem.domain, PETSc.ScalarType(1.0))
    area = fem_utils.assemble_scalar(fem.form(one * ufl.dx(domain=problem.domain)), problem.comm)
    return float(np.sqrt(area / problem.cells())) * 2.0 ** problem.tm.info.get("refinements", 0)


def oriented(problem, mode: np.ndarray) -> np.ndarray:
    """The mode with a sign fixed by its surface profile: the first sample (in order along the surface, or of
    phase around it) whose excursion exceeds half the largest is positive. A positive imperfection then means
    the same on any number of ranks; the largest excursion alone would not do: a sinusoid's crest and trough
    are equal up to roundoff."""
    _, prof, _, _ = surface_profile(problem, mode, outward=False)
    if not prof.size:
        return mode
    big = np.abs(prof) > 0.5 * np.max(np.abs(prof))
    return -mode if prof[int(np.argmax(big))] < 0 else mode


class BranchSwitcher:
    """Applies the perturbation of :mod:`app.onset.branching` to a problem's converged state."""

    def __init__(self, problem, stepper, criterion, imperfection: float, length: float, log=None, modes: str = "1"):
        """``criterion``: the run's :class:`app.onset.criteria.Criterion` (whether its mode needs its content);
        ``modes``: which of a multiple onset's crossing modes the first switch adds ("1", "2", "1+2", ...)."""
        self.p, self.stepper, self.criterion = problem, stepper, criterion
        self.imperfection, self.length = imperfection, length
        # "1": the first eigenmode as computed; else the wave vectors (i, j) whose pure shapes the switch adds
        self.modes = [] if modes == "1" else [tuple(int(v) for v in w.split(":")) for w in modes.split("+")]
        self.log = log or (lambda msg: None)
        self.switches: list[Switch] = []

    def switch(self, crossing) -> Switch:
        """Perturb the current state (the crossing's unstable end) along ``crossing.mode`` and switch the
        stepper to minimizers."""
        p, st = self.p, self.stepper
        mode = self.combined(crossing) if not self.switches else oriented(p, crossing.mode)
        amplitude, _ = surface_shape(p, mode)
        if amplitude <= 0:
            amplitude = float(np.max(np.abs(mode[p.u_dofs]))) or 1.0
        scale = self.imperfection * self.length / amplitude
        delta = scale * mode
        with_flux = self.criterion.adds_content and p.diffusion  # the drained mode is a displacement only
        if with_flux:
            delta[p.q_dofs] = self.content_flux(delta)
        before = p.fluid_volume()
        s = p.state.x.array
        s[p.u_dofs] += delta[p.u_dofs]
        s[p.q_dofs] += delta[p.q_dofs]
        inflow = p.fluid_volume() - before
        st.inflow += inflow
        st.follow_minimizers()
        st.relax()  # without diffusion: settle onto the branch at the onset's load
        # the count of the mode added (the first eigenpair's), not the crossing's N_c (the minimum of the band)
        count = crossing.first_mode_wrinkle_count
        rec = Switch(st.t, p.growth(), count, abs(self.imperfection) * self.length, with_flux, inflow)
        self.switches.append(rec)
        self.log(f"  branch switch at t = {st.t:.6f} s: mode (N = {count:g}) added with surface "
                 f"amplitude {1e3 * rec.imperfection_mm:.4g} um" + (" (with its fluid content)" if with_flux else "")
                 + "; following the buckled branch")
        return rec

    def combined(self, crossing) -> np.ndarray:
        """The onset's mode the switch adds: the first eigenmode as computed (``modes`` "1"), or for each wave
        vector (i, j) of ``modes`` the combination of the modes crossing together whose surface is closest to
        the pure shape (i, j) (:func:`app.model.patterns.shape_coefficient`: the combination weighted by each
        mode's coefficient on it), scaled to unit surface amplitude, and these summed. A shape the crossing
        modes do not contain (less than half of it) is left out, with a log line."""
        p = self.p
        if not self.modes:
            return oriented(p, crossing.mode)
        vectors = (crossing.crossing_modes or [crossing.mode])[:max(1, crossing.multiplicity)]
        profiles = [surface_profile(p, v, outward=False) for v in vectors]
        shape = shape_of(p)
        total, used = None, []
        for i, j in self.modes:
            c = np.array([shape_coefficient(shape, pos, prof, i, j) for pos, prof, _, _ in profiles])
            mode = sum(ck * v for ck, v in zip(c, vectors))
            pos, prof, _, _ = surface_profile(p, mode, outward=False)
            share = next((f for a, b, f in surface_spectrum(shape, pos, prof) if (a, b) == (i, j)), 0.0)
            if share < 0.5:
                self.log(f"  stability.branch_modes: the {len(vectors)} mode(s) crossing at t = {crossing.time:.6g} s "
                         f"hold little of the shape ({i}, {j}) ({100 * share:.0f}% of their best mix); left out")
                continue
            amplitude, _ = surface_shape(p, mode)
            mode = mode / (amplitude or 1.0)
            total = mode if total is None else total + mode
            used.append(f"({i}, {j})")
        if total is None:
            self.log("  stability.branch_modes: none of the shapes asked for is among the crossing modes; adding the "
                     "first eigenmode")
            return oriented(p, crossing.mode)
        self.log(f"  branch switch: adding the shape(s) {' + '.join(used)} of the {len(vectors)} mode(s) crossing "
                 "together")
        return total

    def content_flux(self, delta: np.ndarray) -> np.ndarray:
        """The flux dQ whose divergence is the drained content change of displacement ``delta`` (local q part):
        K_tau's minimizer over dQ with the displacement held at ``delta``."""
        p = self.p
        tau = TAU_FACTOR * max(self.stepper.t, self.stepper.dt_prev, 1e-12)
        op = HessianOperator(zero_increment_hessian(p, tau), p.comm)
        try:
            op.matrix()
            n_owned = fem_utils.owned_size(p.W)
            is_q = np.zeros(n_owned, dtype=bool)
            is_q[p.q_dofs[p.q_dofs < n_owned]] = True
            free_q = fem_utils.owned_index_set(p.W, np.flatnonzero(is_q & ~op.fixed()), p.comm)
            z = op.A.createVecRight()
            z.array[:] = 0.0
            u_owned = p.u_dofs[p.u_dofs < n_owned]
            z.array[u_owned] = delta[u_owned]
            out = solve_with_held(op.A, free_q, z, p.W, p.comm)[p.q_dofs]
            for obj in (z, free_q):
                obj.destroy()
            return out
        finally:
            op.destroy()

    def export_state(self) -> dict:
        return {"switches": [s.as_dict() for s in self.switches]}

    def import_state(self, state: dict) -> None:
        self.switches = [Switch(**s) for s in state.get("switches", ())]
