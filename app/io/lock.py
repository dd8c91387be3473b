"""One live job per result directory: a command that writes a result directory holds an advisory lock on it
(``DIR/.hydrobuckle.lock``, ``flock``) from its pre-flight to its end.

A second job that would write the same directory, a directory inside it, or a directory that contains
one a live job holds, is refused before it writes anything: one line naming the directory and the other
job (its pid, host, command and start time), exit 2. The operating system releases the lock when the
holding process ends in any way (a normal end, an exception, SIGKILL), so a finished or killed job
never blocks a later one, and a finished directory can be overwritten as before. A job removes its lock
file when it ends (a directory holds no trace of the lock afterwards; one killed by SIGKILL leaves the
file, unlocked); a job that locked a file its previous holder has just removed tries again on the new
file, so two jobs never hold two files of one name.

Rank 0 takes and tests the locks and every rank gets its verdict. Processes a job starts itself (the
``mpirun`` launches of ``bench --ranks``) inherit its locks through the environment variable
:data:`INHERITED`.
"""

from __future__ import annotations

import atexit
import datetime
import fcntl
import json
import os
import socket
import sys
from pathlib import Path

from app.schema import ConfigError

LOCK_NAME = ".hydrobuckle.lock"
INHERITED = "HYDROBUCKLE_HELD_DIRS"  # os.pathsep-separated directories a parent job holds for this process

_held: dict[str, int] = {}  # absolute directory -> file descriptor holding its lock (this process)


def _key(path) -> str:
    return os.path.realpath(os.path.abspath(str(path)))


def _inherited() -> set[str]:
    return {p for p in os.environ.get(INHERITED, "").split(os.pathsep) if p}


def held_env() -> str:
    """The value of :data:`INHERITED` for a child process: this process's locks and the ones it inherited."""
    return os.pathsep.join(sorted(set(_held) | _inherited()))


def _holder(lock_file: Path) -> str:
    try:
        d = json.loads(lock_file.read_text() or "{}")
    except (OSError, ValueError):
        d = {}
    if not d:
        return "another hydrobuckle job"
    return (f"another hydrobuckle job (pid {d.get('pid')} on {d.get('host')}, `{d.get('command')}`, started "
            f"{d.get('started')})")


def _live(lock_file: Path) -> bool:
    """Whether another process holds ``lock_file``'s lock now (tested without waiting)."""
    try:
        fd = os.open(lock_file, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)  # closing releases a lock taken just now
    return False


def _mine(directory: str) -> bool:
    return directory in _held or directory in _inherited()


def _conflict(directory: Path) -> str | None:
    """Why ``directory`` cannot be claimed by this process, or None."""
    key = _key(directory)
    here = Path(key)
    for other in [here, *here.parents]:
        lock_file = other / LOCK_NAME
        if _mine(str(other)) or not lock_file.is_file() or not _live(lock_file):
            continue
        where = "is" if other == here else f"lies inside '{other}', which is"
        return f"{where} in use by {_holder(lock_file)}"
    for lock_file in _locks_below(here):
        other = lock_file.parent
        if other == here or _mine(str(other)) or not _live(lock_file):
            continue
        return f"contains '{other}', which is in use by {_holder(lock_file)}"
    return None


def _locks_below(directory: Path) -> list[Path]:
    """The lock files in the tree below ``directory`` (unreadable subdirectories skipped)."""
    found = []
    for root, _dirs, files in os.walk(directory, onerror=lambda _err: None):
        if LOCK_NAME in files:
            found.append(Path(root) / LOCK_NAME)
    return sorted(found)


def _acquire(directory: Path) -> str | None:
    """Rank 0: lock ``directory`` (created if missing) for this process; a sentence if another job holds it."""
    key = _key(directory)
    if _mine(key):
        return None
    problem = _conflict(directory)
    if problem:
        return problem
    Path(key).mkdir(parents=True, exist_ok=True)
    path = Path(key) / LOCK_NAME
    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # taken between the test and now
            os.close(fd)
            return f"is in use by {_holder(path)}"
        try:  # a holder that ended removes its file: ours must still be the one the path names
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    me = {"pid": os.getpid(), "host": socket.gethostname(), "command": " ".join(["hydrobuckle", *sys.argv[1:]]),
          "started": datetime.datetime.now().isoformat(timespec="seconds")}
    try:  # the description is for the message of a refused job; the lock is the flock (a full disk: no text)
        os.ftruncate(fd, 0)
        os.pwrite(fd, (json.dumps(me) + "\n").encode(), 0)
    except OSError:
        pass
    _held[key] = fd
    return None


def claim(directory, comm, option: str = "-o/--output") -> None:
    """Collective: hold ``directory``'s lock for the rest of this process (or until :func:`release_all`);
    a ConfigError on every rank, naming the directory and the job that holds it, if another job does."""
    problem = None
    if comm.rank == 0:
        try:
            problem = _acquire(Path(directory))
        except OSError as err:
            problem = f"cannot be locked ({err.strerror or err})"
    problem = comm.bcast(problem, root=0)
    if problem:
        raise ConfigError("", f"result directory '{directory}' ({option}) {problem}; wait for that job to end or "
                          "choose another directory")


def release_all() -> None:
    """Release every lock this process holds and remove its files (the end of a command): a directory is
    left as the command left it, without a lock file (a job killed by SIGKILL leaves its file behind,
    unlocked: harmless, the next job takes it)."""
    for key, fd in _held.items():
        try:
            path = Path(key) / LOCK_NAME
            if os.stat(path).st_ino == os.fstat(fd).st_ino:
                path.unlink()
        except OSError:
            pass
        try:
            os.close(fd)
        except OSError:
            pass
    _held.clear()


atexit.register(release_all)  # a command that ends without passing through cli.main's own release
