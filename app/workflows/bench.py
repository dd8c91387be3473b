"""``hydrobuckle bench``: the paper's default bilayer to onset at three mesh sizes, timed by category.

Per accepted step the time splits into form assembly, factorizations and triangular solves (of the
Newton iterations, from PETSc's event log), exact stability tests (K on the free dofs and its LDL^T
inertia), eigen-solves, output and other; the setup (mesh, spaces, forms) is reported apart.

``R_step`` = (time of the time loop) / (accepted steps x t_factor), with t_factor the mean time of one numeric
factorization of the Newton K in the same run: the cost of a step in factorizations (1 would be one
factorization per step and nothing else). R = (time of the time loop) / ((Newton factorizations + accepted
steps) x t_factor): the bound of one factorization per factorization Newton made (every solve's: accepted,
rejected and bisection steps) plus one per step for its stability test; R = 1 means the run costs exactly
that (without factor reuse Newton factorizes once per iteration).
``R_performed`` divides by the factorizations actually made instead: Newton's plus every exact stability
test (larger than R where steps are screened on the Newton factor, which factorizes nothing; smaller
with the default drained criterion, tested exactly every step and in the bisection, although its matrix
has only the displacement dofs and factorizes faster than K). ``R_accepted_steps`` counts only the accepted steps'
Newton iterations in the bound (history.csv), leaving rejected and bisection solves in the time only.

``--baseline`` runs every size twice in the same invocation, first with :data:`BASELINE` (the settings before
factor reuse and the predictive step controller) and then with the current defaults, and reports the ratios of the
two: speedups measured side
by side, on the same machine minutes apart, not absolute times from different days. With ``--ranks`` the
two variants are separate launches (each its own processes, so each peak memory is its own); in one
process the peak is reset before every run (Linux), but memory the allocator kept from an earlier run may
still count.

``--error-estimate`` also times each size's error estimate (``stability.error_estimate``: its companion runs)
after the size's run and reports its cost as a multiple of the run. With ``--baseline`` the baseline's
estimate is the one before the companions were rearranged (:func:`estimate_before`: the time companion on
the run's mesh, then the mesh companion, one after the other on all ranks); the current one is
:func:`app.workflows.error_estimate.companion_error_estimate` (the time companion on the coarse mesh, both
side by side on two or more ranks).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from app import config, interrupt, logging_setup, timing
from app.io import lock, writes
from app.workflows import error_estimate as ee
from app.workflows import preflight
from app.workflows.bench_report import BASELINE, fits, report, table
from app.workflows.error_estimate import companion_error_estimate
from app.workflows.run import simulate
from app.workflows.variants import variant

SIZES = {"coarse": 2.0, "default": 1.0, "fine": 0.7, "finer": 0.5}  # element size x s, film layers / s


def _element_size(name: str) -> float | None:
    """A size given as an element size in mm (a positive number), else None."""
    try:
        value = float(name)
    except ValueError:
        return None
    return value if value > 0 else None


def size_config(name: str, overrides: list[str]) -> dict:
    """The config of a bench size: the default config (with ``overrides``) at a named size's scale of its element
    size, or at an element size in mm; its film layers scaled inversely, so the elements keep their shape."""
    cfg = config.resolve({}, list(overrides))
    given, base = _element_size(name), cfg["mesh"]["element_size"]
    scale = SIZES[name] if given is None else given / base
    size = base * scale if given is None else given
    return variant(cfg, {"mesh.element_size": size,
                         "mesh.film_layers": max(1, round(cfg["mesh"]["film_layers"] / scale)),
                         "output.plot": False, "stability.error_estimate": False,
                         "output.checkpoint_every": 0})  # timings of the solver, not of checkpoints


def bench_one(cfg: dict, comm, outdir: Path, estimate: str | None = None) -> dict | None:
    """One size's timings; with ``estimate`` ("current" or "baseline") also its error estimate's."""
    timing.reset()
    per_run = reset_peak_memory()
    t0 = time.perf_counter()
    s = simulate(cfg, outdir, comm, progress=False)
    wall = time.perf_counter() - t0
    if s["status"] == "interrupted":
        return None
    tt = timing.totals
    fact, _ = timing.petsc_event_time(timing.FACTOR_EVENTS, "newton")
    num_time, n_num = timing.petsc_event_time(("MatLUFactorNum", "MatCholFctrNum"), "newton")
    n_stab = timing.counts["stability_test"]
    solves, _ = timing.petsc_event_time(timing.SOLVE_EVENTS, "newton")
    newton_linear = tt["newton"] - tt["assembly"]
    steps = max(1, s["steps"])
    its = _newton_iterations(outdir)
    t_factor = num_time / max(1, n_num)  # one numeric factorization of the Newton K
    split = {
        "assembly": tt["assembly"],
        "factorization": fact,
        "triangular_solves": solves,
        "newton_other": max(0.0, newton_linear - fact - solves),
        "stability_test": tt["stability_test"],
        "eigen_solve": tt["eigen_solve"],
        "output": tt["output"],
    }
    split["other"] = max(0.0, wall - tt["setup"] - sum(split.values()))
    loop = wall - tt["setup"]  # the time loop: stepping, stability tests, bisection, eigen-solves, output
    per_step = loop / steps
    its_per_step = its / steps
    # The factorization bound of the issue: one factorization per Newton iteration (of every solve the
    # run made: accepted, rejected and bisection steps) plus one per accepted step for its stability test.
    budget = n_num + steps
    performed = n_num + n_stab  # factorizations actually made (screened steps factorize nothing extra)
    crit = s.get("critical") or {}
    rss = comm.gather(peak_memory_mb(per_run), root=0)
    return {"ranks": comm.size, "dofs": s["mesh"]["dofs"], "cells": s["mesh"]["cells"], "steps": s["steps"],
            "newton_iterations": its, "newton_per_step": its_per_step, "wall_time_s": wall,
            "setup_time_s": tt["setup"], "time_to_gc_s": wall,
            "g_c_um": crit.get("growth_um"), "N_c": crit.get("wrinkle_count"),
            "time_per_step_s": per_step, "t_factor_s": t_factor, "factorizations": n_num,
            "R": loop / (budget * t_factor) if t_factor > 0 else None,
            "R_step": per_step / t_factor if t_factor > 0 else None,
            "solver_factorizations": s["linear_solver"]["factorizations"],
            "R_performed": loop / (performed * t_factor) if t_factor > 0 else None,
            "R_accepted_steps": per_step / ((its_per_step + 1) * t_factor) if t_factor > 0 else None,
            "newton_factorizations": n_num, "stability_tests": n_stab,
            "screening": cfg["stability"]["screening"],
            "screened_steps": (s.get("stability_tests") or {}).get("screened_steps", 0),
            "per_step_split_s": {k: v / steps for k, v in split.items()},
            "peak_rss_mb_per_rank": rss, "peak_rss_since_reset": per_run,
            **({"error_estimate": time_estimate(cfg, crit.get("growth_um"), comm, outdir, estimate, wall)}
               if estimate and s["status"] == "buckled" else {})}


def time_estimate(cfg: dict, g: float, comm, outdir: Path, which: str, run_wall: float) -> dict:
    """The wall time of the run's error estimate (``which``: "current" or "baseline") and its bars."""
    t0 = time.perf_counter()
    est = (companion_error_estimate if which == "current" else estimate_before)(cfg, g, outdir, comm, progress=False)
    wall = time.perf_counter() - t0
    return {"layout": which, "wall_time_s": wall, "ratio_to_run": wall / run_wall,
            **{k: est.get(k) for k in ("time_um", "mesh_um", "total_um", "time_companion_mesh")}}


