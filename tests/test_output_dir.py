"""An impossible result directory (-o) is bad input: one line `hydrobuckle: error: ...` naming the
path on rank 0 (nothing on the others, no traceback), exit 2, before any computation and without
creating anything, from run, study, sweep, converge and bench (docs/reliability.md)."""

from __future__ import annotations

import os

import pytest
from conftest import REPO

from app import cli
from app.workflows import preflight

CONFIG = str(REPO / "configs" / "bilayer.toml")


def _commands(out: str) -> dict:
    return {
        "run": ["run", CONFIG, "-o", out],
        "study": ["study", "bilayer-modulus-ratio", "--values", "8", "-o", out],
        "sweep": ["sweep", CONFIG, "--param", "material.film.modulus_ratio", "--values", "8,10", "-o", out],
        "converge": ["converge", CONFIG, "--only", "time", "-o", out],
        "bench": ["bench", "--sizes", "coarse", "-o", out],
    }


def _bad_paths(tmp) -> dict:
    """Impossible result directories: under /proc, below a regular file, a regular file itself."""
    afile = tmp / "a-file"
    afile.write_text("x")  # every rank writes the same content: harmless
    return {"proc": "/proc/hb-results", "parent-is-file": str(afile / "results"), "is-file": str(afile)}


def _expect_refusal(argv, path, comm, capsys):
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (argv, out, err)
    assert "Traceback" not in err and out == ""
    lines = err.strip().splitlines()
    if comm.rank == 0:
        assert len(lines) == 1 and lines[0].startswith("hydrobuckle: error: "), err
        assert f"'{path}'" in lines[0], err
    else:
        assert lines == [], err
    return lines


@pytest.mark.parametrize("command", ["run", "study", "sweep", "converge", "bench"])
def test_impossible_output_dir_is_bad_input(command, shared_tmp, comm, capsys):
    before = sorted(os.listdir(shared_tmp))
    for kind, path in _bad_paths(shared_tmp).items():
        _expect_refusal(_commands(path)[command], path, comm, capsys)
    assert not os.path.exists("/proc/hb-results")
    comm.barrier()
    assert sorted(os.listdir(shared_tmp)) == sorted(set(before) | {"a-file"})  # nothing created, no probe left


def test_message_names_the_reason(shared_tmp, comm, capsys):
    paths = _bad_paths(shared_tmp)
    cli.main(["run", CONFIG, "-o", paths["parent-is-file"]])
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert f"'{shared_tmp / 'a-file'}' is a file, not a directory" in err
    cli.main(["run", CONFIG, "-o", paths["is-file"]])
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert "exists and is not a directory" in err


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only directory")
def test_read_only_parent_is_bad_input(shared_tmp, comm, capsys):
    ro = shared_tmp / "read-only"
    if comm.rank == 0:
        ro.mkdir()
        ro.chmod(0o555)
    comm.barrier()
    try:
        _expect_refusal(["run", CONFIG, "-o", str(ro / "out")], str(ro / "out"), comm, capsys)
    finally:
        comm.barrier()
        if comm.rank == 0:
            ro.chmod(0o755)


@pytest.mark.parametrize("command", ["run", "study", "sweep", "converge", "bench"])
def test_read_only_file_system_is_bad_input(command, tmpfs, comm, capsys):
    """A result directory on a file system mounted read-only (root may write anywhere else): refused
    before anything runs, one line naming the path and the OS's reason, exit 2."""
    disk = tmpfs("100k", readonly=True)
    path = str(disk / "out")
    lines = _expect_refusal(_commands(path)[command], path, comm, capsys)
    if comm.rank == 0:
        assert lines[0].endswith(f"no directory can be created in '{disk}' (Read-only file system)"), lines
    comm.barrier()
    assert not os.path.exists(path)


def test_writable_output_dir_passes_the_check(shared_tmp, comm):
    """A fresh path and an existing directory pass, and the check creates nothing."""
    for path in (shared_tmp / "new" / "deeper", shared_tmp):
        preflight.check_output(path, comm)
    comm.barrier()
    assert not (shared_tmp / "new").exists()
    assert not [p for p in os.listdir(shared_tmp) if p.startswith(".hydrobuckle-probe-")]
