"""Stability analysis: onset against film-wrinkling theory, inertia vs SLEPc, bisection, stable cases."""

import csv
import json

import pytest

from app import config
from app.run import simulate
from app.theory import film_wrinkling_strain, film_wrinkling_wavelength

SWELLING = {
    "geometry": {"length": 0.3, "substrate_thickness": 0.15, "film_thickness": 0.01},
    "mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
    "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
    "output": {"fields": False, "plot": False},
}


def swelling_case(*overrides) -> dict:
    return config.resolve(SWELLING, list(overrides))


def _history(outdir):
    with open(outdir / "history.csv") as f:
        return list(csv.DictReader(f))


def test_compression_wrinkling_matches_stiff_film_theory(shared_tmp, comm):
    """Undrained compression of a stiff film (ratio 50) on a deep substrate: critical strain within
    10% of eps_c = (1/4)(3 Es/Ef)^(2/3) and wrinkle count within 1 of L/l_c."""
    cfg = config.resolve({
        "geometry": {"length": 1.5, "substrate_thickness": 0.5, "film_thickness": 0.01},
        "mesh": {"element_size": 0.0033, "film_layers": 3, "substrate_grading": 1.25},
        "material": {"film": {"modulus_ratio": 50.0}},
        "loading": {"kind": "compression", "compression_strain": 0.07},
        "time": {"end": 1.0, "dt_initial": 0.05, "dt_max": 0.05},
        "output": {"fields": False, "plot": False}})
    s = simulate(cfg, shared_tmp / "comp", comm)
    assert s["status"] == "buckled"
    from app.problem import layer_materials

    mats = layer_materials(cfg)
    eps_c = film_wrinkling_strain(mats["film"], mats["substrate"])
    l_c = film_wrinkling_wavelength(mats["film"], mats["substrate"], 0.01)
    crit = s["critical"]
    assert crit["applied_strain"] == pytest.approx(eps_c, rel=0.10)  # measured -1.9%
    assert abs(crit["wrinkle_count"] - 1.5 / l_c) <= 1.0  # measured 9.5 vs 10.25


def test_inertia_and_lambda_min_agree_in_sign_on_every_step(shared_tmp, comm):
    cfg = swelling_case("stability.eigen_every=1", "stability.stop_at_onset=false", "stability.max_crossings=2")
    s = simulate(cfg, shared_tmp / "sign", comm)
    assert s["status"] == "buckled"
    rows = _history(shared_tmp / "sign")[1:]
    assert len(rows) > 10
    stable = [int(r["negative_eigenvalues"]) == 0 for r in rows]
    positive = [float(r["lambda_min"]) > 0 for r in rows]
    assert stable == positive
    assert not all(stable)  # the run went past the onset
    # K is positive definite at the crossing's stable end and indefinite at its unstable end
    crit = s["critical"]
    assert crit["lambda_min_before"] > 0 > crit["lambda_min_after"]
    assert crit["bracket"][0] <= crit["time"] <= crit["bracket"][1]


def test_bisection_tolerance_halving_moves_gc_less_than_tolerance(shared_tmp, comm):
    tol = 2e-3
    g = []
    for k, t in enumerate((tol, tol / 2)):
        s = simulate(swelling_case(f"stability.tolerance={t}"), shared_tmp / f"b{k}", comm)
        g.append(s["critical"]["growth_mm"])
        b = s["critical"]["bracket"]
        assert (b[1] - b[0]) <= t * b[1]
    assert abs(g[0] - g[1]) / g[1] < tol


def test_homogeneous_gel_does_not_buckle_early(shared_tmp, comm):
    """Modulus ratio 1 and a short run: K stays positive definite, status "stable", no critical block."""
    cfg = swelling_case("material.film.modulus_ratio=1.0", "time.end=0.5")
    s = simulate(cfg, shared_tmp / "stable", comm)
    assert s["status"] == "stable"
    assert "critical" not in s
    assert all(int(r["negative_eigenvalues"]) == 0 for r in _history(shared_tmp / "stable"))


def test_summary_reports_modes_and_writes_mode_files(shared_tmp, comm):
    cfg = swelling_case("stability.modes=3", "output.plot=true")
    out = shared_tmp / "modes"
    s = simulate(cfg, out, comm)
    crit = s["critical"]
    assert crit["growth_um"] == pytest.approx(1e3 * crit["growth_mm"])
    assert len(crit["modes"]) == 3
    values = [m["eigenvalue"] for m in crit["modes"]]
    assert values == sorted(values) and values[0] < 0
    assert (out / "mode.xdmf").exists() and (out / "mode.png").stat().st_size > 0
    assert json.loads((out / "summary.json").read_text())["status"] == "buckled"
