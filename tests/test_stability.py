"""Stability analysis: onset against film-wrinkling theory, inertia vs SLEPc, bisection, stable cases."""

import csv
import json

import pytest
from cases import swelling_case

from app import config
from app.workflows.run import simulate
from app.model.theory import film_wrinkling_strain, film_wrinkling_wavelength

def _history(outdir):
    with open(outdir / "history.csv") as f:
        return list(csv.DictReader(f))


def test_compression_wrinkling_matches_stiff_film_theory(shared_tmp, comm):
    """Undrained compression of a stiff film (ratio 50) on a deep substrate against plane-strain
    film-on-substrate theory (docs/validation.md): eps_c = (1/4)(3 Es/Ef)^(2/3).

    The strain is measured -1.9% off (finite substrate, nonlinear film, mesh); with the volumetric
    penalty integrated at 2x2 Gauss points (volumetric locking) it was +5.4% at this mesh, so the bound
    of 3% separates the two. The wrinkle count must be one that theory cannot tell from the optimum:
    eps(N)/eps_c = (k/k_c)^2/3 + 2 k_c/(3 k) with k = 2 pi N / L within 1% of 1 (9.5..11 here; the
    model's own strain error of ~2% cannot pick among them)."""
    L = 1.5
    cfg = config.resolve({
        "geometry": {"length": L, "substrate_thickness": 0.5, "film_thickness": 0.01},
        "mesh": {"element_size": 0.0033, "film_layers": 3, "substrate_grading": 1.25},
        "material": {"film": {"modulus_ratio": 50.0}},
        "loading": {"kind": "compression", "compression_strain": 0.07},
        "time": {"end": 1.0, "dt_initial": 0.05, "dt_max": 0.05},
        "output": {"fields": False, "plot": False}})
    s = simulate(cfg, shared_tmp / "comp", comm)
    assert s["status"] == "buckled"
    from app.factory import layer_materials

    mats = layer_materials(cfg)
    eps_c = film_wrinkling_strain(mats["film"], mats["substrate"])
    l_c = film_wrinkling_wavelength(mats["film"], mats["substrate"], 0.01)
    crit = s["critical"]
    assert crit["applied_strain"] == pytest.approx(eps_c, rel=0.03)  # measured -1.9%; locked: +5.4%

    def strain_ratio(n):
        k = n * l_c / L  # k / k_c
        return k ** 2 / 3 + 2 / (3 * k)

    band = [n / 2 for n in range(1, 200) if strain_ratio(n / 2) <= 1.01]
    assert crit["wrinkle_count"] in band, (crit["wrinkle_count"], band)  # measured 9.5; band 9.5..11


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
    lo, hi = crit["bracket"]
    assert lo <= crit["time"] <= hi and hi - lo <= cfg["stability"]["tolerance"] * hi
    # the located crossing agrees with the per-step inertia: stable on every step up to the bracket
    assert all(int(r["negative_eigenvalues"]) == 0 for r in rows if float(r["time"]) <= lo)


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
    assert values == sorted(values)
    # SLEPc's spectrum at the unstable end against the LDL^T inertia there (Sylvester's law): exactly
    # one eigenvalue below zero, and it is the lambda_min the onset was interpolated from
    assert sum(v < 0 for v in values) == crit["negative_eigenvalues"] == 1
    assert values[0] == crit["lambda_min_after"]
    assert (out / "mode.xdmf").exists() and (out / "mode.png").stat().st_size > 0
    # stop_at_onset (default): the run ends on the step that revealed the onset, with one crossing
    assert cfg["stability"]["stop_at_onset"] and "crossings" not in s
    negative = [int(r["negative_eigenvalues"]) > 0 for r in _history(out)]
    assert negative[-1] and not any(negative[:-1])
    assert s["final"]["time"] >= crit["bracket"][1]
    assert json.loads((out / "summary.json").read_text())["status"] == "buckled"
