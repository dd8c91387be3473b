"""Command line: ``hydrobuckle run|validate|version``.

Exit codes: 0 success, 1 solver failure (summary.json says "failed", history kept),
2 bad input (one line naming the key and the allowed range; no result directory is created; a checkpoint
that ``run --resume`` cannot continue: its directory is left as it was), or a result file that cannot
be written (one line naming it; what was written, and the last checkpoint, are kept),
130 / 143 interrupted by SIGINT / SIGTERM (summary.json says "interrupted", history kept).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app import config

EXIT_OK, EXIT_SOLVER, EXIT_INPUT = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors also exit 2, with one line
        self.print_usage(sys.stderr)
        print(f"hydrobuckle: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_INPUT)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="hydrobuckle", description="Swelling-induced wrinkling of constrained hydrogels.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a simulation from a TOML config")
    run.add_argument("config", help="TOML config file (keys: see README)")
    run.add_argument("-o", "--output", help="result directory (default results/<config name>)")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a config key, e.g. --set material.film.modulus_ratio=20")
    run.add_argument("-q", "--quiet", action="store_true", help="no per-step progress lines")
    run.add_argument("--force", action="store_true", help="run a mesh above the size limit (5,000,000 cells)")
    run.add_argument("--resume", metavar="DIR", help="continue the run in result directory DIR from its last "
                     "checkpoint (output.checkpoint_every); any number of ranks")
    val = sub.add_parser("validate", help="check a config, print its mesh size estimate and the config resolved")
    val.add_argument("config")
    val.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    val.add_argument("--force", action="store_true", help="accept a mesh above the size limit (5,000,000 cells)")
    sub.add_parser("version", help="print hydrobuckle, dolfinx, PETSc, SLEPc and gmsh versions")
    sub.add_parser("warmup", help="compile the built-in problems' forms now, so the first run starts at once")
    msh = sub.add_parser("mesh", help="build a config's geometry and write it as a gmsh .msh file")
    msh.add_argument("config")
    msh.add_argument("-o", "--output", required=True, help="the .msh file to write")
    msh.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    st = sub.add_parser("study", help="run one of the paper's parameter studies (--list shows them)")
    st.add_argument("name", nargs="?", help="study name")
    st.add_argument("--list", action="store_true", help="list the studies and exit")
    _study_options(st)
    sw = sub.add_parser("sweep", help="sweep one config key over values")
    sw.add_argument("config")
    sw.add_argument("--param", required=True, help="dotted config key, e.g. material.film.modulus_ratio")
    sw.add_argument("--values", required=True, help="comma-separated values")
    _study_options(sw)
    be = sub.add_parser("bench", help="time the default bilayer to onset at three mesh sizes")
    be.add_argument("--sizes", default="coarse,default,fine", help="comma-separated: coarse, default, fine, finer")
    be.add_argument("--ranks", help="comma-separated rank counts to launch under mpirun, e.g. 1,2")
    be.add_argument("-o", "--output", default="results/bench", help="directory for bench.json and the runs")
    be.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    be.add_argument("--json-only", help=argparse.SUPPRESS)
    be.add_argument("-q", "--quiet", action="store_true")
    conv = sub.add_parser("converge", help="time-step and mesh refinement study of g_c (Richardson estimate)")
    conv.add_argument("config")
    conv.add_argument("-o", "--output", help="study directory (default results/<config name>-converge)")
    conv.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    conv.add_argument("--levels", type=int, default=3, help="refinement levels per study (2..6, default 3)")
    conv.add_argument("--only", choices=["time", "mesh"], help="run only one of the two studies")
    conv.add_argument("--coarsen", action="store_true",
                      help="levels coarser than the config (cheap error estimate of the config itself)")
    conv.add_argument("--force", action="store_true", help="run every level anew (a rerun otherwise keeps the "
                      "levels an earlier converge finished and resumes an interrupted one from its checkpoint)")
    conv.add_argument("-q", "--quiet", action="store_true")
    red = sub.add_parser("reduced", help="the exact 1D reduction of a bilayer or circular-tube config: g_c, N_c "
                         "and the margin curve in seconds (docs/reduction.md)")
    red.add_argument("config")
    red.add_argument("-o", "--output", help="result directory (default results/<config name>-reduced)")
    red.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    red.add_argument("-q", "--quiet", action="store_true")
    for command in (st, sw, conv, be):  # refused with a line that says how these commands continue
        command.add_argument("--resume", nargs="?", const="", default=None, help=argparse.SUPPRESS)
    return p


RERUN = {
    "study": "study continues by itself: rerun the same command (finished cases are kept, an interrupted case "
             "resumes from its checkpoint; --force runs every case anew)",
    "sweep": "sweep continues by itself: rerun the same command (finished cases are kept, an interrupted case "
             "resumes from its checkpoint; --force runs every case anew)",
    "converge": "converge continues by itself: rerun the same command (finished levels are kept, an interrupted "
                "level resumes from its checkpoint; --force runs every level anew)",
    "bench": "bench cannot be resumed: it times whole runs, and an interrupted bench writes no bench.json; "
             "rerun the same command",
}


def _no_resume(args) -> None:
    """``--resume`` belongs to ``run``: on the commands that run several directories, a ConfigError
    saying how they continue instead."""
    if getattr(args, "resume", None) is not None:
        raise config.ConfigError("", f"--resume: {RERUN[args.command]}")


def _comm():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def _input_error(comm, err: Exception) -> int:
    if comm is None or comm.rank == 0:
        print(f"hydrobuckle: error: {err}", file=sys.stderr)
    return EXIT_INPUT


def _check_geometry(cfgs, comm, labels=None) -> None:
    """Input errors only a geometry's files can show (a user .msh: missing, unreadable, groups the
    config names but the file lacks), as ConfigError before any result directory exists."""
    from app import geometry

    seen = set()
    for i, cfg in enumerate(cfgs):
        key = repr(sorted(cfg["geometry"].items()))
        if key in seen:
            continue
        seen.add(key)
        try:
            geometry.check(cfg, comm)
        except config.ConfigError as err:
            if labels is None:
                raise
            raise config.ConfigError("", f"{err} (case {labels[i]})") from None


def _check_output(path, comm) -> None:
    """The result directory must be creatable (or exist) and be writable: checked on rank 0 before
    anything runs, without creating it; a ConfigError naming the path on every rank otherwise."""
    problem = _output_problem(Path(path)) if comm.rank == 0 else None
    problem = comm.bcast(problem, root=0)
    if problem:
        raise config.ConfigError("", f"result directory '{path}' (-o/--output): {problem}")


def _take_output(path, comm) -> None:
    """The last pre-flight step of a command that writes a result directory: :func:`_check_output`, then
    the directory is claimed for this job (:mod:`app.io.lock`; it is created then): refused if another
    live job holds it, a directory around it or one inside it."""
    from app.io import lock

    _check_output(path, comm)
    lock.claim(path, comm)


def _output_problem(path: Path) -> str | None:
    import tempfile

    try:
        p = path.absolute()
        if p.exists() and not p.is_dir():
            return "exists and is not a directory"
        probe = p
        while not probe.exists():  # the nearest existing ancestor: where the directory would be created
            probe = probe.parent
        if not probe.is_dir():
            return f"'{probe}' is a file, not a directory"
        tempfile.TemporaryDirectory(prefix=".hydrobuckle-probe-", dir=probe).cleanup()
    except OSError as err:
        where = probe if "probe" in locals() else path
        return f"no directory can be created in '{where}' ({err.strerror})"
    return None


def _check_mesh_size(cfg, force: bool, label: str | None = None) -> dict | None:
    """The kind's mesh size estimate (None for a user's file); above the limit a ConfigError naming
    mesh.element_size, unless ``force`` (an absurd element size would hang inside gmsh). ``label``: the
    case of a command that runs several (study, sweep, converge, bench), which have no --force for it."""
    from app import geometry
    from app.geometry.base import MAX_CELLS, size_line

    est = geometry.kind_of(cfg).estimate(cfg)
    if est is not None and est["cells"] > MAX_CELLS and not force:
        way_out = ", or --force" if label is None else " (only 'run' accepts such a mesh, with --force)"
        where = "" if label is None else f" ({label})"
        raise config.ConfigError("mesh.element_size", f"= {cfg['mesh']['element_size']:g}{where} gives an estimated "
                                 f"{size_line(est)}: more than the limit of {MAX_CELLS:,} cells; allowed: a "
                                 f"coarser mesh.element_size (or fewer mesh.film_layers){way_out}")
    return est


def _check_mesh_sizes(cfgs, labels) -> None:
    """The size limit for every case of a multi-run command, before anything runs."""
    for cfg, label in zip(cfgs, labels):
        _check_mesh_size(cfg, False, label)


def cmd_validate(args) -> int:
    try:
        cfg = config.load(args.config, args.set)
        est = _check_mesh_size(cfg, args.force)
    except config.ConfigError as err:  # one line under mpirun too (the printed config: every rank)
        return _input_error(_comm(), err)
    from app.geometry.base import size_line

    if est is not None:  # a TOML comment: the printout stays a loadable config
        print(f"# mesh estimate: {size_line(est)}")
    print(config.dumps(cfg))
    return EXIT_OK


def cmd_version(args) -> int:
    from app.io.output import versions

    for k, v in versions().items():
        print(f"{k} {v}")
    return EXIT_OK


def cmd_warmup(args) -> int:
    from app.workflows.warmup import warmup

    comm = _comm()
    _setup_logging(comm, quiet=True)
    seconds = warmup(comm, log=print if comm.rank == 0 else (lambda _msg: None))
    if comm.rank == 0:
        print(f"warmup: form cache ready in {seconds:.1f} s")
    return EXIT_OK


def cmd_run(args) -> int:
    comm = _comm()
    try:
        cfg = config.load(args.config, args.set)
        _check_mesh_size(cfg, args.force)
        _check_geometry([cfg], comm)
        outdir = Path(args.output) if args.output else Path("results") / Path(args.config).stem
        resume = None
        if args.resume:
            from app.io import checkpoint

            if args.output and Path(args.output).absolute() != Path(args.resume).absolute():
                raise config.ConfigError("", f"--resume '{args.resume}' continues in that directory: leave out "
                                         f"-o/--output '{args.output}'")
            outdir = Path(args.resume)
            from app.io import lock

            if outdir.is_dir():  # a live job's checkpoint is not to be read, nor its directory written
                lock.claim(outdir, comm, "--resume")
            resume = checkpoint.check(outdir, cfg, comm)
        _take_output(outdir, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    _setup_logging(comm, args.quiet)
    from app.io.checkpoint import CheckpointError
    from app.io.writes import ResultWriteError
    from app.workflows.pipeline import run_case

    try:
        summary = run_case(cfg, outdir, comm, resume=resume)
    except (CheckpointError, ResultWriteError) as err:  # a checkpoint that does not fit the rebuilt mesh
        return _input_error(comm, err)                  # (DIR untouched); a result file not written
    return EXIT_OK if summary["status"] != "failed" else EXIT_SOLVER


def cmd_converge(args) -> int:
    comm = _comm()
    try:
        _no_resume(args)
        cfg = config.load(args.config, args.set)
        if not 2 <= args.levels <= 6:
            raise config.ConfigError("--levels", f"= {args.levels} is out of range; allowed: 2..6")
        if not cfg["stability"]["enabled"]:
            raise config.ConfigError("stability.enabled", "must be true for a convergence study of g_c")
        studies = (args.only,) if args.only else ("time", "mesh")
        from app.workflows.convergence import refined_configs

        for study in studies:
            levels = refined_configs(cfg, study, args.levels, 4.0, 2.0, args.coarsen)
            _check_mesh_sizes([c for _, _, c in levels], [f"converge level {label}" for label, _, _ in levels])
        _check_geometry([cfg], comm)
        outdir = Path(args.output) if args.output else Path("results") / (Path(args.config).stem + "-converge")
        _take_output(outdir, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    _setup_logging(comm, args.quiet)
    from app import interrupt
    from app.io.writes import ResultWriteError
    from app.workflows.convergence import converge

    try:
        with interrupt.Watch(comm):  # a signal between two levels is recorded too: no further level starts
            report = converge(cfg, outdir, comm, levels=args.levels, studies=studies, coarsen=args.coarsen,
                              force=args.force)
    except ResultWriteError as err:
        return _input_error(comm, err)
    return EXIT_OK if report["base"] else EXIT_SOLVER


def _study_options(p) -> None:
    p.add_argument("-o", "--output", help="study directory (default results/<study name>)")
    if p.prog.endswith("study"):
        p.add_argument("--values", help="comma-separated values replacing the study's defaults")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a key in every case")
    p.add_argument("--ranks-per-case", type=int, default=1, help="MPI ranks per case (cases run side by side)")
    p.add_argument("--force", action="store_true", help="rerun cases that are already complete")
    p.add_argument("--error-estimate", action="store_true",
                   help="estimate each case's discretization error (two coarsened companion runs per case)")
    p.add_argument("--isomodes", action=argparse.BooleanOptionalAction, default=None,
                   help="continue past the onset and record later crossings (isomode curves)")
    p.add_argument("--reduced", action="store_true",
                   help="every case by the exact 1D reduction (bilayer and circular tube; seconds per case, one "
                        "rank per case; default directory results/<name>-reduced)")
    p.add_argument("-q", "--quiet", action="store_true")


def _check_reducible(cases) -> None:
    from app.reduced.section import reducible

    for c in cases:
        why = reducible(c.cfg)
        if why:
            raise config.ConfigError("--reduced", f"case {c.label}: {why}")


def _parse_values(text: str) -> list:
    out = []
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        _, v = config.parse_override(f"v={item}")
        out.append(v)
    if not out:
        raise config.ConfigError("--values", "needs at least one value, e.g. --values 0.01,0.02")
    return out


def cmd_reduced(args) -> int:
    comm = _comm()
    from app.reduced.section import reducible

    try:
        cfg = config.load(args.config, args.set)
        why = reducible(cfg)
        if why:
            raise config.ConfigError("", why)
        outdir = Path(args.output) if args.output else Path("results") / (Path(args.config).stem + "-reduced")
        _take_output(outdir, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    _setup_logging(comm, args.quiet)
    from app import interrupt, logging_setup
    from app.reduced.solve import Interrupted
    from app.reduced.transient import TransientFailed
    from app.workflows import reduced

    log = logging_setup.get()
    code = EXIT_OK
    with interrupt.Watch(comm):
        if comm.rank == 0:  # a 1D problem: one rank computes, the others wait
            try:
                summary = reduced.run(cfg, outdir, stop=lambda: interrupt._received != 0)
                log.info("hydrobuckle: result: " + reduced.describe(summary["reduced"]) + f" ({outdir}, "
                         f"{summary['reduced']['seconds']:.1f} s)")
            except TransientFailed as err:
                reduced.write_failure(outdir, cfg, str(err))
                log.error(f"hydrobuckle: the 1D transient failed: {err}; summary.json says so")
                code = EXIT_SOLVER
            except Interrupted as err:
                log.error(f"hydrobuckle: interrupted ({err}): {outdir} has no summary.json")
        code = comm.bcast(code, root=0)
        interrupt.pending(comm)  # the exit code of a signal (130 / 143), agreed by every rank
    return code


def cmd_study(args) -> int:
    from app.workflows import studies

    try:
        _no_resume(args)
    except config.ConfigError as err:
        return _input_error(_comm(), err)
    if args.list or not args.name:
        for name, spec in studies.STUDIES.items():
            values = ", ".join(f"{v:g}" for v in spec.values)
            print(f"{name:26s} {spec.description}\n{'':26s} {spec.param} = {values}")
        return EXIT_OK if args.list else _input_error(_comm(), config.ConfigError(
            "study", "needs a name; allowed: " + ", ".join(studies.STUDIES)))
    comm = _comm()
    if args.name not in studies.STUDIES:
        return _input_error(comm, config.ConfigError("study", f"{args.name!r} is unknown; allowed: "
                                                     + ", ".join(studies.STUDIES)))
    outdir = Path(args.output) if args.output else Path("results") / (args.name + ("-reduced" if args.reduced else ""))
    try:
        values = _parse_values(args.values) if args.values else None
        spec, cases = studies.study_cases(args.name, outdir, values, args.set, args.error_estimate, args.isomodes)
        if args.reduced:
            _check_reducible(cases)
        _check_mesh_sizes([c.cfg for c in cases], [f"case {c.label}" for c in cases])
        _check_ranks(args, comm)
        _check_geometry([c.cfg for c in cases], comm, [c.label for c in cases])
        _take_output(outdir, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    _setup_logging(comm, args.quiet)
    return _run_study(studies, comm, outdir, cases, spec.description, spec.param, args)


def _run_study(studies, comm, outdir, cases, title, param, args) -> int:
    from app.io.writes import ResultWriteError

    try:
        rows = studies.run_study(cases, outdir, comm, title, param, args.ranks_per_case, args.force,
                                 "reduced" if args.reduced else "2d")
    except ResultWriteError as err:
        return _input_error(comm, err)
    return _study_exit(rows, outdir, comm)


def cmd_sweep(args) -> int:
    from app.workflows import studies

    comm = _comm()
    outdir = Path(args.output) if args.output else Path("results") / (
        Path(args.config).stem + ("-sweep-reduced" if args.reduced else "-sweep"))
    try:
        _no_resume(args)
        values = _parse_values(args.values)
        if not Path(args.config).is_file():
            raise config.ConfigError("", f"config file '{args.config}' does not exist")
        import tomllib

        user = tomllib.loads(Path(args.config).read_text())
        config.set_dotted(config.defaults(), args.param, values[0])  # the key must exist
        cases = studies.build_cases(user, args.param, values, outdir, args.set, isomodes=bool(args.isomodes),
                                    error_estimate=args.error_estimate)
        if args.reduced:
            _check_reducible(cases)
        _check_mesh_sizes([c.cfg for c in cases], [f"case {c.label}" for c in cases])
        _check_ranks(args, comm)
        _check_geometry([c.cfg for c in cases], comm, [c.label for c in cases])
        _take_output(outdir, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    except ValueError as err:
        return _input_error(comm, config.ConfigError("", f"config file '{args.config}': {err}"))
    _setup_logging(comm, args.quiet)
    title = f"{Path(args.config).stem}: sweep of {args.param}"
    return _run_study(studies, comm, outdir, cases, title, args.param, args)


def _check_ranks(args, comm) -> None:
    if not 1 <= args.ranks_per_case <= comm.size:
        raise config.ConfigError("--ranks-per-case", f"= {args.ranks_per_case} is out of range; "
                                 f"allowed: 1..{comm.size} (the number of MPI ranks)")


def _study_exit(rows, outdir, comm) -> int:
    from app.workflows import studies

    if comm.rank == 0:
        done = sum(r["status"] in studies.COMPLETE for r in rows)
        files = [f for f in ("study.csv", "study.png", "modes.png", "isomodes.png") if (outdir / f).is_file()]
        print(f"hydrobuckle: study {outdir}: {done}/{len(rows)} cases complete; {', '.join(files)}")
    return EXIT_OK if all(r["status"] in studies.COMPLETE for r in rows) else EXIT_SOLVER


def cmd_bench(args) -> int:
    from app.workflows import bench

    comm = _comm()
    try:
        _no_resume(args)
        sizes = [x.strip() for x in args.sizes.split(",") if x.strip()]
        bad = [x for x in sizes if x not in bench.SIZES]
        if bad or not sizes:
            raise config.ConfigError("--sizes", f"{','.join(bad) or '(none)'}; allowed: " + ", ".join(bench.SIZES))
        twice = sorted({x for x in sizes if sizes.count(x) > 1})
        if twice:  # one result per size: a repeated size would overwrite the other
            raise config.ConfigError("--sizes", f"{','.join(twice)} given more than once; allowed: each of "
                                     + ", ".join(bench.SIZES) + " at most once")
        ranks = None
        if args.ranks:
            try:
                ranks = [int(x) for x in args.ranks.split(",")]
            except ValueError:
                ranks = [0]
            if any(k < 1 for k in ranks):
                raise config.ConfigError("--ranks", f"= {args.ranks}; allowed: positive integers, e.g. 1,2")
            if comm.size > 1:
                raise config.ConfigError("--ranks", "launches mpirun itself: run `hydrobuckle bench --ranks ...` "
                                         "without mpirun")
        size_cfgs = [bench.size_config(name, args.set) for name in sizes]
        _check_mesh_sizes(size_cfgs, [f"bench size {name}" for name in sizes])
        _check_geometry(size_cfgs, comm)
        _take_output(args.output, comm)
    except config.ConfigError as err:
        return _input_error(comm, err)
    _setup_logging(comm, args.quiet)
    from app import interrupt, logging_setup
    from app.io import writes

    outdir = Path(args.output)
    try:
        with interrupt.Watch(comm):  # a signal between two sizes is recorded too: no further size starts
            doc = _bench(bench, args, sizes, ranks, outdir, comm)
    except writes.ResultWriteError as err:
        return _input_error(comm, err)
    except bench.BenchFailed as err:
        if comm.rank == 0:
            print(f"hydrobuckle: error: {err}", file=sys.stderr)
        return EXIT_SOLVER
    if doc is None:  # interrupted (exit 130 / 143: main); timings of a part of a run are no benchmark
        logging_setup.get().info(f"bench: interrupted: no bench.json written in {outdir}; rerun the command")
        return EXIT_OK
    if args.json_only:
        return EXIT_OK
    text = bench.table(doc) if comm.rank == 0 else ""  # the per-rank memory is gathered on rank 0 only

    def files():
        writes.at(outdir, outdir.mkdir, parents=True, exist_ok=True)
        for name, content in (("bench.json", json.dumps(doc, indent=2)), ("bench.md", text)):
            writes.at(outdir / name, writes.write_text, outdir / name, content + "\n")

    try:
        writes.on_rank0(comm, outdir, files)  # every rank may read bench.json once the command returns
    except writes.ResultWriteError as err:
        return _input_error(comm, err)
    if comm.rank == 0:
        print(text)
    return EXIT_OK


def _bench(bench, args, sizes, ranks, outdir, comm) -> dict | None:
    """bench.json's content (with --json-only: the result, written to that file), or None if
    interrupted. A stale bench.json/bench.md goes first: a directory holds them only once a bench has
    ended."""
    from app.io import writes

    def clear():
        for name in ("bench.json", "bench.md"):
            (outdir / name).unlink(missing_ok=True)

    if not args.json_only:
        writes.on_rank0(comm, outdir, clear)
    if ranks:
        by_ranks = bench.launch_ranks(ranks, sizes, args.set, outdir)
        return None if by_ranks is None else bench.report(by_ranks)
    result = bench.run_bench(sizes, args.set, outdir, comm)
    if result is not None and args.json_only:  # a launch of `bench --ranks`: for the launching process
        path = Path(args.json_only)
        writes.on_rank0(comm, path, writes.write_text, path, json.dumps(result))
        return result
    return None if result is None else bench.report({comm.size: result})


def cmd_mesh(args) -> int:
    comm = _comm()
    try:
        cfg = config.load(args.config, args.set)
        from app import geometry

        kind = geometry.kind_of(cfg)
        if not kind.exportable:
            able = [k.name for k in geometry.KINDS if k.exportable]
            raise config.ConfigError("geometry.kind", f"{kind.name!r} {kind.not_exportable_because}; allowed here: "
                                     + ", ".join(able))
        out = Path(args.output)
        if comm.rank == 0:
            out.parent.mkdir(parents=True, exist_ok=True)
        setup = kind.build(cfg, comm, msh_path=str(out))
    except config.ConfigError as err:
        return _input_error(comm, err)
    if comm.rank == 0:
        tm = setup.tm
        print(f"hydrobuckle: wrote {out}: cell groups {sorted(tm.cell_names)}, facet groups "
              f"{sorted(tm.facet_names)}; {tm.info}")
    return EXIT_OK


def _setup_logging(comm, quiet: bool) -> None:
    import logging

    from app import logging_setup

    logging_setup.setup(comm, logging.WARNING if quiet else logging.INFO)


COMMANDS = {"run": cmd_run, "validate": cmd_validate, "version": cmd_version, "converge": cmd_converge,
            "mesh": cmd_mesh, "study": cmd_study, "sweep": cmd_sweep, "bench": cmd_bench, "warmup": cmd_warmup,
            "reduced": cmd_reduced}


def main(argv: list[str] | None = None) -> int:
    """The command line's exit code (``argv`` None: the process's own arguments, and the process is
    ended here if an HDF5 file could not be closed, see :func:`app.compat.end_process`)."""
    args = _parser().parse_args(argv)
    from app.io import lock

    try:
        code = COMMANDS[args.command](args)
    finally:
        lock.release_all()
    from app import interrupt

    code = interrupt.exit_code() or code  # 130 / 143 after SIGINT / SIGTERM (status "interrupted")
    compat = sys.modules.get("app.compat")  # not imported: no HDF5 file was written
    if argv is None:
        code = interrupt.leave(code)  # a multi-rank job: the ranks agree on the code, rank 0 ends with it
        if compat is not None and compat.has_abandoned():
            compat.end_process(interrupt.job_code)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
