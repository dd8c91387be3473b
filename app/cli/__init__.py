"""Command line: printing and exit codes (the arguments: :mod:`app.cli.parser`); what a command does is in
app.workflows.

Exit codes: 0 success, 1 solver failure (summary.json says "failed", history kept),
2 bad input (one line naming the key and the allowed range; no result directory is created; a checkpoint
that ``run --resume`` cannot continue: its directory is left as it was), or a result file that cannot
be written (one line naming it; what was written, and the last checkpoint, are kept),
130 / 143 interrupted by SIGINT / SIGTERM (summary.json says "interrupted", history kept).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from app import config
from app.cli.parser import EXIT_INPUT, parser

EXIT_OK, EXIT_SOLVER = 0, 1


def _comm():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def _outdir(args, name: str, suffix: str = "") -> Path:
    """-o/--output, else results/<name><suffix>."""
    return Path(args.output) if args.output else Path("results") / (name + suffix)


def _say(comm, text: str) -> None:
    if comm.rank == 0:
        print(text)


def _start(comm, args) -> None:
    """Logging of a command that passed its pre-flight (progress lines unless -q)."""
    import logging

    from app import logging_setup

    logging_setup.setup(comm, logging.WARNING if getattr(args, "quiet", True) else logging.INFO)


def cmd_validate(args) -> int:
    from app.geometry.base import size_line
    from app.workflows import preflight

    cfg = config.load(args.config, args.set)
    est = preflight.mesh_size(cfg, args.force)
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
    _start(comm, args)
    seconds = warmup(comm, log=print if comm.rank == 0 else (lambda _msg: None))
    _say(comm, f"warmup: form cache ready in {seconds:.1f} s")
    return EXIT_OK


def _prepare(args, suffix: str | None, own=None, **check):
    """A one-config command's communicator, config and result directory (-o, else results/<config
    name><suffix>; None: chosen by the command), after the command's ``own(cfg)`` checks and the shared
    pre-flight (app.workflows.preflight); the command's logging started."""
    from app.workflows import preflight

    comm, cfg = _comm(), config.load(args.config, args.set)
    if own is not None:
        own(cfg)
    outdir = None if suffix is None else _outdir(args, Path(args.config).stem, suffix)
    preflight.check([cfg], comm, outdir, **check)
    _start(comm, args)
    return comm, cfg, outdir


def cmd_run(args) -> int:
    from app.workflows import preflight
    from app.workflows.pipeline import run_case

    comm, cfg, _ = _prepare(args, None, force=args.force)
    outdir, resume = _outdir(args, Path(args.config).stem), None
    if args.resume:
        outdir, resume = preflight.resume(args.resume, args.output, cfg, comm)
    preflight.take_output(outdir, comm)
    summary = run_case(cfg, outdir, comm, resume=resume)
    return EXIT_OK if summary["status"] != "failed" else EXIT_SOLVER


def cmd_converge(args) -> int:
    from app import interrupt
    from app.workflows import convergence

    studies = (args.only,) if args.only else ("time", "mesh")
    comm, cfg, outdir = _prepare(args, "-converge", lambda cfg: convergence.check(cfg, args.levels, studies,
                                                                                  args.coarsen), sizes=False)
    with interrupt.Watch(comm):  # a signal between two levels is recorded too: no further level starts
        report = convergence.converge(cfg, outdir, comm, levels=args.levels, studies=studies,
                                      coarsen=args.coarsen, force=args.force)
    return EXIT_OK if report["base"] else EXIT_SOLVER


def cmd_reduced(args) -> int:
    from app.workflows import reduction

    if args.crossover:
        comm, cfg, _ = _prepare(args, None, lambda cfg: reduction.crossover_args(cfg, args.crossover), reduced=True,
                                sizes=False, inputs=False)
        key, lo, hi, target = reduction.crossover_args(cfg, args.crossover)
        _say(comm, "hydrobuckle: " + reduction.crossover_command(cfg, key, lo, hi, target, comm))
        return EXIT_OK
    comm, cfg, outdir = _prepare(args, "-reduced", reduced=True, sizes=False, inputs=False)
    return reduction.command(cfg, outdir, comm)


