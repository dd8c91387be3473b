"""What ``hydrobuckle bench`` reports of its measurements: bench.json's content (the speedups from 1 rank,
the ratios against the baseline settings, how time per step and t_factor scale with the dofs) and bench.md's
table. The measuring and the launches are :mod:`app.workflows.bench`.
"""

from __future__ import annotations

import math
import os

#: ``--baseline``: the overrides that restore the settings before the performance work (a factorization every
#: Newton iteration, the elementary step controller); they come after the user's --set, so a baseline run is the
#: baseline whatever is set
BASELINE = ["solver.reuse=false", "time.controller=elementary"]


def fits(results: dict) -> dict:
    runs = results.values()
    return {"time_per_step_vs_dofs_exponent": _loglog_fit([(r["dofs"], r["time_per_step_s"]) for r in runs]),
            "t_factor_vs_dofs_exponent": _loglog_fit([(r["dofs"], r["t_factor_s"]) for r in runs])}


def _loglog_fit(points) -> float | None:
    pts = [(math.log(d), math.log(t)) for d, t in points if d and t]
    if len(pts) < 2:
        return None
    n = len(pts)
    mx = sum(p[0] for p in pts) / n
    my = sum(p[1] for p in pts) / n
    den = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / den if den else None


def blas_library() -> str:
    """The BLAS library PETSc/MUMPS load (Debian's alternatives link), which sets t_factor."""
    for path in ("/usr/lib/x86_64-linux-gnu/libblas.so.3", "/usr/lib/aarch64-linux-gnu/libblas.so.3"):
        if os.path.exists(path):
            return os.path.realpath(path)
    return "unknown"


def report(by_ranks: dict) -> dict:
    """bench.json content: per rank count and size, the speedups from 1 rank, and with a baseline the ratios
    of each size's baseline run to its current run."""
    ranks = sorted(by_ranks)
    doc = {"blas": blas_library(), "runs": {str(k): by_ranks[k] for k in ranks}}
    doc["speedup"] = _rank_speedups(doc["runs"])
    against = {str(k): {name: against_baseline(run["baseline"]["sizes"][name], r)
                        for name, r in run["sizes"].items()}
               for k, run in by_ranks.items() if "baseline" in run}
    if against:
        doc["against_baseline"] = {"overrides": BASELINE, "runs": against}
    return doc


def against_baseline(base: dict, now: dict) -> dict:
    """One size's current run against its baseline run: speedups (baseline time / current time), both R_step,
    the factorizations of each, and how far g_c and N_c moved."""
    def loop(r):
        return r["wall_time_s"] - r["setup_time_s"]

    g0, g1 = base["g_c_um"], now["g_c_um"]
    return {"speedup_wall": base["wall_time_s"] / now["wall_time_s"], "speedup_loop": loop(base) / loop(now),
            "R_step_baseline": base["R_step"], "R_step": now["R_step"],
            "factorizations_baseline": base["factorizations"], "factorizations": now["factorizations"],
            "g_c_um_baseline": g0, "g_c_um": g1,
            "g_c_relative_change": abs(g1 - g0) / abs(g0) if g0 and g1 is not None else None,
            "N_c_baseline": base["N_c"], "N_c": now["N_c"],
            **({"error_estimate_speedup": base["error_estimate"]["wall_time_s"] / now["error_estimate"]["wall_time_s"]}
               if "error_estimate" in base and "error_estimate" in now else {})}


