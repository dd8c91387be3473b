"""A result directory from a config, as ``run``, ``study`` and ``sweep`` make it: the simulation, then
the steps that complete its summary (the companion error estimate when ``stability.error_estimate``; the
exact 1D counterpart of a bilayer or circular tube when ``reduced.beside_2d``),
then summary.json, written once, last of all: a directory without it holds an unfinished run.

The other commands run plain simulations (a convergence level, a benchmark size, a companion run
itself) and take no pipeline steps.
"""

from __future__ import annotations

from app import config
from app.workflows.crease_onset import add_creases
from app.workflows.error_estimate import add_error_estimate
from app.workflows.reduction import add_reduced
from app.workflows.run import simulate


def after_run_steps(cfg: dict, outdir, comm) -> list:
    """The steps that amend a run's summary before it is written."""
    steps = []
    if cfg["stability"]["error_estimate"]:
        steps.append(lambda summary: add_error_estimate(summary, cfg, outdir, comm))
    if cfg["reduced"]["beside_2d"] and cfg["stability"]["enabled"] and not config.reducible(cfg):
        steps.append(lambda summary: add_reduced(summary, cfg, comm))
    if cfg["stability"]["creases"]:
        steps.append(lambda summary: add_creases(summary, cfg, comm))
    return steps


def run_case(cfg: dict, outdir, comm, progress: bool = True, resume=None, monitor=None) -> dict:
    """Simulate ``cfg`` into ``outdir`` with its pipeline steps; return the summary (``resume``: the
    directory's checked checkpoint to continue from, :func:`app.io.checkpoint.check`; ``monitor``: told
    every accepted step of the run itself)."""
    return simulate(cfg, outdir, comm, progress=progress, after=after_run_steps(cfg, outdir, comm), resume=resume,
                    monitor=monitor)
