"""What the commands that run several directories do when interrupted, and how they continue
(docs/reliability.md, "What can be resumed"): converge continues when rerun (finished levels kept, an
interrupted level resumed from its checkpoint) and its interrupted tables say so; bench cannot be
resumed and an interrupted bench leaves no bench.json; ``--resume`` (run's option) is refused on all
four with one line saying how they continue.

References: the uninterrupted converge of the same config (its convergence.json, level by level,
serially: bit for bit, 1e-10), the listing of the directories (which files exist), the exit codes of
SIGINT (130) and of bad input (2)."""

from __future__ import annotations

import signal

import pytest
from cases import LONG
from conftest import EXE, child_jobs, finish, on_rank0, read_json, run_child, start, wait_rows, write_on_rank0

from app import cli

CONVERGE = ["--only", "time", "--levels", "2"]


def _interrupt_then_rerun(toml, out, full):
    argv = ["converge", str(toml), *CONVERGE, "-o", str(out)]
    proc = start([EXE, *argv, "-q"])
    wait_rows(proc, out / "base" / "history.csv", 20)
    proc.send_signal(signal.SIGINT)
    code, _, _ = finish(proc)
    listing = sorted(p.name for p in out.iterdir())
    stopped = read_json(out / "convergence.json")
    md = (out / "convergence.md").read_text().splitlines()[0]
    again = run_child([EXE, *argv])
    continued = read_json(out / "convergence.json")
    third = run_child([EXE, *argv])
    uninterrupted = run_child([EXE, "converge", str(toml), *CONVERGE, "-o", str(full), "-q"])
    assert uninterrupted.returncode == 0, uninterrupted.stderr[-2000:]
    return code, listing, stopped, md, again, continued, third, read_json(full / "convergence.json")


def _same_report(ref: dict, got: dict) -> None:
    """Two convergence.json documents: every level's row (but its wall time) and every estimate."""
    assert got["status"] == ref["status"] == "complete"
    assert len(got["rows"]) == len(ref["rows"])
    for a, b in zip(ref["rows"], got["rows"]):
        for key in a:
            if key != "wall_time_s":
                assert b[key] == pytest.approx(a[key], rel=1e-10) if isinstance(a[key], float) else b[key] == a[key]
    for key in ("g_c_um", "converged_estimate_um", "error_estimate_um"):
        assert got["base"][key] == pytest.approx(ref["base"][key], rel=1e-10)
    assert got["studies"]["time"]["values"] == pytest.approx(ref["studies"]["time"]["values"], rel=1e-10)


@child_jobs
def test_interrupted_converge_is_marked_and_continues_when_rerun(shared_tmp):
    """SIGINT during converge's base run: exit 130, no further level started, and the tables of what ran
    say "interrupted" (no Richardson estimate, no plot, convergence.md says so first) rather than look
    finished. The same command again resumes the base level from its checkpoint and runs the other
    level; a third time keeps both finished levels. Both give the uninterrupted converge's report."""
    toml = write_on_rank0(shared_tmp / "long.toml", LONG)
    out, full = shared_tmp / "converge", shared_tmp / "full"
    code, listing, stopped, md, again, continued, third, ref = on_rank0(_interrupt_then_rerun, toml, out, full)
    assert code == 130
    assert listing == ["base", "convergence.csv", "convergence.json", "convergence.md"], listing
    assert stopped["status"] == "interrupted" and stopped["base"] == {}
    assert [r["status"] for r in stopped["rows"]] == ["interrupted"]
    assert "converged" not in stopped["studies"]["time"]
    assert md.startswith("INTERRUPTED")
    assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
    assert "converge: time0: resuming at step" in again.stdout and "converge: time1 (" in again.stdout
    _same_report(ref, continued)
    assert third.returncode == 0, third.stderr[-2000:]
    assert third.stdout.count("finished by an earlier converge, kept") == 2
    _same_report(ref, read_json(out / "convergence.json"))
    assert (out / "convergence.png").is_file()


def _interrupt_bench(out):
    out.mkdir(parents=True)
    (out / "bench.json").write_text("{}\n")  # an earlier bench's result: it must not survive as this one's
    proc = start([EXE, "bench", "--sizes", "coarse,default", "-o", str(out), "--set", "geometry.length=0.2"])
    wait_rows(proc, out / "run-coarse-np1" / "history.csv", 5)
    proc.send_signal(signal.SIGINT)
    code, stdout, _ = finish(proc)
    return code, stdout, sorted(p.name for p in out.iterdir()), read_json(out / "run-coarse-np1" / "summary.json")


@pytest.mark.slow
@child_jobs
def test_interrupted_bench_writes_no_result(shared_tmp):
    """SIGINT during bench's first size: exit 130, the second size never starts, and neither bench.json
    nor bench.md exists (the earlier one is removed when a bench starts): timings of a part of a run are
    no benchmark, and a bench cannot be resumed."""
    code, stdout, listing, summary = on_rank0(_interrupt_bench, shared_tmp / "bench")
    assert code == 130, stdout[-2000:]
    assert listing == ["run-coarse-np1"], listing
    assert summary["status"] == "interrupted"
    assert "bench: interrupted: no bench.json written" in stdout


@pytest.mark.parametrize("command, words", [
    ("study", "finished cases are kept"), ("sweep", "finished cases are kept"),
    ("converge", "finished levels are kept"), ("bench", "bench cannot be resumed")])
def test_resume_is_refused_where_it_does_not_apply(command, words, shared_tmp, comm, capsys):
    """``--resume DIR`` belongs to ``run``: the other commands refuse it before anything runs (exit 2,
    one line on rank 0 naming --resume and how that command continues; nothing created)."""
    toml = write_on_rank0(shared_tmp / "long.toml", LONG)
    out = shared_tmp / "out"
    argv = {"study": ["study", "bilayer-modulus-ratio", "-o", str(out)],
            "sweep": ["sweep", str(toml), "--param", "material.film.modulus_ratio", "--values", "1,2", "-o", str(out)],
            "converge": ["converge", str(toml), "-o", str(out)],
            "bench": ["bench", "-o", str(out)]}[command]
    assert cli.main(argv + ["--resume", str(out)]) == 2
    err = capsys.readouterr().err
    if comm.rank == 0:
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("hydrobuckle: error: --resume: "), err
        assert words in lines[0], err
    else:
        assert err == ""
    assert not out.exists()
