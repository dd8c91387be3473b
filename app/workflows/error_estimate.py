"""The discretization error of one run's g_c from two cheaper companion runs (``stability.error_estimate``).

A step of the run pipeline (:mod:`app.workflows.pipeline`): after a buckled run, the same config
coarsened by 2 in time (tolerance x4, steps x2) and by 2 in mesh (element size x2, half the film
layers when even) runs into ``error-estimate/time`` and ``error-estimate/mesh``; each error is
|g - g_coarse| / (2^p - 1) with an assumed order p, and the result goes into the run's summary as
``critical.discretization_error`` before summary.json is written.
"""

from __future__ import annotations

from pathlib import Path

from app import config, logging_setup

# Orders assumed by the single-run error estimate (measured in docs/validation.md: time ~1.2,
# mesh ~1.8 on the default bilayer); the lower values make the estimate conservative.
ASSUMED_TIME_ORDER = 1.0
ASSUMED_MESH_ORDER = 1.5


def companion_error_estimate(cfg: dict, g_c_um: float, outdir, comm) -> dict:
    """Discretization error of one run's g_c from two cheaper companion runs."""
    from app.workflows.convergence import refined_configs
    from app.workflows.run import simulate
    from app.workflows.variants import variant

    log = logging_setup.get()
    out = {"method": f"companion runs coarsened by 2 in time and mesh, assumed orders "
                     f"{ASSUMED_TIME_ORDER:g} (time) and {ASSUMED_MESH_ORDER:g} (mesh)"}
    total = 0.0
    for study, order in (("time", ASSUMED_TIME_ORDER), ("mesh", ASSUMED_MESH_ORDER)):
        try:
            _, _, c = refined_configs(cfg, study, 2, 4.0, 2.0, coarsen=True)[1]
        except config.ConfigError as err:
            out[f"{study}_um"] = None
            out[f"{study}_note"] = str(err)
            continue
        c = variant(c, {"output.plot": False})
        log.info(f"error estimate: companion run coarsened in {study}")
        s = simulate(c, Path(outdir) / "error-estimate" / study, comm)
        g = s.get("critical", {}).get("growth_um")
        if g is None:
            out[f"{study}_um"] = None
            continue
        err = abs(g_c_um - g) / (2 ** order - 1)
        out[f"{study}_um"] = err
        out[f"{study}_companion_g_c_um"] = g
        total += err
    out["total_um"] = total
    out["relative"] = total / g_c_um if g_c_um else None
    return out


def add_error_estimate(summary: dict, cfg: dict, outdir, comm) -> None:
    """Pipeline step: a buckled run's ``critical.discretization_error`` from its companion runs."""
    if summary["status"] != "buckled":
        return
    c = summary["critical"]
    est = companion_error_estimate(cfg, c["growth_um"], outdir, comm)
    c["discretization_error"] = est
    logging_setup.get().info(
        f"hydrobuckle: result: g_c = {c['growth_um']:.4f} um +- {est['total_um']:.4f} um, N_c = "
        f"{c['wrinkle_count']:g} (estimated discretization error from the coarsened companion runs logged "
        f"above: time {est.get('time_um') or 0:.4f}, mesh {est.get('mesh_um') or 0:.4f})")