def cmd_study(args) -> int:
    from app.workflows import studies

    if args.tables is not None:
        from app.workflows.study_tables import tables

        if not Path(args.tables).is_dir():
            raise config.ConfigError("", f"study --tables {args.tables}: no such directory; allowed: a directory "
                                     "holding <study>/study.csv (default results)")
        print(tables(Path(args.tables)), end="")
        return EXIT_OK
    if args.list or not args.name:
        print(studies.listing())
        if args.list:
            return EXIT_OK
    outdir = _outdir(args, args.name or "", "-reduced" if args.reduced else "")
    spec, cases = studies.study_cases(args.name, outdir, args.values, args.set, args.error_estimate, args.isomodes)
    return _run_study(studies, outdir, cases, spec.description, spec.param, args)


def cmd_sweep(args) -> int:
    from app.workflows import studies

    outdir = _outdir(args, Path(args.config).stem, "-sweep-reduced" if args.reduced else "-sweep")
    cases = studies.sweep_cases(args.config, args.param, args.values, outdir, args.set,
                                isomodes=bool(args.isomodes), error_estimate=args.error_estimate)
    return _run_study(studies, outdir, cases, f"{Path(args.config).stem}: sweep of {args.param}", args.param, args)


def _run_study(studies, outdir, cases, title, param, args) -> int:
    comm = _comm()
    complete, line = studies.command(cases, outdir, comm, title, param, args.ranks_per_case, args.force,
                                     args.reduced, start=lambda: _start(comm, args))
    _say(comm, f"hydrobuckle: {line}")
    return EXIT_OK if complete else EXIT_SOLVER


def cmd_bench(args) -> int:
    from app.workflows import bench

    comm = _comm()
    if args.factor_one:  # a process of bench --factor: its row as JSON
        from app.workflows.bench_factor import factor_one

        print(json.dumps(factor_one(args.factor_one, args.set, comm)))
        return EXIT_OK
    if args.factor and (args.ranks or args.baseline or args.error_estimate):
        raise config.ConfigError("", "bench --factor times one factorization per size; allowed with it: --sizes, "
                                 "--set, -o (not --ranks, --baseline, --error-estimate)")
    sizes, ranks = bench.parse_sizes(args.sizes), bench.parse_ranks(args.ranks, comm)
    bench.check(sizes, args.set, args.output, comm)  # the directory named as the user wrote it
    _start(comm, args)
    if args.factor:
        from app.workflows import bench_factor

        _say(comm, bench_factor.command(sizes, args.set, Path(args.output), comm))
        return EXIT_OK
    text = bench.command(sizes, ranks, args.set, Path(args.output), comm, args.json_only, args.baseline, args.only,
                         args.error_estimate)
    if text:
        _say(comm, text)
    return EXIT_OK


def cmd_mesh(args) -> int:
    from app import geometry

    comm = _comm()
    line = geometry.export(config.geometry_input(config.load(args.config, args.set)), Path(args.output), comm)
    _say(comm, f"hydrobuckle: {line}")
    return EXIT_OK


COMMANDS = {"run": cmd_run, "validate": cmd_validate, "version": cmd_version, "converge": cmd_converge,
            "mesh": cmd_mesh, "study": cmd_study, "sweep": cmd_sweep, "bench": cmd_bench, "warmup": cmd_warmup,
            "reduced": cmd_reduced}


def main(argv: list[str] | None = None) -> int:
    """The command line's exit code (``argv`` None: the process's own arguments, and the process is
    ended here if an HDF5 file could not be closed, see :func:`app.interrupt.end_process`). Bad input (a
    ConfigError, a checkpoint that cannot be resumed) and a result file that cannot be written end any
    command with one line on rank 0 and exit 2."""
    args = parser().parse_args(argv)
    from app.io import lock
    from app.io.writes import ResultWriteError
    from app.workflows.bench import BenchFailed

    try:
        if args.command != "run":  # the commands that run several directories refuse --resume, saying why
            from app.workflows.reruns import no_resume

            no_resume(args.command, getattr(args, "resume", None))
        code = COMMANDS[args.command](args)
    except (config.ConfigError, ResultWriteError, BenchFailed) as err:
        if _comm().rank == 0:
            print(f"hydrobuckle: error: {err}", file=sys.stderr)
        code = EXIT_SOLVER if isinstance(err, BenchFailed) else EXIT_INPUT
    finally:
        lock.release_all()
    from app import interrupt

    return interrupt.finish(code, process=argv is None)


if __name__ == "__main__":
    raise SystemExit(main())
