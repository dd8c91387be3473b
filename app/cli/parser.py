"""The command line's arguments: each command, its options and their help (``hydrobuckle COMMAND --help``)."""

from __future__ import annotations

import argparse
import sys

EXIT_INPUT = 2  # argparse's usage errors are bad input too
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
        p.add_argument("config", help="TOML config file (keys: docs/reference, or hydrobuckle validate CONFIG)")
    if output is not None:
        p.add_argument("-o", "--output", help=output, **output_kw)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config key, e.g. --set material.film.modulus_ratio=20")
    if quiet:
        p.add_argument("-q", "--quiet", action="store_true", help="no per-step progress lines")
    return p


def parser() -> argparse.ArgumentParser:
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
    st.add_argument("--tables", nargs="?", const="results", metavar="DIR",
                    help="print every study's tables (docs/reproduction.md) from the results under DIR (default "
                         "results: each <study>/study.csv and <study>-reduced/study.csv) and exit")
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
    be = _add(sub, "bench", "time the default bilayer (or, with --set geometry.kind=plate, the 3D plate) to onset "
              "at three mesh sizes", config_arg=False,
              output="directory for bench.json and the runs", default="results/bench")
    be.add_argument("--sizes", default="coarse,default,fine",
                    help="comma-separated: coarse, default, fine, finer, or element sizes in mm (film layers scaled)")
    be.add_argument("--factor", action="store_true",
                    help="instead of timing runs: build each size's problem, factor K once in a process of its own "
                         "and print its dofs, times and peak memory (how large a case the direct solver holds)")
    be.add_argument("--factor-one", help=argparse.SUPPRESS)  # one size of --factor, in its own process
    be.add_argument("--ranks", help="comma-separated rank counts to launch under mpirun, e.g. 1,2")
    be.add_argument("--baseline", action="store_true",
                    help="also run each size with the settings before factor reuse (solver.reuse=false), just "
                         "before the current ones, and print the ratios")
    be.add_argument("--error-estimate", action="store_true",
                    help="also time each size's error estimate (its companion runs) against the run; with "
                         "--baseline the baseline's is the estimate before (time companion on the run's mesh, then "
                         "the mesh companion)")
    be.add_argument("--json-only", help=argparse.SUPPRESS)
    be.add_argument("--only", choices=["baseline", "current"], help=argparse.SUPPRESS)  # a launch of --baseline
    conv = _add(sub, "converge", "time-step and mesh refinement study of g_c (Richardson estimate)",
                output="study directory (default results/<config name>-converge)")
    conv.add_argument("--levels", type=int, default=3, help="refinement levels per study (2..6, default 3)")
    conv.add_argument("--only", choices=["time", "mesh"], help="run only one of the two studies")
    conv.add_argument("--coarsen", action="store_true",
                      help="levels coarser than the config (cheap error estimate of the config itself)")
    conv.add_argument("--force", action="store_true", help="run every level anew (a rerun otherwise keeps the "
                      "levels an earlier converge finished and resumes an interrupted one from its checkpoint)")
    red = _add(sub, "reduced", "the exact 1D reduction of a bilayer or circular-tube config: g_c, N_c and the "
               "margin curve in seconds (docs/reduction.md)",
               output="result directory (default results/<config name>-reduced)")
    red.add_argument("--crossover", nargs=4, metavar=("KEY", "LO", "HI", "TIME"),
                     help="instead: the value of KEY in [LO, HI] at which the 1D onset time equals TIME [s] (e.g. "
                          "a run's creases.film_onset: the crossover by nucleation), by bisection; printed, no "
                          "result directory")
    for command in (st, sw, conv, be):  # refused with a line that says how these commands continue
        command.add_argument("--resume", nargs="?", const="", default=None, help=argparse.SUPPRESS)
    return p
