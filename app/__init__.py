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

from app.version import __version__

__all__ = ["ConfigError", "Result", "Study", "load_config", "load_result", "run", "run_reduced", "studies",
           "study", "sweep"]


def __getattr__(name: str):
    if name in __all__:
        from app import api

        return getattr(api, name)
    raise AttributeError(f"module 'app' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
