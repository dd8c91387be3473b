"""Three dimensions (docs/three-d.md): the plate against independent references.

- A plate one element wide with u_z = 0 on both faces is the plane-strain bilayer on the same x-y mesh: its
  incremental potential is the width times the bilayer's for z-independent fields, so the two runs must
  agree to the solvers' roundoff (measured 1e-14 in g_c, 1 and 2 ranks), step for step.
- A square plate's onset against the exact 1D reduction: the laterally uniform state is the bilayer's, and
  a mode cos(m pi x / L) cos(n pi z / W) is critical where |k| meets the 1D margin curve, so the plate's g_c is
  the 1D minimum over the lattice of |k| (within the 3D run's own error bar), and its critical wave vectors
  are that lattice point's (m, n): on a square, (1, 0) and (0, 1) crossing together.
- The plate on 1 and 2 ranks, and a checkpoint resumed: the same run.
- The surface's wave-vector measure on analytic fields, and the lattice on Pythagorean triples.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import REPO, on_rank0, read_csv, same_rows, same_summary
from mpi4py import MPI

from app import config
from app.io import checkpoint
from app.model.surface import plane_count, plane_modes, plane_wave_vector
from app.workflows.pipeline import run_case
from app.workflows.run import simulate

SECTION = {"length": 0.1, "substrate_thickness": 0.05, "film_thickness": 0.01}
COMMON = {"mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
          "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
          "stability": {"error_estimate": False}, "output": {"fields": False, "plot": False},
          "reduced": {"beside_2d": False}}
# a square plate 0.05 mm wide: the 1D margin curve's minimum (a wavelength near 0.1 mm) falls on the lattice
# points (1, 0) and (0, 1); the next, (1, 1), is 41% further in |k| and 8% later
SQUARE = {"geometry": {"kind": "plate", "length": 0.05, "width": 0.05, "substrate_thickness": 0.05},
          "mesh": {"element_size": 0.00625, "film_layers": 2, "substrate_grading": 1.25},
          "time": {"end": 1.5}, "output": {"fields": False, "plot": False}}


def _case(kind: str, **geometry) -> dict:
    return config.resolve({**COMMON, "geometry": {**SECTION, "kind": kind, **geometry}}, [])


def test_a_plate_one_element_wide_is_the_plane_strain_bilayer(shared_tmp, comm):
    """The same steps, growth and onset as the bilayer on the plate's x-y mesh; the fluid volume is the width
    times the bilayer's (per unit depth)."""
    width = COMMON["mesh"]["element_size"]
    flat = simulate(_case("bilayer"), shared_tmp / "2d", comm, progress=False)
    slab = simulate(_case("plate", width=width), shared_tmp / "3d", comm, progress=False)
    assert slab["mesh"]["elements_across_width"] == 1 and slab["mesh"]["cells"] == flat["mesh"]["cells"]
    a, b = flat["critical"], slab["critical"]
    assert flat["status"] == slab["status"] == "buckled" and flat["steps"] == slab["steps"]
    assert abs(b["growth_mm"] - a["growth_mm"]) <= 1e-8 * a["growth_mm"]
    assert abs(b["time"] - a["time"]) <= 1e-8 * a["time"]
    assert b["wrinkle_count"] == a["wrinkle_count"] and b["modes"][0]["wave_vector"][1] == 0
    rows_2d, rows_3d = read_csv(shared_tmp / "2d" / "history.csv"), read_csv(shared_tmp / "3d" / "history.csv")
    assert len(rows_2d) == len(rows_3d)
    for r2, r3 in zip(rows_2d, rows_3d):
        for key in ("time", "growth_mm", "mu_bar"):
            assert abs(float(r3[key]) - float(r2[key])) <= 1e-8 * max(abs(float(r2[key])), 1e-12), key
        assert abs(float(r3["fluid_volume"]) - width * float(r2["fluid_volume"])) <= 1e-8 * width * float(
            r2["fluid_volume"])
        assert r3["newton_its"] == r2["newton_its"]


@pytest.mark.slow
def test_a_square_plate_buckles_at_the_1d_lattice_minimum(shared_tmp, comm):
    """g_c within the 3D error bar of the 1D reduction's minimum over the plate's lattice of |k|; two modes
    cross together, (1, 0) and (0, 1), the lattice point the 1D answer names."""
    summary = run_case(config.resolve(SQUARE, []), shared_tmp / "square", comm, progress=False)
    c, r = summary["critical"], summary["reduced"]
    bar = c["discretization_error"]["total_um"]
    assert r["kind"] == "wrinkles" and sorted(map(tuple, r["wave_vectors"])) == [(0, 1), (1, 0)]
    assert abs(c["growth_um"] - r["growth_um"]) <= bar, (c["growth_um"], r["growth_um"], bar)
    assert bar <= 0.05 * c["growth_um"]
    assert c["multiplicity"] == 2
    assert sorted(tuple(m["wave_vector"]) for m in c["modes"][:2]) == [(0, 1), (1, 0)]
    assert c["modes"][2]["eigenvalue"] > 0  # the next mode, (1, 1), has not crossed
    # the lattice point is pi / L: N = |k| L / (2 pi) = 1/2 along the plate, as the 1D answer counts it
    assert r["wrinkle_count"] == pytest.approx(0.5, rel=1e-12) and c["wrinkle_count"] == pytest.approx(0.5)


