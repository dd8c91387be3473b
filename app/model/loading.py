"""Loadings as strategies, registered by name (``loading.kind``): what drives a run in time and which
boundary conditions it puts on each boundary role.

A loading owns its ``loading.*`` keys (defaults, ranges, docs), the surface chemical potential mu_bar(t),
an applied displacement in time, the kinks the stepper must not step across, the Dirichlet and no-flux
conditions by boundary role (:class:`BoundaryConditions`), whether the permeable surface carries the
term mu_bar dQ.n, what the history records as applied_strain, and what it needs from the geometry (e.g.
a boundary to move: ``GeometryKind.provides``). The problem turns the conditions into dolfinx objects;
nothing here knows about meshes. A new loading: a subclass and one line in :data:`LOADINGS`' registration
at the end of this file.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from app.geometry.base import HELD_COMPONENTS, Drive
from app.registry import Registry
from app.schema import Key, gt, in_closed, in_open, key


@dataclass(frozen=True)
class BoundaryConditions:
    """The conditions of a loading on named facet groups.

    Attributes:
        held: per displacement component x, y, z: the facet groups where it is zero (a 2D mesh has no z).
        driven: the facet group, and its component, that follows :meth:`Loading.applied_displacement`; None:
            none.
        flux_open: the facet groups free of the no-flux condition (every other exterior facet has zero normal
            flux); None: diffusion off, every flux dof zero (s stays s0).
    """

    held: tuple[tuple[str, ...], ...]  # per displacement component x, y, z: facet groups where it is zero (a 2D
    # mesh has no z)
    driven: Drive | None = None  # the facet group whose component follows applied_displacement(t)
    flux_open: tuple[str, ...] | None = ()  # groups free of the no-flux condition (every other exterior facet
    # has zero normal flux); None: diffusion off, every flux dof zero (s stays s0)


class Loading:
    """One value of ``loading.kind``; an instance is the loading of one run.

    Subclass it (its ``name`` and :meth:`mu_bar` at least), then register the class in
    :data:`LOADINGS`. Times are in seconds from the start of the run.
    """

    name: ClassVar[str] = ""
    keys: ClassVar[dict[str, Key]] = {}  # loading.* keys it reads
    needs: ClassVar[frozenset[str]] = frozenset()  # what the geometry kind must provide
    surface_term: ClassVar[bool] = True  # the permeable surface carries mu_bar dQ.n
    #: no fluid moves (conditions() gives flux_open None): a state at load t has no history, which the trial
    #: crease of stability.creases needs (app.onset.creases)
    fluid_frozen: ClassVar[bool] = False
    #: a bath at mu_bar(t) reaches the body through its permeable surface: the state at load t in
    #: equilibrium with it (quasi-static swelling) has no history either; the trial crease compares grand
    #: potentials there (app.model.equilibrium)
    bath_equilibrium: ClassVar[bool] = False

    def __init__(self, params: dict, *, mu_start: float, end_time: float, drive: Drive | None = None):
        """``params``: this loading's keys; ``mu_start``: mu0 of the material under the permeable surface
        (the surface starts in equilibrium with it); ``drive``: the geometry's movable boundary.

        Args:
            params: the [loading] table; the values of this loading's :attr:`keys` are kept as ``self.params``.
            mu_start: mu0 of the material under the permeable surface [MPa].
            end_time: the run's end, ``time.end`` [s].
            drive: the geometry's movable boundary (``GeometrySetup.drive``); None: the geometry has none.

        Raises:
            KeyError: ``params`` lacks one of :attr:`keys` (a resolved config has them all).
        """
        self.params = {k: params[k] for k in self.keys}
        self.mu_start, self.end_time, self.drive = mu_start, end_time, drive

    @property
    def kind(self) -> str:
        """The loading's ``loading.kind``: its :attr:`name`."""
        return self.name

    def mu_bar(self, t: float) -> float:
        """Chemical potential imposed on the permeable surface [MPa].

        Every loading implements it (the base raises NotImplementedError). Where :attr:`surface_term` is
        False it is recorded in the history only.

        Args:
            t: the time [s].

        Returns:
            mu_bar(t) [MPa].
        """
        raise NotImplementedError

    def applied_strain(self, t: float) -> float:
        """What the history records as applied_strain.

        Args:
            t: the time [s].

        Returns:
            The applied strain at ``t`` (dimensionless); 0 for a loading that applies none (the base).
        """
        return 0.0

    def applied_displacement(self, t: float) -> float:
        """Displacement of the driven boundary's component [mm].

        Only read when :meth:`conditions` names a driven boundary.

        Args:
            t: the time [s].

        Returns:
            The displacement at ``t`` [mm]; 0 in the base.
        """
        return 0.0

    def kinks(self) -> list[float]:
        """Times where the load rate jumps: steps must not cross them.

        Returns:
            The times [s]; none in the base.
        """
        return []

    def load_end(self) -> float:
        """The time after which the load no longer changes (what a scan over equilibrium states covers).

        Returns:
            That time [s]; the base: the run's end (``time.end``).
        """
        return self.end_time

    def conditions(self, boundaries: dict[str, str]) -> BoundaryConditions:
        """Dirichlet and no-flux conditions for facet groups with roles (``GeometrySetup.boundaries``):
        every role holds its components (``HELD_COMPONENTS``), fluid passes the permeable ones only.

        That is the base's rule; a loading that moves a boundary or stops the fluid overrides it.

        Args:
            boundaries: facet group -> boundary role.

        Returns:
            The :class:`BoundaryConditions`; the base's have no driven boundary.
        """
        return BoundaryConditions(_held(boundaries), None, _with_role(boundaries, "permeable"))


