"""hydrobuckle: swelling-induced wrinkling of constrained hydrogels.

A two-field (displacement, fluid-volume flux) incremental minimization principle for finite
elasticity coupled with Fickian diffusion, discretized with Q1 x RTCF elements on FEniCSx, with
a stability analysis of the coupled Hessian to locate the onset of wrinkling.

The Python API (:mod:`app.api`) is re-exported here::

    import app as hb

    result = hb.run(hb.load_config("configs/bilayer.toml"), "results/bilayer")
    print(result.g_c_um, result.g_c_error_um, result.N_c)

Its names are imported on first use, so ``import app`` (and the command line) stays light.
"""

import os

from app.version import __version__  # noqa: F401 - app.__version__

# PT-Scotch, dolfinx's graph partitioner on both stacks, partitions with threads, and with more than one
# thread the same mesh on the same ranks comes out with its parts given to the ranks in either order (measured
# on 2 ranks: 2 runs in 10 swapped), so the roundoff, and past an unstable state the branch taken, differed
# between identical runs. One thread makes the layout a function of the mesh and the rank count. Set before
# any of hydrobuckle's modules imports dolfinx (read when a mesh is partitioned); a user's own setting is kept.
os.environ.setdefault("SCOTCH_PTHREAD_NUMBER", "1")

__all__ = ["ConfigError", "Result", "Study", "load_config", "load_result", "run", "run_reduced", "studies",
           "study", "sweep"]


def __getattr__(name: str):
    if name in __all__:
        from app import api

        return getattr(api, name)
    raise AttributeError(f"module 'app' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
