"""MPI-aware pytest fixtures: one shared tmp dir per test across ranks, collective clean-up; and the
helpers of the tests that start `hydrobuckle` as a child process (serially or under mpirun) and read
what it wrote."""

from __future__ import annotations

import csv
import gc
import json
import logging
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mpi4py import MPI

from app import config, logging_setup

# Tests that the 2-rank session leaves to the serial one, because there they would only repeat it:
#: its computation has no communicator (the 1D reduction, config validation): every rank would compute the same
rank_local = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="rank-local computation: every rank would repeat "
                                "it; the serial session runs it")
#: a long physics check (minutes) whose distributed runs the 1 = 2 ranks comparisons (test_parallel.py) cover
long_physics = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a long physics check: the serial session runs "
                                  "it; 1 = 2 ranks is tests/test_parallel.py's")
#: it starts its own runs as child processes from rank 0 (serially and under mpirun -n 2) and checks them there
child_jobs = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="starts its own runs as child processes (1 and 2 "
                                "ranks): the serial session starts the same ones")


# --- the long tests shared between the two stacks' CI halves ------------------------------------------
#: "SECONDS NODEID" per line: the suite's longest tests, as measured serially (docs/testing.md)
LONG_TESTS = Path(__file__).parent / "data" / "long-tests.txt"


def listed_seconds(path: Path = LONG_TESTS) -> dict[str, float]:
    seconds = {}
    for line in path.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            value, nodeid = line.split(maxsplit=1)
            seconds[nodeid.strip()] = float(value)
    return seconds


def _module_fixtures(item) -> set:
    """The module-scoped fixtures an item uses: tests that share one share its cost, so they stay together."""
    info = getattr(item, "_fixtureinfo", None)
    defs = info.name2fixturedefs.items() if info is not None else ()
    return {(item.module.__name__, name) for name, fds in defs if fds and fds[-1].scope == "module"}


def long_test_shares(items, n: int, seconds: dict[str, float]) -> dict[str, int]:
    """Each collected item's share (1..n), for the items that cost time: listed in ``seconds``, or joined
    to a listed item by a module-scoped fixture (its setup is paid once per share that runs one of them).
    Units (such joined items) go longest first to the share with the least time so far (ties: the lowest
    share), so that the shares take about the same time. Items not in the result run in every share."""
    unit = {item.nodeid: item.nodeid for item in items}

    def root(x):
        while unit[x] != x:
            unit[x] = unit[unit[x]]
            x = unit[x]
        return x

    by_fixture: dict = {}
    for item in items:
        for key in _module_fixtures(item):
            by_fixture.setdefault(key, []).append(item.nodeid)
    for members in by_fixture.values():
        for other in members[1:]:
            unit[root(other)] = root(members[0])
    cost: dict[str, float] = {}
    for item in items:
        cost[root(item.nodeid)] = cost.get(root(item.nodeid), 0.0) + seconds.get(item.nodeid, 0.0)
    load, share_of_unit = [0.0] * n, {}
    for u in sorted((u for u in cost if cost[u] > 0), key=lambda u: (-cost[u], u)):
        k = min(range(n), key=lambda i: (load[i], i))
        load[k] += cost[u]
        share_of_unit[u] = k + 1
    return {item.nodeid: share_of_unit[root(item.nodeid)] for item in items if root(item.nodeid) in share_of_unit}


def _share() -> tuple[int, int] | None:
    """HYDROBUCKLE_TEST_SHARE=k/n: this session runs share k of n of the long tests (unset: all of them)."""
    text = os.environ.get("HYDROBUCKLE_TEST_SHARE", "").strip()
    if not text:
        return None
    try:
        k, n = (int(v) for v in text.split("/"))
    except ValueError:
        k = n = 0
    if not 1 <= k <= n:
        raise pytest.UsageError(f"HYDROBUCKLE_TEST_SHARE must be k/n with 1 <= k <= n (got {text!r})")
    return k, n


def pytest_collection_modifyitems(config, items):
    """With HYDROBUCKLE_TEST_SHARE=k/n (.ci/run: Debian 12 1/2, Debian 13 2/2, in both the serial and the
    2-rank session), each test of tests/data/long-tests.txt (with the tests that share its module
    fixtures) runs in one share only; every other test runs in every share. The same on every rank.

    The same tests are marked ``long``: the quick lane (``bash scripts/test.sh --quick``) deselects them
    with ``-m "not long"``."""
    long_ids = long_test_shares(items, 1, listed_seconds())
    for item in items:
        if item.nodeid in long_ids:
            item.add_marker(pytest.mark.long)
    share = _share()
    if share is None:
        return
    k, n = share
    shares = long_test_shares(items, n, listed_seconds())
    keep = [item for item in items if shares.get(item.nodeid, k) == k]
    dropped = [item for item in items if shares.get(item.nodeid, k) != k]
    if dropped:
        config.hook.pytest_deselected(items=dropped)
    items[:] = keep
    if MPI.COMM_WORLD.rank == 0:
        mine = sum(v == k for v in shares.values())
        print(f"\nhydrobuckle: share {k}/{n}: {mine} of the {len(shares)} long tests "
              f"({LONG_TESTS.name} and the tests sharing their module fixtures); every other test", flush=True)


