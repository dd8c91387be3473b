"""The loading in time: a thin, fast-draining layer under a slow surface ramp follows the analytic
equilibrium path of a laterally constrained layer, evaluated at the end of each step (backward Euler
applies the surface potential of t_(n+1), not of t_n)."""

import pytest
from conftest import run_to_end

from app import config
from app.model.theory import constrained_layer_stretch


def test_quasi_static_swelling_follows_equilibrium_at_step_end(comm):
    """Homogeneous layer, h = 2 um (drains in ~h^2/(M alpha) ~ 2 ms), fixed steps of 0.1 s during the
    1 s ramp: after each step the thickness stretch is the analytic equilibrium stretch at
    mu_bar(t_(n+1)) (docs/validation.md, steady constrained layer). Measured: growth within 0.9% of it
    (the drainage lag), while the equilibrium at mu_bar(t_n) is 35-45% away."""
    h = 0.002
    cfg = config.resolve({
        "geometry": {"length": 0.004, "substrate_thickness": h / 2, "film_thickness": h / 2},
        "mesh": {"element_size": 0.002, "film_layers": 2, "substrate_grading": 1.0},
        "material": {"film": {"modulus_ratio": 1.0}},
        "time": {"end": 0.8, "dt_initial": 0.1, "dt_max": 0.1, "adaptive": False},
        "stability": {"enabled": False},
        "output": {"fields": False, "plot": False}})
    p, _, rows = run_to_end(cfg, comm)
    mat = p.materials["substrate"]
    assert [round(r.time, 12) for r in rows] == [round(0.1 * k, 12) for k in range(9)]
    for r in rows[2:]:  # from t = 0.2 on, where the growth is well above the mesh's roundoff
        growth = r.growth_mm / h
        expected = constrained_layer_stretch(mat, p.loading.mu_bar(r.time)) - 1
        assert growth == pytest.approx(expected, rel=0.02), r.time


# --- the loading strategies against hand values ---------------------------------------------------

BILAYER_ROLES = {"left": "roller_x", "right": "roller_x", "bottom": "roller_y", "top": "permeable"}


def test_swelling_ramp_kinks_and_conditions_by_role():
    from app.model.loading import LOADINGS

    lo = LOADINGS.get("swelling")({"chemical_potential": -4.0, "ramp_time": 2.0}, mu_start=-84.0, end_time=10.0)
    assert [lo.mu_bar(t) for t in (-1.0, 0.0, 0.5, 1.0, 2.0, 7.0)] == [-84.0, -84.0, -64.0, -44.0, -4.0, -4.0]
    assert lo.kinks() == [2.0]
    assert lo.applied_strain(5.0) == 0.0 and lo.applied_displacement(5.0) == 0.0
    assert lo.surface_term and lo.kind == "swelling"
    bc = lo.conditions(BILAYER_ROLES)
    assert bc.held == (("left", "right"), ("bottom",), ()) and bc.driven is None and bc.flux_open == ("top",)
    tube = lo.conditions({"inner": "permeable", "outer": "fixed", "side": "free"})
    assert tube.held == (("outer",), ("outer",), ("outer",)) and tube.flux_open == ("inner",)  # z unused in 2D
    plate = lo.conditions({"left": "roller_x", "right": "roller_x", "front": "roller_z", "back": "roller_z",
                           "bottom": "roller_y", "top": "permeable"})
    assert plate.held == (("left", "right"), ("bottom",), ("front", "back")) and plate.flux_open == ("top",)


def test_compression_moves_the_driven_edge_with_diffusion_off():
    from app.geometry import Drive
    from app.model.loading import LOADINGS

    drive = Drive("right", 0, 2.0)
    lo = LOADINGS.get("compression")({"chemical_potential": 0.0, "ramp_time": 1.0, "compression_strain": 0.1},
                                     mu_start=-80.0, end_time=10.0, drive=drive)
    assert lo.applied_strain(0.0) == 0.0 and lo.applied_strain(5.0) == 0.05 and lo.applied_strain(20.0) == 0.1
    assert lo.applied_displacement(5.0) == -0.1 and lo.applied_displacement(20.0) == -0.2
    assert lo.kinks() == [] and not lo.surface_term
    assert lo.mu_bar(0.5) == -40.0  # the ramp is recorded in the history, it does not act
    bc = lo.conditions(BILAYER_ROLES)
    assert bc.held == (("left",), ("bottom",), ()) and bc.driven == drive and bc.flux_open is None


def test_loading_keys_and_kinds_come_from_the_registry():
    from app.model.loading import LOADINGS

    assert LOADINGS.names() == ("swelling", "compression")
    assert config.schema()["loading"]["kind"].default == "swelling"
    cfg = config.resolve({})
    for lo in LOADINGS:
        for name, key in lo.keys.items():
            assert config.schema()["loading"][name] is key and cfg["loading"][name] == key.default
    cfg = config.resolve({}, ["loading.kind=compression", "loading.compression_strain=0.2", "time.end=4"])
    from app import factory

    lo = factory.loading(cfg, mu_start=-1.0)
    assert lo.kind == "compression" and lo.applied_strain(2.0) == 0.1
