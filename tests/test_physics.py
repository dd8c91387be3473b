"""Transient runs against independent references: fluid-volume balance, the analytic steady state
of a laterally constrained layer, the analytic homogeneous compression, and the Terzaghi-type
early-time behaviour through the error-controlled stepping."""

import numpy as np
import pytest
from conftest import run_to_end, small_bilayer
from scipy.optimize import brentq

from app import config
from app.material import Hydrogel, constrained_layer_stretch


def _run(cfg, comm):
    return run_to_end(cfg, comm)


def test_fluid_volume_balance_during_swelling(comm):
    """d/dt int s dV = inflow through the permeable top, step by step (zero flux elsewhere)."""
    cfg = small_bilayer(**{"time.end": 1.2})
    _, st, rows = _run(cfg, comm)
    v0 = rows[0].fluid_volume
    assert rows[-1].inflow > 1e-3 * v0  # fluid really entered
    for r in rows:
        assert r.fluid_volume - v0 == pytest.approx(r.inflow, rel=1e-10, abs=1e-15)
    # swelling is monotone under a rising surface potential
    g = np.array([r.growth_mm for r in rows])
    assert (np.diff(g) > 0).all()


def test_steady_state_of_constrained_layer_matches_analytic_stretch(comm):
    """Homogeneous layer, u_x = 0, traction-free top, mu = 0 -> stretch 4.887, the closed form of eqs.
    3.3-3.4 with F = diag(1, l): P_yy = 0 and mu = mu_bar (docs/validation.md, section 1)."""
    cfg = config.resolve({
        "geometry": {"length": 0.02, "substrate_thickness": 0.02, "film_thickness": 0.005},
        "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.0},
        "material": {"film": {"modulus_ratio": 1.0}},
        "time": {"end": 3000.0, "dt_initial": 0.01, "dt_max": 500.0, "tolerance": 1e-2},
        "output": {"fields": False, "plot": False}})
    p, _, rows = _run(cfg, comm)
    lam = constrained_layer_stretch(p.materials["substrate"], 0.0)
    assert lam == pytest.approx(4.887, abs=1e-3)
    thickness = 0.025
    assert rows[-1].growth_mm == pytest.approx(thickness * (lam - 1), rel=5e-3)
    # and the fluid content is the analytic one: int s = thickness * L * s(lam)
    from app.material import constrained_layer_fluid

    s_exact = constrained_layer_fluid(p.materials["substrate"], lam)
    assert rows[-1].fluid_volume == pytest.approx(thickness * 0.02 * s_exact, rel=5e-3)


def _compression_stretch(mat: Hydrogel, strain: float) -> float:
    """Thickness stretch of a homogeneous, undrained (s = s0) block: F = diag(1 - e, l), P_yy = 0."""
    g, e, J0, s0 = mat.shear_modulus, mat.penalty, mat.preswelling, mat.s0
    a = 1 - strain

    def pyy(lam):
        J = a * lam
        return g / J0 * (J0 ** (2 / 3) * lam - 1 / lam) + e * (J * J0 - 1 - s0) * a

    return brentq(pyy, 0.5, 3.0, xtol=1e-15)


def test_homogeneous_compression_is_undrained_and_matches_analytic(comm):
    strain = 0.08
    cfg = small_bilayer(**{"loading.kind": "compression", "loading.compression_strain": strain,
                           "material.film.modulus_ratio": 1.0, "time.end": 1.0, "time.dt_initial": 0.25,
                           "time.dt_max": 0.25})
    p, _, rows = _run(cfg, comm)
    thickness = 0.06
    lam = _compression_stretch(p.materials["substrate"], strain)
    assert rows[-1].applied_strain == pytest.approx(strain)
    assert rows[-1].growth_mm == pytest.approx(thickness * (lam - 1), rel=1e-8)
    # diffusion is off: the fluid content never changes
    for r in rows:
        assert r.fluid_volume == pytest.approx(rows[0].fluid_volume, rel=1e-13)
        assert r.inflow == 0.0


def _terzaghi(Tv, terms=200):
    m = np.arange(terms)
    k = (2 * m + 1) * np.pi / 2
    return 1 - np.sum(2 / k ** 2 * np.exp(-np.outer(Tv, k ** 2)), axis=1)


def test_small_step_swelling_follows_terzaghi_consolidation(comm):
    """A small jump of the surface potential on a homogeneous constrained layer drained at the top:
    linearized, the fluid content obeys ds/dt = c d2s/dy2 with c = J0^(1/3) M s0 dmu/ds (constrained),
    and the growth fraction follows U(T) = 1 - sum 2/k^2 exp(-k^2 T), T = c t / h^2."""
    from app.material import chemical_potential_value, constrained_layer_fluid

    h = 0.05
    cfg = config.resolve({
        "geometry": {"length": 0.02, "substrate_thickness": 0.04, "film_thickness": 0.01},
        "mesh": {"element_size": 0.01, "film_layers": 8, "substrate_grading": 1.0},
        "material": {"film": {"modulus_ratio": 1.0}},
        "loading": {"ramp_time": 1e-4, "chemical_potential": -83.85},
        "time": {"end": 1.5, "dt_initial": 1e-5, "dt_max": 0.01, "tolerance": 1e-9},
        "output": {"fields": False, "plot": False}})
    p, _, rows = _run(cfg, comm)
    mat = p.materials["substrate"]
    lam_inf = constrained_layer_stretch(mat, cfg["loading"]["chemical_potential"])
    d = 1e-6
    ds = constrained_layer_fluid(mat, 1 + d) - constrained_layer_fluid(mat, 1 - d)
    dmu = (chemical_potential_value(mat, 1 + d, constrained_layer_fluid(mat, 1 + d))
           - chemical_potential_value(mat, 1 - d, constrained_layer_fluid(mat, 1 - d)))
    c = mat.preswelling ** (1 / 3) * mat.mobility * mat.s0 * dmu / ds
    t = np.array([r.time for r in rows])
    U = np.array([r.growth_mm for r in rows]) / (h * (lam_inf - 1))
    Tv = c * t / h ** 2
    sel = (Tv > 0.02) & (Tv < 1.0)
    assert sel.sum() > 10
    assert np.max(np.abs(U[sel] - _terzaghi(Tv[sel]))) < 5e-3  # measured 7e-4 (16 cells through h)
