"""The exact 1D reduction as a command (``hydrobuckle reduced``) and beside every bilayer or tube run
(the pipeline step :func:`add_reduced`: summary.json ``reduced``).

A reduced answer is converged like a 2D one: three 1D computations (the base; its time steps halved; its
mesh refined), the time-extrapolated value with an error bar from both differences
(:func:`app.reduced.solve.converged`). It is computed on rank 0 of the run's communicator and shared.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path

from app import config, factory, interrupt, logging_setup
from app.io import writes
from app.reduced.solve import Estimate, Interrupted, Settings, converged
from app.reduced.transient import Resolution, TransientFailed
from app.workflows.variants import variant

SOLVER = "reduced-1d"


def settings(cfg: dict) -> Settings:
    r = cfg["reduced"]
    res = Resolution(r["degree"], r["film_cells"], r["grading"], r["surface_grading"], r["step_change"],
                     cfg["time"]["dt_max"],
                     min(cfg["time"]["dt_initial"], 1e-3))
    st = cfg["stability"]
    return Settings(st["criterion"], st["tau"], cfg["time"]["end"], r["horizon"], r["max_wavenumber"], r["grid"], res)


def _um(x):
    return None if x is None else 1e3 * x


def _crossing(c, section=None) -> dict | None:
    if c is None:
        return None
    out = {"mode_number": c.n, "wrinkle_count": c.wrinkles, "wavelength_mm": c.wavelength, "time": c.time,
           "growth_um": _um(c.growth)}
    waves = section.wave_vectors(c.n) if section is not None and c.n is not None else None
    if waves is not None:  # the plate: the half-wave pairs (m, n) of the critical |k|
        out["wave_vectors"] = [list(w) for w in waves]
    return out


def summarize(est: Estimate, st: Settings, seconds: float, section=None) -> dict:
    """The JSON block of a reduced answer (summary.json of ``reduced``; ``reduced`` in a 2D summary)."""
    base = est.levels[0].curve if est.levels else None
    v = est.value
    if v is None:
        kind = "stable"
    elif v.n is None:
        kind = "surface"  # the permeable surface first fails at short waves: no wavelength of its own
    else:
        kind = "wrinkles"
    out = {
        "solver": SOLVER,
        "criterion": st.criterion,
        "kind": kind,
        "growth_um": _um(v.growth) if v else None,
        "growth_error_um": _um(est.growth_error),
        "time": v.time if v else None,
        "time_error": est.time_error,
        "mode_number": v.n if v else None,
        "wrinkle_count": v.wrinkles if v else None,
        "wavelength_mm": v.wavelength if v else None,
        "error_parts_um": {k: (_um(x) if isinstance(x, float) else x) for k, x in est.parts.items()},
        "first_finite_wavelength": _crossing(base.finite_minimum(), section) if base else None,
        "short_wave_limit": _crossing(base.short_wave) if base else None,
        "tested_mode_numbers": [1, base.n_max] if base else None,
        "end_time": base.end_time if base else None,
        "levels": [{"name": lev.name, "cells": lev.cells, "degree": lev.resolution.degree, "steps": len(lev.steps) - 1,
                    "onset": _crossing(lev.onset(), section), "seconds": round(lev.seconds, 3)} for lev in est.levels],
        "seconds": round(seconds, 3),
    }
    if kind == "surface":
        out["where"] = "permeable surface"
    waves = section.wave_vectors(v.n) if section is not None and kind == "wrinkles" else None
    if waves is not None:  # the plate: every (m, n) at the critical |k| crosses together
        out["wave_vectors"] = [list(w) for w in waves]
    return out


ISOMODES = 12  # earliest mode crossings a study row lists (its isomode curves)


def compute(cfg: dict, stop=None) -> dict:
    """The converged reduced answer of ``cfg`` as a summary block; NotReducible if it has none,
    TransientFailed if the 1D transient cannot be continued, Interrupted once ``stop()`` is true."""
    st = settings(cfg)
    t0 = time.perf_counter()
    section = factory.section(cfg)
    est = converged(section, st, stop=stop)
    block = summarize(est, st, time.perf_counter() - t0, section)
    block["mu_bar"] = section.loading.mu_bar(block["time"]) if block["time"] is not None else None
    curve = est.levels[0].curve
    early = sorted(curve.modes.values(), key=lambda c: c.time)[:ISOMODES]
    block["isomodes"] = [[c.wrinkles, 1e3 * c.growth] for c in early]
    if section.width is not None or section.axial:  # 3D: each early mode's wave vectors, for the 3D run's order
        block["mode_crossings"] = [{"wave_vectors": [list(w) for w in section.wave_vectors(c.n)],
                                    "growth_um": 1e3 * c.growth, "time": c.time} for c in early]
    block["_estimate"] = est  # the caller's: margin curve and histories (removed before JSON)
    return block


def describe(block: dict) -> str:
    """One line of a reduced answer."""
    if block["kind"] == "stable":
        return f"1D reduction ({block['criterion']}): stable up to t = {block['end_time']:.4g} s"
    err = block["growth_error_um"]
    bar = f" +- {err:.4f} um" if err is not None else ""
    if block["kind"] == "surface":
        ff = block["first_finite_wavelength"]
        tail = (f"; the first finite wavelength: N = {ff['wrinkle_count']:g} at {ff['growth_um']:.4f} um"
                if ff else "")
        return (f"1D reduction ({block['criterion']}): the permeable surface is unstable at short waves (no "
                f"wavelength of its own) from g = {block['growth_um']:.4f} um{bar} at t = {block['time']:.5f} s{tail}")
    waves = block.get("wave_vectors")
    waves = f", wave vectors {', '.join(str(tuple(w)) for w in waves)}" if waves else ""
    return (f"1D reduction ({block['criterion']}): g_c = {block['growth_um']:.4f} um{bar}, N_c = "
            f"{block['wrinkle_count']:g}{waves} at t_c = {block['time']:.5f} s")


def add_reduced(summary: dict, cfg: dict, comm) -> None:
    """Pipeline step: a bilayer or circular-tube run's exact 1D counterpart, in ``summary["reduced"]``
    (not after an interrupted or failed run). A SIGINT/SIGTERM while it is computed ends it: the run's
    summary is written without it (``reduced.kind = "interrupted"``) and the command exits 130/143."""
    if summary["status"] in ("interrupted", "failed"):
        return
    log = logging_setup.get()
    log.info("hydrobuckle: computing the exact 1D counterpart (reduced.beside_2d; about 10 s)")
    block = None
    with interrupt.Watch(comm):
        if comm.rank == 0:
            try:
                block = compute(cfg, stop=lambda: interrupt._received != 0)
                block.pop("_estimate")
            except TransientFailed as err:
                block = {"solver": SOLVER, "kind": "failed", "error": str(err)}
            except Interrupted:
                block = {"solver": SOLVER, "kind": "interrupted"}
        block = comm.bcast(block, root=0)
        if interrupt.pending(comm):  # collective: the CLI's exit code says which signal
            block = {"solver": SOLVER, "kind": "interrupted"}
    summary["reduced"] = block
    if block["kind"] == "failed":
        log.info(f"hydrobuckle: 1D reduction: failed ({block['error']}); the 2D answer is kept")
        return
    if block["kind"] == "interrupted":
        log.info("hydrobuckle: 1D reduction: interrupted; the 2D answer is kept")
        return
    order = mode_order(summary)
    if order is not None:
        block["first_3d_mode"] = order
    log.info("hydrobuckle: " + describe(block) + compare(summary))


def mode_order(summary: dict) -> dict | None:
    """Where a 3D run's first mode stands in the 1D order, when it is not the 1D's first: its wave vector,
    its 1D crossing (growth, and the gap to the 1D first) and whether that gap lies within the 3D error bar
    (``within_error_bar``: then which of the two comes first is not resolved at the run's mesh; None without an
    error bar). A 3D tube's mode with an axial
    wave has no 1D counterpart (``"in_1d": False``). None for 2D runs and where the first modes agree."""
    red, c = summary.get("reduced") or {}, summary.get("critical") or {}
    modes, first_1d = c.get("modes") or [], red.get("wave_vectors")
    wave = modes[0].get("wave_vector") if modes else None
    if wave is None or not first_1d or list(wave) in first_1d or red.get("growth_um") is None:
        return None
    err = (c.get("discretization_error") or {}).get("total_um")
    hit = next((m for m in red.get("mode_crossings") or [] if list(wave) in m["wave_vectors"]), None)
    if hit is None:
        return {"wave_vector": list(wave), "in_1d": False}
    gap = hit["growth_um"] - red["mode_crossings"][0]["growth_um"]  # both on the 1D base level (the same mesh)
    return {"wave_vector": list(wave), "in_1d": True, "growth_um": hit["growth_um"], "gap_um": gap,
            "within_error_bar": (gap <= err) if err else None}


def compare(summary: dict) -> str:
    """How the 2D onset stands against the reduced one, in its own error bars (for the log line)."""
    red, c = summary.get("reduced") or {}, summary.get("critical") or {}
    g2, g1 = c.get("growth_um"), red.get("growth_um")
    if g2 is None or g1 is None:
        return ""
    err = (c.get("discretization_error") or {}).get("total_um")
    d = g2 - g1
    dim = "3D" if red.get("wave_vectors") else "2D"  # a plate's block lists its lattice point's (m, n)
    text = f"; {dim} - 1D = {d:+.4f} um ({100 * d / g1:+.2f}%"
    if err:
        text += f", {abs(d) / err:.2f} of the {dim} error bar"
    text += ")"
    if err and abs(d) > err + (red.get("growth_error_um") or 0.0):
        text += (f"; the exact 1D value lies outside the {dim} error bar: the {dim} mesh misses something its "
                 "companion runs do not show (a thick film's surface diffusion layer: try mesh.film_grading "
                 "or more mesh.film_layers; docs/reduction.md section 5)")
    order = red.get("first_3d_mode") or mode_order(summary)
    if order is not None:
        wave = tuple(order["wave_vector"])
        if not order["in_1d"]:
            text += (f"; the 3D's first mode {wave} is not among the 1D's earliest"
                     + (" (an axial wave, which the 1D reduction of axially uniform modes does not cover)"
                        if red.get("wave_vectors") and all(w[1] == 0 for w in red["wave_vectors"]) and wave[1] else ""))
        else:
            text += (f"; the 3D's first mode {wave} crosses in 1D at {order['growth_um']:.4f} um, "
                     f"{order['gap_um']:+.4f} um after the 1D's first: "
                     + ("no error bar to judge it by (stability.error_estimate = false)"
                        if order["within_error_bar"] is None else
                        "within the 3D error bar, so which of the two comes first is not resolved at this mesh (a "
                        "finer one tells)" if order["within_error_bar"] else
                        "outside the 3D error bar, so the 3D mesh puts the wrong mode first (refine it)"))
    if red["kind"] == "surface" and c.get("wrinkle_count") is not None:
        text += ("; the 2D N_c is a finite wave after the surface's short-wave onset, which a mesh cannot "
                 "resolve (docs/reduction.md)")
    return text


# --- the command ---------------------------------------------------------------------------------------


OUTPUTS = ("summary.json", "margin.csv", "history.csv", "margin.png", "config.toml")


def run(cfg: dict, outdir: Path, stop=None) -> dict:
    """``hydrobuckle reduced``: config.toml, margin.csv, history.csv, margin.png and summary.json (last).
    An earlier result's files go first, so a run that does not finish never leaves one that looks it."""
    outdir.mkdir(parents=True, exist_ok=True)
    for name in OUTPUTS:
        (outdir / name).unlink(missing_ok=True)
    writes.write_text(outdir / "config.toml", config.dumps(cfg))
    block = compute(cfg, stop=stop)
    est = block.pop("_estimate")
    _write_margin(outdir / "margin.csv", est)
    _write_history(outdir / "history.csv", est)
    try:
        from app.io.plots import reduced_margin_plot

        reduced_margin_plot(outdir / "margin.png", est, block)
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        pass
    summary = {"status": "buckled" if block["kind"] != "stable" else "stable", "solver": SOLVER, "reduced": block}
    writes.write_json(outdir / "summary.json", summary)
    return summary


