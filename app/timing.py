"""Wall-clock accounting by category (assembly, factorizations, solves, stability, eigen, output),
for the benchmark. Cheap enough to stay on: a dict of floats and perf_counter calls."""

from __future__ import annotations

import contextlib
import time
from collections import defaultdict

from petsc4py import PETSc

CATEGORIES = ("assembly", "factorization", "triangular_solves", "stability_test", "eigen_solve", "output")
FACTOR_EVENTS = ("MatLUFactorSym", "MatLUFactorNum", "MatCholFctrSym", "MatCholFctrNum")
SOLVE_EVENTS = ("MatSolve",)

totals: dict[str, float] = defaultdict(float)
counts: dict[str, int] = defaultdict(int)
_stages: dict[str, PETSc.Log.Stage] = {}


def reset() -> None:
    totals.clear()
    counts.clear()
    PETSc.Log.begin()


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
        info = PETSc.Log.Event(name).getPerfInfo(_stages[category].id)
        t += info["time"]
        n += int(info["count"])
    return t, n
