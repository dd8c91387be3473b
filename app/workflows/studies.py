"""Parameter studies: the paper's studies by name (``hydrobuckle study``) and any sweep
(``hydrobuckle sweep``), resumable and spread over groups of MPI ranks.

Each case runs in its own subdirectory with the normal run outputs. A case whose directory holds a
summary with status buckled/stable and the same resolved config is complete and is skipped on a
rerun (unless ``force``). Cases are distributed round-robin over groups of ``ranks_per_case`` ranks
(MPI sub-communicators); every case runs exactly as it would alone on that many ranks, so results do
not depend on how the study was launched. Rank 0 of the world then writes study.csv, study.png and
modes.png (and isomodes.png for studies that track later crossings).
"""

from __future__ import annotations

import copy
import csv
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

from app import config, geometry, interrupt, logging_setup
from app.io import writes
from app.io.checkpoint import CheckpointError
from app.io.writes import ResultWriteError
from app.reduced.solve import Interrupted
from app.reduced.transient import TransientFailed
from app.workflows import preflight, progress, reduction
from app.workflows.pipeline import run_case
from app.workflows.reruns import COMPLETE, finished, resumable  # noqa: F401 - COMPLETE: read by the CLI
from app.workflows.variants import variant

ISOMODE_CROSSINGS = 6  # later crossings tracked per case for isomode curves


@dataclass
class StudySpec:
    """A named study: a base config (dotted keys), the swept key, its default values, and series."""

    name: str
    description: str
    base: dict
    param: str
    values: list
    series: dict = field(default_factory=dict)  # label -> extra dotted overrides (e.g. chi values)
    scale_mesh_with_film: bool = True
    isomodes: bool = False
    paper_trend: str = ""
    creases: bool = False  # rows carry the crease onset and both verdicts (stability.creases)


def _bilayer(**kw):
    return {"geometry.kind": "bilayer", "material.preswelling": 1.01, "material.interaction": 0.1,
            "time.end": 10.0, "time.dt_max": 0.05, **kw}


def _tube(**kw):
    return {"geometry.kind": "tube", "material.preswelling": 1.01, "material.interaction": 0.1,
            "geometry.outer_radius": 1.0, "time.end": 10.0, "time.dt_max": 0.05, **kw}