def write_failure(outdir: Path, cfg: dict, message: str) -> None:
    summary = {"status": "failed", "solver": SOLVER, "error": message}
    writes.write_json(outdir / "summary.json", summary)


def _write_margin(path: Path, est: Estimate) -> None:
    """Each located mode's first crossing (the base level), then the short-wave limit (n empty)."""
    curve = est.levels[0].curve
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["mode_number", "wrinkle_count", "wavelength_mm", "time", "growth_um"])
        for n in sorted(curve.modes):
            c = curve.modes[n]
            w.writerow([n, f"{c.wrinkles:g}", f"{c.wavelength:.8g}", f"{c.time:.10g}", f"{1e3 * c.growth:.10g}"])
        if curve.short_wave is not None:
            c = curve.short_wave
            w.writerow(["", "", "0", f"{c.time:.10g}", f"{1e3 * c.growth:.10g}"])


def _write_history(path: Path, est: Estimate) -> None:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "mu_bar", "growth_um", "lateral_stretch"])
        for s in est.levels[0].steps:
            w.writerow([f"{s.t:.10g}", f"{s.mu_bar:.10g}", f"{1e3 * s.growth:.10g}", f"{s.lam_x:.10g}"])


def command(cfg: dict, outdir: Path, comm) -> int:
    """``hydrobuckle reduced``: the exit code (0; 1 when the 1D transient failed, summary.json saying so; the
    code of a signal, agreed by every rank). A 1D problem: rank 0 computes, the others wait."""
    log = logging_setup.get()
    code = 0
    with interrupt.Watch(comm):
        if comm.rank == 0:
            try:
                summary = run(cfg, outdir, stop=lambda: interrupt._received != 0)
                log.info("hydrobuckle: result: " + describe(summary["reduced"]) + f" ({outdir}, "
                         f"{summary['reduced']['seconds']:.1f} s)")
            except TransientFailed as err:
                write_failure(outdir, cfg, str(err))
                log.error(f"hydrobuckle: the 1D transient failed: {err}; summary.json says so")
                code = 1
            except Interrupted as err:
                log.error(f"hydrobuckle: interrupted ({err}): {outdir} has no summary.json")
        code = comm.bcast(code, root=0)
        interrupt.pending(comm)  # the exit code of a signal (130 / 143), agreed by every rank
    return code


