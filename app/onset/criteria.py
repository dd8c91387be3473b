"""The stability criteria: which perturbations count when a state's stability is tested
(``stability.criterion``; docs/validation.md, "Which instabilities count").

A criterion is one :class:`Criterion` subclass and one registration in :data:`CRITERIA`: its matrix (the form
from :mod:`app.model.operators`, the linear algebra from :mod:`app.solvers.stability`), whether the Newton
factor of a step may screen it, whether its mode needs its fluid content added when a branch is followed,
its parameters (``stability.<key>``, declared once here and put into the config schema from the registry),
the short-wave check it corresponds to, and its entry in summary.json. Everything that used to compare the
criterion's name goes through these.

For every tau, negatives(undrained) <= negatives(rate with tau) <= negatives(drained) (K_uu is a principal
block of K_tau; K_tau decreases with tau): the drained onset comes first.
"""

from __future__ import annotations

from typing import ClassVar

from app.registry import Registry
from app.schema import Key, gt, key

# dolfinx, PETSc and SLEPc are imported when a matrix is built, not with the registry (the config schema
# reads it, and validating a config must not load them)


class Criterion:
    """A stability criterion: subclass, fill in the class attributes and :meth:`operator`, register an
    instance in :data:`CRITERIA`."""

    name: ClassVar[str] = ""
    doc: ClassVar[str] = ""  # what it counts, for the schema's documentation of stability.criterion
    keys: ClassVar[dict[str, Key]] = {}  # its parameters: stability.<name> (every criterion's are in the schema)
    #: followed branch: the mode is a displacement whose cells' fluid content must change with it
    #: (app.onset.branching adds the flux of that change where fluid can move)
    adds_content: ClassVar[bool] = False
    #: the permeable surface's short-wave check under this criterion (app.onset.surface_check: drained or undrained)
    surface: ClassVar[str] = "drained"

    def operator(self, problem, params: dict):
        """The matrix whose inertia decides stability at the problem's converged state.

        Every criterion implements it (the base raises NotImplementedError).

        Args:
            problem: the run's :class:`app.model.problem.Problem`; its converged state is what the matrix reads.
            params: the criterion's parameters: ``stability.<key>`` of each of its :attr:`keys`.

        Returns:
            An operator of :mod:`app.solvers.stability` (``matrix``, ``embed``, ``eliminated_negatives``,
            ``n_free``), e.g. a ``HessianOperator`` or a ``DrainedOperator``.

        Raises:
            ValueError: the criterion cannot test this problem (the drained one on a body without a permeable
                boundary).
        """
        raise NotImplementedError

    def analyzer(self, problem, params: dict):
        """The :class:`app.solvers.stability.StabilityAnalyzer` of :meth:`operator`.

        Args:
            problem: the run's :class:`app.model.problem.Problem`.
            params: the criterion's parameters, as in :meth:`operator`.

        Returns:
            The analyzer (its ``inertia`` and eigenpairs); the caller frees it with ``destroy()``.

        Raises:
            ValueError: as :meth:`operator`.
        """
        from app.solvers.stability import StabilityAnalyzer  # (lazy: the config schema reads this registry)

        return StabilityAnalyzer(self.operator(problem, params), problem.comm)

    def newton_may_screen(self, params: dict, dt: float) -> bool:
        """Whether the Newton factor of a step of size dt (K_dt) has at least this criterion's negative
        eigenvalues, so that screening with it cannot miss a crossing (app.onset.screening).

        Args:
            params: the criterion's parameters, as in :meth:`operator`.
            dt: the step size [s].

        Returns:
            True if the Newton factor may screen this criterion; the base: False (every step gets the exact test).
        """
        return False

    def summary(self, params: dict) -> dict:
        """summary.json's ``criterion`` entry: the name and the parameters.

        Args:
            params: the criterion's parameters, as in :meth:`operator`.

        Returns:
            ``{"name": ..., <key>: <value> for each of its keys}``.
        """
        return {"name": self.name, **{k: params[k] for k in self.keys}}

    def surface_label(self) -> str:
        """What the permeable surface's short-wave check (:attr:`surface`) reports as its criterion.

        Returns:
            The surface criterion's name if it is this criterion's own, else e.g.
            ``"drained (the short-wave limit of rate)"``.
        """
        return self.surface if self.surface == self.name else f"{self.surface} (the short-wave limit of {self.name})"


