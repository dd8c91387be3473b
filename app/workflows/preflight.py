"""What a command checks before anything runs or is created: every case's mesh size, the geometry's input
files, the 1D reduction's reach, the ranks per case, and the result directory (creatable, writable, then
claimed for this job). A failure is a :class:`app.config.ConfigError` naming the key (the CLI prints it as
one line, exit 2) and leaves no result directory behind."""

from __future__ import annotations

import tempfile
from pathlib import Path

from app import config, geometry
from app.geometry.base import MAX_CELLS, size_line
from app.io import checkpoint, lock


def check(cfgs: list[dict], comm, outdir, labels: list[str] | None = None, force: bool = False,
          reduced: bool = False, ranks_per_case: int | None = None, sizes: bool = True,
          inputs: bool = True) -> None:
    """The checks of one command's cases, in this order: the 1D reduction's reach (``reduced``), each mesh's
    size (``sizes``; ``force`` only for a single run, ``labels`` None), the ranks per case, the geometries'
    input files (``inputs``), then the result directory ``outdir`` (claimed last; None: not yet).
    ``labels``: the cases' labels (a study's or sweep's), named in the errors as "case <label>"."""
    if reduced:
        for i, cfg in enumerate(cfgs):
            why = config.reducible(cfg)
            if why:
                raise (config.ConfigError("--reduced", f"case {labels[i]}: {why}") if labels else
                       config.ConfigError("", why))
    if sizes:
        for i, cfg in enumerate(cfgs):
            mesh_size(cfg, force and labels is None, None if labels is None else f"case {labels[i]}")
    if ranks_per_case is not None and not 1 <= ranks_per_case <= comm.size:
        raise config.ConfigError("--ranks-per-case", f"= {ranks_per_case} is out of range; "
                                 f"allowed: 1..{comm.size} (the number of MPI ranks)")
    if inputs:
        geometry_inputs(cfgs, comm, labels)
    if outdir is not None:
        take_output(outdir, comm)


def mesh_size(cfg: dict, force: bool, label: str | None = None) -> dict | None:
    """The kind's mesh size estimate (None for a user's file); above the limit a ConfigError naming
    mesh.element_size, unless ``force`` (an absurd element size would hang inside gmsh). ``label``: the
    case of a command that runs several (study, sweep, converge, bench), which have no --force for it."""
    g = config.geometry_input(cfg)
    est = geometry.kind_of(g).estimate(g)
    if est is not None and est["cells"] > MAX_CELLS and not force:
        way_out = ", or --force" if label is None else " (only 'run' accepts such a mesh, with --force)"
        where = "" if label is None else f" ({label})"
        raise config.ConfigError("mesh.element_size", f"= {cfg['mesh']['element_size']:g}{where} gives an estimated "
                                 f"{size_line(est)}: more than the limit of {MAX_CELLS:,} cells; allowed: a "
                                 f"coarser mesh.element_size (or fewer mesh.film_layers){way_out}")
    return est


def geometry_inputs(cfgs, comm, labels=None) -> None:
    """Input errors only a geometry's files can show (a user .msh: missing, unreadable, groups the
    config names but the file lacks), as ConfigError before any result directory exists."""
    seen = set()
    for i, cfg in enumerate(cfgs):
        key = repr(sorted(cfg["geometry"].items()))
        if key in seen:
            continue
        seen.add(key)
        try:
            geometry.check(config.geometry_input(cfg), comm)
        except config.ConfigError as err:
            if labels is None:
                raise
            raise config.ConfigError("", f"{err} (case {labels[i]})") from None


def check_output(path, comm) -> None:
    """The result directory must be creatable (or exist) and be writable: checked on rank 0 before
    anything runs, without creating it; a ConfigError naming the path on every rank otherwise."""
    problem = output_problem(Path(path)) if comm.rank == 0 else None
    problem = comm.bcast(problem, root=0)
    if problem:
        raise config.ConfigError("", f"result directory '{path}' (-o/--output): {problem}")


def take_output(path, comm) -> None:
    """:func:`check_output`, then the directory is claimed for this job (:mod:`app.io.lock`; it is created
    then): refused if another live job holds it, a directory around it or one inside it."""
    check_output(path, comm)
    lock.claim(path, comm)


def output_problem(path: Path) -> str | None:
    """Why no result directory can be made at ``path`` (None: it can)."""
    probe = path
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
        return f"no directory can be created in '{probe}' ({err.strerror})"
    return None


def resume(resume_dir, output, cfg: dict, comm):
    """``run --resume DIR``: (DIR, its checkpoint) when ``cfg`` may continue it; a ConfigError for a
    different -o/--output, a live job holding DIR; a CheckpointError for a checkpoint that cannot be read
    or a result-changing key changed."""
    if output and Path(output).absolute() != Path(resume_dir).absolute():
        raise config.ConfigError("", f"--resume '{resume_dir}' continues in that directory: leave out "
                                 f"-o/--output '{output}'")
    outdir = Path(resume_dir)
    if outdir.is_dir():  # a live job's checkpoint is not to be read, nor its directory written
        lock.claim(outdir, comm, "--resume")
    return outdir, checkpoint.check(outdir, cfg, comm)
