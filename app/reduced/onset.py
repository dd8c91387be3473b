"""Which mode of a laterally uniform transient first loses stability, and when: the margin curve.

During the transient every accepted step is screened on a logarithmic grid of mode numbers up to the
largest tested wavenumber and in the short-wave limit of the permeable surface (:class:`HalfSpace`).
Afterwards the integer modes around the earliest crossings are located exactly: the first step at which
each is indefinite (bisection over the stored steps), then the crossing time and growth by linear
interpolation of the mode's margin (the smallest eigenvalue of its Jacobi-scaled K) between the two steps.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from app import fem_utils
from app.reduced.halfspace import HalfSpace
from app.reduced.modes import BandedPencil, ModeOperator
from app.reduced.transient import LayeredModel, Snapshot


@dataclass(frozen=True)
class Crossing:
    """The first loss of stability of one mode (n None: the short-wave limit of the surface)."""

    n: float | None
    time: float
    growth: float  # [mm]
    wrinkles: float | None = None
    wavelength: float | None = None  # along the surface [mm]

    def as_dict(self) -> dict:
        return asdict(self)


class Stability:
    """The mode operators about the states of one :class:`LayeredModel`, and the surface's local state."""

    def __init__(self, model: LayeredModel, criterion: str, tau: float | None = None):
        self.model, self.criterion = model, criterion
        m, sec = model, model.section
        self.base = fem.Function(m.W)
        u, q = ufl.split(self.base)
        F0 = m.deformation(u)
        s0 = m.mat.s0 - m.div(q)
        self.tau = fem.Constant(m.domain, PETSc.ScalarType(tau or 1.0))
        held = {1: sec.base} if sec.shape == "planar" and not sec.clamped else {0: sec.base, 1: sec.base}
        if criterion == "rate":
            held[3 if sec.shape == "planar" else 2] = sec.base  # no normal flux through the held end
        self.op = ModeOperator(m.domain, sec.shape, m.res.degree, F0, s0, m.mat, criterion, tau=self.tau,
                               weight=m.weight, held=held)
        at_surface = (m.r - sec.base) / (sec.surface - sec.base)
        tangent, normal = (0, 1) if sec.shape == "planar" else (1, 0)
        self._surface = [fem.form(e * at_surface * ufl.ds) for e in (F0[tangent, tangent], F0[normal, normal], s0)]
        self.half = HalfSpace(sec.materials[sec.film], criterion, degree=m.res.degree)

    def set_state(self, snap: Snapshot) -> None:
        self.base.x.array[:] = snap.state
        self.model.lam_x.value = snap.lam_x

    def pencil(self, snap: Snapshot) -> BandedPencil:
        self.set_state(snap)
        return self.op.polynomial()

    def surface_state(self, snap: Snapshot) -> tuple[float, float, float]:
        self.set_state(snap)
        return tuple(float(fem_utils.assemble_scalar(f, MPI.COMM_SELF)) for f in self._surface)

    def surface_pencil(self, snap: Snapshot) -> BandedPencil:
        """The short-wave limit at the surface's state, as a pencil constant in k (test it at k = 1)."""
        lt, ln, s = self.surface_state(snap)
        return BandedPencil([self.half.band(((lt, 0.0), (0.0, ln)), s), 0.0, 0.0])


def mode_grid(n_max: int, count: int) -> list[int]:
    """Integer mode numbers 1..n_max, logarithmically spaced (every integer while they are few)."""
    if n_max <= count:
        return list(range(1, n_max + 1))
    return sorted({int(round(v)) for v in np.geomspace(1, n_max, count)})


class Screen:
    """The per-step callback of the transient: screens every accepted step, and asks it to stop
    ``horizon`` (relative) after the first crossing of a finite mode (a surface unstable at short waves
    first: the screen goes on to the first finite wavelength, or the end of the run)."""

    def __init__(self, stab: Stability, grid: list[int], horizon: float):
        self.stab, self.grid, self.horizon = stab, grid, horizon
        self.section = stab.model.section
        self.first_unstable: dict = {}  # mode n (None: the short-wave limit) -> index of its first indefinite step
        self.t_first: float | None = None

    def __call__(self, snap: Snapshot, index: int) -> bool:
        if snap.t == 0.0:
            return False
        P = self.stab.pencil(snap)
        for n in self.grid:
            if n not in self.first_unstable and not P.definite(self.section.wavenumber(n)):
                self.first_unstable[n] = index
        if None not in self.first_unstable and not self.stab.surface_pencil(snap).definite(1.0):
            self.first_unstable[None] = index
        if any(n is not None for n in self.first_unstable) and self.t_first is None:
            self.t_first = snap.t  # the first finite mode (the short-wave limit alone does not end the screen)
        return self.t_first is not None and snap.t >= self.t_first * (1.0 + self.horizon)


@dataclass
class MarginCurve:
    """Crossings of the screened grid, of the integer modes located exactly, and of the short-wave limit."""

    criterion: str
    shape: str
    modes: dict[int, Crossing] = field(default_factory=dict)  # integer n located exactly
    grid: dict[int, int] = field(default_factory=dict)  # n -> first indefinite step on the screen
    short_wave: Crossing | None = None
    n_max: int = 0
    end_time: float = 0.0

    def first(self) -> Crossing | None:
        """The earliest finite-wavelength crossing."""
        return min(self.modes.values(), key=lambda c: c.time) if self.modes else None

    def finite_minimum(self) -> Crossing | None:
        """The earliest crossing of a mode whose critical time is a local minimum inside the tested range
        (a mode with a wavelength of its own), or None if t_c only falls towards the shortest waves."""
        ns = sorted(self.modes)
        best = None
        for i, n in enumerate(ns):
            c = self.modes[n]
            left = self.modes[ns[i - 1]].time if i > 0 else math.inf
            right = self.modes[ns[i + 1]].time if i + 1 < len(ns) else None
            if right is None:
                continue  # the last located mode: no evidence of a minimum
            if c.time <= left and c.time <= right and (best is None or c.time < best.time):
                best = c
        return best


