"""Wall-clock accounting by category (assembly, factorizations, solves, stability, eigen, output),
for the benchmark. Cheap enough to stay on: a dict of floats and perf_counter calls."""

from __future__ import annotations

import contextlib
import time
from collections import defaultdict

from petsc4py import PETSc

FACTOR_EVENTS = ("MatLUFactorSym", "MatLUFactorNum", "MatCholFctrSym", "MatCholFctrNum")
SOLVE_EVENTS = ("MatSolve",)

totals: dict[str, float] = defaultdict(float)
counts: dict[str, int] = defaultdict(int)
_stages: dict[str, PETSc.Log.Stage] = {}
_baseline: dict[tuple[str, str], tuple[float, int]] = {}  # PETSc's event log never resets: offsets


def reset() -> None:
    """Start a new measurement: clear the timers and take PETSc's cumulative event log as the zero."""
    totals.clear()
    counts.clear()
    PETSc.Log.begin()
    _baseline.clear()
    for category in _stages:
        for name in FACTOR_EVENTS + SOLVE_EVENTS:
            _baseline[(category, name)] = _raw(name, category)


def _raw(name: str, category: str) -> tuple[float, int]:
    info = PETSc.Log.Event(name).getPerfInfo(_stages[category].id)
    return info["time"], int(info["count"])


def _stage(category: str) -> PETSc.Log.Stage:
    if category not in _stages:
        _stages[category] = PETSc.Log.Stage(f"hb_{category}")
    return _stages[category]


@contextlib.contextmanager
def timed(category: str):
    """Time a block; PETSc events inside it are logged under a stage of the same name."""
    stage = _stage(category)
    stage.push()
    t0 = time.perf_counter()
    try:
        yield
    finally:
        totals[category] += time.perf_counter() - t0
        counts[category] += 1
        stage.pop()


def petsc_event_time(names, category: str) -> tuple[float, int]:
    """Total time and count of PETSc log events inside ``timed(category)`` blocks."""
    t, n = 0.0, 0
    if category not in _stages:
        return t, n
    for name in names:
        t1, n1 = _raw(name, category)
        t0, n0 = _baseline.get((category, name), (0.0, 0))
        t += t1 - t0
        n += n1 - n0
    return t, n