CROSSOVER_WIDTH = 1e-3  # the bisection stops once the bracket is this fraction of the value


def crossover_args(cfg: dict, raw: list[str]) -> tuple[str, float, float, float]:
    """``reduced --crossover KEY LO HI TIME`` checked: a known numeric key, 0 < LO < HI, TIME in (0, time.end];
    each value a valid config (a ConfigError naming the key otherwise)."""
    key, *numbers = raw
    try:
        lo, hi, target = (float(x) for x in numbers)
    except ValueError:
        raise config.ConfigError("--crossover", f"LO HI TIME must be numbers (got {' '.join(numbers)})") from None
    if not 0 < lo < hi:
        raise config.ConfigError("--crossover", f"needs 0 < LO < HI (got {lo:g}, {hi:g})")
    if not 0 < target <= cfg["time"]["end"]:
        raise config.ConfigError("--crossover", f"TIME must lie in (0, time.end = {cfg['time']['end']:g}] s "
                                 f"(got {target:g})")
    for v in (lo, hi):
        _with(cfg, key, v)  # a validated variant: a bad key or value is a ConfigError here
    return key, lo, hi, target


def _with(cfg: dict, key: str, value: float) -> dict:
    return variant(cfg, {key: value, "reduced.horizon": 0.0})


def onset_time(cfg: dict) -> tuple[float | None, str]:
    """The 1D onset time of ``cfg`` and what goes first (the wrinkle count, or "surface")."""
    block = compute(cfg)
    n = block["wrinkle_count"]
    return block["time"], "surface" if n is None else f"N = {n:g}"


