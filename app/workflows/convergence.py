"""Time-step and mesh refinement study of the critical growth: ``hydrobuckle converge``.

Time: the adaptive integrator's tolerance is divided by ``time_factor`` (4) per level; for backward
Euler with local-error control the steps scale as sqrt(tolerance), so each level halves the steps
(refinement ratio 2); time.dt_initial and time.dt_max are halved with them, so that steps held by a
bound refine too. With ``time.adaptive = false`` the fixed step is halved instead. Mesh: the
element size along the surface is divided and the number of film element layers multiplied by
``mesh_factor`` (2) per level, so element shapes are kept while h halves.

For each study the three finest levels give a Richardson estimate: observed order
p = log(|g0 - g1| / |g1 - g2|) / log r, converged value g_inf = g2 + (g2 - g1)/(r^p - 1), and each
level's error |g_k - g_inf|. The base configuration's total error estimate is the sum of its time
and mesh errors; its converged estimate adds both corrections.

Rerun into the same directory, converge continues where an earlier invocation stopped (SIGINT,
SIGTERM, a kill, a full disk): a level whose directory holds its finished run is kept, an interrupted
or killed level resumes from its checkpoint (:mod:`app.workflows.reruns`; ``force``: every level
anew). The tables are removed when a converge starts and written when it ends; an interrupted one
writes what ran with ``"status": "interrupted"`` and no estimate (convergence.md says so first).
"""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

from app import config, geometry, interrupt, logging_setup
from app.io import writes
from app.io.checkpoint import CheckpointError
from app.workflows import preflight, progress, reruns
from app.workflows.run import simulate
from app.workflows.variants import variant

TABLES = ("convergence.csv", "convergence.json", "convergence.md", "convergence.png")


def richardson(values: list[float], ratio: float) -> dict:
    """Richardson extrapolation of a sequence refined by a constant ratio (last three values)."""
    out = {"values": list(values), "ratio": ratio, "order": None, "converged": None, "errors": None,
           "monotone": None}
    if len(values) < 2 or any(v is None for v in values):
        return out
    if len(values) == 2:
        g0, g1 = values
        p = 1.0
    else:
        g0, g1, g2 = values[-3:]
        d1, d2 = g0 - g1, g1 - g2
        out["monotone"] = bool(d1 * d2 > 0)
        if d1 == 0 or d2 == 0 or d1 * d2 < 0:
            p = None
        else:
            p = math.log(abs(d1) / abs(d2)) / math.log(ratio)
        g0, g1 = g1, g2
    if p is None:
        # Not in the asymptotic range: take the finest value; add the largest change as its error.
        g_inf = values[-1]
        spread = max(abs(a - b) for a, b in zip(values[:-1], values[1:]))
        out.update(converged=g_inf, errors=[abs(v - g_inf) + spread for v in values])
        return out
    p_used = min(max(p, 0.5), 4.0)
    g_inf = g1 + (g1 - g0) / (ratio ** p_used - 1)
    out.update(order=p, converged=g_inf, errors=[abs(v - g_inf) for v in values])
    return out


TIME_FACTOR = 4.0  # adaptive steps: the time tolerance's ratio between levels (steps ~ sqrt(tolerance))
MESH_FACTOR = 2.0  # the element size's ratio between levels


def refined_configs(cfg: dict, study: str, levels: int, time_factor: float = TIME_FACTOR,
                    mesh_factor: float = MESH_FACTOR, coarsen: bool = False):
    """(label, parameter value, config) per level, level 0 = the base config; level k is refined k
    times, or coarsened k times with ``coarsen`` (cheaper: the base is then the finest level)."""
    out = []
    for k in range(levels):
        e = -k if coarsen else k
        changes = {"stability.stop_at_onset": True}
        if study == "time":
            if cfg["time"]["adaptive"]:
                # the steps scale as sqrt(tolerance); the step bounds scale with them, or the steps a bound
                # holds (dt_max in a slow phase, dt_initial at the start) would not refine and the level
                # would be less than a refinement by sqrt(time_factor) (an error estimate from it too small)
                t = cfg["time"]
                value = changes["time.tolerance"] = t["tolerance"] / time_factor ** e
                r = time_factor ** (0.5 * e)
                dt0 = min(t["dt_initial"] / r, t["end"])
                changes.update({"time.dt_initial": dt0, "time.dt_max": max(t["dt_max"] / r, dt0),
                                "time.dt_min": min(t["dt_min"], dt0)})
            else:
                value = dt = cfg["time"]["dt_initial"] / 2 ** e
                changes.update({"time.dt_initial": dt, "time.dt_min": min(cfg["time"]["dt_min"], dt),
                                "time.dt_max": max(cfg["time"]["dt_max"], dt)})
        else:
            g = config.geometry_input(cfg)
            value, more = geometry.kind_of(g).refined(g, e, mesh_factor)
            changes.update(more)
        out.append((f"{study}{k}", value, variant(cfg, changes)))
    return out


