"""A result file that cannot be written (docs/reliability.md, "Write errors"): the command ends with one
line `hydrobuckle: error: cannot write PATH: REASON` naming the file, exit code 2, no traceback and no
hang on 1 or 2 ranks, and keeps what it had written: history.csv valid CSV up to its last whole row,
the last checkpoint, from which `run --resume` then completes.

The disk is a real one that fills up: a tmpfs mounted for the test (as root; skipped otherwise).
References: the file each command writes first (its layout, written out here), CSV validity, the
history rows against the checkpoint's and the XDMF time steps, the uninterrupted run of the same config
on the same number of ranks (see TOL), and the disk itself (nothing half-written left on it)."""

from __future__ import annotations

import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from cases import LONG
from conftest import (
    child_jobs,
    EXE,
    MPIRUN,
    PYTHON,
    fill,
    finish,
    on_rank0,
    ours,
    read_csv,
    read_json,
    run_child,
    same_rows,
    same_summary,
    start,
    valid_history,
    wait_rows,
    write_on_rank0,
)
from mpi4py import MPI

from app import cli, config
from app.io import checkpoint

NO_SPACE = "No space left on device"
# Against the uninterrupted run on as many ranks: serially bit for bit (1e-10 as tests/test_checkpoint.py);
# every 2-rank launch partitions the mesh anew (dolfinx 0.5), so two uninterrupted 2-rank runs differ
# by roundoff as runs on different rank counts do (measured 1.4e-10, the step-error column at the
# onset): the cross-layout tolerance of tests/test_checkpoint.py.
TOL = {1: 1e-10, 2: 1e-8}


def _launch(ranks: int) -> list[str]:
    return MPIRUN if ranks == 2 else []


def _run_reference(toml, out, ranks):
    done = run_child([*_launch(ranks), EXE, "run", str(toml), "-o", str(out), "-q"])
    assert done.returncode == 0, done.stderr[-2000:]
    return read_csv(out / "history.csv"), read_json(out / "summary.json")


@pytest.fixture(scope="module")
def long_runs(tmp_path_factory):
    """``reference(ranks)``: (config file, history rows, summary) of the uninterrupted run of
    cases.LONG on that many ranks, run once as a child process."""
    comm = MPI.COMM_WORLD
    d = Path(comm.bcast(str(tmp_path_factory.mktemp("long")) if comm.rank == 0 else None, root=0))
    toml = write_on_rank0(d / "long.toml", LONG)
    cache = {}

    def reference(ranks: int):
        if ranks not in cache:
            cache[ranks] = on_rank0(_run_reference, toml, d / f"reference{ranks}", ranks)
        return (toml, *cache[ranks])

    return reference


def _checkpoint_rows_are_a_prefix(out, table) -> int:
    """The checkpoint's step; its rows are history.csv's first rows (the same times, bit for bit)."""
    meta = checkpoint.check(out, config.load(out / "config.toml"), MPI.COMM_SELF).meta
    assert [r["time"] for r in meta["rows"]] == [float(r["time"]) for r in table[: len(meta["rows"])]]
    return meta["step"]


# --- every command: a disk that is full from the start ------------------------------------------------

SHRINK = ["geometry.length=0.15", "geometry.substrate_thickness=0.15", "mesh.element_size=0.01",
          "mesh.film_layers=2"]


def _commands(toml, out):
    """(arguments, the first file the command writes) for a result directory ``out``."""
    size = MPI.COMM_WORLD.size
    sets = [a for s in SHRINK for a in ("--set", s)]
    return {
        "run": (["run", str(toml), "-o", str(out)], out / "config.toml"),
        "sweep": (["sweep", str(toml), "--param", "material.film.modulus_ratio", "--values", "1,2", "-o", str(out)],
                  out / "modulus_ratio=1" / "config.toml"),
        "converge": (["converge", str(toml), "--only", "time", "--levels", "2", "-o", str(out)],
                     out / "base" / "config.toml"),
        "study": (["study", "bilayer-modulus-ratio", "--values", "8", "-o", str(out), *sets],
                  out / "modulus_ratio=8" / "config.toml"),
        "bench": (["bench", "--sizes", "coarse", "-o", str(out), *sets], out / f"run-coarse-np{size}" / "config.toml"),
    }


