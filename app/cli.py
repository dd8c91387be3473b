"""Command line: parsing, printing, exit codes; what a command does is in app.workflows.

Exit codes: 0 success, 1 solver failure (summary.json says "failed", history kept),
2 bad input (one line naming the key and the allowed range; no result directory is created; a checkpoint
that ``run --resume`` cannot continue: its directory is left as it was), or a result file that cannot
be written (one line naming it; what was written, and the last checkpoint, are kept),
130 / 143 interrupted by SIGINT / SIGTERM (summary.json says "interrupted", history kept).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app import config

EXIT_OK, EXIT_SOLVER, EXIT_INPUT = 0, 1, 2
SIZE_LIMIT = "the size limit (5,000,000 cells)"


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own usage errors also exit 2, with one line
        self.print_usage(sys.stderr)
        print(f"hydrobuckle: error: {message}", file=sys.stderr)
        raise SystemExit(EXIT_INPUT)


def _add(sub, name: str, help: str, config_arg: bool = True, output: str | None = None, quiet: bool = True,
         **output_kw):
    """A subcommand with the usual arguments: the config file, --set, -o/--output (``output``: its help), -q."""
    p = sub.add_parser(name, help=help)
    if config_arg:
        p.add_argument("config", help="TOML config file (keys: see README)")
    if output is not None:
        p.add_argument("-o", "--output", help=output, **output_kw)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config key, e.g. --set material.film.modulus_ratio=20")
    if quiet:
        p.add_argument("-q", "--quiet", action="store_true", help="no per-step progress lines")
    return p


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="hydrobuckle", description="Swelling-induced wrinkling of constrained hydrogels.")
    sub = p.add_subparsers(dest="command", required=True)
    run = _add(sub, "run", "run a simulation from a TOML config", output="result directory (default "
               "results/<config name>)")
    run.add_argument("--force", action="store_true", help=f"run a mesh above {SIZE_LIMIT}")
    run.add_argument("--resume", metavar="DIR", help="continue the run in result directory DIR from its last "
                     "checkpoint (output.checkpoint_every); any number of ranks")
    val = _add(sub, "validate", "check a config, print its mesh size estimate and the config resolved", quiet=False)
    val.add_argument("--force", action="store_true", help=f"accept a mesh above {SIZE_LIMIT}")
    sub.add_parser("version", help="print hydrobuckle, dolfinx, PETSc, SLEPc and gmsh versions")
    sub.add_parser("warmup", help="compile the built-in problems' forms now, so the first run starts at once")
    _add(sub, "mesh", "build a config's geometry and write it as a gmsh .msh file", output="the .msh file to write",
         quiet=False, required=True)
    st = _add(sub, "study", "run one of the paper's parameter studies (--list shows them)", config_arg=False,
              output="study directory (default results/<study name>)")
    st.add_argument("name", nargs="?", help="study name")
    st.add_argument("--list", action="store_true", help="list the studies and exit")
    st.add_argument("--values", help="comma-separated values replacing the study's defaults")
    sw = _add(sub, "sweep", "sweep one config key over values", output="study directory (default "
              "results/<config name>-sweep)")
    sw.add_argument("--param", required=True, help="dotted config key, e.g. material.film.modulus_ratio")
    sw.add_argument("--values", required=True, help="comma-separated values")
    for s in (st, sw):
        s.add_argument("--ranks-per-case", type=int, default=1, help="MPI ranks per case (cases run side by side)")
        s.add_argument("--force", action="store_true", help="rerun cases that are already complete")
        s.add_argument("--error-estimate", action="store_true",
                       help="estimate each case's discretization error (two coarsened companion runs per case)")
        s.add_argument("--isomodes", action=argparse.BooleanOptionalAction, default=None,
                       help="continue past the onset and record later crossings (isomode curves)")
        s.add_argument("--reduced", action="store_true",
                       help="every case by the exact 1D reduction (bilayer and circular tube; seconds per case, "
                            "one rank per case; default directory results/<name>-reduced)")
    be = _add(sub, "bench", "time the default bilayer to onset at three mesh sizes", config_arg=False,
              output="directory for bench.json and the runs", default="results/bench")
    be.add_argument("--sizes", default="coarse,default,fine", help="comma-separated: coarse, default, fine, finer")
    be.add_argument("--ranks", help="comma-separated rank counts to launch under mpirun, e.g. 1,2")
    be.add_argument("--json-only", help=argparse.SUPPRESS)
    conv = _add(sub, "converge", "time-step and mesh refinement study of g_c (Richardson estimate)",
                output="study directory (default results/<config name>-converge)")
    conv.add_argument("--levels", type=int, default=3, help="refinement levels per study (2..6, default 3)")
    conv.add_argument("--only", choices=["time", "mesh"], help="run only one of the two studies")
    conv.add_argument("--coarsen", action="store_true",
                      help="levels coarser than the config (cheap error estimate of the config itself)")
    conv.add_argument("--force", action="store_true", help="run every level anew (a rerun otherwise keeps the "
                      "levels an earlier converge finished and resumes an interrupted one from its checkpoint)")
    _add(sub, "reduced", "the exact 1D reduction of a bilayer or circular-tube config: g_c, N_c and the margin "
         "curve in seconds (docs/reduction.md)", output="result directory (default results/<config name>-reduced)")
    for command in (st, sw, conv, be):  # refused with a line that says how these commands continue
        command.add_argument("--resume", nargs="?", const="", default=None, help=argparse.SUPPRESS)
    return p


def _comm():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def _no_resume(args) -> None:
    """``--resume`` belongs to ``run``: the commands that run several directories say how they continue."""
    if getattr(args, "resume", None) is not None:
        from app.workflows.reruns import HOW_TO_CONTINUE

        raise config.ConfigError("", f"--resume: {HOW_TO_CONTINUE[args.command]}")


def _outdir(args, name: str, suffix: str = "") -> Path:
    """-o/--output, else results/<name><suffix>."""
    return Path(args.output) if args.output else Path("results") / (name + suffix)


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
    if comm.rank == 0:
        print(f"warmup: form cache ready in {seconds:.1f} s")
    return EXIT_OK


def cmd_run(args) -> int:
    from app.workflows import preflight

    comm = _comm()
    cfg = config.load(args.config, args.set)
    preflight.check([cfg], comm, None, force=args.force)
    outdir, resume = _outdir(args, Path(args.config).stem), None
    if args.resume:
        outdir, resume = preflight.resume(args.resume, args.output, cfg, comm)
    preflight.take_output(outdir, comm)
    _start(comm, args)
    from app.workflows.pipeline import run_case

    summary = run_case(cfg, outdir, comm, resume=resume)
    return EXIT_OK if summary["status"] != "failed" else EXIT_SOLVER


def cmd_converge(args) -> int:
    from app import interrupt
    from app.workflows import convergence, preflight

    comm = _comm()
    studies = (args.only,) if args.only else ("time", "mesh")
    _no_resume(args)
    cfg = config.load(args.config, args.set)
    convergence.check(cfg, args.levels, studies, args.coarsen)
    outdir = _outdir(args, Path(args.config).stem, "-converge")
    preflight.check([cfg], comm, outdir, sizes=False)
    _start(comm, args)
    with interrupt.Watch(comm):  # a signal between two levels is recorded too: no further level starts
        report = convergence.converge(cfg, outdir, comm, levels=args.levels, studies=studies,
                                      coarsen=args.coarsen, force=args.force)
    return EXIT_OK if report["base"] else EXIT_SOLVER


def cmd_reduced(args) -> int:
    from app.workflows import preflight, reduced

    comm = _comm()
    cfg = config.load(args.config, args.set)
    outdir = _outdir(args, Path(args.config).stem, "-reduced")
    preflight.check([cfg], comm, outdir, reduced=True, sizes=False, inputs=False)
    _start(comm, args)
    return reduced.command(cfg, outdir, comm)


def cmd_study(args) -> int:
    from app.workflows import studies

    _no_resume(args)
    if args.list or not args.name:
        print(studies.listing())
        if args.list:
            return EXIT_OK
        raise config.ConfigError("study", "needs a name; allowed: " + ", ".join(studies.STUDIES))
    if args.name not in studies.STUDIES:
        raise config.ConfigError("study", f"{args.name!r} is unknown; allowed: " + ", ".join(studies.STUDIES))
    outdir = _outdir(args, args.name, "-reduced" if args.reduced else "")
    values = config.parse_values(args.values) if args.values else None
    spec, cases = studies.study_cases(args.name, outdir, values, args.set, args.error_estimate, args.isomodes)
    return _run_study(studies, outdir, cases, spec.description, spec.param, args)


def cmd_sweep(args) -> int:
    from app.workflows import studies

    outdir = _outdir(args, Path(args.config).stem, "-sweep-reduced" if args.reduced else "-sweep")
    _no_resume(args)
    try:
        cases = studies.sweep_cases(args.config, args.param, config.parse_values(args.values), outdir, args.set,
                                    isomodes=bool(args.isomodes), error_estimate=args.error_estimate)
    except config.ConfigError:
        raise
    except ValueError as err:  # a value the TOML reader or a case's resolution could not take
        raise config.ConfigError("", f"config file '{args.config}': {err}") from None
    title = f"{Path(args.config).stem}: sweep of {args.param}"
    return _run_study(studies, outdir, cases, title, args.param, args)


def _run_study(studies, outdir, cases, title, param, args) -> int:
    """The study's or sweep's cases: the shared pre-flight, then every case; the exit code."""
    from app.workflows import preflight

    comm = _comm()
    preflight.check([c.cfg for c in cases], comm, outdir, [c.label for c in cases], reduced=args.reduced,
                    ranks_per_case=args.ranks_per_case)
    _start(comm, args)
    rows = studies.run_study(cases, outdir, comm, title, param, args.ranks_per_case, args.force,
                             "reduced" if args.reduced else "2d")
    complete, line = studies.outcome(rows, outdir)
    if comm.rank == 0:
        print(f"hydrobuckle: {line}")
    return EXIT_OK if complete else EXIT_SOLVER


def cmd_bench(args) -> int:
    from app import logging_setup
    from app.workflows import bench

    comm, outdir = _comm(), Path(args.output)
    _no_resume(args)
    sizes, ranks = bench.parse_sizes(args.sizes), bench.parse_ranks(args.ranks, comm)
    bench.check(sizes, args.set, args.output, comm)  # the directory named as the user wrote it
    _start(comm, args)
    try:
        text = bench.command(sizes, ranks, args.set, outdir, comm, args.json_only)
    except bench.BenchFailed as err:
        if comm.rank == 0:
            print(f"hydrobuckle: error: {err}", file=sys.stderr)
        return EXIT_SOLVER
    if text is None:  # interrupted (exit 130 / 143: main); timings of a part of a run are no benchmark
        logging_setup.get().info(f"bench: interrupted: no bench.json written in {outdir}; rerun the command")
    elif text and comm.rank == 0:
        print(text)
    return EXIT_OK


def cmd_mesh(args) -> int:
    from app import geometry

    comm = _comm()
    line = geometry.export(config.load(args.config, args.set), Path(args.output), comm)
    if comm.rank == 0:
        print(f"hydrobuckle: {line}")
    return EXIT_OK


COMMANDS = {"run": cmd_run, "validate": cmd_validate, "version": cmd_version, "converge": cmd_converge,
            "mesh": cmd_mesh, "study": cmd_study, "sweep": cmd_sweep, "bench": cmd_bench, "warmup": cmd_warmup,
            "reduced": cmd_reduced}


def main(argv: list[str] | None = None) -> int:
    """The command line's exit code (``argv`` None: the process's own arguments, and the process is
    ended here if an HDF5 file could not be closed, see :func:`app.interrupt.end_process`). Bad input (a
    ConfigError, a checkpoint that cannot be resumed) and a result file that cannot be written end any
    command with one line on rank 0 and exit 2."""
    args = _parser().parse_args(argv)
    from app.io import lock
    from app.io.writes import ResultWriteError

    try:
        code = COMMANDS[args.command](args)
    except (config.ConfigError, ResultWriteError) as err:
        if _comm().rank == 0:
            print(f"hydrobuckle: error: {err}", file=sys.stderr)
        code = EXIT_INPUT
    finally:
        lock.release_all()
    from app import interrupt

    code = interrupt.exit_code() or code  # 130 / 143 after SIGINT / SIGTERM (status "interrupted")
    hdf5 = sys.modules.get("app.io.hdf5")  # not imported: no HDF5 file was written
    if argv is None:
        code = interrupt.leave(code)  # a multi-rank job: the ranks agree on the code, rank 0 ends with it
        if hdf5 is not None and hdf5.has_abandoned():
            interrupt.end_process(interrupt.job_code)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
