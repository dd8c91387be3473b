"""hydrobuckle's Python API: build a config, run a case, the exact 1D reduction, a study; read the answers.

Every function here does what the command of the same name does (``hydrobuckle run``, ``reduced``,
``study``, ``sweep``), with the same checks, files and summary, and returns the answer as an object::

    import app as hb

    cfg = hb.load_config("configs/bilayer.toml", {"mesh.element_size": 0.008})
    result = hb.run(cfg, "results/coarse")
    print(result.g_c_um, result.g_c_error_um, result.N_c)

Bad input raises :class:`ConfigError` (its message is the CLI's one line) before any result directory is
made; a run whose solver fails returns a :class:`Result` with ``status == "failed"`` and everything it
computed, as the CLI does (exit code 1 there).

Under MPI, call the same functions on every rank of the communicator (``comm``, default
``MPI.COMM_WORLD``): each rank returns the same :class:`Result`.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from app import __all__, config  # noqa: F401 - __all__: the names the package re-exports, listed once in app/__init__.py
from app.results import Result, Study
from app.schema import ConfigError

Overrides = Mapping[str, Any] | Sequence[str] | None


def _override_list(overrides: Overrides) -> list[str]:
    """``{"mesh.element_size": 0.008}``, ``["mesh.element_size=0.008"]`` or one such string as the CLI's
    ``--set`` items; a value TOML cannot hold is a ConfigError naming its key."""
    if overrides is None:
        return []
    if isinstance(overrides, str):
        return [overrides]
    if isinstance(overrides, Mapping):
        items = []
        for k, v in overrides.items():
            if v is None or isinstance(v, Mapping):
                raise ConfigError(str(k), f"= {v!r} cannot be set as an override; allowed: a number, a string, "
                                  "a boolean or a list")
            items.append(f"{k}={config.toml_value(v)}")
        return items
    return [str(item) for item in overrides]


def load_config(path: str | Path | None = None, overrides: Overrides = None) -> dict:
    """A resolved, validated config, as the command line reads one.

    Args:
        path: the TOML file; None: every key at its default.
        overrides: applied as ``--set`` does: a mapping of dotted keys to values, ``"KEY=VALUE"`` strings, or
            one such string.

    Returns:
        The config as nested dicts, every key of the schema present (the reference's Configuration page
        lists them), the geometry kind's own defaults applied.

    Raises:
        ConfigError: an unknown key, a wrong type or a value out of range, naming the key.
    """
    if path is None:
        return config.resolve({}, _override_list(overrides))
    return config.load(path, _override_list(overrides))


def _comm(comm):
    if comm is None:
        from mpi4py import MPI

        return MPI.COMM_WORLD
    return comm


def _logging(comm, verbose: bool) -> None:
    from app import logging_setup

    logging_setup.setup(comm, logging.INFO if verbose else logging.WARNING, root=False)


def _read_on_rank0(comm, read):
    """``read()`` on rank 0, its value (or its error) on every rank: the result files are rank 0's, and a
    multi-node job need not share a file system."""
    value, error = None, None
    if comm.rank == 0:
        try:
            value = read()
        except Exception as err:  # noqa: BLE001 - raised again on every rank
            error = err
    value, error = comm.bcast((value, error), root=0)
    if error is not None:
        raise error
    return value


def _finish(comm) -> None:
    """After a command: the locks released; a SIGINT/SIGTERM that stopped it (its summary says
    ``interrupted`` and the run can be resumed) is raised as KeyboardInterrupt, so a script or notebook stops
    too, and is forgotten so that the next call starts afresh."""
    from mpi4py import MPI

    from app import interrupt
    from app.io import lock

    lock.release_all()
    signal_number = interrupt.agreed or comm.allreduce(interrupt._received, op=MPI.MAX)
    interrupt.reset()
    if signal_number:
        raise KeyboardInterrupt(f"hydrobuckle: interrupted by {interrupt.name(signal_number)}; what was computed "
                                "is kept (run: summary.json says 'interrupted', run --resume continues)")


def load_result(outdir: str | Path) -> Result:
    """The result a finished run, or ``hydrobuckle run``, wrote into a directory.

    Args:
        outdir: the result directory (its summary.json, history.csv and the other files).

    Returns:
        The :class:`Result` read back.
    """
    return Result.load(outdir)


def run(cfg: dict, outdir: str | Path, comm=None, verbose: bool = False, force: bool = False) -> Result:
    """Run one case as ``hydrobuckle run`` does: the pre-flight checks (mesh size, input files, the result
    directory), the simulation to its onset (or past it, as the config says), its error estimate and its
    exact 1D counterpart where the config asks for them; everything written into ``outdir``.

    Args:
        cfg: a resolved config (:func:`load_config`; change ``geometry.kind`` through its overrides, not in
            the dict, so that the new kind's defaults apply). It is validated again.
        outdir: the result directory to write.
        comm: the communicator to run on (default ``MPI.COMM_WORLD``); call on every rank.
        verbose: the progress lines (one per step) on rank 0.
        force: accept a mesh above the size limit.

    Returns:
        The :class:`Result` of ``outdir``, the same on every rank. A solver failure is not an exception: its
        ``status`` is ``"failed"``, everything computed kept.

    Raises:
        ConfigError: bad input; nothing is written.
        app.io.writes.ResultWriteError: a result file could not be written; what was written is kept.
        KeyboardInterrupt: after a SIGINT or SIGTERM, once the run has stopped and saved its state
            (``hydrobuckle run --resume`` continues it).
    """
    from app import interrupt
    from app.workflows import preflight
    from app.workflows.pipeline import run_case

    comm = _comm(comm)
    cfg = config.resolve(cfg)  # validated again: a dict edited by hand is checked like a file
    outdir = Path(outdir)
    interrupt.reset()
    try:
        preflight.check([cfg], comm, outdir, force=force)
        _logging(comm, verbose)
        run_case(cfg, outdir, comm, progress=verbose)
    finally:
        _finish(comm)
    return _read_on_rank0(comm, lambda: Result.load(outdir))


def run_reduced(cfg: dict, outdir: str | Path, comm=None, verbose: bool = False) -> Result:
    """The exact 1D reduction of a bilayer or circular tube, as ``hydrobuckle reduced``: g_c and N_c
    converged in 1D mesh and time with an error bar, the margin curve (``margin.csv``) in ``outdir``.

    Args:
        cfg: a resolved config (:func:`load_config`).
        outdir: the result directory to write.
        comm: the communicator (default ``MPI.COMM_WORLD``); rank 0 computes.
        verbose: the progress lines on rank 0.

    Returns:
        The :class:`Result` of ``outdir`` on every rank (``solver`` is ``"reduced-1d"``).

    Raises:
        ConfigError: a config the reduction does not cover, naming the key that decides it.
    """
    from app import interrupt
    from app.workflows import preflight
    from app.workflows import reduction as reduced_workflow

    comm = _comm(comm)
    cfg = config.resolve(cfg)
    outdir = Path(outdir)
    interrupt.reset()
    try:
        preflight.check([cfg], comm, outdir, reduced=True, sizes=False, inputs=False)
        _logging(comm, verbose)
        reduced_workflow.command(cfg, outdir, comm)
    finally:
        _finish(comm)
    return _read_on_rank0(comm, lambda: Result.load(outdir))


def _study(cases, outdir: Path, comm, title: str, param: str, ranks_per_case: int, force: bool, solver: str,
           verbose: bool) -> Study:
    from app import interrupt
    from app.workflows import studies

    comm = _comm(comm)
    interrupt.reset()
    try:
        studies.command(cases, outdir, comm, title, param, ranks_per_case, force, solver == "reduced",
                        start=lambda: _logging(comm, verbose))
    finally:
        _finish(comm)
    data = _read_on_rank0(comm, lambda: json.loads((outdir / "study.json").read_text()))
    return Study(outdir, data["title"], data["parameter"], data["rows"])


def _values(values) -> str | None:
    if values is None:
        return None
    if isinstance(values, str | bytes) or not len(values):
        raise ConfigError("values", f"= {values!r}; allowed: a non-empty list of values")
    return ",".join(config.toml_value(v) for v in values)


def study(name: str, outdir: str | Path, values: Sequence | None = None, overrides: Overrides = None, comm=None,
          reduced: bool = False, error_estimate: bool = False, ranks_per_case: int = 1, force: bool = False,
          verbose: bool = False) -> Study:
    """One of the paper's parameter studies, as ``hydrobuckle study NAME``: every case in its own
    subdirectory of ``outdir``, then study.csv/.json/.png. Resumable: a case already complete with the same
    config is not run again.

    Args:
        name: the study (:func:`studies` names them).
        outdir: the study directory.
        values: replaces the study's own values of its key.
        overrides: config changes for every case, as in :func:`load_config`.
        comm: the communicator (default ``MPI.COMM_WORLD``); cases run side by side on its ranks.
        reduced: every case by the exact 1D reduction (seconds a case).
        error_estimate: every case with its error bar (``stability.error_estimate``).
        ranks_per_case: MPI ranks per case.
        force: run every case anew.
        verbose: the progress lines.

    Returns:
        The :class:`Study`: its rows and each case's :class:`Result`.

    Raises:
        ConfigError: an unknown study or a value out of its key's range; nothing is written.
    """
    from app.workflows import studies as st

    outdir = Path(outdir)
    spec, cases = st.study_cases(name, outdir, _values(values), _override_list(overrides), error_estimate)
    return _study(cases, outdir, comm, spec.description, spec.param, ranks_per_case, force,
                  "reduced" if reduced else "2d", verbose)


def sweep(config_path: str | Path, param: str, values: Sequence, outdir: str | Path, overrides: Overrides = None,
          comm=None, reduced: bool = False, error_estimate: bool = False, ranks_per_case: int = 1,
          force: bool = False, verbose: bool = False) -> Study:
    """A sweep of any key of a config file over values, as ``hydrobuckle sweep``.

    Args:
        config_path: the TOML config every case starts from.
        param: the dotted key to sweep, e.g. ``"material.film.modulus_ratio"``.
        values: its values, one case each.
        outdir: the study directory.
        overrides, comm, reduced, error_estimate, ranks_per_case, force, verbose: as in :func:`study`.

    Returns:
        The :class:`Study`.

    Raises:
        ConfigError: an unknown key, or a value a case's config cannot take; nothing is written.
    """
    from app.workflows import studies as st

    outdir = Path(outdir)
    cases = st.sweep_cases(config_path, param, _values(values), outdir, _override_list(overrides),
                           error_estimate=error_estimate)
    return _study(cases, outdir, comm, f"{Path(config_path).stem}: sweep of {param}", param, ranks_per_case, force,
                  "reduced" if reduced else "2d", verbose)


def studies() -> dict[str, str]:
    """The paper's studies.

    Returns:
        Each study's name (for :func:`study`) with its description.
    """
    from app.workflows.studies import STUDIES

    return {name: spec.description for name, spec in STUDIES.items()}
