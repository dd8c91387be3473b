"""The discretization error of one run's g_c from two companion runs (``stability.error_estimate``).

A step of the run pipeline (:mod:`app.workflows.pipeline`): after a buckled run, the same config
coarsened by 2 in time (tolerance x4, steps x2) and by 2 in mesh (element size x2, half the film
layers) runs into ``error-estimate/time`` and ``error-estimate/mesh``; each error is
|g - g_coarse| / (2^p - 1) with an assumed order p, and the result goes into the run's summary as
``critical.discretization_error`` before summary.json is written.

Where a mesh cannot be coarsened (a user's .msh file, which can only be split; an odd number of film
layers), the mesh companion is the mesh refined by 2 instead (a .msh file split once: 4x the cells),
and the error of the run's own mesh is |g - g_fine| 2^p / (2^p - 1). It costs more than a coarse
companion, and the log says so. A companion that fails leaves its error None with the reason; the
run's own answer is kept either way.
"""

from __future__ import annotations

from pathlib import Path

from app import config, geometry, logging_setup

# Orders assumed by the single-run error estimate (measured in docs/validation.md: time ~1.2,
# mesh ~1.8 on the default bilayer); the lower values make the estimate conservative.
ASSUMED_TIME_ORDER = 1.0
ASSUMED_MESH_ORDER = 1.5


def companion_config(cfg: dict, study: str) -> tuple[dict, str]:
    """The companion's config and its direction ("coarsened" or "refined"): coarsened by 2 where the
    config allows it, else (mesh only) refined by 2; ConfigError if neither exists."""
    from app.workflows.convergence import refined_configs

    try:
        return refined_configs(cfg, study, 2, coarsen=True)[1][2], "coarsened"
    except config.ConfigError:
        if study != "mesh":
            raise
        return refined_configs(cfg, study, 2)[1][2], "refined"


def companion_error(g: float, g_companion: float, order: float, direction: str) -> float:
    """The run's error from one companion's answer (Richardson with an assumed order): a coarser companion
    is 2^p times as far from the limit as the run, a finer one 2^-p times."""
    r = 2.0 ** order
    d = abs(g - g_companion)
    return d / (r - 1) if direction == "coarsened" else d * r / (r - 1)


def companion_error_estimate(cfg: dict, g_c_um: float, outdir, comm) -> dict:
    """Discretization error of one run's g_c from two companion runs."""
    from app.workflows.run import simulate
    from app.workflows.variants import variant

    log = logging_setup.get()
    out = {"method": f"companion runs coarsened by 2 in time and mesh (or refined where the mesh cannot be "
                     f"coarsened), assumed orders {ASSUMED_TIME_ORDER:g} (time) and {ASSUMED_MESH_ORDER:g} (mesh)"}
    total = 0.0
    for study, order in (("time", ASSUMED_TIME_ORDER), ("mesh", ASSUMED_MESH_ORDER)):
        try:
            c, direction = companion_config(cfg, study)
        except config.ConfigError as err:
            out[f"{study}_um"] = None
            out[f"{study}_note"] = str(err)
            log.info(f"error estimate: no companion run in {study}: {err}")
            continue
        c = variant(c, {"output.plot": False})
        out[f"{study}_companion"] = direction
        if direction == "refined":
            how = ("the file's cells split once" if geometry.kind_of(cfg).uniform_refinement
                   else "element size / 2, film layers x 2")
            log.info(f"error estimate: the mesh cannot be coarsened, so its companion run is the mesh refined by 2 "
                     f"({how}: about 4x the cells of the run)")
        log.info(f"error estimate: companion run {direction} in {study}")
        s = simulate(c, Path(outdir) / "error-estimate" / study, comm)
        g = s.get("critical", {}).get("growth_um")
        if g is None:
            out[f"{study}_um"] = None
            out[f"{study}_note"] = f"the companion run ended with status {s['status']!r} and no onset"
            continue
        err = companion_error(g_c_um, g, order, direction)
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
    missing = [s for s in ("time", "mesh") if est.get(f"{s}_um") is None]
    logging_setup.get().info(
        f"hydrobuckle: result: g_c = {c['growth_um']:.4f} um +- {est['total_um']:.4f} um, N_c = "
        f"{c['wrinkle_count']:g} (estimated discretization error from the companion runs logged "
        f"above: time {est.get('time_um') or 0:.4f}, mesh {est.get('mesh_um') or 0:.4f}"
        + (f"; no {' and no '.join(missing)} error: see discretization_error in summary.json" if missing else "")
        + ")")