@pytest.mark.parametrize("command", ["run", "sweep", "converge", "study", "bench"])
def test_every_command_names_the_file_a_full_disk_refuses(command, tmpfs, shared_tmp, comm, capsys):
    """On a full disk each command stops at its first file: exit 2, one line on rank 0 naming that file
    and the OS's reason, nothing on the other rank (the ranks agreed), and no file half-written."""
    toml = write_on_rank0(shared_tmp / "long.toml", LONG)
    disk = tmpfs("100k")
    on_rank0(fill, disk)
    argv, first = _commands(toml, disk / "out")[command]
    assert cli.main(argv + ["-q"]) == 2
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert err.splitlines() == [f"hydrobuckle: error: cannot write {first}: {NO_SPACE}"], err
    else:
        assert err == "", err
    files = on_rank0(lambda: sorted(str(p) for p in disk.rglob("*") if p.is_file()))
    assert files == [str(disk / "filler")]


# --- one row that does not fit --------------------------------------------------------------------------


def _rows_until_full(disk: Path):
    from app.io.writes import RowFile

    rows = [f"{i},{'x' * 994}\n" for i in range(8)]  # 1000 bytes each: 4 fit into one 4096-byte page
    f = RowFile(disk / "rows.csv", new=True)
    f.append(rows[0])  # the file's first page
    fill(disk)  # no further page
    written, error = 1, None
    try:
        for row in rows[1:]:
            f.append(row)
            written += 1
    except OSError as err:
        error = err.strerror
    f.close()
    return (disk / "rows.csv").read_text(), "".join(rows[:written]), written, error


def test_a_row_that_does_not_fit_is_cut_back_off(tmpfs):
    """history.csv's writer (RowFile) on a disk with no free page: rows fill the file's last page; the
    fifth row of 1000 bytes fits only in part (96 bytes) and is cut back off, so the file holds exactly
    the four whole rows."""
    content, expected, written, error = on_rank0(_rows_until_full, tmpfs("100k"))
    assert (written, error) == (4, NO_SPACE)
    assert content == expected


# --- a run that fills the disk ------------------------------------------------------------------------


def _fields_fill_the_disk(toml, out, ranks):
    first = run_child([*_launch(ranks), EXE, "run", str(toml), "-o", str(out), "-q", "--set", "output.fields=true"])
    table = valid_history(out / "history.csv")
    summary = read_json(out / "summary.json")
    step = _checkpoint_rows_are_a_prefix(out, table)
    times = [float(t.get("Value")) for t in ET.parse(out / "fields.xdmf").getroot().iter("Time")]
    resumed = run_child([*_launch(ranks), EXE, "run", str(toml), "--resume", str(out), "-q",
                         "--set", "output.fields=false"])
    return first, table, summary, step, times, resumed


@child_jobs
@pytest.mark.parametrize("ranks", [1, 2])
def test_a_disk_filled_by_the_fields_stops_the_run_with_one_line(ranks, long_runs, tmpfs):
    """The fields fill a 400 kB disk after about 13 steps. Before a field output the disk cannot take
    (rank 0 reserves its bytes first, so no rank fails inside HDF5), the run stops: one line naming
    fields.h5, exit 2. Kept: history.csv (valid, one row more than the fields: that step's history was
    still written), fields.xdmf (valid XML, a time step per written output, the history's times), the
    summary ("failed", the same message), a checkpoint at most output.checkpoint_every steps back.
    Then `run --resume` without fields (output.* may change) completes in place, equal to the
    uninterrupted run."""
    toml, ref_rows, ref = long_runs(ranks)
    out = tmpfs("400k") / "out"
    first, table, summary, step, times, resumed = on_rank0(_fields_fill_the_disk, toml, out, ranks)
    line = f"hydrobuckle: error: cannot write {out / 'fields.h5'}: {NO_SPACE}"
    # The run ends without MPI_Finalize (HDF5 holds the unwritable file and its close in MPI_Finalize
    # hung: interrupt.end_process); when rank 0 has ended, Open MPI 5's launcher ends the other rank and
    # sometimes says so with a PMIx line of its own (measured: 1 of 5 runs on Debian 13).
    said = [ln for ln in ours(first.stderr) if "PMIX ERROR: PMIX_ERR_UNREACH" not in ln]
    assert first.returncode == 2 and said == [line], first.stderr[-3000:]
    assert 5 < len(table) < 100  # it stopped mid-run (the whole run has about 580 steps)
    assert times == [float(r["time"]) for r in table[:-1]]
    assert summary["status"] == "failed" and summary["message"] == line.removeprefix("hydrobuckle: error: ")
    assert summary["steps"] == len(table) - 1 and summary["ranks"] == ranks
    assert 0 <= summary["steps"] - step <= 10
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    same_rows(ref_rows, read_csv(out / "history.csv"), TOL[ranks])
    same_summary(ref, read_json(out / "summary.json"), TOL[ranks])
    assert not (out / "fields.h5").exists() and not (out / checkpoint.FILE).exists()


