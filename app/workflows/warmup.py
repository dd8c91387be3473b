"""Compile the forms of the built-in problems ahead of the first run (``hydrobuckle warmup``).

dolfinx compiles every form to C the first time it meets it and caches the result (under
``$XDG_CACHE_HOME/fenics``, default ``~/.cache/fenics``). The forms depend on the geometry kind (its
boundary tags), the loading, the quadrature degrees and the outputs, not on the mesh size, so a
two-step run of each built-in case on a very coarse mesh compiles everything a default run of that
case needs. ``scripts/install.sh`` and the Docker image call this, so a user's first run does not
wait for the compiler.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from app import config, factory
from app.reduced.solve import compile_forms
from app.workflows.reduction import settings
from app.workflows.run import simulate

# (label, user config): each differs from the others in at least one compiled form
CASES = (
    ("bilayer (swelling)", {"geometry": {"kind": "bilayer", "length": 0.1, "substrate_thickness": 0.05},
                            "mesh": {"element_size": 0.025, "film_layers": 1}}),
    ("bilayer (compression)", {"geometry": {"kind": "bilayer", "length": 0.1, "substrate_thickness": 0.05},
                               "mesh": {"element_size": 0.025, "film_layers": 1},
                               "loading": {"kind": "compression"}}),
    ("tube", {"geometry": {"kind": "tube"}, "mesh": {"element_size": 0.2, "film_layers": 1}}),
)
COMMON = {
    "time": {"end": 2e-3, "dt_initial": 1e-3, "dt_max": 1e-3},
    "stability": {"screening": "exact", "eigen_every": 1, "error_estimate": False, "modes": 1},
    "output": {"fields": True, "plot": False},
}


def _merge(a: dict, b: dict) -> dict:
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in a.items()}
    for k, v in b.items():
        out[k] = {**out.get(k, {}), **v} if isinstance(v, dict) else v
    return out


def warmup(comm, log=print) -> float:
    """Run every case of :data:`CASES` for two tiny steps; return the wall time [s]."""
    t0 = time.perf_counter()
    tmp = tempfile.mkdtemp(prefix="hydrobuckle-warmup-") if comm.rank == 0 else None
    tmp = comm.bcast(tmp, root=0)
    for label, user in CASES:
        t = time.perf_counter()
        cfg = config.resolve(_merge(user, COMMON))
        simulate(cfg, Path(tmp) / label.split()[0], comm, progress=False)
        log(f"warmup: {label} forms ready ({time.perf_counter() - t:.1f} s)")
    if comm.rank == 0:  # the 1D reduction's forms (the 2D run's counterpart and `hydrobuckle reduced`)

        for label, user in (("bilayer", {}), ("tube", {"geometry": {"kind": "tube"}})):
            t = time.perf_counter()
            cfg = config.resolve(user)
            compile_forms(factory.section(cfg), settings(cfg))
            log(f"warmup: 1D reduction of the {label} forms ready ({time.perf_counter() - t:.1f} s)")
    comm.barrier()
    if comm.rank == 0:
        import shutil

        shutil.rmtree(tmp, ignore_errors=True)
    return time.perf_counter() - t0
