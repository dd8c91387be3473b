"""The Python API (app.api, re-exported from ``app``): the same checks, files and summary as the command
line, and answers read back from what was written."""

from __future__ import annotations

import csv
import json
import subprocess
from pathlib import Path

import pytest
from cases import API_BILAYER_TOML
from conftest import EXE, MPIRUN, REPO, child_env, child_jobs, rank_local, read_json, same_summary
from mpi4py import MPI

import app as hb
from app import cli, config


def _small(dirpath):
    path = dirpath / "small.toml"
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(API_BILAYER_TOML)
    MPI.COMM_WORLD.barrier()
    return path


@rank_local
def test_the_api_is_the_package_s_top_level_and_import_stays_light():
    """Every exported name resolves from ``app``; ``import app`` alone does not import dolfinx (the command
    line's bad-input paths stay quick), checked in a fresh interpreter."""
    from app import api

    for name in hb.__all__:
        assert getattr(hb, name) is getattr(api, name)
    code = "import sys, app; assert 'dolfinx' not in sys.modules and 'app.api' not in sys.modules"
    proc = subprocess.run([str(Path(EXE).parent / "python"), "-c", code], env=child_env(), cwd=REPO, capture_output=True,
                          text=True)
    assert proc.returncode == 0, proc.stderr
    with pytest.raises(AttributeError):
        hb.no_such_function  # noqa: B018


@rank_local
def test_load_config_takes_overrides_as_the_cli_s_set(tmp_path):
    """A mapping and ``KEY=VALUE`` strings give the config ``--set`` gives (the same resolved dict as
    ``hydrobuckle validate`` prints); defaults without a file; a bad value is the CLI's one line."""
    path = _small(tmp_path)
    a = hb.load_config(path, {"material.film.modulus_ratio": 20, "loading.kind": "swelling", "time.adaptive": False})
    b = hb.load_config(path, ["material.film.modulus_ratio=20", "loading.kind=swelling", "time.adaptive=false"])
    assert a == b == config.load(path, ["material.film.modulus_ratio=20", "time.adaptive=false"])
    assert a["material"]["film"]["modulus_ratio"] == 20.0 and a["time"]["adaptive"] is False
    assert hb.load_config() == config.resolve({})
    with pytest.raises(hb.ConfigError) as err:
        hb.load_config(path, {"mesh.film_layers": 0})
    assert "mesh.film_layers" in str(err.value) and "\n" not in str(err.value)


def test_bad_input_raises_before_any_directory_exists(shared_tmp):
    """A config edited by hand into an invalid state is checked again by ``run``: ConfigError naming the
    key, and no result directory (1 and 2 ranks)."""
    cfg = hb.load_config(_small(shared_tmp))
    cfg["mesh"]["film_layers"] = 0
    with pytest.raises(hb.ConfigError, match="mesh.film_layers"):
        hb.run(cfg, shared_tmp / "bad")
    assert not (shared_tmp / "bad").exists()