@pytest.fixture(autouse=True)
def _collective_cleanup():
    """Keep collective destructors of PETSc/dolfinx objects in step across ranks."""
    yield
    gc.collect()
    MPI.COMM_WORLD.barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD


@pytest.fixture
def shared_tmp(tmp_path_factory) -> Path:
    """A temporary directory that is the same path on every rank."""
    comm = MPI.COMM_WORLD
    path = str(tmp_path_factory.mktemp("hb")) if comm.rank == 0 else None
    return Path(comm.bcast(path, root=0))


@pytest.fixture(scope="session", autouse=True)
def _quiet_logging():
    logging_setup.setup(MPI.COMM_WORLD, logging.WARNING)


class LogLines(logging.Handler):
    """A log handler that keeps each message."""

    def __init__(self):
        super().__init__()
        self.lines = []

    def emit(self, record):
        self.lines.append(record.getMessage())


@pytest.fixture
def log_lines(monkeypatch):
    """The INFO lines hydrobuckle's log shows during a test (rank 0; the other ranks log nothing), also
    of a command that sets its logging up again (``cli.main``, with -q or not)."""
    handler = LogLines()

    def attach():
        log = logging_setup.get()
        log.addHandler(handler)
        if MPI.COMM_WORLD.rank == 0:
            log.setLevel(logging.INFO)
        return log

    setup = logging_setup.setup

    def setup_and_attach(comm, level=logging.INFO, **kw):
        setup(comm, level, **kw)
        return attach()

    monkeypatch.setattr(logging_setup, "setup", setup_and_attach)
    attach()
    yield handler.lines
    setup(MPI.COMM_WORLD, logging.WARNING)


def small_bilayer(**overrides) -> dict:
    """A small, fast bilayer config (0.1 mm wide, 0.05 mm substrate); dotted-key overrides."""
    user = {
        "geometry": {"length": 0.1, "substrate_thickness": 0.05, "film_thickness": 0.01},
        "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.3},
        "time": {"end": 0.3, "dt_initial": 0.01, "dt_max": 0.1},
        "output": {"fields": False, "plot": False},
        "reduced": {"beside_2d": False},  # tests/test_reduction.py tests the 1D counterpart
    }
    return config.resolve(user, [f"{k}={v}" for k, v in overrides.items()])


def time_stepper(problem, cfg: dict):
    """A TimeStepper with the [time] and [solver] settings of a resolved config."""
    from app import factory
    from app.workflows.run import RunSettings

    settings = RunSettings.from_config(cfg)
    return factory.time_stepper(problem, settings.time, settings.solver)


def run_to_end(cfg: dict, comm):
    """Integrate a config to time.end without the stability test: (problem, stepper, records)."""
    from app import factory

    p = factory.problem(cfg, comm)
    st = time_stepper(p, cfg)
    rows = [st.initial_record()]
    while not st.done():
        rows.append(st.advance())
    st.destroy()
    return p, st, rows


REPO = Path(__file__).resolve().parents[1]


def _venv_bin() -> Path:
    """The bin directory of the venv running the tests (scripts/test.sh: the checkout's .venv)."""
    here = Path(sys.executable).parent
    return here if (here / "hydrobuckle").is_file() else REPO / ".venv" / "bin"


EXE = str(_venv_bin() / "hydrobuckle")  # the console script
PYTHON = str(_venv_bin() / "python")


def open_mpi_major() -> int:
    """The major version of the Open MPI that `mpirun` starts (0: not Open MPI, or none)."""
    import re
    import subprocess

    try:
        out = subprocess.run(["mpirun", "--version"], capture_output=True, text=True, timeout=60,
                             env=child_env()).stdout
    except (OSError, subprocess.SubprocessError):
        return 0
    m = re.search(r"Open MPI\)?\s+(\d+)\.", out)
    return int(m.group(1)) if m else 0