class Drained(Criterion):
    """The fluid free to redistribute: the stored energy's Hessian with each cell's content eliminated. A
    gradient flow leaves a state exactly when this test fails; the limit tau -> infinity of K_tau. Without
    diffusion it is the undrained test."""

    name = "drained"
    doc = "drained (fluid may redistribute; any growing mode)"
    adds_content = True

    def operator(self, problem, params: dict):
        if not problem.diffusion:  # no fluid motion: drained = undrained
            return UNDRAINED.operator(problem, params)
        if problem.permeable_facets() == 0:
            raise ValueError("stability.criterion = 'drained' needs a permeable boundary (the fluid content of a "
                             "closed body is conserved); use 'undrained' or 'rate'")
        from app.model.operators import DrainedHessian
        from app.solvers.stability import DrainedOperator

        return DrainedOperator(DrainedHessian(problem), problem.comm)


class Undrained(Criterion):
    """The fluid frozen (tau -> 0): K_uu at fixed content. Biot's surface instability of an incompressible
    solid. K_uu is a principal block of every K_dt, so the Newton factor may always screen it (interlacing)."""

    name = "undrained"
    doc = "undrained (fluid frozen)"
    surface = "undrained"

    def operator(self, problem, params: dict):
        return _hessian(problem, 1.0, keep=problem.u_dofs)

    def newton_may_screen(self, params: dict, dt: float) -> bool:
        return True


class Rate(Criterion):
    """K_tau with stability.tau: instabilities that grow faster than about 1/tau (the seed paper's choice
    when tau is the step). The Newton factor may screen it when dt >= 2 tau (K_dt = K_inf + D/dt <= K_tau;
    the factor 2 covers the change of the dissipation metric D over a step)."""

    name = "rate"
    doc = "rate (K with stability.tau)"
    keys = {"tau": key(float, 1.0e-2, gt(0), "criterion = rate only: step of the dissipation block of K [s]")}

    def operator(self, problem, params: dict):
        return _hessian(problem, params["tau"])

    def newton_may_screen(self, params: dict, dt: float) -> bool:
        return dt >= 2.0 * params["tau"]


CRITERIA: Registry[Criterion] = Registry("stability criterion")
CRITERIA.register(Drained())
UNDRAINED = CRITERIA.register(Undrained())
CRITERIA.register(Rate())
DEFAULT = "drained"


def _hessian(problem, tau: float, keep=None):
    from app.model.operators import zero_increment_hessian
    from app.solvers.stability import HessianOperator

    return HessianOperator(zero_increment_hessian(problem, tau), problem.comm, keep=keep)


class LossOfStability:
    """The time stepper's diagnosis after a step failed twice in a row for the same reason
    (:meth:`app.solvers.stepping.TimeStepper._diagnose`): ``check(dt)`` tests the converged state with the
    "rate" criterion at tau = dt (K as Newton sees it), then, where fluid can move in or out, with the drained
    criterion, stopping at the first with negative eigenvalues. Returns (what was tested, its negative
    eigenvalues) for each test run. ``remedy``: what a user can do once the state has lost stability, which the
    stepper's :class:`~app.solvers.stepped_problem.LostStability` message ends with.

    Args:
        problem: the run's :class:`app.model.problem.Problem`, whose converged state is tested.
    """

    remedy = ("enable the stability test (stability.enabled = true, stability.criterion = drained) to locate the "
              "onset and its mode, and stability.after_onset = \"branch\" to follow the buckled branch")

    def __init__(self, problem):
        self.problem = problem

    def __call__(self, dt: float) -> list[tuple[str, int]]:
        """Test the converged state (collective: call on every rank of the problem's communicator).

        Args:
            dt: the failing step's size [s]: the "rate" test's tau.

        Returns:
            (what was tested, its number of negative eigenvalues) for each test run, in order: the "rate"
            test (``"K with tau = <dt> s"``), then, where fluid can move in or out and that K had no negative
            eigenvalue, the drained one (``"the drained K"``).
        """
        p, out = self.problem, []
        for name in ("rate", "drained") if p.diffusion else ("rate",):
            if name == "drained" and p.permeable_facets() == 0:
                continue
            analyzer = CRITERIA.get(name).analyzer(p, {"tau": dt})
            try:
                nneg = analyzer.inertia()[0]
            finally:
                analyzer.destroy()
            out.append((f"K with tau = {dt:.3g} s" if name == "rate" else "the drained K", nneg))
            if nneg > 0:
                break
        return out