STUDIES = {s.name: s for s in [
    StudySpec("bilayer-film-thickness", "bilayer, gamma_f/gamma_s = 8: g_c and N_c against the film thickness w",
              _bilayer(**{"material.film.modulus_ratio": 8.0}), "geometry.film_thickness",
              [0.005, 0.0075, 0.01, 0.015, 0.02, 0.03, 0.05, 0.1], isomodes=True,
              paper_trend="g_c rises and N_c falls with w; g_c is the envelope of isomodes"),
    StudySpec("bilayer-modulus-ratio", "bilayer, w = 0.01 mm: against gamma_f/gamma_s",
              _bilayer(**{"geometry.film_thickness": 0.01}), "material.film.modulus_ratio",
              [1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 15.0, 20.0, 30.0, 50.0],
              paper_trend="g_c falls, steeply below about 10; N_c first rises, then falls"),
    StudySpec("bilayer-preswelling", "bilayer, w = 0.01 mm, gamma_f/gamma_s = 20: against J0, for chi = 0.1 and 0.8",
              _bilayer(**{"geometry.film_thickness": 0.01, "material.film.modulus_ratio": 20.0}),
              "material.preswelling", [1.01, 1.1, 1.3, 1.5],
              series={"chi=0.1": {"material.interaction": 0.1}, "chi=0.8": {"material.interaction": 0.8}},
              paper_trend="g_c and N_c nearly independent of J0 and chi (g_c within 1 um)"),
    StudySpec("tube-film-thickness", "tube, H = 0.2 mm, gamma_f/gamma_s = 10: against w",
              _tube(**{"geometry.substrate_thickness": 0.2, "material.film.modulus_ratio": 10.0}),
              "geometry.film_thickness", [0.01, 0.02, 0.03, 0.04, 0.05],
              paper_trend="g_c rises and N_c falls with w"),
    StudySpec("tube-substrate-thickness", "tube, w = 0.02 mm, gamma_f/gamma_s = 10: against H",
              _tube(**{"geometry.film_thickness": 0.02, "material.film.modulus_ratio": 10.0}),
              "geometry.substrate_thickness", [0.1, 0.15, 0.2, 0.3, 0.4],
              paper_trend="g_c and N_c fall as H grows"),
    StudySpec("tube-modulus-ratio", "tube, w = 0.02 mm, H = 0.2 mm: against gamma_f/gamma_s",
              _tube(**{"geometry.film_thickness": 0.02, "geometry.substrate_thickness": 0.2}),
              "material.film.modulus_ratio", [1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 50.0],
              paper_trend="g_c falls, steeply below about 20; N_c first rises, then falls"),
    StudySpec("tube-aspect-ratio", "elliptic tube, w = 0.02 mm, gamma_f/gamma_s = 10, passage area of r = 0.78 mm: "
              "g_c,x against a/b", {**_tube(**{"geometry.film_thickness": 0.02, "geometry.substrate_thickness": 0.2,
                                                "material.film.modulus_ratio": 10.0}),
                                     "geometry.kind": "elliptic-tube"},
              "geometry.aspect_ratio", [1.0, 1.1, 1.2, 1.3, 1.4, 1.5],
              paper_trend="g_c,x rises slightly with a/b; wrinkles fade where the substrate is thinner"),
    StudySpec("bilayer-creases", "compressed bilayer (configs/bilayer-creases.toml: film 0.05 on 0.95 mm, fluid "
              "frozen): the crease onset against the wrinkling onset over gamma_f/gamma_s, which comes first by "
              "least energy and by nucleation",
              {"geometry.kind": "bilayer", "geometry.length": 1.0, "geometry.substrate_thickness": 0.95,
               "geometry.film_thickness": 0.05, "mesh.element_size": 0.025, "mesh.film_layers": 4,
               "mesh.substrate_grading": 1.1, "loading.kind": "compression", "loading.compression_strain": 0.6,
               "time.end": 1.0, "time.dt_initial": 0.02, "time.dt_max": 0.02, "stability.creases": True,
               "stability.crease_size": 0.0125, "stability.crease_resolution": 16, "output.fields": False},
              "material.film.modulus_ratio", [1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0], scale_mesh_with_film=False,
              creases=True, paper_trend="not the paper's: the crease falls more slowly with the ratio than the "
              "wrinkle; crossover by least energy near 3.5, by nucleation near 1.55 (docs/creases.md)"),
]}


@dataclass
class Case:
    label: str
    series: str
    value: object
    cfg: dict
    outdir: Path