def crossover(cfg: dict, key: str, lo: float, hi: float, target: float, log) -> dict:
    """The value of ``key`` in [lo, hi] at which the exact 1D onset time equals ``target`` (bisection on the
    onset's sign against it, to CROSSOVER_WIDTH; each value a 1D run of seconds). {"value", "error", "rows"};
    value None when the onset does not cross ``target`` between lo and hi (an onset beyond time.end counts
    as later than any target)."""
    rows = []

    def side(v):
        t, what = onset_time(_with(cfg, key, v))
        rows.append({"value": v, "time": t, "first": what})
        log(f"reduced: {key} = {v:.6g}: onset at " + (f"t = {t:.6g} s ({what})" if t is not None else
                                                       "none up to time.end"))
        return t is None or t > target

    late_lo, late_hi = side(lo), side(hi)
    if late_lo == late_hi:
        return {"value": None, "error": None, "rows": rows}
    while hi - lo > CROSSOVER_WIDTH * abs(hi):
        mid = 0.5 * (lo + hi)
        if side(mid) == late_lo:
            lo = mid
        else:
            hi = mid
    return {"value": 0.5 * (lo + hi), "error": 0.5 * (hi - lo), "rows": rows}


def crossover_command(cfg: dict, key: str, lo: float, hi: float, target: float, comm) -> str:
    """``hydrobuckle reduced --crossover``: rank 0 bisects, the line is every rank's."""
    log = logging_setup.get()
    found = crossover(cfg, key, lo, hi, target, log.info) if comm.rank == 0 else None
    found = comm.bcast(found, root=0)
    if found["value"] is None:
        return (f"the 1D onset does not cross t = {target:g} s between {key} = {lo:g} and {hi:g} (onsets: "
                + ", ".join("none" if r["time"] is None else f"{r['time']:.5g} s" for r in found["rows"]) + ")")
    return (f"the 1D onset time equals {target:g} s at {key} = {found['value']:.5g} +- {found['error']:.2g} "
            f"({len(found['rows'])} 1D runs)")
