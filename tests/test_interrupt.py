"""SIGINT / SIGTERM during a run (docs/reliability.md): the run stops between steps, keeps
history.csv, writes summary.json with status "interrupted" and exits 130 / 143. Under mpirun the
signal goes to mpirun, which forwards it to every rank (Open MPI 4.1 kills them 1 s later, Open MPI 5
0.25 s later); a scheduler signals the ranks themselves and leaves them the time they need. Before
the ranks' output was sent to /dev/null on the signal, the mpirun case passed in some sessions and
failed in 11 of 11 attempts in another (rank 0 blocked writing a progress line, no summary)."""

from __future__ import annotations

import os
import signal

import pytest

from cases import BUCKLING_STRIP_TOML
from conftest import (EXE, finish, on_rank0, open_mpi_major, read_json, session_processes, start, valid_history,
                      wait_rows)

# a tiny homogeneous layer under a slow ramp (no onset, no failure) and a far end time: it runs until stopped
LONG = """
[geometry]
length = 0.1
substrate_thickness = 0.05
film_thickness = 0.01
[mesh]
element_size = 0.01
film_layers = 2
[time]
end = 1000.0
dt_initial = 0.001
dt_max = 0.005
[material.film]
modulus_ratio = 1.0
[loading]
ramp_time = 1000.0
[stability]
enabled = false
error_estimate = false
[output]
fields = false
plot = false
"""


def _interrupt(cmd, out, sig, rows=5):
    """Start ``cmd``, wait until history.csv has ``rows`` data rows, send ``sig``; the finished process."""
    proc = start(cmd)
    try:
        wait_rows(proc, out / "history.csv", rows)
        proc.send_signal(sig)
    except BaseException:
        finish(proc, timeout=0)  # killed at once
        raise
    return finish(proc, timeout=60)


def _check_results(out, sig_name, ranks, rows=5):
    summary = read_json(out / "summary.json")
    table = valid_history(out / "history.csv")  # no torn rows, steps 0..N, times increasing
    assert summary["status"] == "interrupted"
    assert summary["ranks"] == ranks
    assert f"interrupted by {sig_name}" in summary["message"]
    assert len(table) >= rows  # every row written before the signal (it may come just after one: no more)
    # the summary's final state is the last history row, named in the message
    assert summary["steps"] == int(table[-1]["step"])
    assert summary["final"]["time"] == float(table[-1]["time"])
    assert f"t = {float(table[-1]['time']):.6g} s" in summary["message"]
    return summary


@pytest.mark.slow
def test_sigint_serial_exits_130_with_history_and_summary(shared_tmp):
    """Ctrl-C on a serial run: exit 130, status "interrupted", the rows up to the interruption."""
    cfg = shared_tmp / "long.toml"
    out = shared_tmp / "int"
    on_rank0(cfg.write_text, LONG)
    code, stdout, stderr = on_rank0(_interrupt, [EXE, "run", str(cfg), "-o", str(out)], out, signal.SIGINT)
    assert code == 130, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr
    assert "hydrobuckle: interrupted by SIGINT" in stdout
    _check_results(out, "SIGINT", ranks=1)


@pytest.mark.slow
def test_sigterm_serial_exits_143(shared_tmp):
    """A wall-time limit's SIGTERM on a serial run: exit 143 (128 + 15)."""
    cfg = shared_tmp / "long.toml"
    out = shared_tmp / "term"
    on_rank0(cfg.write_text, LONG)
    code, stdout, stderr = on_rank0(_interrupt, [EXE, "run", str(cfg), "-o", str(out)], out, signal.SIGTERM)
    assert code == 143, stdout[-2000:] + stderr[-2000:]
    _check_results(out, "SIGTERM", ranks=1)


def _rank_pids(proc) -> list[int]:
    """The rank processes (hydrobuckle itself) among ``proc``'s session: not mpirun / prterun."""
    pids = []
    for pid in session_processes(proc):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
        except OSError:
            continue
        if argv and b"run" in argv and not any(w in argv[0] for w in (b"mpirun", b"prterun", b"orterun")):
            pids.append(pid)
    return pids


def _signal_ranks(cmd, out, sig, rows=5):
    """Start ``cmd`` (an mpirun job); as a scheduler's wall-time limit (srun, a batch system) does, ``sig``
    to every rank (not to mpirun) once history.csv has ``rows`` data rows; the finished process."""
    proc = start(cmd)
    try:
        wait_rows(proc, out / "history.csv", rows)
        ranks = _rank_pids(proc)
        assert len(ranks) == 2, ranks
        for pid in ranks:
            os.kill(pid, sig)
    except BaseException:
        finish(proc, timeout=0)
        raise
    return finish(proc, timeout=120)


