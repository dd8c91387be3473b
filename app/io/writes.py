"""Result files that cannot be written (a full disk, an I/O error): the error names the file, every rank
agrees on it, and nothing is left half-written where that can be avoided (docs/reliability.md, "Write
errors").

Rank 0 writes the text files alone (history.csv, summary.json, config.toml, the plots,
mode_surface.csv, the tables of study, converge and bench): :func:`on_rank0` runs such a write there and
broadcasts its outcome, so every rank raises the same :class:`ResultWriteError` or none. Whole files are
written aside and renamed (:func:`replace_file`, or :func:`aside` and :func:`commit` for a file written in
several collective parts, a checkpoint): a failed write leaves the previous file, or none, and a renamed
file is on the disk (synced before and after the rename). Every JSON file goes through :func:`json_text`:
standard JSON for results (NaN and infinities as null), Python's exact round trip for checkpoints.
Rows are appended with :class:`RowFile`, which cuts a row that did not fit back off: history.csv stays
valid CSV.

The HDF5 data of fields.xdmf and mode.xdmf is written by every rank together. A rank that fails inside
HDF5 can leave the others waiting in one of its collectives, and the file can then no longer be closed
(measured: Open MPI 4.1, HDF5 1.10, a full tmpfs: one rank fails, the other hangs in the next close).
So before such a write rank 0 reserves the bytes it needs (:func:`reserve`): a disk that cannot take
them fails there, with the file system's own error, before any rank enters HDF5.
"""

from __future__ import annotations

import errno
import json
import math
import os
from pathlib import Path, PurePath

import numpy as np

SPACE_PROBE = ".hydrobuckle-space"  # the scratch file :func:`space_problem` allocates and removes


class ResultWriteError(Exception):
    """A result file could not be written; raised on every rank of the run alike. The CLI prints it as
    one line ``hydrobuckle: error: cannot write PATH: REASON`` and exits 2."""

    def __init__(self, path, reason: str):
        self.path, self.reason = str(path), reason
        super().__init__(f"cannot write {self.path}: {reason}")


def reason_of(err: BaseException) -> str:
    """One line: the OS's words for an OSError (``No space left on device``), else the exception's."""
    if isinstance(err, OSError) and err.strerror:
        return err.strerror
    text = f"{type(err).__name__}: {err}".replace("\n", " ")
    return text[:300]


def on_rank0(comm, path, write, *args, **kwargs):
    """Call ``write(*args, **kwargs)`` on rank 0 only (collective): its return value on rank 0 (None
    elsewhere), or the same :class:`ResultWriteError` on every rank if it raised: for ``path``, or for
    the file a :func:`at` inside ``write`` names (a write of several files)."""
    result, error = None, None
    if comm.rank == 0:
        try:
            result = write(*args, **kwargs)
        except ResultWriteError as err:
            error = (err.path, err.reason)
        except Exception as err:  # noqa: BLE001 - every failure of a rank-0 write must reach the other ranks
            error = (str(path), reason_of(err))
    error = comm.bcast(error, root=0)
    if error is not None:
        raise ResultWriteError(*error)
    return result


def at(path, write, *args, **kwargs):
    """``write(*args, **kwargs)``, its failure as a :class:`ResultWriteError` naming ``path`` (on the
    calling rank only: for a rank-0 write of several files inside :func:`on_rank0`)."""
    try:
        return write(*args, **kwargs)
    except ResultWriteError:
        raise
    except Exception as err:  # noqa: BLE001
        raise ResultWriteError(path, reason_of(err)) from None