def estimate_before(cfg: dict, g: float, outdir: Path, comm, progress: bool = False) -> dict:
    """The error estimate as it was before (the baseline of ``--error-estimate``): the time companion on the
    run's own mesh, then the mesh companion, one after the other on all ranks (into error-estimate-before)."""
    log, out = logging_setup.get(), {}
    plans = {study: ee.companion_plan(cfg, study, out, log) for study in ("time", "mesh")}
    done = ee.side_by_side({study: p[0] for study, p in plans.items() if p is not None}, outdir, comm, progress,
                           together=False, root="error-estimate-before")
    for study, order in (("time", ee.ASSUMED_TIME_ORDER), ("mesh", ee.ASSUMED_MESH_ORDER)):
        ee.record_companion(out, study, done, plans[study], g, order)
    out["total_um"] = sum(out[f"{s}_um"] or 0.0 for s in ("time", "mesh"))
    out["time_companion_mesh"] = "the run's"
    return out


def reset_peak_memory() -> bool:
    """Reset this process's peak resident set size (Linux: "5" to /proc/self/clear_refs), so that the next
    :func:`peak_memory_mb` is the peak of what runs in between, not of the process's earlier runs (the other
    sizes and the baseline of one bench). False where it cannot be reset."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_memory_mb(since_reset: bool) -> float:
    """Peak resident set size [MB]: since :func:`reset_peak_memory` (VmHWM) if it succeeded, else of the whole
    process (getrusage)."""
    if since_reset:
        try:
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024.0
        except OSError:
            pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _newton_iterations(outdir: Path) -> int:
    import csv

    path = Path(outdir) / "history.csv"
    total = 0
    if path.is_file():
        with open(path) as f:
            for r in csv.DictReader(f):
                total += int(r["newton_its"] or 0)
    return total


class BenchFailed(Exception):
    """A launch of ``bench --ranks`` that failed (one line; the CLI exits 1)."""


def run_bench(sizes: list[str], overrides: list[str], outdir: Path, comm, baseline: bool = False,
              only: str | None = None, error_estimate: bool = False) -> dict | None:
    """The timings of every size (with ``baseline``, also of :data:`BASELINE`, run just before it; ``only``:
    just one of the two, "baseline" or "current"), or None once SIGINT/SIGTERM stopped a run or came between
    two runs (no further run starts: a benchmark cannot be resumed, its runs would be timed in parts)."""
    log = logging_setup.get()
    results: dict = {"current": {}, "baseline": {}}
    variants = (("baseline", BASELINE), ("current", [])) if baseline else (("current", []),)
    variants = tuple(v for v in variants if only in (None, v[0]))
    for name in sizes:
        for label, extra in variants:
            if interrupt.pending(comm):
                log.info(f"bench: interrupted: size {name} ({label} settings) and later ones not run")
                return None
            cfg = size_config(name, list(overrides) + extra)
            log.info(f"bench: {name} mesh (element size {cfg['mesh']['element_size']:g} mm, "
                     f"{cfg['mesh']['film_layers']} film layers) on {comm.size} rank(s), {label} settings")
            suffix = "-baseline" if label == "baseline" else ""
            results[label][name] = r = bench_one(cfg, comm, outdir / f"run-{name}-np{comm.size}{suffix}",
                                                 label if error_estimate else None)
            if r is None:
                return None
    out = {"ranks": comm.size, "sizes": results["current"], **fits(results["current"])}
    if baseline:
        out["baseline"] = {"overrides": BASELINE, "sizes": results["baseline"], **fits(results["baseline"])}
    return out


def launch_ranks(ranks: list[int], sizes: list[str], overrides: list[str], outdir: Path,
                 baseline: bool = False, error_estimate: bool = False) -> dict | None:
    """Run the benchmark under ``mpirun -n k`` for each k (a fresh launch each) and combine; None once
    interrupted (SIGINT/SIGTERM here or in a launch); :class:`BenchFailed` if a launch fails. With
    ``baseline``, the baseline and the current settings are two launches per k, one after the other."""
    out = {}
    est = ["--error-estimate"] if error_estimate else []
    for k in ranks:
        if baseline:  # each variant in its own processes: its peak memory is its own
            parts = {}
            for only in ("baseline", "current"):
                parts[only] = _launch(k, sizes, overrides, outdir, ["--baseline", "--only", only] + est)
                if parts[only] is None:
                    return None
            out[k] = {**parts["current"], "baseline": parts["baseline"]["baseline"]}
        else:
            out[k] = _launch(k, sizes, overrides, outdir, est)
            if out[k] is None:
                return None
    return out


def _launch(k: int, sizes: list[str], overrides: list[str], outdir: Path, extra: list[str]) -> dict | None:
    """One ``mpirun -n k ... bench --json-only``: its result, None once interrupted; BenchFailed if it failed."""
    from mpi4py import MPI

    if interrupt.pending(MPI.COMM_SELF):
        return None
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        tmp = f.name
    cmd = ["mpirun", "-n", str(k), "--oversubscribe", sys.executable, "-m", "app", "bench", "--sizes",
           ",".join(sizes), "-o", str(outdir), "--json-only", tmp, "-q"] + extra
    for o in overrides:
        cmd += ["--set", o]
    env = dict(os.environ)
    if os.getuid() == 0:
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    env[lock.INHERITED] = lock.held_env()  # the launch writes into this bench's directory
    code = subprocess.run(cmd, env=env).returncode
    try:
        if interrupt.pending(MPI.COMM_SELF) or code in interrupt.EXIT_CODES.values():
            return None  # a Ctrl-C reaches this process too (mpirun itself then exits 1)
        if code != 0:
            raise BenchFailed(f"bench: `mpirun -n {k} ... bench --json-only` exited with code {code}")
        return json.loads(Path(tmp).read_text())
    finally:
        os.unlink(tmp)


def parse_sizes(text: str) -> list[str]:
    """``--sizes``: known names or element sizes in mm, each at most once (one result per size); else a
    ConfigError."""
    sizes = [x.strip() for x in text.split(",") if x.strip()]
    bad = [x for x in sizes if x not in SIZES and _element_size(x) is None]
    if bad or not sizes:
        raise config.ConfigError("--sizes", f"{','.join(bad) or '(none)'}; allowed: " + ", ".join(SIZES)
                                 + " or an element size in mm (> 0)")
    twice = sorted({x for x in sizes if sizes.count(x) > 1})
    if twice:
        raise config.ConfigError("--sizes", f"{','.join(twice)} given more than once; allowed: each of "
                                 + ", ".join(SIZES) + " at most once")
    return sizes


def parse_ranks(text: str | None, comm) -> list[int] | None:
    """``--ranks``: positive rank counts to launch under mpirun (not from inside mpirun); None: this job."""
    if not text:
        return None
    try:
        ranks = [int(x) for x in text.split(",")]
    except ValueError:
        ranks = [0]
    if any(k < 1 for k in ranks):
        raise config.ConfigError("--ranks", f"= {text}; allowed: positive integers, e.g. 1,2")
    if comm.size > 1:
        raise config.ConfigError("--ranks", "launches mpirun itself: run `hydrobuckle bench --ranks ...` "
                                 "without mpirun")
    return ranks


def check(sizes: list[str], overrides: list[str], outdir, comm) -> None:
    """The pre-flight of every size's config (app.workflows.preflight), then the directory claimed."""
    size_cfgs = [size_config(name, overrides) for name in sizes]
    for cfg, name in zip(size_cfgs, sizes):
        preflight.mesh_size(cfg, False, f"bench size {name}")
    preflight.check(size_cfgs, comm, outdir, sizes=False)


