"""A clamped base (``geometry.base = "clamped"``: u = 0 at the substrate's base instead of rollers, u_y = 0).

The laterally uniform state does not see the difference; the modes do: a clamped base holds a mode's u_x
too, which stiffens a thin substrate. The exact 1D reduction holds its modes the same way, so it certifies
both bases:
- the 2D bilayer on a thin substrate (0.03 mm, a third of the wavelength), each base within its 2D error bar
  of its own 1D answer, with the 1D N_c; and the clamp's effect on g_c (+6% in 1D) reproduced by the 2D runs
  to within 10% of itself (measured 3.8%: the mesh errors of the two runs cancel in the difference);
- the 3D plate one element wide with a clamped base is the 2D bilayer with a clamped base (1e-8);
- a clamped base under a compression (which moves the right edge's u_x) is a one-line ConfigError."""

from __future__ import annotations

import pytest

from app import config
from app.schema import ConfigError
from app.workflows.pipeline import run_case
from app.workflows.run import simulate

THIN = ["geometry.substrate_thickness=0.03", "geometry.length=0.5", "output.fields=false", "output.plot=false"]


@pytest.mark.slow
def test_the_clamped_and_the_rollered_base_each_meet_their_1d_answer(shared_tmp, comm):
    runs = {}
    for base in ("rollers", "clamped"):
        cfg = config.load("configs/bilayer.toml", THIN + [f"geometry.base={base}"])
        runs[base] = run_case(cfg, shared_tmp / base, comm, progress=False)
    for base, s in runs.items():
        c, r = s["critical"], s["reduced"]
        bar = c["discretization_error"]["total_um"]
        assert abs(c["growth_um"] - r["growth_um"]) <= bar, (base, c["growth_um"], r["growth_um"], bar)
        assert c["wrinkle_count"] == r["wrinkle_count"], base
    d2 = runs["clamped"]["critical"]["growth_um"] - runs["rollers"]["critical"]["growth_um"]
    d1 = runs["clamped"]["reduced"]["growth_um"] - runs["rollers"]["reduced"]["growth_um"]
    assert d1 > 0.05 * runs["rollers"]["reduced"]["growth_um"]  # the clamp matters on this substrate
    assert abs(d2 - d1) <= 0.1 * d1, (d2, d1)


def test_a_clamped_plate_one_element_wide_is_the_clamped_bilayer(shared_tmp, comm):
    common = {"geometry": {"length": 0.1, "substrate_thickness": 0.05, "film_thickness": 0.01, "base": "clamped"},
              "mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
              "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
              "stability": {"error_estimate": False}, "output": {"fields": False, "plot": False},
              "reduced": {"beside_2d": False}}
    flat = simulate(config.resolve({**common, "geometry": {**common["geometry"], "kind": "bilayer"}}, []),
                    shared_tmp / "c2d", comm, progress=False)
    slab = simulate(config.resolve({**common, "geometry": {**common["geometry"], "kind": "plate", "width": 0.005}},
                                   []), shared_tmp / "c3d", comm, progress=False)
    a, b = flat["critical"], slab["critical"]
    assert flat["status"] == slab["status"] == "buckled" and flat["steps"] == slab["steps"]
    assert abs(b["growth_mm"] - a["growth_mm"]) <= 1e-8 * a["growth_mm"]
    rollers = simulate(config.resolve({**common, "geometry": {**common["geometry"], "kind": "bilayer",
                                                              "base": "rollers"}}, []),
                       shared_tmp / "r2d", comm, progress=False)
    assert rollers["critical"]["growth_mm"] < a["growth_mm"]  # the clamp is felt: it is not the rollered run


def test_a_clamped_base_under_compression_is_refused():
    with pytest.raises(ConfigError, match=r"geometry\.base.*'clamped'.*allowed with loading.kind = 'compression'"):
        config.load("configs/bilayer.toml", ["geometry.base=clamped", "loading.kind=compression"])