def _with_role(boundaries: dict[str, str], *roles: str) -> tuple[str, ...]:
    return tuple(g for g, role in boundaries.items() if role in roles)


def _held(boundaries: dict[str, str], except_: tuple[str, int] | None = None) -> tuple[tuple[str, ...], ...]:
    return tuple(tuple(g for g, role in boundaries.items()
                       if c in HELD_COMPONENTS.get(role, ()) and (g, c) != except_) for c in (0, 1, 2))


RAMP_KEYS = {
    "chemical_potential": key(float, 0.0, in_closed(-1000.0, 0.0), "mu_bar after the ramp [MPa]", unit="MPa"),
    "ramp_time": key(float, 1.0, gt(0), "[s]", unit="s"),
}


class RampedSurface(Loading):
    """The surface chemical potential rises linearly from the surface material's mu0 to
    ``chemical_potential`` in ``ramp_time`` and is then held."""

    keys = RAMP_KEYS

    def mu_bar(self, t: float) -> float:
        frac = min(max(t / self.params["ramp_time"], 0.0), 1.0)
        return self.mu_start + (self.params["chemical_potential"] - self.mu_start) * frac


class Swelling(RampedSurface):
    """The paper's loading: the ramp acts on the permeable surface, where fluid enters; steps do not cross
    the end of the ramp."""

    name = "swelling"
    bath_equilibrium = True

    def kinks(self) -> list[float]:
        return [self.params["ramp_time"]]

    def load_end(self) -> float:
        return min(self.end_time, self.params["ramp_time"])


class Compression(RampedSurface):
    """A purely mechanical check case: diffusion off (every flux dof zero, s = s0) and the geometry's driven
    boundary moved to -compression_strain * length linearly in time (``time.end``). mu_bar(t) is the ramp,
    recorded in the history only: it does not act (no surface term)."""

    name = "compression"
    keys = {**RAMP_KEYS, "compression_strain": key(float, 0.1, in_open(0.0, 0.9), "compression loading only")}
    needs = frozenset({"drive"})
    surface_term = False
    fluid_frozen = True

    def applied_strain(self, t: float) -> float:
        return self.params["compression_strain"] * min(t / self.end_time, 1.0)

    def applied_displacement(self, t: float) -> float:
        return -self.applied_strain(t) * self.drive.length

    def conditions(self, boundaries: dict[str, str]) -> BoundaryConditions:
        d = self.drive
        return BoundaryConditions(_held(boundaries, except_=(d.group, d.component)), d, None)


LOADINGS: Registry[type[Loading]] = Registry("loading")
for _loading in (Swelling, Compression):  # registration order = the order docs list them
    LOADINGS.register(_loading)
DEFAULT_LOADING = "swelling"
