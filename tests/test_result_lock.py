"""One live job per result directory (app/io/lock.py; docs/configuration.md): a command whose result
directory, a directory around it or one inside it is held by a live job is refused with one line naming
the directory and that job, exit 2, before it writes anything; the first job's results stay its own; a
finished or killed job's directory can be written again.

Before the fix two runs started with the same -o both exited 0 and the directory held the second run's
summary.json and history.csv: the first run's result was gone without a word."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest
from cases import LONG
from conftest import EXE, PYTHON, REPO, child_env, finish, on_rank0, read_json, start, valid_history, wait_rows
from mpi4py import MPI

from app import cli
from app.io import lock

CONFIG = str(REPO / "configs" / "bilayer.toml")

HOLD = ("import sys, time\nfrom mpi4py import MPI\nfrom app.io import lock\n"
        "lock.claim(sys.argv[1], MPI.COMM_SELF)\nprint('held', flush=True)\ntime.sleep(600)\n")


def _holder(directory):
    """Rank 0: a process that holds ``directory``'s lock until killed (a stand-in for a live job)."""
    proc = subprocess.Popen([PYTHON, "-c", HOLD, str(directory)], env=child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert proc.stdout.readline().strip() == "held", proc.communicate()
    return proc.pid


def _kill(pid):
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)


def _refused(argv, comm, capsys, *words):
    capsys.readouterr()
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (argv, out, err)
    lines = err.strip().splitlines()
    if comm.rank == 0:
        assert len(lines) == 1 and "Traceback" not in err, err
        for w in words:
            assert w in lines[0], (w, lines[0])
    else:
        assert lines == []
    return lines


def test_every_command_refuses_a_directory_a_live_job_holds(shared_tmp, comm, capsys):
    """run, study, sweep, converge and bench into the held directory, a run into a directory inside it,
    a converge into the directory around it: each refused (exit 2, one line naming the directory and the
    holder's pid), nothing written; once the holder is killed (SIGKILL: no clean-up of its own) the lock
    is gone and the same directory is taken."""
    held = shared_tmp / "held"
    pid = on_rank0(_holder, held)
    try:
        for argv in (["run", CONFIG, "-o", str(held)],
                     ["study", "bilayer-modulus-ratio", "--values", "8", "-o", str(held)],
                     ["sweep", CONFIG, "--param", "material.film.modulus_ratio", "--values", "8,10", "-o", str(held)],
                     ["converge", CONFIG, "--only", "time", "-o", str(held)],
                     ["bench", "--sizes", "coarse", "-o", str(held)]):
            _refused(argv, comm, capsys, f"'{held}'", "is in use by another hydrobuckle job", f"pid {pid}")
        _refused(["run", CONFIG, "-o", str(held / "inside")], comm, capsys, f"lies inside '{held}'", f"pid {pid}")
        _refused(["converge", CONFIG, "--only", "time", "-o", str(shared_tmp)], comm, capsys,
                 f"contains '{held}'", f"pid {pid}")
        comm.barrier()
        assert sorted(os.listdir(held)) == [lock.LOCK_NAME]  # nothing written by the refused commands
        assert not (held / "inside").exists()
    finally:
        on_rank0(_kill, pid)
    lock.claim(held, comm)  # the killed holder's lock is gone with its process
    lock.release_all()


@pytest.mark.slow
def test_inherited_lock_lets_a_job_s_own_launches_in(shared_tmp, comm):
    """A process given the held directory in HYDROBUCKLE_HELD_DIRS (what bench --ranks hands its mpirun
    launches) may write into it; without it, the same process is refused."""
    held = shared_tmp / "held-inherited"
    pid = on_rank0(_holder, held)
    probe = ("import sys\nfrom mpi4py import MPI\nfrom app.io import lock\nfrom app.schema import ConfigError\n"
             "try:\n    lock.claim(sys.argv[1], MPI.COMM_SELF)\n    print('taken')\n"
             "except ConfigError as err:\n    print('refused:', err)\n")

    def attempt(inherit: bool) -> str:
        env = child_env()
        if inherit:
            env[lock.INHERITED] = os.path.realpath(held)
        return subprocess.run([PYTHON, "-c", probe, str(held / "size-1")], env=env, capture_output=True, text=True,
                              timeout=120).stdout.strip()

    try:
        assert on_rank0(attempt, False).startswith("refused:")
        assert on_rank0(attempt, True) == "taken"
    finally:
        on_rank0(_kill, pid)


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own runs as child processes: once, serially")
def test_second_run_into_a_running_run_s_directory(shared_tmp):
    """Two `hydrobuckle run` with the same -o, the second started while the first runs: the second exits 2
    with one line naming the directory and the first run's pid and command; the first completes and its
    summary, config and history are its own; a third run into the finished directory is taken (exit 0)."""
    cfg = shared_tmp / "long.toml"
    cfg.write_text(LONG)
    out = shared_tmp / "same"
    first = start([EXE, "run", str(cfg), "-o", str(out), "-q", "--set", "time.dt_max=0.002"])
    try:
        wait_rows(first, out / "history.csv", 5)
        second = subprocess.run([EXE, "run", CONFIG, "-o", str(out), "--set", "material.film.modulus_ratio=20"],
                                env=child_env(), capture_output=True, text=True, timeout=300)
        assert first.poll() is None, "the first run ended before the second was refused: lengthen it"
    finally:
        code, _, err = finish(first)
    assert second.returncode == 2, second.stdout + second.stderr
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1 and f"'{out}'" in lines[0] and f"pid {first.pid}" in lines[0], second.stderr
    assert "time.dt_max=0.002" in lines[0]  # the holder's command
    assert code == 0, err
    s = read_json(out / "summary.json")
    assert s["config"]["material"]["film"]["modulus_ratio"] == 1.0 and s["config"]["time"]["dt_max"] == 0.002
    rows = valid_history(out / "history.csv")
    assert int(rows[-1]["step"]) == s["steps"]
    t0 = time.monotonic()
    third = subprocess.run([EXE, "run", str(cfg), "-o", str(out), "-q", "--set", "time.end=0.05"], env=child_env(),
                           capture_output=True, text=True, timeout=300)
    assert third.returncode == 0, third.stderr
    assert read_json(out / "summary.json")["config"]["time"]["end"] == 0.05
    assert time.monotonic() - t0 < 300