def replace_file(path, write) -> None:
    """Write a whole file aside (``write(tmp_path)``), then :func:`commit` it over ``path``: a failed write
    leaves the previous file (or none) and no partial one. The aside name keeps the suffix (matplotlib reads
    the format from it). A ``write`` that writes nothing leaves ``path`` as it was."""
    path = Path(path)
    tmp = aside(path)
    try:
        write(tmp)
        if tmp.exists():  # a writer may have nothing to write (a gallery without modes)
            commit(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def commit(tmp, path) -> None:
    """Rename the whole file ``tmp`` over ``path``, durably: ``tmp``'s data reach the disk before the rename
    and the directory's entry after it, so a crash leaves the old file or the new one, whole. ``tmp`` must
    be closed; an error leaves ``tmp`` for the caller to remove."""
    with open(tmp, "rb") as f:
        os.fsync(f.fileno())
    os.replace(tmp, path)
    sync_directory(Path(path).parent)


def sync_directory(path) -> None:
    """fsync a directory (its entries); where the file system cannot, nothing."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def aside(path) -> Path:
    """Where :func:`replace_file` writes ``path`` first."""
    path = Path(path)
    return path.with_name(f"{path.stem}.tmp{path.suffix}")


def write_text(path, text: str) -> None:
    """A whole text file, by :func:`replace_file`."""
    replace_file(path, lambda tmp: Path(tmp).write_text(text))


def json_safe(value, exact: bool = False):
    """``value`` as plain JSON types: numpy scalars and arrays as numbers and lists, tuples as lists, paths as
    strings. Not ``exact`` (a result file): NaN and infinities become None, so any JSON reader takes the
    file. ``exact`` (a checkpoint): they stay floats, for Python's round trip. Anything else is a TypeError
    naming its type."""
    if isinstance(value, dict):
        return {str(k): json_safe(v, exact) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v, exact) for v in value]
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist(), exact)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, PurePath):
        return str(value)
    if isinstance(value, float):
        return value if exact or math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    raise TypeError(f"cannot write {type(value).__name__} as JSON")


def json_text(value, exact: bool = False, indent: int | None = 2) -> str:
    """The one JSON writer (:func:`json_safe`, then ``json.dumps``): a result file's text ends with a
    newline and is standard JSON; ``exact`` keeps NaN and infinities (a checkpoint's, read back by
    Python)."""
    text = json.dumps(json_safe(value, exact), indent=indent, allow_nan=exact)
    return text if exact else text + "\n"


def write_json(path, value) -> None:
    """A whole result file of JSON (:func:`json_text`), by :func:`replace_file`."""
    write_text(path, json_text(value))


class RowFile:
    """Rank 0: a text file appended one whole row at a time, each written straight to the file (no
    buffer left to flush later). A row that cannot be written whole is cut back off, so the file always
    ends with the last whole row."""

    def __init__(self, path, new: bool):
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if new else os.O_APPEND)
        self.path = Path(path)
        self.fd = os.open(self.path, flags, 0o644)

    def append(self, text: str) -> None:
        data = memoryview(text.encode())
        start = os.lseek(self.fd, 0, os.SEEK_END)
        try:
            while data:
                data = data[os.write(self.fd, data):]
        except OSError:
            try:
                os.ftruncate(self.fd, start)
                os.lseek(self.fd, start, os.SEEK_SET)
            except OSError:
                pass
            raise

    def close(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None


# --- space for collective HDF5 writes --------------------------------------------------------------


def space_problem(directory, nbytes: int, ballast=None, ballast_bytes: int = 0) -> str | None:
    """Can ``directory`` take ``nbytes`` more now? None, or the file system's reason why not.

    The bytes are allocated (posix_fallocate), then given back: in a scratch file that is removed, or, with
    ``ballast``, at the end of that file, which is cut back to ``ballast_bytes`` and stays: space kept
    aside for a later write that must not fail (an HDF5 file's close). Where the file system cannot
    allocate ahead, statvfs's free space is compared instead."""
    probe = Path(ballast) if ballast is not None else Path(directory) / SPACE_PROBE
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT, 0o600)
    except OSError as err:
        return reason_of(err)
    try:
        os.posix_fallocate(fd, 0, max(1, int(ballast_bytes + nbytes)))
    except OSError as err:
        if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
            return reason_of(err)
        try:
            st = os.statvfs(directory)
        except OSError as err2:
            return reason_of(err2)
        free = st.f_bavail * st.f_frsize
        if free < nbytes:
            return f"{os.strerror(errno.ENOSPC)} ({free:,} bytes free, about {int(nbytes):,} needed)"
    finally:
        try:
            if ballast is not None:
                os.ftruncate(fd, ballast_bytes)
            else:
                probe.unlink()
        except OSError:
            pass
        os.close(fd)
    return None


def reserve(comm, directory, nbytes: int | None, path, ballast=None, ballast_bytes: int = 0) -> None:
    """Collective: unless rank 0 can allocate ``nbytes`` (given on rank 0) in ``directory`` now (besides
    the ``ballast`` file's ``ballast_bytes``, see :func:`space_problem`), the same
    :class:`ResultWriteError` for ``path`` on every rank, before anything of the write has started."""
    error = space_problem(directory, nbytes, ballast, ballast_bytes) if comm.rank == 0 else None
    error = comm.bcast(error, root=0)
    if error is not None:
        raise ResultWriteError(path, error)


def release(comm, ballast) -> None:
    """Collective: remove a ballast file (rank 0), giving its space to the write that needs it."""
    if comm.rank == 0:
        try:
            Path(ballast).unlink(missing_ok=True)
        except OSError:
            pass
    comm.barrier()
