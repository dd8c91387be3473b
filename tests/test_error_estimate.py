"""The error bar's honesty (stability.error_estimate): the error a run reports for its g_c covers the run's
distance to the converged value, taken from a refinement sequence computed here, independently of the
estimate (its companions are coarser; the sequence is finer), with its own Richardson extrapolation.

Case: the 0.3 mm bilayer strip (tests/cases.py SWELLING) at element 0.01 mm / 2 film layers, the level whose
bar is tested; mesh levels 0.005/4, 0.0025/8, 0.00125/16 and time levels tolerance / 4, / 16, / 64 give
the limits. Measured (serial): g = 6.8959 um; mesh bar 0.2090 um for a distance 0.2000 um to the mesh limit
6.6959 um; time bar 0.0684 um (its companion on the coarse mesh; 0.0598 um on the run's mesh) for a distance
0.0569 um to the time limit 6.9528 um (of the run's mesh); total bar 0.277 um for 0.143 um. Before the time companion's step bounds were coarsened with its tolerance (dt_max held the steps
of the slow phase, so the companion was less than 2x coarser) the time bar was 0.0446 um: 22% short."""

from __future__ import annotations

import math

import pytest
from cases import swelling_case
from mpi4py import MPI

from app.workflows.pipeline import run_case
from app.workflows.run import simulate

BASE = ("mesh.element_size=0.01", "mesh.film_layers=2")


def _limit(values: list[float], ratio: float = 2.0) -> float:
    """Richardson limit of the last three values of a sequence refined by ``ratio`` (observed order)."""
    g0, g1, g2 = values[-3:]
    p = math.log(abs(g0 - g1) / abs(g1 - g2)) / math.log(ratio)
    return g2 + (g2 - g1) / (ratio ** p - 1)


@pytest.fixture(scope="module")
def sequences(tmp_path_factory):
    comm = MPI.COMM_WORLD
    base = tmp_path_factory.mktemp("err") if comm.rank == 0 else None
    from pathlib import Path

    base = Path(comm.bcast(str(base) if base else None))
    cfg = swelling_case(*BASE)
    summary = run_case(cfg, base / "level", comm, progress=False)  # the run and its two companions
    tol = cfg["time"]["tolerance"]
    mesh = [summary["critical"]["growth_um"]]
    for k in (1, 2, 3):
        c = swelling_case(f"mesh.element_size={0.01 / 2 ** k}", f"mesh.film_layers={2 * 2 ** k}",
                          "stability.error_estimate=false")
        mesh.append(simulate(c, base / f"mesh{k}", comm, progress=False)["critical"]["growth_um"])
    time = [summary["critical"]["growth_um"]]
    for k in (1, 2, 3):
        t = cfg["time"]  # refined as a converge level is (steps x 2: tolerance / 4, step bounds / 2)
        c = swelling_case(*BASE, f"time.tolerance={tol / 4 ** k}", f"time.dt_initial={t['dt_initial'] / 2 ** k}",
                          f"time.dt_max={t['dt_max'] / 2 ** k}", "stability.error_estimate=false")
        time.append(simulate(c, base / f"time{k}", comm, progress=False)["critical"]["growth_um"])
    return summary, mesh, time


def test_reported_error_covers_the_distance_to_the_converged_value(sequences):
    """Each part of the bar covers its own distance (mesh: to the mesh limit at the run's time tolerance;
    time: to the time limit on the run's mesh), and the total covers both together; the bar is not
    vacuous either: at most 4x the distance it has to cover."""
    summary, mesh, time = sequences
    g = summary["critical"]["growth_um"]
    err = summary["critical"]["discretization_error"]
    assert err["mesh_companion"] == "coarsened" and err["time_companion"] == "coarsened"
    assert err["time_companion_mesh"] == "coarsened"
    d_mesh, d_time = abs(g - _limit(mesh)), abs(g - _limit(time))
    assert all(abs(a - b) > abs(b - c) for a, b, c in zip(mesh, mesh[1:], mesh[2:])), mesh  # converging
    assert all(abs(a - b) > abs(b - c) for a, b, c in zip(time, time[1:], time[2:])), time
    assert d_mesh <= err["mesh_um"] <= 4 * d_mesh, (d_mesh, err, mesh)
    assert d_time <= err["time_um"] <= 4 * d_time, (d_time, err, time)
    assert abs(g - (_limit(mesh) + _limit(time) - g)) <= err["total_um"]