def command(sizes: list[str], ranks: list[int] | None, overrides: list[str], outdir: Path, comm,
            json_only: str | None = None, baseline: bool = False, only: str | None = None,
            error_estimate: bool = False) -> str | None:
    """``hydrobuckle bench``: run (or launch per rank count) every size and write bench.json and bench.md;
    returns the table (rank 0; '' elsewhere and for a ``--json-only`` launch), or None when interrupted (no
    bench.json: timings of a part of a run are no benchmark). A stale bench.json/bench.md goes first: a
    directory holds them only once a bench has ended. Raises BenchFailed and ResultWriteError."""
    def clear():
        for name in ("bench.json", "bench.md"):
            (outdir / name).unlink(missing_ok=True)

    with interrupt.Watch(comm):  # a signal between two sizes is recorded too: no further size starts
        if not json_only:
            writes.on_rank0(comm, outdir, clear)
        if ranks:
            by_ranks = launch_ranks(ranks, sizes, overrides, outdir, baseline, error_estimate)
            doc = None if by_ranks is None else report(by_ranks)
        else:
            result = run_bench(sizes, overrides, outdir, comm, baseline, only, error_estimate)
            if result is not None and json_only:  # a launch of `bench --ranks`: for the launching process
                path = Path(json_only)
                writes.on_rank0(comm, path, writes.write_text, path, writes.json_text(result, exact=True))
                return ""
            doc = None if result is None else report({comm.size: result})
    if doc is None:
        logging_setup.get().info(f"bench: interrupted: no bench.json written in {outdir}; rerun the command")
        return None
    text = table(doc) if comm.rank == 0 else ""  # the per-rank memory is gathered on rank 0 only

    def files():
        writes.at(outdir, outdir.mkdir, parents=True, exist_ok=True)
        writes.at(outdir / "bench.json", writes.write_json, outdir / "bench.json", doc)
        writes.at(outdir / "bench.md", writes.write_text, outdir / "bench.md", text + "\n")

    writes.on_rank0(comm, outdir, files)  # every rank may read bench.json once the command returns
    return text