def check(cfg: dict, levels: int, studies, coarsen: bool) -> None:
    """``converge``'s own input: the level count, the stability test on, every level's mesh within the size
    limit (a ConfigError naming the key otherwise)."""
    if not 2 <= levels <= 6:
        raise config.ConfigError("--levels", f"= {levels} is out of range; allowed: 2..6")
    if not cfg["stability"]["enabled"]:
        raise config.ConfigError("stability.enabled", "must be true for a convergence study of g_c")
    for study in studies:
        for label, _, c in refined_configs(cfg, study, levels, coarsen=coarsen):
            preflight.mesh_size(c, False, f"converge level {label}")


def _level(c: dict, d: Path, comm, label: str, force: bool, log) -> tuple[dict, bool]:
    """One level's summary: kept from an earlier converge (finished, the same config), resumed from its
    checkpoint, or run; and whether it was kept."""
    if not force:
        done = comm.bcast(reruns.finished(c, d) if comm.rank == 0 else None, root=0)
        if done is not None:
            log.info(f"converge: {label}: finished by an earlier converge, kept")
            return done, True
        resume = reruns.resumable(c, d, comm, log, f"converge: {label}")
        if resume is not None:
            log.info(f"converge: {label}: resuming at step {resume.meta['step']}")
            try:
                return simulate(c, d, comm, resume=resume), False
            except CheckpointError as err:  # the checkpoint does not fit the rebuilt mesh: start anew
                log.info(f"converge: {label}: {err}; running from the start")
    return simulate(c, d, comm), False


