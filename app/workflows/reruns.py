"""What a rerun of a command that runs several directories (study, sweep, converge) keeps from the
invocation before it, which an interrupt, a kill or a full disk stopped: a directory that already
holds this config's finished run is kept (:func:`finished`), an interrupted or killed run continues
from its checkpoint (:func:`resumable`). ``--force`` on those commands starts every run anew.
"""

from __future__ import annotations

import json
from pathlib import Path

from app import config
from app.io import checkpoint

COMPLETE = ("buckled", "stable", "equilibrium")  # statuses of a finished run (a rerun keeps it)

#: how each command that cannot take --resume continues instead (its one-line refusal)
HOW_TO_CONTINUE = {
    "study": "study continues by itself: rerun the same command (finished cases are kept, an interrupted case "
             "resumes from its checkpoint; --force runs every case anew)",
    "sweep": "sweep continues by itself: rerun the same command (finished cases are kept, an interrupted case "
             "resumes from its checkpoint; --force runs every case anew)",
    "converge": "converge continues by itself: rerun the same command (finished levels are kept, an interrupted "
                "level resumes from its checkpoint; --force runs every level anew)",
    "bench": "bench cannot be resumed: it times whole runs, and an interrupted bench writes no bench.json; "
             "rerun the same command",
}


def no_resume(command: str, resume: str | None) -> None:
    """``--resume`` belongs to ``run``: the commands that run several directories refuse it with one line
    saying how they continue."""
    if resume is not None:
        raise config.ConfigError("", f"--resume: {HOW_TO_CONTINUE[command]}")


def finished(cfg: dict, outdir, solver: str = "2d") -> dict | None:
    """The summary of a finished run of exactly ``cfg`` in ``outdir`` (its config.toml equal to ``cfg``,
    a status in :data:`COMPLETE`, by ``solver``: "2d", or "reduced" for the exact 1D reduction), else None."""
    summary, cfg_file = Path(outdir) / "summary.json", Path(outdir) / "config.toml"
    if not summary.is_file() or not cfg_file.is_file():
        return None
    try:
        s = json.loads(summary.read_text())
        by = "reduced" if s.get("solver") == "reduced-1d" else "2d"
        return s if s.get("status") in COMPLETE and by == solver and config.load(cfg_file) == cfg else None
    except (ValueError, OSError, config.ConfigError):
        return None


def resumable(cfg: dict, outdir, comm, log, label: str):
    """The checkpoint in ``outdir`` if ``cfg`` may resume it (collective), else None; a checkpoint of
    another config is logged (``label``: the command and case) and the run starts anew."""
    has = comm.bcast((Path(outdir) / checkpoint.FILE).is_file() if comm.rank == 0 else None, root=0)
    if not has:
        return None
    try:
        return checkpoint.check(outdir, cfg, comm)
    except checkpoint.CheckpointError as err:
        if comm.rank == 0:
            log.info(f"{label}: {err}; running from the start")
        return None
