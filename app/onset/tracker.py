"""The onset tracker: everything the [stability] table asks of a run, behind one object.

After every accepted step the run asks the tracker twice: :meth:`OnsetTracker.test` gives the step's
verdict (the screened or exact negative-eigenvalue count, an increase confirmed exactly, lambda_min
every ``eigen_every`` steps) and records it with the step; :meth:`OnsetTracker.resolve` then locates
every new crossing by bisection, records it, hands the first one's mode to the writer, and applies
the :class:`~app.onset.policy.CrossingPolicy`, whose answer ends the run or not. The tracker leaves the
stepper at the state the run continues from. With ``stability.enabled = false`` the run gets an
:class:`NoStabilityTest` that does none of this.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from app.model.surface import shape_of
from app.onset.bisection import Bisection
from app.onset.branching import BranchSwitcher, typical_cell_size
from app.onset.criteria import CRITERIA, DEFAULT, Criterion
from app.onset.crossing import Crossing
from app.onset.policy import AfterCrossing, CrossingPolicy
from app.onset.screening import StabilityScreen
from app.onset.surface_check import SurfaceCheck


@dataclass(frozen=True)
class StabilitySettings:
    """The [stability] table."""

    enabled: bool = True
    tolerance: float = 1e-3  # relative width of a crossing's time bracket
    policy: CrossingPolicy = CrossingPolicy()
    modes: int = 3  # eigenpairs reported at a crossing
    eigen_every: int = 0  # lambda_min every n steps (0: only at crossings)
    screening: str = "newton"
    error_estimate: bool = False  # companion runs after the run (app.workflows.error_estimate)
    criterion: str = DEFAULT  # which perturbations count (app.onset.criteria)
    params: dict = field(default_factory=lambda: {"tau": 1e-2})  # the criterion's parameters (its keys)
    imperfection: float = 0.01  # after_onset = branch: the mode's surface amplitude / film thickness
    surface_check: bool = True  # the permeable surface's short-wave limit every step (app.onset.surface_check)
    branch_modes: str = "1"  # after_onset = branch: which of the onset's crossing modes the switch adds ("1+2")

    @property
    def rule(self) -> Criterion:
        return CRITERIA.get(self.criterion)

    def newton_screen_valid(self, dt: float) -> bool:
        """Whether the Newton factor of a step of size dt may screen the criterion (app.onset.screening)."""
        return self.rule.newton_may_screen(self.params, dt)


def onset_tracker(problem, stepper, settings: StabilitySettings, on_first_crossing=None, log=None, detail=None,
                  reference_length: float | None = None):
    """The tracker a run with these settings needs (:class:`NoStabilityTest` when the test is off).
    ``reference_length``: what stability.imperfection is a fraction of (app.factory.reference_length)."""
    if not settings.enabled:
        return NoStabilityTest()
    return OnsetTracker(problem, stepper, settings, on_first_crossing, log, detail, reference_length)


class OnsetTracker:
    """Stability verdicts and crossings of one run. ``log`` gets the crossing messages, ``detail`` the
    screening and bisection steps (progress lines)."""

    COLUMNS = ("negative_eigenvalues", "lambda_min")  # added to history.csv

    def __init__(self, problem, stepper, settings: StabilitySettings, on_first_crossing=None, log=None,
                 detail=None, reference_length: float | None = None):
        self.settings, self.stepper = settings, stepper
        self.log = log or (lambda msg: None)
        detail = detail or (lambda msg: None)
        self.analyzer = settings.rule.analyzer(problem, settings.params)
        self.screen = StabilityScreen(stepper, self.analyzer, settings.screening, log=detail,
                                      newton_screen_valid=settings.newton_screen_valid)
        self.bisection = Bisection(problem, stepper, self.analyzer, tolerance=settings.tolerance,
                                   n_modes=settings.modes, log=detail)
        self.on_first_crossing = on_first_crossing or (lambda crossing: None)
        self.count = 0  # negative eigenvalues on the path so far
        self.crossings: list = []
        self._bracket = None
        self.problem = problem
        self.limits: dict = {}  # the other criteria's verdicts at the first crossing's unstable end
        self.branch = None  # app.onset.branching.BranchSwitcher with after_onset = "branch"
        self.restabilized: list[dict] = []  # on a branch: where the negative count fell
        self.surface = None  # app.onset.surface_check.SurfaceCheck: the permeable surface's short-wave limit
        self.surface_onset: dict | None = None
        if settings.surface_check and problem.diffusion and problem.loading.surface_term \
                and problem.geo.facets_with_role("permeable"):
            self.surface = SurfaceCheck(problem, settings.rule)
        if settings.policy.branches:
            self.branch = BranchSwitcher(problem, stepper, settings.rule, settings.imperfection,
                                         reference_length or typical_cell_size(problem), log=self.log,
                                         modes=settings.branch_modes)
            # a saddle that the minimizer's line search cannot leave is left like a crossing: a step of the
            # imperfection's size along a direction of negative curvature (app.solvers.minimizer)
            stepper.escape_length = abs(settings.imperfection) * self.branch.length

    def start(self, rec) -> None:
        """The initial state's exact count, recorded with it."""
        self.count = self.screen.start()
        rec.extra.update({"negative_eigenvalues": self.count, "lambda_min": float("nan")})
        self._test_surface(rec)

    def _test_surface(self, rec) -> None:
        """The permeable surface's short-wave limit at this state, until it first fails (on the unbuckled path)."""
        if self.surface is None or self.surface_onset is not None or self.stepper.minimizing:
            return
        onset = self.surface.test(rec.time, rec.growth_mm)
        if onset is not None:
            self.surface_onset = onset
            where = ", ".join(f"{v:.4g}" for v in onset["where"])
            self.log(f"  the permeable surface became unstable at short waves (below the mesh): t = "
                     f"{onset['time']:.6f} s, growth = {onset['growth_um']:.4f} um, at ({where}) mm")

    def test(self, rec) -> None:
        """The verdict on the step just accepted, recorded in ``rec``; a confirmed increase is kept
        for :meth:`resolve`."""
        self._test_surface(rec)
        nneg = self.screen.screen()
        self._bracket = None
        if nneg < self.count and self.stepper.minimizing:  # on a branch the state can become stable again
            self.log(f"  t = {rec.time:.6f} s: the branch has {nneg} negative eigenvalue(s), {self.count - nneg} "
                     f"fewer than before (the buckled state settles)")
            self.restabilized.append({"time": rec.time, "growth_mm": rec.growth_mm, "negative_eigenvalues": nneg})
            self.count = nneg
        if nneg > self.count:
            self._bracket = self.screen.confirm(self.count, nneg)
            nneg = self._bracket[0] if self._bracket is not None else self.count
        lam = float("nan")
        every = self.settings.eigen_every
        if every and rec.step % every == 0:
            lam = self.analyzer.lambda_min(nneg)
        rec.extra.update({"negative_eigenvalues": nneg, "lambda_min": lam})

    def resolve(self) -> bool:
        """Locate the crossings the last test found, one bisection per new negative eigenvalue;
        True when the policy ends the run."""
        if self._bracket is None:
            self.screen.accepted(self.stepper.snapshot())
            return False
        nneg, lo, unstable = self._bracket
        self._bracket = None
        self.log(f"  K lost positive definiteness between t = {lo.t:.6f} and {unstable.t:.6f} s "
                 f"({nneg - self.count} new negative eigenvalue(s))")
        stop = False
        while self.count < nneg:
            crossing = self.bisection.locate(lo, unstable, base_count=self.count)
            self.crossings.append(crossing)
            self.log(f"  crossing #{len(self.crossings)}: t = {crossing.time:.6f} s, "
                     f"growth = {1e3 * crossing.growth_mm:.4f} um, N = {crossing.wrinkle_count:g}"
                     + _waves(crossing, self.problem))
            if len(self.crossings) == 1:
                self.limits = self._other_limits()
                self.on_first_crossing(crossing)
            self.count += 1
            lo = crossing.hi if crossing.hi_count == self.count else crossing.lo
            stop = self.settings.policy.stops(len(self.crossings))
            if stop or self.branch is not None:
                break
        if not stop and self.branch is not None:
            # the branch starts at the last accepted state (the bracket's unstable end, within one step of the
            # crossing: the history stays monotone in time), perturbed along the first crossing's mode; further
            # crossings of the unbuckled path up to that state are not located: the run has left that path
            self.stepper.restore(unstable)
            self.branch.switch(crossing)
            self.screen.screening = "exact"  # the minimizer's factors are shifted: no screening with them
            # the branch's reference count: the perturbed state's, but never below the crossing's unstable end
            # (an equilibrium with nneg negative eigenvalues). The perturbed state is no equilibrium: in contact
            # the perturbation can open pairs and count fewer, and the same instability found again at the next
            # converged state would be a new crossing at every step (docs/postbuckling.md)
            self.count = max(self.screen.start(), nneg)
            return False
        self.count = max(self.count, nneg)
        self.stepper.restore(unstable)
        if not stop:
            self.screen.restart(unstable)
        return stop

    def _other_limits(self) -> dict:
        """Negative-eigenvalue counts of the criteria not chosen, at the current state (the first crossing's
        unstable end), and what they mean: whether the drained and undrained onsets differ here."""
        p, chosen = self.problem, self.settings.criterion
        if not p.diffusion:
            return {}
        counts = {}
        for criterion in ("drained", "undrained"):
            if criterion == chosen:
                continue
            try:
                analyzer = CRITERIA.get(criterion).analyzer(p, self.settings.params)
            except ValueError:
                continue
            try:
                counts[criterion] = analyzer.inertia()[0]
            finally:
                analyzer.destroy()
        out = {f"{c}_negative_eigenvalues": n for c, n in counts.items()}
        if counts.get("undrained") == 0:
            out["note"] = ("the undrained test (fluid frozen) is still stable at this onset: the instability needs "
                           "the fluid to redistribute, so it grows on the diffusion time scale; the undrained "
                           "onset is later (stability.criterion = undrained gives it)")
            self.log(f"  note: {out['note']}")
        elif counts.get("drained", 1) == 0:
            out["note"] = "the drained test is stable here: unexpected (drained is never more stable than undrained)"
        return out

    # --- the summary's stability entries -----------------------------------------------------

    def status(self, status: str) -> str:
        """A run that did not fail or end at a model limit ("contact", "inverted": a followed branch) is
        "buckled", else "equilibrium" (time.stop_at_equilibrium) or "stable"."""
        if status in ("failed", "contact", "inverted"):
            return status
        return "buckled" if self.crossings else ("equilibrium" if status == "equilibrium" else "stable")

    def onset_summary(self) -> dict:
        c = self.crossings
        out = {"critical": {**c[0].as_dict(), "criterion": self.criterion_summary(), "other_limits": self.limits}} \
            if c else {}
        if len(c) > 1 or (c and self.settings.policy.after is not AfterCrossing.STOP):
            out["crossings"] = [x.as_dict() for x in c]
        if self.surface_onset is not None:
            out["surface_onset"] = {**self.surface_onset,
                                    "before_critical": not c or self.surface_onset["time"] < c[0].time}
        return out

    @property
    def switches(self) -> int:
        """The branch switches made so far (0 without a followed branch)."""
        return len(self.branch.switches) if self.branch is not None else 0

    def branch_summary(self) -> dict:
        """The summary's ``postbuckling`` block (after_onset = "branch"; empty otherwise)."""
        if self.branch is None:
            return {}
        st, s = self.stepper, self.settings
        solver = st.solver.counters()
        return {"postbuckling": {
            "after_onset": s.policy.after.value, "imperfection": s.imperfection, "branch_modes": s.branch_modes,
            "imperfection_mm": abs(s.imperfection) * self.branch.length,
            "switches": [w.as_dict() for w in self.branch.switches],
            "branch_crossings": [x.as_dict() for x in self.crossings[1:]],
            "restabilized": list(self.restabilized),
            "minimizer": {k: solver.get(k, 0) for k in ("shifted_factorizations", "saddles", "polishes", "escapes",
                                                           "snap_rounds")}
            | {"energy_rejections": st.energy_rejections,
               "inadmissible_predictions": st.inadmissible_predictions}}}

    def criterion_summary(self) -> dict:
        return self.settings.rule.summary(self.settings.params)

    def tests_summary(self) -> dict:
        s = self.screen
        return {"stability_tests": {"criterion": self.criterion_summary(), "screening": self.settings.screening,
                                    "screened_steps": s.screened_steps,
                                    "exact_tests": self.analyzer.tests, "false_alarms": s.false_alarms,
                                    "late_screens": s.late_screens}}

    def destroy(self) -> None:
        self.analyzer.destroy()

    # --- checkpoints (app.io.checkpoint) -----------------------------------------------------

    def export_state(self) -> dict:
        """Everything a resumed run needs to continue this tracker identically (between steps)."""
        return {"count": self.count, "crossings": list(self.crossings), "exact_tests": self.analyzer.tests,
                "screen": self.screen.export_state(), "limits": dict(self.limits),
                "branch": {**self.branch.export_state(), "restabilized": list(self.restabilized)}
                if self.branch is not None else None, "surface_onset": self.surface_onset}

    def checkpoint_state(self, ref) -> dict:
        """This tracker in a checkpoint's meta (JSON; snapshots as ``ref(snapshot)``): the negative count, the
        crossings so far, the screen, the other criteria's verdicts, the branch and the surface check's onset
        (its per-step history is per facet of a rank's partition: a resumed check starts it afresh)."""
        state = self.export_state()
        return {"count": state["count"], "exact_tests": state["exact_tests"], "limits": state["limits"],
                "branch": state["branch"], "crossings": [c.checkpoint_state() for c in state["crossings"]],
                "screen": self.screen.checkpoint_state(ref), "surface_onset": state["surface_onset"]}

    def restore_checkpoint(self, state: dict, snapshots: list) -> None:
        """The state :meth:`checkpoint_state` wrote, with its snapshots restored."""
        self.import_state({"count": state["count"], "exact_tests": state["exact_tests"],
                           "crossings": [Crossing.from_checkpoint(c) for c in state["crossings"]],
                           "screen": StabilityScreen.from_checkpoint(state["screen"], snapshots),
                           "limits": state.get("limits", {}), "branch": state.get("branch"),
                           "surface_onset": state.get("surface_onset")})  # written since 2026-12 only

    def import_state(self, state: dict) -> None:
        self.count, self.crossings = state["count"], list(state["crossings"])
        self.analyzer.tests = state["exact_tests"]
        self.screen.import_state(state["screen"])
        self.limits = dict(state.get("limits", {}))
        if self.surface is not None:
            self.surface_onset = state.get("surface_onset")
        branch = state.get("branch")
        if branch and self.branch is not None:
            self.branch.import_state(branch)
            self.restabilized = list(branch.get("restabilized", ()))
            self.screen.screening = "exact" if self.stepper.minimizing else self.screen.screening


class NoStabilityTest:
    """``stability.enabled = false``: no test, no history columns, nothing in the summary."""

    COLUMNS = ()
    crossings = ()
    switches = 0

    def start(self, rec) -> None:
        pass

    def test(self, rec) -> None:
        pass

    def resolve(self) -> bool:
        return False

    def status(self, status: str) -> str:
        return status

    def onset_summary(self) -> dict:
        return {}

    def tests_summary(self) -> dict:
        return {}

    def branch_summary(self) -> dict:
        return {}

    def destroy(self) -> None:
        pass

    def checkpoint_state(self, ref) -> None:
        return None

    def restore_checkpoint(self, state, snapshots) -> None:
        pass


def _waves(crossing, problem) -> str:
    """A 3D crossing's critical wave vectors for its log line, named by the problem's surface
    (:attr:`app.model.shapes.SurfaceShape.wave_label`); '' in 2D."""
    waves = [tuple(m["wave_vector"]) for m in crossing.modes[:crossing.multiplicity] if "wave_vector" in m]
    if not waves:
        return ""
    return (f", {shape_of(problem).wave_label} {', '.join(map(str, waves))}"
            + (f", {crossing.multiplicity} modes crossing together" if crossing.multiplicity > 1 else ""))