def launcher_quiet() -> list[str]:
    """mpirun's option that keeps its own banner after a rank's non-zero exit off stderr: ``-q`` in Open
    MPI 4 (Debian 12); Open MPI 5 (Debian 13) has none (see :func:`ours`)."""
    return ["-q"] if open_mpi_major() < 5 else []


def ours(stderr: str) -> list[str]:
    """stderr's lines without the block Open MPI 5's launcher adds after a rank's non-zero exit ("prterun
    detected that one or more processes exited with non-zero status", between dashed rules): what
    hydrobuckle itself said."""
    out, block, skipping = [], [], False
    for line in stderr.splitlines():
        if line.startswith("-" * 20):
            if skipping:
                skipping = False
                if not any("exited with non-zero status" in b for b in block):
                    out.extend(block + [line])
                block = []
            else:
                skipping, block = True, [line]
            continue
        if not skipping and line.startswith("mca_fbtl_posix_pwritev: error in (p)write(v)"):
            continue  # Open MPI 5's MPI-IO reports the failed HDF5 write itself (hydrobuckle's line follows)
        (block if skipping else out).append(line)
    return out + block


def child_env() -> dict:
    """The environment for a child process that starts its own MPI job (mpirun or a singleton):
    the parent's Open MPI/PMIx variables removed, so a test running under ``mpirun -n 2`` can
    launch one too."""
    import os

    env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "OPAL_", "PRTE_"))}
    env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1", OMP_NUM_THREADS="1",
               OPENBLAS_NUM_THREADS="1", OMPI_MCA_rmaps_base_oversubscribe="1",
               OMPI_MCA_btl="^tcp")  # one machine: as scripts/mpi-env.sh
    return env


MPIRUN = ["mpirun", *launcher_quiet(), "-n", "2", "--oversubscribe"]


def on_rank0(fn, *args, **kwargs):
    """Call ``fn`` on rank 0 only and return its result on every rank (its exception is re-raised
    on every rank). The other ranks wait without spinning, so a child MPI job started by ``fn``
    gets the cores."""
    import time

    comm = MPI.COMM_WORLD
    if comm.size == 1:
        return fn(*args, **kwargs)
    if comm.rank == 0:
        try:
            payload = (True, fn(*args, **kwargs))
        except BaseException as err:  # noqa: B036 - handed to the other ranks, then re-raised
            payload = (False, err)
        for r in range(1, comm.size):
            comm.send(payload, dest=r, tag=77)
    else:
        while not comm.iprobe(source=0, tag=77):  # wait without spinning in MPI
            time.sleep(0.05)
        payload = comm.recv(source=0, tag=77)  # any size (irecv's default buffer is 32 kB)
    ok, value = payload
    if not ok:
        raise value
    return value


# --- a run against an uninterrupted one (history rows and summaries) -----------------------------------------


def _rel(a, b) -> float:
    a, b = float(a), float(b)
    if a == b or (math.isnan(a) and math.isnan(b)):
        return 0.0
    return abs(a - b) / max(abs(a), abs(b))


def same_rows(ref: list[dict], got: list[dict], rel: float) -> None:
    """Two history tables: the same columns and rows, every value within ``rel`` (relative)."""
    assert len(got) == len(ref), (len(got), len(ref))
    assert list(got[0]) == list(ref[0])
    # the surface amplitude of an unbuckled state is roundoff (~1e-18 mm): relative to the column's largest
    # value (at least 1 um), not to itself
    floor = {k: max(abs(float(r[k])) for r in ref) for k in ("amplitude_mm",) if k in ref[0]}
    for a, b in zip(ref, got):
        for k in a:
            if a[k] != b[k]:
                assert a[k] != "" and b[k] != "", (k, a, b)
                if k in floor:
                    assert abs(float(a[k]) - float(b[k])) <= rel * max(floor[k], 1e-3), (k, a["step"], a[k], b[k])
                else:
                    assert _rel(a[k], b[k]) <= rel, (k, a["step"], a[k], b[k])


CRITICAL = ("time", "growth_mm", "wrinkle_count", "first_mode_wrinkle_count", "lambda_min_before",
            "lambda_min_after", "negative_eigenvalues", "bisection_solves")