def table(doc: dict) -> str:
    lines = [f"BLAS: {doc.get('blas', 'unknown')}", "",
             "| ranks | size | dofs | steps | Newton it. (factorizations) | wall [s] | setup [s] | per step [s] "
             "| t_factor [s] | R_step | R | R_performed | assembly | factor | solves | stability | eigen | output "
             "| other | RSS/rank [MB] | g_c [um] |",
             "|" + "---|" * 21]
    for k, run in doc["runs"].items():
        for name, r in run["sizes"].items():
            sp = r["per_step_split_s"]
            lines.append(
                f"| {k} | {name} | {r['dofs']} | {r['steps']} | {r['newton_iterations']} ({r['factorizations']}) | "
                f"{r['wall_time_s']:.1f} | {r['setup_time_s']:.1f} | {r['time_per_step_s']:.3f} | "
                f"{r['t_factor_s']:.4f} | {_f(r['R_step'])} | {_f(r['R'])} | {_f(r['R_performed'])} | "
                f"{sp['assembly']:.3f} | "
                f"{sp['factorization']:.3f} | {sp['triangular_solves']:.3f} | {sp['stability_test']:.3f} | "
                f"{sp['eigen_solve']:.3f} | {sp['output']:.3f} | {sp['other'] + sp['newton_other']:.3f} | "
                f"{max(r['peak_rss_mb_per_rank']):.0f} | {_f(r['g_c_um'])} |")
    for k, run in doc["runs"].items():
        lines.append(f"\nranks {k}: time per step ~ dofs^{_f(run['time_per_step_vs_dofs_exponent'])}, "
                     f"t_factor ~ dofs^{_f(run['t_factor_vs_dofs_exponent'])}")
    for k, sp in doc["speedup"].items():
        lines.append(f"speedup 1 -> {k} ranks: " + ", ".join(f"{n} {v:.2f}" for n, v in sp.items()))
    if "against_baseline" in doc:
        lines += ["", "Against the baseline (" + ", ".join(doc["against_baseline"]["overrides"])
                  + "), run just before each current run:", "",
                  "| ranks | size | wall baseline [s] | wall [s] | speedup (wall) | speedup (time loop) "
                  "| R_step baseline | R_step | factorizations baseline | factorizations | g_c baseline [um] "
                  "| g_c [um] | g_c change | N_c baseline | N_c |", "|" + "---|" * 15]
        for k, run in doc["against_baseline"]["runs"].items():
            for name, a in run.items():
                base = doc["runs"][k]["baseline"]["sizes"][name]
                now = doc["runs"][k]["sizes"][name]
                lines.append(f"| {k} | {name} | {base['wall_time_s']:.1f} | {now['wall_time_s']:.1f} | "
                             f"{a['speedup_wall']:.2f} | {a['speedup_loop']:.2f} | {_f(a['R_step_baseline'])} | "
                             f"{_f(a['R_step'])} | {a['factorizations_baseline']} | {a['factorizations']} | "
                             f"{_f(a['g_c_um_baseline'])} | {_f(a['g_c_um'])} | {_e(a['g_c_relative_change'])} | "
                             f"{_f(a['N_c_baseline'])} | {_f(a['N_c'])} |")
        base_speedups = _rank_speedups({k: r["baseline"] for k, r in doc["runs"].items() if "baseline" in r})
        for k, sp in base_speedups.items():
            lines.append(f"baseline speedup 1 -> {k} ranks: " + ", ".join(f"{n} {v:.2f}" for n, v in sp.items()))
    rows = [(k, label, name, r) for k, run in doc["runs"].items()
            for label, sizes in (("baseline", run.get("baseline", {}).get("sizes", {})), ("current", run["sizes"]))
            for name, r in sizes.items() if "error_estimate" in r]
    if rows:
        lines += ["", "Error estimate (companion runs) against its run (baseline: time companion on the run's mesh, "
                  "then the mesh companion; current: time companion on the coarse mesh, side by side on >= 2 ranks):",
                  "", "| ranks | size | settings | run [s] | estimate [s] | estimate / run | time bar [um] "
                  "| mesh bar [um] | total [um] |", "|" + "---|" * 9]
        for k, label, name, r in rows:
            e = r["error_estimate"]
            lines.append(f"| {k} | {name} | {label} | {r['wall_time_s']:.1f} | {e['wall_time_s']:.1f} | "
                         f"{e['ratio_to_run']:.2f} | {_f(e['time_um'])} | {_f(e['mesh_um'])} | {_f(e['total_um'])} |")
    return "\n".join(lines)


def _rank_speedups(runs: dict) -> dict:
    """{k: {size: wall on 1 rank / wall on k ranks}} of ``runs`` ({rank count (str): {"sizes": ...}})."""
    one = runs.get("1")
    if one is None:
        return {}
    return {k: {n: one["sizes"][n]["wall_time_s"] / r["wall_time_s"] for n, r in run["sizes"].items()
                if n in one["sizes"]} for k, run in runs.items() if k != "1"}


def _e(v):
    return "-" if v is None else f"{v:.1e}"


def _f(v):
    return "-" if v is None else f"{v:.3g}"