@pytest.mark.skipif(MPI.COMM_WORLD.size != 2, reason="compares a 1-rank and a 2-rank run")
def test_a_plate_on_one_and_two_ranks(shared_tmp, comm):
    cfg = config.resolve({**SQUARE, "stability": {"error_estimate": False}, "reduced": {"beside_2d": False}}, [])
    world = simulate(cfg, shared_tmp / "two", comm, progress=False)
    one = on_rank0(simulate, cfg, shared_tmp / "one", MPI.COMM_SELF, progress=False)
    same_summary(one, world, 1e-8)
    same_rows(read_csv(shared_tmp / "one" / "history.csv"), read_csv(shared_tmp / "two" / "history.csv"), 1e-8)


def test_a_plate_resumes_like_an_uninterrupted_run(shared_tmp, comm):
    """Stopped after 8 steps (a checkpoint keyed by hexahedral faces), resumed: the same history and onset."""
    cfg = config.resolve({**SQUARE, "stability": {"error_estimate": False}, "reduced": {"beside_2d": False},
                          "output": {**SQUARE["output"], "checkpoint_every": 3}}, [])
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    part = shared_tmp / "part"
    stopped = simulate(cfg, part, comm, progress=False, stop_after=8)
    assert stopped["status"] == "interrupted" and full["steps"] > 11
    resumed = simulate(cfg, part, comm, progress=False, resume=checkpoint.check(part, cfg, comm))
    same_rows(read_csv(shared_tmp / "full" / "history.csv"), read_csv(part / "history.csv"), 1e-10)
    same_summary(full, resumed, 1e-10)


def _grid(nx: int, nz: int, L: float, W: float):
    x, z = np.meshgrid(np.linspace(0, L, nx + 1), np.linspace(0, W, nz + 1), indexing="ij")
    return np.column_stack([x.ravel(), z.ravel()])


@pytest.mark.parametrize("m, n", [(2, 1), (0, 3), (5, 0), (4, 4)])
def test_the_wave_vector_of_an_analytic_surface_field(m, n):
    """cos(m pi x / L) cos(n pi z / W) (plus a uniform swelling) on a 32 x 24 grid: its (m, n), all of its
    energy there, and its count |k| L / (2 pi)."""
    L, W = 0.3, 0.2
    pos = _grid(32, 24, L, W)
    f = 0.7 + np.cos(m * math.pi * pos[:, 0] / L) * np.cos(n * math.pi * pos[:, 1] / W)
    assert plane_wave_vector(pos, f) == (m, n)
    energy, sides = plane_modes(pos, f - 0.7)
    assert energy[m, n] == pytest.approx(1.0, rel=1e-9) and np.allclose(sides, (L, W))
    assert plane_count(m, n, sides) == pytest.approx(math.hypot(m / L, n / W) * L / 2)


def test_the_plate_lattice_lists_equal_wavenumbers_together():
    """On a square, |k| = 5 pi / L is reached by (0, 5), (3, 4), (4, 3) and (5, 0) (a Pythagorean triple), and
    the lattice is increasing from pi / L."""
    from app import factory

    cfg = config.resolve({"geometry": {"kind": "plate", "length": 0.25, "width": 0.25}}, [])
    sec = factory.section(cfg)
    ks, pairs = sec.lattice()
    assert ks[0] == pytest.approx(math.pi / 0.25) and (np.diff(ks) > 0).all()
    i = int(np.argmin(abs(ks - 5 * math.pi / 0.25)))
    assert sorted(pairs[i]) == [(0, 5), (3, 4), (4, 3), (5, 0)]
    assert sec.wavenumber(i + 1) == ks[i] and sec.wrinkle_count(i + 1) == pytest.approx(2.5)


@pytest.mark.parametrize("setting, value", [("contact", True), ("creases", True), ("after_onset", "branch")])
def test_the_2d_only_options_are_refused_for_a_plate_with_one_line(shared_tmp, capsys, setting, value):
    """Self-contact, the trial crease and the branch's end checks read the surface as a curve: a plate config
    asking for them gets one line naming the key and what is allowed, exit 2, and no result directory."""
    from app import cli

    out = shared_tmp / f"refused-{setting}"
    text = f"{value}".lower() if isinstance(value, bool) else f'"{value}"'
    code = cli.main(["run", str(REPO / "configs" / "plate.toml"), "--set", f"stability.{setting}={text}", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    if MPI.COMM_WORLD.rank == 0:
        line = [ln for ln in err.splitlines() if ln.startswith("hydrobuckle: error:")]
        assert len(line) == 1 and f"'stability.{setting}'" in line[0] and "2D only; allowed for" in line[0]


def test_a_rectangular_plate_lattice_weighs_each_side_by_its_length():
    """L = 0.3, W = 0.2: |k| = pi sqrt((m / L)^2 + (n / W)^2) in increasing order, (1, 0), (0, 1), (1, 1),
    (2, 0), each alone, and the count is |k| L / (2 pi)."""
    from app import factory

    L, W = 0.3, 0.2
    sec = factory.section(config.resolve({"geometry": {"kind": "plate", "length": L, "width": W}}, []))
    ks, pairs = sec.lattice()
    expected = [(1, 0), (0, 1), (1, 1), (2, 0)]
    assert [sorted(map(tuple, p)) for p in pairs[:4]] == [[w] for w in expected]
    for i, (m, n) in enumerate(expected):
        assert ks[i] == pytest.approx(math.pi * math.hypot(m / L, n / W), rel=1e-12)
        assert sec.wrinkle_count(i + 1) == pytest.approx(plane_count(m, n, (L, W)), rel=1e-12)