def same_summary(ref: dict, got: dict, rel: float, counters: bool = True) -> None:
    """Two summaries: the same status and counters (the linear solver's iteration count only with
    ``counters``); every crossing's time, growth, counts, brackets and eigenvalues within ``rel`` (eigenvalues
    near zero relative to the largest reported one)."""
    assert got["status"] == ref["status"], got["message"]
    for key in ("steps", "rejected_steps", "failed_solves", "stability_tests") + (("linear_solver",) if counters else ()):
        assert got.get(key) == ref.get(key), key
    crossings = [(ref.get("critical"), got.get("critical"))] + list(zip(ref.get("crossings", []),
                                                                       got.get("crossings", [])))
    assert len(ref.get("crossings", [])) == len(got.get("crossings", []))
    for a, b in crossings:
        assert (a is None) == (b is None)
        if a is None:
            continue
        # eigenvalues near zero (at the bracket ends) relative to the largest reported one, as test_pinned
        scale = max(abs(m["eigenvalue"]) for m in a["modes"])

        def close(x, y, eigenvalue=False):
            return abs(x - y) <= rel * max(abs(x), abs(y), scale if eigenvalue else 0.0)

        for key in CRITICAL:
            assert close(a[key], b[key], key.startswith("lambda")), (key, a[key], b[key])
        assert all(close(x, y) for x, y in zip(a["bracket"], b["bracket"]))
        assert [m["wrinkle_count"] for m in a["modes"]] == [m["wrinkle_count"] for m in b["modes"]]
        assert all(close(x["eigenvalue"], y["eigenvalue"], True) for x, y in zip(a["modes"], b["modes"]))
    a, b = ref.get("surface_onset"), got.get("surface_onset")  # the short-wave check's onset
    assert (a is None) == (b is None), (a, b)
    if a is not None:
        assert a["where"] == b["where"] and a["before_critical"] == b["before_critical"]
        assert abs(a["time"] - b["time"]) <= rel * a["time"] and abs(a["growth_mm"] - b["growth_mm"]) <= rel * abs(
            a["growth_mm"])
    _same_final(ref["final"], got["final"], rel)
    _same_postbuckling(ref.get("postbuckling"), got.get("postbuckling"), rel, counters)


def _same_final(a: dict, b: dict, rel: float) -> None:
    assert a["wrinkle_count"] == b["wrinkle_count"]
    for key in ("time", "growth_mm"):
        assert _rel(a[key], b[key]) <= rel, (key, a[key], b[key])
    # an unbuckled state's amplitude is roundoff: relative to the growth
    assert abs(a["amplitude_mm"] - b["amplitude_mm"]) <= rel * max(abs(a["amplitude_mm"]), abs(a["growth_mm"]))


SWITCH = ("time", "growth_mm", "wrinkle_count", "imperfection_mm", "with_flux")


def _same_postbuckling(a: dict | None, b: dict | None, rel: float, counters: bool) -> None:
    """The whole postbuckling block: settings, every switch (its inflow relative to the largest one's, an
    inflow of a flux-free switch is roundoff), every crossing on the branch as a critical record, every
    restabilization, and the minimizer's counters (with ``counters``)."""
    assert (a is None) == (b is None)
    if a is None:
        return
    assert set(a) == set(b)
    for key in ("after_onset", "imperfection", "imperfection_mm"):
        assert a[key] == b[key], key
    assert len(a["switches"]) == len(b["switches"])
    inflow = max([abs(x["inflow"]) for x in a["switches"]] + [1e-300])
    for x, y in zip(a["switches"], b["switches"]):
        for key in SWITCH:
            same = x[key] == y[key] if isinstance(x[key], (bool, str)) else _rel(x[key], y[key]) <= rel
            assert same, ("switch", key, x[key], y[key])
        assert abs(x["inflow"] - y["inflow"]) <= rel * inflow + 1e-15, ("switch inflow", x["inflow"], y["inflow"])
    assert len(a["branch_crossings"]) == len(b["branch_crossings"])
    for x, y in zip(a["branch_crossings"], b["branch_crossings"]):
        scale = max(abs(m["eigenvalue"]) for m in x["modes"])
        for key in CRITICAL:
            tol = rel * max(abs(x[key]), abs(y[key]), scale if key.startswith("lambda") else 0.0)
            assert abs(x[key] - y[key]) <= tol, ("branch crossing", key, x[key], y[key])
        assert all(abs(p - q) <= rel * abs(p) for p, q in zip(x["bracket"], y["bracket"]))
        assert [m["wrinkle_count"] for m in x["modes"]] == [m["wrinkle_count"] for m in y["modes"]]
    assert [r["negative_eigenvalues"] for r in a["restabilized"]] == [r["negative_eigenvalues"] for r in b["restabilized"]]
    for x, y in zip(a["restabilized"], b["restabilized"]):
        assert _rel(x["time"], y["time"]) <= rel and _rel(x["growth_mm"], y["growth_mm"]) <= rel
    if counters:
        assert a["minimizer"] == b["minimizer"]


# --- child processes and what they write -------------------------------------------------------------