class Locator:
    """Exact crossing of any mode over the stored steps (pencils cached per step)."""

    def __init__(self, stab: Stability, steps: list[Snapshot]):
        self.stab, self.steps = stab, steps
        self._cache: dict[int, BandedPencil] = {}
        self._surface: dict[int, BandedPencil] = {}

    def pencil(self, i: int) -> BandedPencil:
        if i not in self._cache:
            if len(self._cache) > 64:
                self._cache.pop(next(iter(self._cache)))
            self._cache[i] = self.stab.pencil(self.steps[i])
        return self._cache[i]

    def surface(self, i: int) -> BandedPencil:
        if i not in self._surface:
            self._surface[i] = self.stab.surface_pencil(self.steps[i])
        return self._surface[i]

    def first_indefinite(self, n: int | None, lo: int = 1) -> int | None:
        """The first stored step at which mode n (None: the short-wave limit) is indefinite, assuming it
        stays so once it is (bisection); None if it is definite at the last step."""
        test = self._test(n)
        hi = len(self.steps) - 1
        if test(hi):
            return None
        if not test(lo):
            return lo
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if test(mid):
                lo = mid
            else:
                hi = mid
        return hi

    def _test(self, n):
        sec = self.stab.model.section
        if n is None:
            return lambda i: self.surface(i).definite(1.0)
        k = sec.wavenumber(n)
        return lambda i: self.pencil(i).definite(k)

    def crossing(self, n: int | None, i: int) -> Crossing:
        """Crossing of mode n between steps i - 1 (definite) and i (indefinite): the root of the quadratic
        through the mode's margin at steps i - 2, i - 1, i (linear at the first step), and the growth
        interpolated the same way."""
        sec = self.stab.model.section
        idx = [j for j in (i - 2, i - 1, i) if j >= 0]
        if n is None:
            m = [self.surface(j).margin(1.0) for j in idx]
        else:
            k = sec.wavenumber(n)
            m = [self.pencil(j).margin(k) for j in idx]
        ts = [self.steps[j].t for j in idx]
        gs = [self.steps[j].growth for j in idx]
        t = interpolated_root(ts, m)
        g = float(np.polyval(np.polyfit(ts, gs, len(ts) - 1), t))
        if n is None:
            return Crossing(None, t, g)
        return Crossing(n, t, g, sec.wrinkle_count(n), 2 * math.pi / sec.local_wavenumber(n))


def interpolated_root(ts: list[float], margins: list[float]) -> float:
    """The zero of the polynomial through (t, margin) (2 or 3 points) between the last two times, where the
    margin changes sign; the linear root if the quadratic has none there."""
    a, b = ts[-2], ts[-1]
    m0, m1 = margins[-2], margins[-1]
    lin = a if m0 == m1 else a + (b - a) * min(max(m0 / (m0 - m1), 0.0), 1.0)
    if len(ts) < 3:
        return lin
    roots = np.roots(np.polyfit(ts, margins, 2))
    inside = [float(r.real) for r in roots if abs(r.imag) < 1e-12 * max(1.0, abs(r.real)) and a <= r.real <= b]
    return min(inside, key=lambda r: abs(r - lin)) if inside else lin


def margin_curve(stab: Stability, steps: list[Snapshot], screen: Screen, span: float = 3.0,
                 max_modes: int = 400) -> MarginCurve:
    """Locate the integer modes from each screened local minimum (and the earliest crossing) / ``span`` to
    times ``span`` (at most ``max_modes`` per window), and the short-wave limit."""
    sec = stab.model.section
    loc = Locator(stab, steps)
    out = MarginCurve(stab.criterion, sec.shape, grid={n: i for n, i in screen.first_unstable.items() if n},
                      n_max=max(screen.grid), end_time=steps[-1].t)
    i_sw = screen.first_unstable.get(None)
    if i_sw is not None:
        out.short_wave = loc.crossing(None, i_sw)
    if out.grid:
        ns_grid = sorted(out.grid)
        idx = [out.grid[n] for n in ns_grid]
        centres = {min(out.grid, key=lambda n: (out.grid[n], n))}
        # each local minimum of the screened crossing steps along n: a mode with a wavelength of its own,
        # also where shorter waves cross earlier still (the surface's limit)
        for j in range(1, len(ns_grid) - 1):
            if idx[j] <= idx[j - 1] and idx[j] <= idx[j + 1]:
                centres.add(ns_grid[j])
        if len(ns_grid) > 1 and idx[0] < idx[1]:
            centres.add(ns_grid[0])
        todo: set[int] = set()
        for c in centres:
            lo = max(1, int(math.floor(c / span)))
            hi = min(out.n_max, int(math.ceil(c * span)))
            ns = range(lo, hi + 1)
            if len(ns) > max_modes:
                ns = sorted({int(round(v)) for v in np.geomspace(lo, hi, max_modes)})
            todo.update(ns)
        for n in sorted(todo):
            i = loc.first_indefinite(n)
            if i is not None:
                out.modes[n] = loc.crossing(n, i)
    return out