def test_run_returns_what_the_cli_writes(shared_tmp, comm):
    """``hb.run`` and ``hydrobuckle run`` (cli.main in the same process, the same ranks) on one config:
    the same summary (every number to 1e-12 serially: the same computation; 1e-10 on 2 ranks, where MUMPS'
    parallel factorization is not bitwise repeatable), the same history; the Result's
    g_c, error bar, N_c, time and 1D counterpart are the summary's, its history the CSV's columns, its
    files the directory's."""
    rel = 1e-12 if comm.size == 1 else 1e-10
    path = _small(shared_tmp)
    assert cli.main(["run", str(path), "-o", str(shared_tmp / "cli"), "-q"]) == 0
    result = hb.run(hb.load_config(path), shared_tmp / "api")
    ref = read_json(shared_tmp / "cli" / "summary.json")
    s = result.summary
    assert s["status"] == ref["status"] == "buckled"
    same_summary(ref, s, rel=rel)
    assert s["config"] == ref["config"]
    for key in ("growth_um", "time", "wrinkle_count"):
        assert s["critical"][key] == pytest.approx(ref["critical"][key], rel=rel)
    assert (s["critical"]["discretization_error"]["total_um"]
            == pytest.approx(ref["critical"]["discretization_error"]["total_um"], rel=rel))
    assert s["reduced"]["growth_um"] == pytest.approx(ref["reduced"]["growth_um"], rel=rel)

    assert result.g_c_um == s["critical"]["growth_um"]
    assert result.g_c_error_um == s["critical"]["discretization_error"]["total_um"]
    assert result.N_c == s["critical"]["wrinkle_count"] and result.critical_time == s["critical"]["time"]
    one_d = result.reduced
    assert one_d.solver == "reduced-1d" and one_d.g_c_um == s["reduced"]["growth_um"]
    assert one_d.g_c_error_um == s["reduced"]["growth_error_um"] and one_d.N_c == s["reduced"]["wrinkle_count"]
    with (shared_tmp / "cli" / "history.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(result.history["time"]) == len(rows)
    assert result.history["growth_mm"] == pytest.approx([float(r["growth_mm"]) for r in rows], rel=rel)
    assert {"summary.json", "history.csv", "config.toml", "mode.png"} <= set(result.files)
    assert hb.load_result(shared_tmp / "api").summary == s
    assert f"{result.g_c_um:.4f}" in str(result)


@child_jobs
@pytest.mark.slow
def test_a_script_under_mpirun_gets_the_same_answer_on_every_rank(tmp_path):
    """``mpirun -n 2 python script.py`` calling ``hb.run``: both ranks return an answer (rank 0 read it and
    shared it), equal to a serial ``hydrobuckle run`` of the config within the 1 = 2 ranks tolerance (1e-6,
    tests/test_parallel.py)."""
    path = _small(tmp_path)
    script = tmp_path / "script.py"
    # each rank writes its answer to a file of its own: mpirun forwards the ranks' output in chunks that may join
    # or lose lines (CI: two RESULT lines joined into one, and once only one of two found)
    script.write_text("import json\nfrom mpi4py import MPI\nimport app as hb\n"
                      f"r = hb.run(hb.load_config({str(path)!r}), {str(tmp_path / 'mpi')!r})\n"
                      "with open(f'result{MPI.COMM_WORLD.rank}.json', 'w') as f:\n"
                      "    json.dump([r.g_c_um, r.N_c, r.status], f)\n")
    proc = subprocess.run([*MPIRUN, str(Path(EXE).parent / "python"), str(script)],
                          env=child_env(), cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    answers = [json.loads((tmp_path / f"result{rank}.json").read_text()) for rank in (0, 1)]
    assert answers[0] == answers[1]
    serial = subprocess.run([EXE, "run", str(path), "-o", str(tmp_path / "serial"), "-q"], env=child_env(),
                            cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert serial.returncode == 0, serial.stderr
    ref = read_json(tmp_path / "serial" / "summary.json")["critical"]
    assert answers[0][0] == pytest.approx(ref["growth_um"], rel=1e-6) and answers[0][1] == ref["wrinkle_count"]


@pytest.mark.slow
def test_reduced_and_a_reduced_sweep_are_the_commands(shared_tmp):
    """``hb.run_reduced`` = ``hydrobuckle reduced`` (the same 1D computation: summary equal but for its wall
    time); ``hb.sweep(..., reduced=True)``: one row per value, each case's g_c the reduction of that case
    alone, and the Study's results read back from the case directories."""
    path = _small(shared_tmp)
    assert cli.main(["reduced", str(path), "-o", str(shared_tmp / "cli-1d")]) == 0
    r = hb.run_reduced(hb.load_config(path), shared_tmp / "api-1d")
    ref = read_json(shared_tmp / "cli-1d" / "summary.json")
    assert r.solver == "reduced-1d" and r.status == ref["status"]
    assert r.g_c_um == pytest.approx(ref["reduced"]["growth_um"], rel=1e-12)
    assert r.g_c_error_um == pytest.approx(ref["reduced"]["growth_error_um"], rel=1e-12)
    assert r.N_c == ref["reduced"]["wrinkle_count"] and "margin.csv" in r.files

    st = hb.sweep(path, "material.film.modulus_ratio", [8.0, 20.0], shared_tmp / "sweep", reduced=True)
    assert st.complete and [row["value"] for row in st.rows] == [8.0, 20.0]
    assert st.rows[0]["g_c_um"] == pytest.approx(r.g_c_um, rel=1e-12)
    assert [x.g_c_um for x in st.results] == [row["g_c_um"] for row in st.rows]
    assert st.results[1].g_c_um < st.results[0].g_c_um  # a stiffer film wrinkles earlier (paper's trend)
    assert "study.csv" in st.files
    assert set(hb.studies()) >= {"bilayer-modulus-ratio", "tube-film-thickness"}


def test_a_failed_run_is_a_result_with_its_status_and_history(shared_tmp):
    """A run that stops on ``time.max_steps`` (a solver-side end, exit code 1 in the CLI) returns, with no
    exception, a Result saying ``failed`` with no g_c, and the steps it computed (1 and 2 ranks)."""
    cfg = hb.load_config(_small(shared_tmp), {"time.max_steps": 3, "stability.error_estimate": False,
                                              "reduced.beside_2d": False})
    r = hb.run(cfg, shared_tmp / "failed")
    assert r.status == "failed" and r.g_c_um is None and r.g_c_error_um is None
    assert list(r.history["step"]) == [0, 1, 2, 3]
    assert "max_steps" in r.summary["message"]


def test_an_interrupted_run_raises_keyboardinterrupt_and_the_next_one_starts_afresh(shared_tmp, monkeypatch):
    """SIGINT after the second step (sent by the process to itself, on every rank): the run stops there with
    summary.json ``interrupted`` and its checkpoint, and ``hb.run`` raises KeyboardInterrupt so a script
    stops too; the next call in the same process runs to its onset (the signal is not carried over), equal to
    a run never interrupted (to 1e-10)."""
    import os
    import signal

    from app.workflows import pipeline

    cfg = hb.load_config(_small(shared_tmp), {"stability.error_estimate": False, "reduced.beside_2d": False})
    real = pipeline.run_case

    def interrupting(cfg, outdir, comm, progress=True, resume=None, monitor=None):
        def kill(rec):
            if rec.step == 2:
                os.kill(os.getpid(), signal.SIGINT)
        return real(cfg, outdir, comm, progress=progress, resume=resume, monitor=kill)

    monkeypatch.setattr(pipeline, "run_case", interrupting)
    with pytest.raises(KeyboardInterrupt, match="SIGINT"):
        hb.run(cfg, shared_tmp / "stopped")
    s = read_json(shared_tmp / "stopped" / "summary.json")
    assert s["status"] == "interrupted" and s["steps"] == 2
    monkeypatch.setattr(pipeline, "run_case", real)
    again = hb.run(cfg, shared_tmp / "again")
    ref = hb.run(cfg, shared_tmp / "ref")
    # equal to roundoff: on 2 ranks MUMPS' parallel factorization is not bitwise repeatable (measured 3e-16)
    assert again.status == ref.status == "buckled" and again.g_c_um == pytest.approx(ref.g_c_um, rel=1e-10)


@rank_local
def test_an_interrupted_reduction_leaves_no_earlier_answer_behind(tmp_path):
    """A 1D reduction stopped before its end, in a directory that holds an earlier answer: that answer's files
    are gone (a stale summary.json would pass for the new config's), so ``load_result`` refuses the
    directory."""
    from app.reduced.solve import Interrupted
    from app.workflows import reduction

    cfg = hb.load_config(_small(tmp_path))
    hb.run_reduced(cfg, tmp_path / "r")
    assert (tmp_path / "r" / "summary.json").is_file()
    with pytest.raises(Interrupted):
        reduction.run(hb.load_config(_small(tmp_path), {"material.film.modulus_ratio": 20}), tmp_path / "r",
                    stop=lambda: True)
    assert not any((tmp_path / "r" / name).exists() for name in ("summary.json", "margin.csv", "history.csv"))
    with pytest.raises(FileNotFoundError, match="no summary.json"):
        hb.load_result(tmp_path / "r")


@rank_local
def test_overrides_and_values_that_cannot_be_set_are_config_errors(tmp_path):
    path = _small(tmp_path)
    assert hb.load_config(path, "time.end=1.5")["time"]["end"] == 1.5  # one KEY=VALUE string
    with pytest.raises(hb.ConfigError, match="time.end"):
        hb.load_config(path, {"time.end": None})
    with pytest.raises(hb.ConfigError, match="values"):
        hb.sweep(path, "material.film.modulus_ratio", [], tmp_path / "s", reduced=True)
    assert not (tmp_path / "s").exists()
