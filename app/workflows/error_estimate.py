"""The discretization error of one run's g_c from two companion runs (``stability.error_estimate``).

A step of the run pipeline (:mod:`app.workflows.pipeline`): after a buckled run, the same config
coarsened by 2 in mesh (element size x2, half the film layers) runs into ``error-estimate/mesh``, and
that coarse mesh coarsened by 2 in time (tolerance x4, steps x2) into ``error-estimate/time``. The mesh
error is |g - g_mesh| / (2^p - 1) and the time error |g_mesh - g_time| / (2^q - 1), with assumed orders
p and q. The time error is measured on the coarse mesh because there a run costs a third of the run's
own: it assumes the time error does not depend much on the mesh (errors that add up). Measured: the
time difference on the coarse mesh is 7% larger than on the run's mesh for the default bilayer (0.0539
vs 0.0504 um), 14% larger for the 0.3 mm strip of tests/test_error_estimate.py (0.0684 vs 0.0598 um) and
23% for the default tube (0.0557 vs 0.0454 um), so the bar errs on the safe side there. The result goes
into the run's summary as ``critical.discretization_error`` before summary.json is written.

Where a mesh cannot be coarsened (a user's .msh file, which can only be split; an odd number of film
layers), the mesh companion is the mesh refined by 2 instead (a .msh file split once: 4x the cells),
the error of the run's own mesh is |g - g_fine| 2^p / (2^p - 1), and the time companion runs on the
run's own mesh (as it also does when the coarse mesh companion found no onset). It costs more than
coarse companions, and the log says so. A companion that fails leaves its error None with the reason;
the run's own answer is kept either way.
"""

from __future__ import annotations

from pathlib import Path

from app import config, geometry, interrupt, logging_setup
from app.io.writes import ResultWriteError
from app.workflows.convergence import refined_configs
from app.workflows.run import simulate
from app.workflows.variants import variant

# Orders assumed by the single-run error estimate (measured in docs/validation.md: time ~1.2,
# mesh ~1.8 on the default bilayer); the lower values make the estimate conservative.
ASSUMED_TIME_ORDER = 1.0
ASSUMED_MESH_ORDER = 1.5
RUN_MESH_TIME = "time-run-mesh"  # the directory of a time companion on the run's mesh after a coarse one had no use


def companion_config(cfg: dict, study: str) -> tuple[dict, str]:
    """The companion's config and its direction ("coarsened" or "refined"): coarsened by 2 where the
    config allows it, else (mesh only) refined by 2; ConfigError if neither exists."""
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


def companion_error_estimate(cfg: dict, g_c_um: float, outdir, comm, progress: bool = True) -> dict:
    """Discretization error of one run's g_c from two companion runs: the mesh companion, and the time
    companion on the mesh companion's coarse mesh (on the run's mesh where the mesh cannot be coarsened, or
    where the coarse mesh found no onset). On two or more ranks the two run side by side, each on half of
    the ranks (:func:`side_by_side`)."""
    log = logging_setup.get()
    out = {"method": f"companion runs coarsened by 2 in mesh (or refined where the mesh cannot be coarsened) and "
                     f"that coarse mesh coarsened by 2 in time; assumed orders {ASSUMED_TIME_ORDER:g} (time) and "
                     f"{ASSUMED_MESH_ORDER:g} (mesh)"}
    mesh = companion_plan(cfg, "mesh", out, log)
    on_coarse = mesh is not None and mesh[1] == "coarsened"
    time = companion_plan(mesh[0] if on_coarse else cfg, "time", out, log)
    jobs = {study: job[0] for study, job in (("mesh", mesh), ("time", time)) if job is not None}
    for study, job in (("mesh", mesh), ("time", time)):
        if job is not None:
            log.info(f"error estimate: companion run {job[1]} in {study}"
                     + (" on the mesh companion's coarse mesh" if study == "time" and on_coarse else ""))
    done = side_by_side(jobs, outdir, comm, progress)
    g_mesh = record_companion(out, "mesh", done, mesh, g_c_um, ASSUMED_MESH_ORDER)
    if time is not None and on_coarse and g_mesh is None and not interrupt.pending(comm):
        # the coarse mesh has no onset to measure the time error against: the time companion on the run's mesh
        log.info(f"error estimate: the mesh companion has no answer; a time companion on the run's mesh instead "
                 f"({RUN_MESH_TIME})")
        on_coarse, time = False, companion_plan(cfg, "time", out, log)
        if time is not None:
            done["time"] = side_by_side({RUN_MESH_TIME: time[0]}, outdir, comm, progress)[RUN_MESH_TIME]
    out["time_companion_mesh"] = "coarsened" if on_coarse else "the run's"
    record_companion(out, "time", done, time, g_mesh if on_coarse else g_c_um, ASSUMED_TIME_ORDER)
    out["total_um"] = sum(out[f"{s}_um"] or 0.0 for s in ("time", "mesh"))
    out["relative"] = out["total_um"] / g_c_um if g_c_um else None
    return out


