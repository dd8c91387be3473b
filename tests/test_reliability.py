"""Runs that end for a stated reason (docs/reliability.md): equilibrium, a residual at its roundoff
floor, and a lost stability diagnosed instead of a cut-back spiral.

References: the closed-form steady stretch of a laterally constrained layer in contact with mu_bar
(app/model/theory.py, checked against the law in test_material.py); the same run with the roundoff
acceptance switched off (it fails although its state is converged); the same run without the
diagnosis (it cuts back to dt_min); the inertia of K from an independent exact LDL^T test.
"""

import csv
import json

import pytest

from app import config
from app.model.problem import Problem
from app.model.theory import constrained_layer_stretch
from app.workflows.run import simulate

H = 0.01  # layer thickness [mm]: substrate 0.005 + film 0.005 of the same material


def _layer(gamma, chi, **time):
    """A homogeneous laterally constrained layer (a bilayer with modulus ratio 1), 2 x 2 cells, no
    stability test (a highly swollen gel may lose stability; here only the fundamental path matters)."""
    return config.resolve({
        "geometry": {"length": 0.02, "substrate_thickness": 0.005, "film_thickness": 0.005},
        "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.0},
        "material": {"shear_modulus": gamma, "interaction": chi, "film": {"modulus_ratio": 1.0}},
        "time": {"end": 1e5, "dt_initial": 0.01, "dt_max": 1e4, "tolerance": 1e-2, **time},
        "stability": {"enabled": False},
        "output": {"fields": False, "plot": False}}, [])


def _read(outdir):
    with open(outdir / "summary.json") as f:
        summary = json.load(f)
    with open(outdir / "history.csv") as f:
        rows = list(csv.DictReader(f))
    return summary, rows


@pytest.mark.parametrize("gamma,chi", [(0.1, 0.1), (0.1, 0.4), (0.5, 0.1), (0.5, 0.4)])
def test_run_stops_at_equilibrium_with_the_analytic_thickness(gamma, chi, comm, shared_tmp):
    """time.stop_at_equilibrium = 1e-3 ends the run with status "equilibrium" long before time.end,
    at the analytic thickness H lambda(mu_bar = 0) within 0.5% (measured 4.0e-5, 2.9e-5, 7.0e-6,
    3.6e-5 short of it, serially and on 2 ranks: the uptake still missing is below 1e-3 of the uptake)."""
    cfg = _layer(gamma, chi, stop_at_equilibrium=1e-3)
    summary = simulate(cfg, shared_tmp, comm, progress=False)
    on_disk, rows = _read(shared_tmp)
    assert summary["status"] == on_disk["status"] == "equilibrium"
    assert "equilibrium at t =" in on_disk["message"]
    assert on_disk["final"]["time"] < 1e-2 * cfg["time"]["end"]  # measured 14-106 s of 1e5 s
    assert len(rows) == on_disk["steps"] + 1
    mat = Problem.from_config(cfg, comm).materials["substrate"]
    lam = constrained_layer_stretch(mat, 0.0)
    thickness = H + on_disk["final"]["growth_mm"]
    assert thickness / (H * lam) - 1 == pytest.approx(0.0, abs=5e-3)
    assert abs(thickness / (H * lam) - 1) < 1e-4  # tighter: what the threshold promises here
    assert thickness < H * lam  # still approaching from below: no overshoot


def test_equilibrium_stop_is_off_by_default(comm, shared_tmp):
    cfg = _layer(0.5, 0.4, end=100.0)
    assert cfg["time"]["stop_at_equilibrium"] == 0.0
    summary = simulate(cfg, shared_tmp, comm, progress=False)
    assert summary["status"] == "completed" and summary["final"]["time"] == pytest.approx(100.0)