def converge(cfg: dict, outdir, comm, levels: int = 3, studies=("time", "mesh"), time_factor: float = TIME_FACTOR,
             mesh_factor: float = MESH_FACTOR, coarsen: bool = False, force: bool = False) -> dict:
    """Run the refinement studies; write convergence.csv/.json/.md/.png; return the report."""
    plans = {study: refined_configs(cfg, study, levels, time_factor, mesh_factor, coarsen) for study in studies}
    log = logging_setup.get()
    outdir = Path(outdir)

    def clear():  # a directory holds the tables only once a converge has ended (or says it stopped)
        outdir.mkdir(parents=True, exist_ok=True)
        for name in TABLES:
            (outdir / name).unlink(missing_ok=True)

    writes.on_rank0(comm, outdir, clear)
    rows = []
    # the levels this converge runs (level 0 once) and what each costs against the base: steps double per
    # time level, cells grow by mesh_factor^2 per mesh level (the estimate of the time left scales with it)
    levels_of = {s: [int(lab[len(s):]) for lab, _, _ in plans[s]] for s in studies}
    units = [(studies[0], 0)] + [(s, k) for s in studies for k in levels_of[s] if k != 0]

    def weight(unit):
        per_level = 2.0 if unit[0] == "time" else mesh_factor ** 2
        return per_level ** (-unit[1] if coarsen else unit[1])

    ran: list = []
    bar = progress.Cases("converge", len(units), 1, lambda: len(ran), log, comm.rank == 0, unit="levels")
    report: dict = {"status": "complete", "base": {}, "studies": {}, "direction": "coarsen" if coarsen else "refine"}
    base_summary = None
    stopped = False
    for study in studies:
        values = []
        for label, value, c in plans[study]:
            level = int(label[len(study):])
            if level == 0 and base_summary is not None:
                s = base_summary  # level 0 of every study is the base configuration: run it once
            elif stopped or interrupt.pending(comm):  # SIGINT/SIGTERM: no further level is started
                if not stopped:
                    log.info(f"converge: interrupted: {label} and the later levels not run")
                stopped = True
                break
            else:
                log.info(f"converge: {label} ({'tolerance' if study == 'time' else 'element_size'} = {value:g})")
                t0 = time.perf_counter()
                s, kept = _level(c, outdir / ("base" if level == 0 else label), comm, label, force, log)
                ran.append((study, level))
                bar.finished(None if kept else time.perf_counter() - t0, weight((study, level)),
                             sum(weight(u) for u in units if u not in ran))
                if level == 0:
                    base_summary = s
            crit = s.get("critical", {})
            row = {"study": study, "level": level, "parameter": value,
                   "film_layers": c["mesh"]["film_layers"], "status": s["status"],
                   "g_c_um": crit.get("growth_um"), "N_c": crit.get("wrinkle_count"), "t_c": crit.get("time"),
                   "dofs": s["mesh"]["dofs"], "steps": s["steps"], "wall_time_s": s["wall_time_s"]}
            rows.append(row)
            values.append(row["g_c_um"])
            stopped = stopped or s["status"] == "interrupted"
        if stopped:  # a part of the levels: no estimate
            report["status"] = "interrupted"
            report["studies"][study] = {"values": values, "N_c": [r["N_c"] for r in rows if r["study"] == study]}
            continue
        ratio = 2.0 if study == "time" else mesh_factor
        if coarsen:  # Richardson wants coarse -> fine; map its errors back to the levels
            rich = richardson(values[::-1], ratio)
            if rich["errors"]:
                rich["errors"] = rich["errors"][::-1]
            rich["values"] = values
        else:
            rich = richardson(values, ratio)
        rich["N_c"] = [r["N_c"] for r in rows if r["study"] == study]
        report["studies"][study] = rich
    base = next((r for r in rows if r["level"] == 0), None)
    if base is not None and base["g_c_um"] is not None and not stopped:
        g = base["g_c_um"]
        corr = sum((st["converged"] - g) for st in report["studies"].values() if st["converged"] is not None)
        err = sum(st["errors"][0] for st in report["studies"].values() if st["errors"])
        report["base"] = {"g_c_um": g, "N_c": base["N_c"], "converged_estimate_um": g + corr,
                          "error_estimate_um": err, "relative_error": err / abs(g + corr) if g + corr else None}
    if rows:
        writes.on_rank0(comm, outdir, _write, outdir, rows, report)  # every rank may read them afterwards
    b = report["base"]
    if b:
        log.info(f"converge: base g_c = {b['g_c_um']:.4f} um, converged estimate {b['converged_estimate_um']:.4f} um, "
                 f"estimated error {b['error_estimate_um']:.4f} um ({100 * (b['relative_error'] or 0):.2f}%)")
    return report


def _write(outdir: Path, rows: list[dict], report: dict) -> None:
    """Rank 0: the tables, each written aside and renamed (a failure names its file)."""
    from app.io.plots import convergence_plot

    def table(tmp):
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)

    lines = []
    if report["status"] != "complete":
        lines += ["INTERRUPTED: not every level ran, so there is no estimate. Rerun the same command to continue "
                  "(finished levels are kept, an interrupted level resumes from its checkpoint).", ""]
    lines += ["| study | level | parameter | film layers | dofs | steps | g_c [um] | N_c | error est. [um] |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        st = report["studies"][r["study"]]
        err = st["errors"][r["level"]] if st.get("errors") else None
        lines.append(f"| {r['study']} | {r['level']} | {r['parameter']:g} | {r['film_layers']} | {r['dofs']} | "
                     f"{r['steps']} | {_fmt(r['g_c_um'])} | {_fmt(r['N_c'])} | {_fmt(err)} |")
    for name, st in report["studies"].items():
        if "order" in st:
            lines.append(f"\n{name}: observed order {_fmt(st['order'])}, converged g_c {_fmt(st['converged'])} um")
    if report["base"]:
        b = report["base"]
        lines.append(f"\nbase: g_c = {b['g_c_um']:.4f} um, converged estimate {b['converged_estimate_um']:.4f} um, "
                     f"estimated error {b['error_estimate_um']:.4f} um")
    files = {"convergence.csv": table,
             "convergence.json": lambda tmp: tmp.write_text(writes.json_text({"rows": rows, **report})),
             "convergence.md": lambda tmp: tmp.write_text("\n".join(lines) + "\n")}
    if report["status"] == "complete":
        files["convergence.png"] = lambda tmp: convergence_plot(rows, report, tmp)
    for name, write in files.items():
        writes.at(outdir / name, writes.replace_file, outdir / name, write)


def _fmt(v):
    if v is None:
        return "-"
    return f"{v:.4g}" if isinstance(v, float) else str(v)