def test_sigterm_to_the_ranks_stops_both_collectively_and_mpirun_reports_143(shared_tmp):
    """A scheduler's SIGTERM to both ranks of `mpirun -n 2 hydrobuckle run` (mpirun itself untouched, so
    nothing kills the ranks while they finish): they agree (allreduce) to stop after the same step,
    rank 0 writes summary.json ("interrupted"), and the job's code is 143 on Open MPI 4 and 5 alike
    (the ranks agree on the code and rank 0 alone ends with it: app.interrupt.leave)."""
    cfg = shared_tmp / "long.toml"
    out = shared_tmp / "ranks"
    on_rank0(cfg.write_text, LONG)
    cmd = ["mpirun", "-n", "2", "--oversubscribe", EXE, "run", str(cfg), "-o", str(out)]
    code, stdout, stderr = on_rank0(_signal_ranks, cmd, out, signal.SIGTERM)
    assert code == 143, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr and "PMIX ERROR" not in stderr, stderr[-2000:]
    _check_results(out, "SIGTERM", ranks=2)


def test_sigterm_to_mpirun_stops_both_ranks_collectively(shared_tmp):
    """SIGTERM to `mpirun -n 2 hydrobuckle run`: mpirun forwards it to both ranks and kills them a fixed
    time later (Open MPI 4.1: SIGKILL 1 s after the SIGTERM; Open MPI 5 / PRRTE 3: SIGCONT, 0.25 s, SIGTERM,
    0.25 s, SIGKILL, hard-coded). Within that time the ranks agree to stop after the same step and write
    summary.json ("interrupted"). Open MPI 4 leaves enough time for this tiny case (measured: every run);
    Open MPI 5's 0.25 s does not on a loaded machine (measured on 2 cores with 3 busy processes: no summary
    in 4 of 8 runs; the ranks' signal handler had not run before the SIGKILL), so there the test asserts
    what always holds: history.csv has no torn row, no traceback, and a summary, if written, says
    "interrupted". mpirun itself reports 1 whatever its ranks returned, so the ranks' behaviour is
    asserted through their files."""
    cfg = shared_tmp / "long.toml"
    out = shared_tmp / "mpi"
    on_rank0(cfg.write_text, LONG)
    cmd = ["mpirun", "-n", "2", "--oversubscribe", EXE, "run", str(cfg), "-o", str(out)]
    code, stdout, stderr = on_rank0(_interrupt, cmd, out, signal.SIGTERM)
    assert code != 0, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr
    # no "interrupted" line: Open MPI stops forwarding the ranks' output, which they send to /dev/null
    # once signalled (else rank 0 blocks writing a progress line until it is killed: no summary)
    if open_mpi_major() >= 5 and not (out / "summary.json").exists():
        assert len(valid_history(out / "history.csv")) >= 5  # the rows seen before the signal, none torn
        return
    _check_results(out, "SIGTERM", ranks=2)


# a small bilayer that buckles within seconds, with its error estimate (the companions side by side on 2 ranks)
ESTIMATE = BUCKLING_STRIP_TOML + """
[time]
end = 1.0
dt_max = 0.01
[stability]
error_estimate = true
[reduced]
beside_2d = false
[output]
fields = false
plot = false
"""


@pytest.mark.slow
def test_sigterm_during_side_by_side_companions_keeps_the_answer(shared_tmp):
    """A scheduler's SIGTERM to both ranks while the error estimate's companions run side by side (one per
    rank): every group stops its companion, the ranks meet again, the run's own answer is written
    (summary.json "buckled", g_c, each stopped companion's part None with its reason) and the job ends 143."""
    cfg = shared_tmp / "estimate.toml"
    out = shared_tmp / "estimate"
    on_rank0(cfg.write_text, ESTIMATE)
    cmd = ["mpirun", "-n", "2", "--oversubscribe", EXE, "run", str(cfg), "-o", str(out)]

    def run():
        proc = start(cmd)
        try:
            wait_rows(proc, out / "error-estimate" / "mesh" / "history.csv", 5)
            for pid in _rank_pids(proc):
                os.kill(pid, signal.SIGTERM)
        except BaseException:
            finish(proc, timeout=0)
            raise
        return finish(proc, timeout=120)

    code, stdout, stderr = on_rank0(run)
    assert code == 143, stdout[-2000:] + stderr[-2000:]
    assert "Traceback" not in stderr and "PMIX ERROR" not in stderr, stderr[-2000:]
    s = read_json(out / "summary.json")
    assert s["status"] == "buckled" and s["critical"]["growth_um"] > 0
    est = s["critical"]["discretization_error"]
    companions = {st: read_json(out / "error-estimate" / st / "summary.json") for st in ("mesh", "time")}
    assert companions["mesh"]["status"] == "interrupted" and companions["mesh"]["ranks"] == 1
    for st, c in companions.items():
        if c["status"] == "interrupted":  # the time companion may have ended before the signal
            assert est[f"{st}_um"] is None and "interrupted" in est[f"{st}_note"], est
    assert est["mesh_um"] is None and est["time_um"] is None  # no time error without the mesh companion's g_c
    assert not (out / "error-estimate" / "time-run-mesh").exists()  # no new run after a signal
