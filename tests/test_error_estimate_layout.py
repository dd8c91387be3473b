"""The error estimate's companion layout (app/workflows/error_estimate.py), with the simulations replaced by a
stand-in that answers from the config: which companion runs on which mesh, what is compared with what, and
what happens when the coarse mesh has no answer. The real runs are tested in test_cli_run, test_commands,
test_own_geometry (a file's mesh) and test_error_estimate (the bar against finer sequences)."""

from __future__ import annotations

import pytest
from cases import swelling_case
from mpi4py import MPI

from app.workflows import error_estimate as ee


def _fake(answers: dict):
    """A simulate stand-in: g_c from (element size, time tolerance), None for a config it has no answer for."""
    calls = []

    def simulate(cfg, outdir, comm, progress=True, **_):
        key = (cfg["mesh"]["element_size"], cfg["time"]["tolerance"])
        calls.append((key, outdir.name, comm.size))
        g = answers.get(key)
        return {"status": "buckled" if g is not None else "completed", "critical": {"growth_um": g} if g else {}}

    return simulate, calls


def test_time_error_on_the_coarse_mesh_and_mesh_error_against_the_run(monkeypatch):
    cfg = swelling_case("mesh.element_size=0.01", "mesh.film_layers=2")
    h, tol = 0.01, cfg["time"]["tolerance"]
    simulate, calls = _fake({(2 * h, tol): 7.0, (2 * h, 4 * tol): 6.9})
    monkeypatch.setattr(ee, "simulate", simulate)
    out = ee.companion_error_estimate(cfg, 6.8, "/tmp/unused", MPI.COMM_WORLD)
    assert out["time_companion_mesh"] == "coarsened"
    assert out["mesh_um"] == pytest.approx(0.2 / (2 ** 1.5 - 1), rel=1e-12)
    assert out["time_um"] == pytest.approx(0.1, rel=1e-12)  # |g_2h - g_2h,2dt| / (2^1 - 1)
    assert out["total_um"] == pytest.approx(out["mesh_um"] + out["time_um"], rel=1e-12)
    names = [name for _, name, _ in calls]  # serially both; on 2 ranks or more each group runs one
    assert len(names) == (2 if MPI.COMM_WORLD.size == 1 else 1)
    assert set(sum(MPI.COMM_WORLD.allgather(names), [])) == {"mesh", "time"}


def test_no_coarse_answer_runs_the_time_companion_on_the_run_mesh(monkeypatch):
    cfg = swelling_case("mesh.element_size=0.01", "mesh.film_layers=2")
    h, tol = 0.01, cfg["time"]["tolerance"]
    simulate, calls = _fake({(h, 4 * tol): 6.75})  # the coarse mesh finds no onset
    monkeypatch.setattr(ee, "simulate", simulate)
    out = ee.companion_error_estimate(cfg, 6.8, "/tmp/unused", MPI.COMM_WORLD)
    assert out["mesh_um"] is None and "no onset" in out["mesh_note"]
    assert out["time_companion_mesh"] == "the run's"
    assert out["time_um"] == pytest.approx(0.05, rel=1e-12)
    assert out["total_um"] == pytest.approx(0.05, rel=1e-12)
    assert calls[-1] == ((h, 4 * tol), ee.RUN_MESH_TIME, MPI.COMM_WORLD.size)  # again, on all ranks


def test_a_failing_companion_costs_its_part_only(monkeypatch):
    cfg = swelling_case("mesh.element_size=0.01", "mesh.film_layers=2")

    def simulate(cfg, outdir, comm, progress=True, **_):
        if outdir.name == "time":
            raise RuntimeError("the solver broke")
        return {"status": "buckled", "critical": {"growth_um": 7.0}}

    monkeypatch.setattr(ee, "simulate", simulate)
    out = ee.companion_error_estimate(cfg, 6.8, "/tmp/unused", MPI.COMM_WORLD)
    assert out["mesh_um"] == pytest.approx(0.2 / (2 ** 1.5 - 1), rel=1e-12)
    assert out["time_um"] is None and "RuntimeError: the solver broke" in out["time_note"]


@pytest.mark.skipif(MPI.COMM_WORLD.size < 2, reason="side by side needs two ranks")
def test_side_by_side_gives_every_rank_every_answer(monkeypatch):
    """On 2 ranks each companion runs on its own rank; every rank gets both answers."""
    seen = []

    def simulate(cfg, outdir, comm, progress=True, **_):
        seen.append((outdir.name, comm.size))
        return {"status": "buckled", "critical": {"growth_um": 1.0 if outdir.name == "mesh" else 2.0}}

    monkeypatch.setattr(ee, "simulate", simulate)
    cfg = swelling_case()
    done = ee.side_by_side({"mesh": cfg, "time": cfg}, "/tmp/unused", MPI.COMM_WORLD)
    assert done == {"mesh": {"g": 1.0}, "time": {"g": 2.0}}
    comm = MPI.COMM_WORLD
    group = comm.rank * 2 // comm.size  # contiguous halves, the first one holding rank 0
    assert seen == [(("mesh", "time")[group], sum(1 for r in range(comm.size) if r * 2 // comm.size == group))]