def companion_plan(base: dict, study: str, out: dict, log):
    """(companion config, direction) of ``base`` in ``study``; None (its part noted in ``out``) if none."""
    try:
        c, direction = companion_config(base, study)
    except config.ConfigError as err:
        out[f"{study}_um"] = None
        out[f"{study}_note"] = str(err)
        log.info(f"error estimate: no companion run in {study}: {err}")
        return None
    if direction == "refined":
        how = ("the file's cells split once" if geometry.kind_of(base["geometry"]["kind"]).uniform_refinement
               else "element size / 2, film layers x 2")
        log.info(f"error estimate: the mesh cannot be coarsened, so its companion run is the mesh refined by 2 "
                 f"({how}: about 4x the cells of the run)")
    return variant(c, {"output.plot": False}), direction


def record_companion(out: dict, study: str, done: dict, job, g_base: float | None, order: float) -> float | None:
    """Put ``study``'s companion answer and its error against ``g_base`` into ``out``; return its g_c."""
    if job is None:
        return None
    out[f"{study}_companion"] = job[1]
    r = done.get(study, {})
    if "g" not in r or g_base is None:
        out[f"{study}_um"] = None
        out[f"{study}_note"] = r.get("note", "no answer to compare with: the mesh companion had none")
        return None
    out[f"{study}_um"] = companion_error(g_base, r["g"], order, job[1])
    out[f"{study}_companion_g_c_um"] = r["g"]
    return r["g"]


def side_by_side(jobs: dict, outdir, comm, progress: bool = True, together: bool = True,
                 root: str = "error-estimate") -> dict:
    """Run each companion config of ``jobs`` ({name: config}) into ``outdir/<root>/<name>``; return
    {name: {"g": its g_c} or {"note": why it has none}} on every rank. With ``together`` and as many ranks as
    jobs or more, the jobs run at the same time, each on its own group of ranks (the first job's group holds
    rank 0, whose log shows its steps; the other groups log nothing, their results are in their
    directories), else one after the other on all ranks. A result file that cannot be written in any group
    is raised on every rank (:class:`~app.io.writes.ResultWriteError`) once every group has ended; any other
    failure of a companion becomes its note."""
    studies = list(jobs)
    if not studies:
        return {}
    groups = len(studies) if together and comm.size >= len(studies) > 1 else 1
    color = comm.rank * groups // comm.size  # contiguous groups, the larger ones first
    sub = comm.Split(color, comm.rank) if groups > 1 else comm
    if groups > 1:
        sizes = [sum(1 for r in range(comm.size) if r * groups // comm.size == k) for k in range(groups)]
        logging_setup.get().info("error estimate: the companion runs side by side: " + ", ".join(
            f"{study} on {n} rank(s)" for study, n in zip(studies, sizes)) + f" (the log shows the {studies[0]} "
            f"companion's steps; the others are in their directories)")
    mine = studies[color::groups]  # this group's jobs
    results, write_error = {}, None
    with interrupt.Watch(comm):  # a group done first waits below, stopped by a signal rather than killed
        try:
            for study in mine:
                if write_error is not None:
                    results[study] = {"note": "not run: a result file could not be written"}
                    continue
                try:
                    s = simulate(jobs[study], Path(outdir) / root / study, sub, progress=progress)
                except ResultWriteError as err:
                    write_error = (err.path, err.reason)
                    results[study] = {"note": str(err)}
                    continue
                except Exception as err:  # noqa: BLE001 - one companion's failure costs its part only
                    results[study] = {"note": f"the companion run failed: {type(err).__name__}: {err}"}
                    continue
                g = s.get("critical", {}).get("growth_um")
                results[study] = ({"g": g} if g is not None else
                                  {"note": f"the companion run ended with status {s['status']!r} and no onset"})
        finally:
            gathered = comm.allgather((results, write_error) if sub.rank == 0 else ({}, None))
            if sub is not comm:
                sub.Free()
    merged = {}
    for res, _ in gathered:
        merged.update(res)
    first = next((err for _, err in gathered if err), None)
    if first is not None:
        raise ResultWriteError(*first)
    return merged


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
