"""The benchmark command runs and writes a well-formed bench.json (timings are not asserted)."""

import json

import pytest
from mpi4py import MPI

from app import cli


def test_bench_writes_well_formed_json(shared_tmp):
    out = shared_tmp / "bench"
    assert cli.main(["bench", "--sizes", "coarse", "-o", str(out), "-q", "--set", "geometry.length=0.2"]) == 0
    doc = json.loads((out / "bench.json").read_text())
    run = doc["runs"][str(MPI.COMM_WORLD.size)]["sizes"]["coarse"]
    assert run["dofs"] > 0 and run["steps"] > 0 and run["newton_iterations"] >= run["steps"]
    assert run["factorizations"] >= run["newton_iterations"]  # one per Newton iteration at least
    # every accepted step is tested: screened on the Newton factor or exactly (more in the bisection)
    assert run["stability_tests"] + run["screened_steps"] >= run["steps"] + 1
    assert run["R"] > 0 and run["t_factor_s"] > 0 and run["R_performed"] >= run["R"]
    split = run["per_step_split_s"]
    assert set(split) >= {"assembly", "factorization", "triangular_solves", "stability_test", "eigen_solve",
                          "output", "other"}
    assert all(v >= 0 for v in split.values())
    assert (sum(split.values()) * run["steps"] + run["setup_time_s"]) == pytest.approx(run["wall_time_s"], rel=0.01)
    assert len(run["peak_rss_mb_per_rank"]) == MPI.COMM_WORLD.size
    assert run["g_c_um"] > 0
    assert "| coarse |" in (out / "bench.md").read_text()


def test_bench_rejects_bad_sizes(capsys):
    assert cli.main(["bench", "--sizes", "huge"]) == 2
    assert cli.main(["bench", "--ranks", "0,x"]) == 2


def test_bench_counts_each_size_separately(shared_tmp):
    """PETSc's event log is cumulative: two sizes in one process must not add up."""
    out = shared_tmp / "bench2"
    args = ["bench", "--sizes", "coarse,coarse", "-o", str(out), "-q", "--set", "geometry.length=0.2"]
    assert cli.main(args) == 0
    # both entries are the same size: the JSON keeps one, but the run before it must not leak in
    run = json.loads((out / "bench.json").read_text())["runs"][str(MPI.COMM_WORLD.size)]["sizes"]["coarse"]
    assert run["factorizations"] <= 2 * run["newton_iterations"]