def _format_value(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def build_cases(base_cfg_user: dict, param: str, values: list, outdir: Path, overrides: list[str],
                series: dict | None = None, scale_mesh_with_film: bool = False, isomodes: bool = False,
                dotted_base: dict | None = None, error_estimate: bool = False) -> list[Case]:
    """Resolve one config per (series, value); bad values fail here, before anything runs."""
    cases = []
    for s_label, s_over in (series or {"": {}}).items():
        for v in values:
            dotted = {**(dotted_base or {}), **s_over, param: v}
            items = [f"{k}={config.toml_value(val)}" for k, val in dotted.items()] + list(overrides)
            try:
                cfg = config.resolve(copy.deepcopy(base_cfg_user), items)
            except config.ConfigError as err:
                raise config.ConfigError("", f"{err} (case {param} = {_format_value(v)})") from None
            changes = {"stability.error_estimate": error_estimate}
            if scale_mesh_with_film and param == "geometry.film_thickness":
                # keep film elements' shape: element length along the film <= f w, f the kind's (bilayer 0.4, tubes 0.5)
                f = geometry.kind_of(cfg["geometry"]["kind"]).film_element_fraction
                if f is not None:
                    changes["mesh.element_size"] = min(cfg["mesh"]["element_size"], f * v)
            if isomodes:
                changes["stability.stop_at_onset"] = False
                changes["stability.max_crossings"] = min(cfg["stability"]["max_crossings"], ISOMODE_CROSSINGS)
            cfg = variant(cfg, changes)
            label = (f"{s_label}_" if s_label else "") + f"{param.split('.')[-1]}={_format_value(v)}"
            cases.append(Case(label, s_label, v, cfg, outdir / label))
    return cases


def is_complete(case: Case, solver: str = "2d") -> bool:
    return finished(case.cfg, case.outdir, solver) is not None


def run_cases(cases: list[Case], comm, ranks_per_case: int = 1, force: bool = False, solver: str = "2d") -> None:
    """Run every case (skipping complete ones) on groups of ``ranks_per_case`` ranks (``solver`` "reduced":
    each case's exact 1D reduction, one rank per case). A case with a
    checkpoint of its config (an interrupted or killed case) continues from it, unless ``force`` (every
    case anew). After SIGINT/SIGTERM each group stops once its current case has stopped: the cases
    it has not started are left without a directory. A result file that cannot be written (a full
    disk) stops its group the same way, and then every rank raises that
    :class:`~app.io.writes.ResultWriteError` (the first group's, in rank order)."""
    log = logging_setup.get()
    k = 1 if solver == "reduced" else max(1, min(ranks_per_case, comm.size))
    n_groups = comm.size // k
    color = comm.rank // k if comm.rank < n_groups * k else n_groups  # leftover ranks idle
    sub = comm.Split(color, comm.rank)
    watch = interrupt.Watch(sub).__enter__()  # a signal between cases is recorded too
    write_error = None
    # shown by world rank 0 only (the one rank that logs): its group's cases time the estimate
    bar = progress.Cases("study", len(cases), n_groups, lambda: sum(is_complete(c, solver) for c in cases), log,
                         comm.rank == 0)
    if comm.rank == 0:
        done = bar.done()
        log.info(f"study: {len(cases)} cases on {n_groups} group(s) of {k} rank(s)"
                 + (f"; {done} complete already" if done and not force else ""))
    try:
        for i, case in enumerate(cases):
            if color >= n_groups or i % n_groups != color:
                continue
            if interrupt.pending(sub):  # collective in the group
                if sub.rank == 0:
                    log.info(f"study: interrupted: {case.label} and the group's later cases not started")
                break
            if not force and is_complete(case, solver):
                if sub.rank == 0:
                    log.info(f"study: {case.label}: complete, skipped")
                continue
            if solver == "reduced":
                t0 = time.perf_counter()
                _run_reduced(case, log)
                log.info(f"study: {case.label}: 1D reduction done in {time.perf_counter() - t0:.1f} s")
                bar.finished(time.perf_counter() - t0)
                continue
            resume = None if force else _checkpoint(case, sub, log)
            if sub.rank == 0:
                how = f"resuming at step {resume.meta['step']}" if resume else "running"
                log.info(f"study: {case.label}: {how} on {sub.size} rank(s)")
            t0 = time.perf_counter()
            try:
                with bar.case(case.label, case.cfg["time"]["end"]) as monitor:
                    try:
                        run_case(case.cfg, case.outdir, sub, progress=False, resume=resume, monitor=monitor)
                    except CheckpointError as err:  # the checkpoint does not fit the rebuilt mesh: start anew
                        if sub.rank == 0:
                            log.info(f"study: {case.label}: {err}; running from the start")
                        run_case(case.cfg, case.outdir, sub, progress=False, monitor=monitor)
            except ResultWriteError as err:  # agreed in the group: no further case can be written either
                write_error = (err.path, err.reason)
                if sub.rank == 0:
                    log.info(f"study: {case.label}: {err}; the group's later cases not started")
                break
            except Exception as err:  # a failed case is reported, the others go on
                if sub.rank == 0:
                    log.info(f"study: {case.label}: failed: {err}")
                    try:
                        case.outdir.mkdir(parents=True, exist_ok=True)
                        (case.outdir / "error.txt").write_text(f"{type(err).__name__}: {err}\n")
                    except OSError:
                        pass
            if sub.rank == 0:
                log.info(f"study: {case.label}: done in {time.perf_counter() - t0:.1f} s")
            bar.finished(time.perf_counter() - t0)
    finally:
        try:  # still watching: a rank whose group is done (or an idle rank) is stopped by a signal, not killed
            errors = comm.allgather(write_error)  # also the barrier that keeps the groups in step
            interrupt.pending(comm)  # a signal any group saw is the whole study's (its exit code)
        finally:
            watch.__exit__()
            sub.Free()
    first = next((e for e in errors if e), None)
    if first is not None:
        raise ResultWriteError(*first)


def _run_reduced(case: Case, log) -> None:
    """One case's exact 1D reduction into its directory (summary.json last); a transient that fails leaves
    error.txt and a failed summary, the other cases go on."""
    try:
        reduction.run(case.cfg, case.outdir, stop=lambda: interrupt._received != 0)
    except Interrupted:
        log.info(f"study: {case.label}: interrupted (no summary.json)")
    except TransientFailed as err:
        log.info(f"study: {case.label}: the 1D transient failed: {err}")
        reduction.write_failure(case.outdir, case.cfg, str(err))
        (case.outdir / "error.txt").write_text(f"TransientFailed: {err}\n")


def _checkpoint(case: Case, comm, log):
    """The case directory's checkpoint if its config may resume it (else None, with the reason logged)."""
    return resumable(case.cfg, case.outdir, comm, log, f"study: {case.label}")


COLUMNS = ("series", "parameter", "value", "status", "g_c_um", "g_c_error_um", "N_c", "t_c", "mu_c",
           "crossings", "wall_time_s", "directory", "solver", "onset", "end_time", "end_energy", "end_pattern",
           "strain_c", "t_reduced", "crease_t", "crease_t_error", "crease_strain", "crease_strain_error",
           "crease_depth_mm", "film_crease_t", "film_crease_t_error", "first_least_energy", "first_nucleation")
CREASE_COLUMNS = COLUMNS[COLUMNS.index("strain_c"):]


def collect(cases: list[Case], param: str) -> list[dict]:
    rows = []
    for case in cases:
        row = {"series": case.series, "parameter": param, "value": case.value, "status": "missing",
               "g_c_um": None, "g_c_error_um": None, "N_c": None, "t_c": None, "mu_c": None, "crossings": "",
               "wall_time_s": None, "directory": case.outdir.name, "solver": "2d", "onset": None,
               "end_time": None, "end_energy": None, "end_pattern": None,  # a followed branch's end
               **dict.fromkeys(CREASE_COLUMNS)}
        f = case.outdir / "summary.json"
        if f.is_file() and json.loads(f.read_text()).get("solver") == "reduced-1d":
            row.update(_reduced_row(json.loads(f.read_text())))
        elif f.is_file():
            s = json.loads(f.read_text())
            crit = s.get("critical") or {}
            est = crit.get("discretization_error") or {}
            crossings = s.get("crossings") or ([crit] if crit else [])
            row.update(status=s["status"], g_c_um=crit.get("growth_um"), g_c_error_um=est.get("total_um"),
                       N_c=crit.get("wrinkle_count"), t_c=crit.get("time"), mu_c=crit.get("mu_bar"),
                       crossings=";".join(f"{c['first_mode_wrinkle_count']:g}@{c['growth_um']:.5g}"
                                          for c in crossings),
                       wall_time_s=s.get("wall_time_s"), onset="wrinkles" if crit else None)
            end = (s.get("postbuckling") or {}).get("end") or {}
            row.update(end_time=end.get("time"), end_energy=end.get("grand_potential"), end_pattern=end.get("pattern"))
            row.update(_crease_cells(s))
        elif (case.outdir / "error.txt").is_file():
            row["status"] = "failed"
        rows.append(row)
    return rows


def _crease_cells(s: dict) -> dict:
    """A 2D case's crease columns (stability.creases): the onset, its depth on the finest level, the film's own
    onset, both verdicts; beside them the wrinkling onset's applied strain and the 1D reduction's onset time."""
    crit, cr = s.get("critical") or {}, s.get("creases") or {}
    onset = cr.get("onset") or {}
    own = (cr.get("film_onset") or {}).get("onset") or {}
    first = cr.get("first") if isinstance(cr.get("first"), dict) else {"least_energy": cr.get("first")}
    depth = next((lv.get("depth_mm") for lv in reversed(cr.get("levels", [])) if lv.get("depth_mm")), None)
    return {"strain_c": crit.get("applied_strain"), "t_reduced": (s.get("reduced") or {}).get("time"),
            "crease_t": onset.get("time"), "crease_t_error": onset.get("time_error"),
            "crease_strain": onset.get("applied_strain"), "crease_strain_error": onset.get("applied_strain_error"),
            "crease_depth_mm": depth, "film_crease_t": own.get("time"), "film_crease_t_error": own.get("time_error"),
            "first_least_energy": first.get("least_energy"), "first_nucleation": first.get("nucleation")}


def crossovers(rows: list[dict]) -> dict:
    """Where, between two rows of a crease study, the verdict changes: the parameter at which the crease's
    onset (least energy: the run's; nucleation: the film's own) equals the wrinkling onset, by linear
    interpolation of their difference in time between the two rows (None where no sign changes)."""
    out = {}
    for name, column in (("least_energy", "crease_t"), ("nucleation", "film_crease_t")):
        pts = [(float(r["value"]), float(r[column]) - float(r["t_c"])) for r in rows
               if r.get(column) not in (None, "") and r.get("t_c") not in (None, "") and not r.get("series")]
        out[name] = next(((a + (b - a) * fa / (fa - fb)) for (a, fa), (b, fb) in zip(pts, pts[1:])
                          if fa < 0 <= fb), None)
    return out


def _reduced_row(s: dict) -> dict:
    """A study row from a reduced case's summary: its onset ("wrinkles", or "surface": the permeable surface
    unstable at short waves, no N_c) and, as crossings, the earliest mode crossings of its margin curve."""
    red = s.get("reduced") or {}
    return {"status": s["status"], "solver": "reduced-1d", "onset": red.get("kind"), "g_c_um": red.get("growth_um"),
            "g_c_error_um": red.get("growth_error_um"), "N_c": red.get("wrinkle_count"), "t_c": red.get("time"),
            "mu_c": red.get("mu_bar"), "wall_time_s": red.get("seconds"),
            "crossings": ";".join(f"{n:g}@{g:.5g}" for n, g in red.get("isomodes", []))}


def write_tables(rows: list[dict], outdir: Path, title: str, param: str) -> None:
    """Rank 0: study.csv, study.png, modes.png (and isomodes.png), each written aside and renamed; a
    failure names its file (a :class:`~app.io.writes.ResultWriteError`)."""
    from app.io.plots import isomode_plot, modes_gallery, numeric, study_plot

    writes.at(outdir, outdir.mkdir, parents=True, exist_ok=True)

    def table(tmp):
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            for r in rows:
                w.writerow({k: ("" if r[k] is None else r[k]) for k in COLUMNS})

    files = {"study.csv": table, "study.png": lambda tmp: study_plot(rows, title, param, tmp),
             "modes.png": lambda tmp: modes_gallery(rows, outdir, title, tmp)}
    if any(r["crossings"] and ";" in r["crossings"] for r in rows) and numeric(rows):
        files["isomodes.png"] = lambda tmp: isomode_plot(rows, title, param, tmp)
    for name, write in files.items():
        writes.at(outdir / name, writes.replace_file, outdir / name, write)


def run_study(cases: list[Case], outdir: Path, comm, title: str, param: str, ranks_per_case: int = 1,
              force: bool = False, solver: str = "2d") -> list[dict]:
    run_cases(cases, comm, ranks_per_case, force, solver)
    rows = collect(cases, param) if comm.rank == 0 else None

    def tables():
        write_tables(rows, outdir, title, param)
        doc = {"title": title, "parameter": param, "rows": rows}
        writes.at(outdir / "study.json", writes.write_json, outdir / "study.json", doc)

    writes.on_rank0(comm, outdir, tables)
    return comm.bcast(rows, root=0)


def outcome(rows: list[dict], outdir: Path) -> tuple[bool, str]:
    """Whether every case of a study is complete, and the line that says how many and which files it wrote."""
    done = sum(r["status"] in COMPLETE for r in rows)
    files = [f for f in ("study.csv", "study.png", "modes.png", "isomodes.png") if (Path(outdir) / f).is_file()]
    return done == len(rows), f"study {outdir}: {done}/{len(rows)} cases complete; {', '.join(files)}"


def listing() -> str:
    """``study --list``: each study's name, description, key and default values."""
    return "\n".join(f"{name:26s} {spec.description}\n{'':26s} {spec.param} = "
                     + ", ".join(f"{v:g}" for v in spec.values) for name, spec in STUDIES.items())


def sweep_cases(path, param: str, values_text: str, outdir: Path, overrides: list[str], isomodes: bool = False,
                error_estimate: bool = False) -> list[Case]:
    """``hydrobuckle sweep``: one case per value (``values_text``, comma-separated) of the dotted key ``param``
    over the config file at ``path`` (its own tables: each case is resolved with the value in place). A value
    the TOML reader or a case's resolution cannot take is a ConfigError naming the file."""
    values = config.parse_values(values_text)
    try:
        user = config.read(path)
        config.set_dotted(config.defaults(), param, values[0])  # the key must exist
        return build_cases(user, param, values, outdir, overrides, isomodes=isomodes, error_estimate=error_estimate)
    except config.ConfigError:
        raise
    except ValueError as err:
        raise config.ConfigError("", f"config file '{path}': {err}") from None


def study_cases(name: str | None, outdir: Path, values_text: str | None, overrides: list[str],
                error_estimate: bool = False, isomodes: bool | None = None) -> tuple[StudySpec, list[Case]]:
    """``hydrobuckle study NAME``: the study's cases (``values_text``: comma-separated values replacing its
    defaults); a missing or unknown name is a ConfigError listing the studies."""
    if name not in STUDIES:
        raise config.ConfigError("study", ("needs a name" if not name else f"{name!r} is unknown")
                                 + "; allowed: " + ", ".join(STUDIES))
    spec = STUDIES[name]
    values = config.parse_values(values_text) if values_text else spec.values
    cases = build_cases({}, spec.param, values, outdir, overrides, series=spec.series,
                        scale_mesh_with_film=spec.scale_mesh_with_film,
                        isomodes=spec.isomodes if isomodes is None else isomodes,
                        dotted_base=spec.base, error_estimate=error_estimate)
    return spec, cases


def command(cases: list[Case], outdir: Path, comm, title: str, param: str, ranks_per_case: int, force: bool,
            reduced: bool, start) -> tuple[bool, str]:
    """``hydrobuckle study`` and ``sweep``: the shared pre-flight of every case, ``start()`` (the command's
    logging), every case, the tables; whether every case is complete and the line saying so."""
    preflight.check([c.cfg for c in cases], comm, outdir, [c.label for c in cases], reduced=reduced,
                    ranks_per_case=ranks_per_case)
    start()
    rows = run_study(cases, outdir, comm, title, param, ranks_per_case, force, "reduced" if reduced else "2d")
    return outcome(rows, outdir)