def write_on_rank0(path: Path, text: str) -> Path:
    """Write a text file on rank 0; every rank may read it once this returns."""
    if MPI.COMM_WORLD.rank == 0:
        Path(path).write_text(text)
    MPI.COMM_WORLD.barrier()
    return Path(path)


def read_json(path) -> dict:
    return json.loads(Path(path).read_text())


def read_csv(path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def valid_history(path) -> list[dict]:
    """history.csv's rows, asserting it is valid CSV as a crash or a full disk must leave it: no torn
    row (every row has every column, step and time filled), steps 0, 1, ..., N, times increasing."""
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        table = list(reader)
    assert table, f"{path}: no rows"
    assert all(len(r) == len(reader.fieldnames) and None not in r.values() and "" not in (r["step"], r["time"])
               for r in table), f"{path}: a torn row"
    assert [int(r["step"]) for r in table] == list(range(len(table)))
    times = [float(r["time"]) for r in table]
    assert times == sorted(times) and times[0] == 0.0
    return table


def run_child(cmd, timeout=300, **kwargs) -> subprocess.CompletedProcess:
    """Run a command to its end in the child environment (:func:`child_env`), output captured."""
    return subprocess.run(cmd, env=child_env(), capture_output=True, text=True, timeout=timeout, **kwargs)


def start(cmd) -> subprocess.Popen:
    """Start a command in its own session (so :func:`kill_session` can reach every process it starts)."""
    return subprocess.Popen(cmd, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)


def wait_rows(proc, hist: Path, rows: int, also: Path | None = None, timeout=300) -> None:
    """Wait until history.csv has more than ``rows`` data rows (and ``also`` exists); the process must
    still be running."""
    t0 = time.monotonic()
    while not (hist.is_file() and len(hist.read_text().splitlines()) > rows and (also is None or also.is_file())):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "no history rows"
        time.sleep(0.02)


def finish(proc, timeout=300):
    """(exit code, stdout, stderr) of a started process; after ``timeout`` seconds its whole session is
    killed (SIGKILL: the code is then -9)."""
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        kill_session(proc, signal.SIGKILL)
        out, err = proc.communicate()
    return proc.returncode, out, err


def session_processes(proc) -> list[int]:
    """The processes in the session of ``proc`` (started by :func:`start`): mpirun and its ranks, which
    Open MPI puts into process groups of their own."""
    pids = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == proc.pid and fields[0] != "Z":  # field 6 of stat: the session id
            pids.append(int(entry))
    return pids


def kill_session(proc, sig) -> list[int]:
    """Send ``sig`` to every process of ``proc``'s session at once (a node failure, ``kill -9`` of a
    job); returns their pids."""
    pids = session_processes(proc)
    for pid in pids:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass
    return pids


# --- a small file system that fills up ------------------------------------------------------------------


def mount_problem(path: Path, size: str, readonly: bool = False) -> str | None:
    """Mount a tmpfs of ``size`` (e.g. "400k") at ``path``: None, or why it cannot be done here."""
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    path.mkdir(parents=True, exist_ok=True)
    options = f"size={size}" + (",ro" if readonly else "")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True, text=True)
    return None if done.returncode == 0 else f"mount -t tmpfs failed: {done.stderr.strip()}"


def unmount(path: Path) -> None:
    subprocess.run(["umount", "-l", str(path)], capture_output=True)


@pytest.fixture
def tmpfs(shared_tmp):
    """``mount(size, name, readonly)``: a tmpfs of ``size`` mounted (by rank 0) at ``shared_tmp / name``;
    the test is skipped where that is not possible (not root, no mount permission); unmounted after the
    test, whatever happened."""
    mounted = []

    def mount(size: str, name: str = "disk", readonly: bool = False) -> Path:
        path = shared_tmp / name
        problem = on_rank0(mount_problem, path, size, readonly)
        if problem:
            pytest.skip(problem)
        mounted.append(path)
        return path

    yield mount
    if mounted:  # every rank is done with the disk's files before rank 0 unmounts it (rank 1 read a summary
        MPI.COMM_WORLD.barrier()  # there after rank 0 had unmounted: FileNotFoundError in one CI run)
    for path in mounted:
        on_rank0(unmount, path)


def fill(directory: Path, leave: int = 0) -> Path:
    """Fill the file system of ``directory`` up to ``leave`` free bytes with a file of zeros."""
    ballast = directory / "filler"
    with open(ballast, "ab", buffering=0) as f:
        block = b"\0" * 4096
        while True:
            try:
                f.write(block)
            except OSError:
                break
    if leave:
        size = ballast.stat().st_size
        os.truncate(ballast, max(0, size - leave))
    return ballast