def _keep_full(disk: Path, stop: threading.Event) -> None:
    """Fill the disk and keep it full (space another writer gives back is taken again at once)."""
    with open(disk / "filler", "ab", buffering=0) as f:
        while not stop.is_set():
            try:
                f.write(b"\0" * 4096)
            except OSError:
                time.sleep(0.002)


def _history_fills_the_disk(toml, out, disk, ranks):
    proc = start([*_launch(ranks), EXE, "run", str(toml), "-o", str(out), "-q"])
    stop = threading.Event()
    keeper = threading.Thread(target=_keep_full, args=(disk, stop))
    try:
        wait_rows(proc, out / "history.csv", 15, also=out / checkpoint.FILE)
        keeper.start()
        code, _, err = finish(proc, timeout=120)
    except BaseException:
        finish(proc, timeout=0)  # killed at once
        raise
    finally:
        stop.set()
        if keeper.is_alive():
            keeper.join()
    (disk / "filler").unlink()
    table = valid_history(out / "history.csv")
    summary = read_json(out / "summary.json") if (out / "summary.json").is_file() else None
    step = _checkpoint_rows_are_a_prefix(out, table)
    resumed = run_child([*_launch(ranks), EXE, "run", str(toml), "--resume", str(out), "-q"])
    return code, err, table, summary, step, resumed


@child_jobs
@pytest.mark.parametrize("ranks", [1, 2])
def test_a_disk_filled_while_history_grows_keeps_whole_rows(ranks, long_runs, tmpfs):
    """Once the run has a checkpoint, the disk is filled and kept full: history.csv (rank 0's rows) soon
    cannot grow. One line naming history.csv, exit 2; the file ends with its last whole row (a row that
    fit only in part was cut back off) and the checkpoint's rows are its first ones; a summary, if
    there was room for it, says "failed". With the space back, `run --resume` equals the uninterrupted
    run."""
    toml, ref_rows, ref = long_runs(ranks)
    disk = tmpfs("512k")  # room for the whole run once the filler is gone
    out = disk / "out"
    code, err, table, summary, step, resumed = on_rank0(_history_fills_the_disk, toml, out, disk, ranks)
    line = f"hydrobuckle: error: cannot write {out / 'history.csv'}: {NO_SPACE}"
    assert code == 2 and ours(err) == [line], err[-3000:]
    assert 15 < len(table) < len(ref_rows)
    assert summary is None or (summary["status"] == "failed" and summary["steps"] >= len(table) - 1)
    assert 0 <= step <= len(table) - 1
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    same_rows(ref_rows, read_csv(out / "history.csv"), TOL[ranks])
    same_summary(ref, read_json(out / "summary.json"), TOL[ranks])


# --- HDF5 itself meets the full disk ----------------------------------------------------------------

# The space reservation switched off: a write error the reservation does not foresee (another process
# filling the disk between the reservation and the write) reaches HDF5 as it would.
UNRESERVED = ("import sys, app.io.writes as w; w.reserve = lambda *a, **k: None; import app.cli; "
              "sys.exit(app.cli.main())")


def _hdf5_meets_the_full_disk(toml, out, ranks):
    t0 = time.monotonic()
    done = run_child([*_launch(ranks), PYTHON, "-c", UNRESERVED, "run", str(toml), "-o", str(out), "-q"],
                     timeout=120)
    return done, time.monotonic() - t0, valid_history(out / "history.csv")


@child_jobs
@pytest.mark.parametrize("ranks", [1, 2])
def test_a_failure_inside_hdf5_is_agreed_on_without_a_hang(ranks, shared_tmp, tmpfs):
    """A 0.3 mm strip (70 kB of fields per step) on a 200 kB disk, the reservation off: HDF5's write
    fails (on 2 ranks: on one rank only). Every rank agrees after that dataset, the file is never
    closed (its close would hang or abort), HDF5's own error stack is not printed, and the process ends
    with one line naming fields.h5 and exit 2 in seconds. Open MPI's MPI-IO may add its own line about
    the failed write on 2 ranks (it prints it itself; conftest.ours leaves it out)."""
    from cases import SWELLING

    cfg = config.resolve(SWELLING, ["output.fields=true", "stability.error_estimate=false"])
    toml = write_on_rank0(shared_tmp / "strip.toml", config.dumps(cfg))
    out = tmpfs("200k") / "out"
    done, seconds, table = on_rank0(_hdf5_meets_the_full_disk, toml, out, ranks)
    said = [ln for ln in ours(done.stderr) if "PMIX ERROR: PMIX_ERR_UNREACH" not in ln]  # as above
    assert done.returncode == 2, done.stderr[-3000:]
    assert said == [f"hydrobuckle: error: cannot write {out / 'fields.h5'}: {NO_SPACE}"], done.stderr[-3000:]
    assert seconds < 60 and len(table) >= 1
