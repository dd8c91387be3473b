"""One reduced computation of a config, and its convergence in the 1D mesh, the time step and the largest
wavenumber tested: the answer with its error bar, like the 2D one."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from app.reduced.onset import Crossing, MarginCurve, Screen, Stability, margin_curve, mode_grid
from app.reduced.section import Section
from app.reduced.transient import LayeredModel, Resolution, Snapshot, Transient, schedule

MAX_WAVENUMBER = 20.0  # largest k w tested on the mode grid (beyond it: the short-wave limit)
GRID = 48  # screened mode numbers per step


@dataclass(frozen=True)
class Settings:
    criterion: str = "drained"
    tau: float = 1.0e-2
    t_end: float = 10.0
    horizon: float = 0.5  # keep going this fraction of the first crossing time past it
    max_wavenumber: float = MAX_WAVENUMBER
    grid: int = GRID
    resolution: Resolution = Resolution()


@dataclass
class Level:
    """One transient + margin curve."""

    name: str
    resolution: Resolution
    time_scale: int
    curve: MarginCurve
    steps: list[Snapshot]
    seconds: float
    newton_its: int
    cells: int = 0  # of the 1D mesh

    def onset(self) -> Crossing | None:
        return earliest(self.curve)


def earliest(curve: MarginCurve) -> Crossing | None:
    """The first loss of stability: a finite mode or the short-wave limit, whichever is earlier."""
    cands = [c for c in (curve.first(), curve.short_wave) if c is not None]
    return min(cands, key=lambda c: c.time) if cands else None


def n_max(section: Section, max_wavenumber: float) -> int:
    """The largest mode number tested: k w = max_wavenumber along the surface."""
    k = max_wavenumber / section.film_thickness
    if section.width is not None:  # the plate: the lattice's distinct |k| up to k
        return max(2, int(np.searchsorted(section.lattice()[0], k, side="right")))
    if section.shape == "planar":
        return max(2, int(math.ceil(k * section.length / math.pi)))
    return max(2, int(math.ceil(k * section.surface)))


class Interrupted(RuntimeError):
    """A computation stopped by its ``stop`` callable (a signal)."""


def compute(section: Section, st: Settings, resolution: Resolution | None = None, schedule=None,
            time_scale: int = 1, name: str = "base", stop=None) -> Level:
    """One transient and its margin curve; ``stop()`` true after a step raises :class:`Interrupted`."""
    res = resolution or st.resolution
    t0 = time.perf_counter()
    model = LayeredModel(section, res)
    stab = Stability(model, st.criterion, st.tau)
    screen = Screen(stab, mode_grid(n_max(section, st.max_wavenumber), st.grid), st.horizon)
    tr = Transient(model)

    def step_done(snap, index):
        if stop is not None and stop():
            raise Interrupted(f"stopped at t = {snap.t:.6g} s")
        return screen(snap, index)

    tr.run(st.t_end, stop=step_done, scale=time_scale, schedule=schedule)
    curve = margin_curve(stab, tr.steps, screen)
    return Level(name, res, time_scale, curve, tr.steps, time.perf_counter() - t0, tr.newton_its, len(model.nodes) - 1)


def compile_forms(section: Section, st: Settings) -> None:
    """Build (and so JIT-compile) every form a computation of ``section`` under ``st`` uses."""
    model = LayeredModel(section, st.resolution)
    Stability(model, st.criterion, st.tau)


@dataclass
class Estimate:
    """A reduced answer with its error bar from the mesh and time levels."""

    value: Crossing | None
    growth_error: float | None = None
    time_error: float | None = None
    parts: dict = field(default_factory=dict)
    levels: list[Level] = field(default_factory=list)


def converged(section: Section, st: Settings, stop=None) -> Estimate:
    """Three levels: the base (adaptive steps), the same steps halved (Richardson in time: backward Euler
    is first order), the mesh refined once. The answer is the time-extrapolated base value; its error bar
    combines the time extrapolation's size (the halved-step error) and the mesh change."""
    base = compute(section, st, stop=stop)
    sched = schedule(base.steps)
    halved = compute(section, st, schedule=sched, time_scale=2, name="time", stop=stop)
    finer = compute(section, st, resolution=st.resolution.refined(1), schedule=sched, name="mesh", stop=stop)
    levels = [base, halved, finer]
    c0, c1, c2 = (lev.onset() for lev in levels)
    if c0 is None or c1 is None or c2 is None:
        return Estimate(c1, levels=levels)
    t = 2 * c1.time - c0.time
    g = 2 * c1.growth - c0.growth
    e_time = abs(c1.growth - c0.growth)
    e_mesh = abs(c2.growth - c0.growth)
    value = Crossing(c1.n, t, g, c1.wrinkles, c1.wavelength)
    return Estimate(value, math.hypot(e_time, e_mesh), math.hypot(abs(c1.time - c0.time), abs(c2.time - c0.time)),
                    {"time": e_time, "mesh": e_mesh, "same_mode": c0.n == c1.n == c2.n}, levels)
