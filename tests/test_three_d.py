"""Three dimensions (docs/three-d.md): the plate and the 3D tube against independent references.

- A plate one element wide with u_z = 0 on both faces is the plane-strain bilayer on the same x-y mesh: its
  incremental potential is the width times the bilayer's for z-independent fields, so the two runs must
  agree to the solvers' roundoff (measured 1e-14 in g_c, 1 and 2 ranks), step for step, and the slab stores
  its width's worth of the bilayer's energy (the plane-strain law is the 3D one with F33 = 1). The same for
  a 3D tube one element long against the 2D tube.
- A square plate's onset against the exact 1D reduction: the laterally uniform state is the bilayer's, and
  a mode cos(m pi x / L) cos(n pi z / W) is critical where |k| meets the 1D margin curve, so the plate's g_c is
  the 1D minimum over the lattice of |k| (within the 3D run's own error bar), and its critical wave vectors
  are that lattice point's (m, n): on a square, (1, 0) and (0, 1) crossing together. The 3D tube against the
  polar 1D reduction of its axially uniform modes, also with the axial mesh halved.
- The plate and tube on 1 and 2 ranks, and a checkpoint resumed: the same run.
- The surface's wave-vector measures on analytic fields, and the lattice on Pythagorean triples.
- Past the onset: competing branches of a double onset (mirror images, squares, energy below the unbuckled
  path), on 1 and 2 ranks and resumed; the overhang test on an analytic field (the pattern rules:
  tests/test_patterns.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import REPO, long_physics, on_rank0, read_csv, same_rows, same_summary
from mpi4py import MPI

from app import config
from app.io import checkpoint
from app.model.shapes3d import plane_count, plane_modes, plane_wave_vector
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
        for key in ("fluid_volume", "energy"):  # per unit depth in 2D: the 3D slab holds its width's worth
            assert abs(float(r3[key]) - width * float(r2[key])) <= 1e-8 * width * abs(float(r2[key])), key
        assert r3["newton_its"] == r2["newton_its"]


@pytest.mark.slow
def test_a_square_plate_buckles_at_the_1d_lattice_minimum(shared_tmp, comm):
    """g_c within the 3D error bar of the 1D reduction's minimum over the plate's lattice of |k|; two modes
    cross together, (1, 0) and (0, 1), the lattice point the 1D answer names."""
    summary = run_case(config.resolve(SQUARE, []), shared_tmp / "square", comm, progress=False)
    c, r = summary["critical"], summary["reduced"]
    bar = c["discretization_error"]["total_um"]
    assert r["kind"] == "wrinkles" and sorted(map(tuple, r["wave_vectors"])) == [(0, 1), (1, 0)]
    assert "first_3d_mode" not in r  # the 3D's first mode is the 1D's: nothing to place
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


@pytest.mark.parametrize("kind", ["plate", "tube-3d"])
@pytest.mark.parametrize("sets, setting", [(["stability.creases=true"], "creases"),
                                           (["stability.contact=true", 'stability.contact_energy="penalty"'],
                                            "contact_energy")])
def test_the_2d_only_options_are_refused_in_3d_with_one_line(shared_tmp, capsys, sets, setting, kind):
    """The trial crease and the contact penalty read the surface as a curve: a plate or 3D tube config asking
    for them gets one line naming the key and what is allowed, exit 2, and no result directory (3D contact is
    the barrier's: tests/test_barrier.py)."""
    from app import cli

    out = shared_tmp / f"refused-{kind}-{setting}"
    args = [a for kv in sets for a in ("--set", kv)]
    code = cli.main(["run", str(REPO / "configs" / f"{kind}.toml"), *args, "-o", str(out)])
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


# --- the 3D tube --------------------------------------------------------------------------------------------
# a small tube with the paper's materials (configs/tube-3d.toml's section): its passage (r = 0.14 mm) wrinkles
# with about 10 waves around
TUBE = {"geometry": {"kind": "tube", "outer_radius": 0.2, "substrate_thickness": 0.05, "film_thickness": 0.01},
        "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.25},
        "time": {"end": 1.5, "dt_initial": 0.001, "dt_max": 0.05},
        "stability": {"error_estimate": False}, "output": {"fields": False, "plot": False},
        "reduced": {"beside_2d": False}}


def _tube(kind: str, **geometry) -> dict:
    return config.resolve({**TUBE, "geometry": {**TUBE["geometry"], "kind": kind, **geometry}}, [])


@pytest.mark.parametrize("kinds, extra", [(("tube", "tube-3d"), {}),
                                          (("elliptic-tube", "elliptic-tube-3d"), {"aspect_ratio": 1.5})])
def test_a_tube_one_element_long_is_the_plane_strain_tube(shared_tmp, comm, kinds, extra):
    """Ends on rollers one element apart: u_z = 0 throughout, and the 3D tube's incremental potential is its
    length times the 2D tube's, so the two runs agree to the solvers' roundoff (measured 4e-15 in g_c), step
    for step, with the fluid volume the length times the 2D one; the critical modes are axially uniform. The
    same for the elliptic passage, whose growth (the minor-axis vertex's inward displacement) is the vertex
    line's average along the axis in 3D."""
    length = TUBE["mesh"]["element_size"]
    flat = simulate(_tube(kinds[0], **extra), shared_tmp / "2d", comm, progress=False)
    tube = simulate(_tube(kinds[1], length=length, **extra), shared_tmp / "3d", comm, progress=False)
    assert tube["mesh"]["elements_along_axis"] == 1 and tube["mesh"]["cells"] == flat["mesh"]["cells"]
    a, b = flat["critical"], tube["critical"]
    assert flat["status"] == tube["status"] == "buckled" and flat["steps"] == tube["steps"]
    assert abs(b["growth_mm"] - a["growth_mm"]) <= 1e-8 * a["growth_mm"]
    assert abs(b["time"] - a["time"]) <= 1e-8 * a["time"]
    assert b["wrinkle_count"] == a["wrinkle_count"] and b["multiplicity"] == a["multiplicity"]
    assert a["multiplicity"] == (2 if kinds[0] == "tube" else 4)  # cos and sin n theta; the ellipse's 10 and 9
    assert [m["wave_vector"] for m in b["modes"]] == [[m2["wrinkle_count"], 0] for m2 in a["modes"]]
    rows_2d, rows_3d = read_csv(shared_tmp / "2d" / "history.csv"), read_csv(shared_tmp / "3d" / "history.csv")
    assert len(rows_2d) == len(rows_3d)
    for r2, r3 in zip(rows_2d, rows_3d):
        for key in ("time", "growth_mm", "mu_bar"):
            assert abs(float(r3[key]) - float(r2[key])) <= 1e-8 * max(abs(float(r2[key])), 1e-12), key
        for key in ("fluid_volume", "energy"):  # the 3D tube holds its length's worth of the 2D one
            assert abs(float(r3[key]) - length * float(r2[key])) <= 1e-8 * length * abs(float(r2[key])), key
        assert r3["newton_its"] == r2["newton_its"]


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size != 2, reason="compares a 1-rank and a 2-rank run")
def test_a_3d_tube_on_one_and_two_ranks(shared_tmp, comm):
    cfg = _tube("tube-3d", length=0.04)
    world = simulate(cfg, shared_tmp / "two", comm, progress=False)
    one = on_rank0(simulate, cfg, shared_tmp / "one", MPI.COMM_SELF, progress=False)
    same_summary(one, world, 1e-8)
    same_rows(read_csv(shared_tmp / "one" / "history.csv"), read_csv(shared_tmp / "two" / "history.csv"), 1e-8)


@pytest.mark.parametrize("n, m", [(9, 0), (3, 2), (0, 1), (12, 5)])
def test_the_wave_vector_of_an_analytic_field_on_a_cylinder(n, m):
    """cos(n theta + 0.3) cos(m pi z / L_z) (plus a uniform swelling) on 64 x 10 nodes of a passage: its
    (n, m), all of its energy there, whatever the phase around."""
    from app.model.shapes3d import CylinderSurface, cylinder_modes

    r, Lz = 0.14, 0.1
    theta, z = np.meshgrid(np.linspace(0, 2 * math.pi, 64, endpoint=False), np.linspace(0, Lz, 10), indexing="ij")
    theta, z = theta.ravel(), z.ravel()
    coords = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])
    radial = 0.7 + np.cos(n * theta + 0.3) * np.cos(m * math.pi * z / Lz)
    disp = np.column_stack([radial * np.cos(theta), radial * np.sin(theta), np.zeros_like(z)])
    shape = CylinderSurface()
    assert shape.wave_vector(coords, disp) == (n, m) and shape.mode_count(coords, disp) == n
    position, profile, _ = shape._project(coords, disp)
    energy = cylinder_modes(position, profile - 0.7)
    assert energy[n, m] == pytest.approx(1.0, rel=1e-9)


def test_the_3d_tube_reduces_to_the_polar_section_with_axially_uniform_modes():
    """The 1D reduction of a 3D tube is the 2D tube's section; its mode n is the wave vector (n, 0)."""
    from app import factory

    tube, tube3d = factory.section(_tube("tube")), factory.section(_tube("tube-3d", length=0.1))
    assert tube3d.layers == tube.layers and tube3d.surface == tube.surface and tube3d.base == tube.base
    assert tube3d.wave_vectors(10) == [(10, 0)] and tube.wave_vectors(10) is None
    assert tube3d.wavenumber(10) == tube.wavenumber(10) == 10.0


@pytest.mark.slow
@long_physics
def test_a_3d_tube_buckles_within_its_error_bar_of_the_polar_1d_minimum_also_on_a_finer_axial_mesh(shared_tmp, comm):
    """configs/tube-3d.toml: g_c within the 3D error bar of the 1D reduction's (axially uniform) minimum, whose
    wave vector is (n, 0); halving the elements along the axis moves g_c by less than that bar (the axial mesh
    is inside the error estimate) and keeps it within the bar of the 1D value. Whichever mode comes first, an
    axially uniform one or one with axial half-waves (measured: (9, 0) at the config's mesh, (8, 1) 0.25%
    earlier with the axial mesh halved), it crosses within the bar of the 1D minimum."""
    path, quiet = REPO / "configs" / "tube-3d.toml", ["output.fields=false", "output.plot=false"]
    summary = run_case(config.load(path, quiet), shared_tmp / "tube", comm, progress=False)
    c, r = summary["critical"], summary["reduced"]
    bar = c["discretization_error"]["total_um"]
    assert r["kind"] == "wrinkles" and r["wave_vectors"] == [[r["mode_number"], 0]]
    assert abs(c["growth_um"] - r["growth_um"]) <= bar, (c["growth_um"], r["growth_um"], bar)
    assert bar <= 0.08 * c["growth_um"] and c["multiplicity"] == 2  # cos and sin of one n around
    finer = config.load(path, [*quiet, "geometry.axial_element_ratio=0.5", "stability.error_estimate=false",
                               "reduced.beside_2d=false"])
    fine = simulate(finer, shared_tmp / "axial", comm, progress=False)
    assert fine["mesh"]["elements_along_axis"] == 2 * summary["mesh"]["elements_along_axis"]
    g = fine["critical"]["growth_um"]
    assert abs(g - c["growth_um"]) <= bar and abs(g - r["growth_um"]) <= bar, (g, c["growth_um"], bar)


def test_an_overhanging_surface_is_found_where_it_turns_over():
    """A plate's top displaced along x by u_x = a cos(k x) (and a small u_y): the surface overhangs only where
    dx/dX = 1 - a k sin(k X) < 0, which needs a k > 1, and it is found there."""
    from app.model.shapes3d import PlaneSurface

    L, W, n = 0.1, 0.05, 40
    x, z = np.meshgrid(np.linspace(0, L, n + 1), np.linspace(0, W, n // 2 + 1), indexing="ij")
    coords = np.column_stack([x.ravel(), np.full(x.size, 0.06), z.ravel()])
    k = 2 * math.pi / L
    for a, folds in ((0.5 / k, False), (2.0 / k, True)):  # u_x = a cos(k x): dx/dX = 1 - a k sin(k X)
        disp = np.column_stack([a * np.cos(k * x.ravel()), 0.01 * np.sin(k * x.ravel()), np.zeros(x.size)])
        where = PlaneSurface().overhang(coords, disp)
        assert (where is not None) == folds
        if folds:  # where 1 - a k sin(k X) < 0: L / 12 < X < 5 L / 12
            assert L / 12 - L / n < where[0] < 5 * L / 12 + L / n and where[1] == pytest.approx(0.06)


# --- past the onset in 3D -----------------------------------------------------------------------------------
# configs/plate-branches.toml: a square plate two wavelengths wide, (2, 0) and (0, 2) crossing together,
# followed to t = 1 s (1.34 g_c)
QUIET = ["output.fields=false", "output.plot=false", "reduced.beside_2d=false"]


def _branch(modes: str | None = None, **stability) -> dict:
    extra = [f'stability.branch_modes="{modes}"'] if modes else []
    extra += [f'stability.{k}="{v}"' for k, v in stability.items()]
    return config.load(REPO / "configs" / "plate-branches.toml", QUIET + extra)


def _grand_potential(rows: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    t = np.array([float(r["time"]) for r in rows])
    return t, np.array([float(r["energy"]) - float(r["mu_bar"]) * float(r["fluid_volume"]) for r in rows])


@pytest.mark.slow
@long_physics
def test_the_competing_branches_of_a_square_plate(shared_tmp, comm):
    """At the double onset (2, 0) & (0, 2): the branches started from the pure stripes (2, 0) and (0, 2) are
    mirror images (the same energy, fluid and amplitude at every step, to 1e-9: measured 1.3e-10 in the
    amplitude, 1e-13 in the energy); the one started from both
    is squares at every reported state; every followed branch holds less grand potential (Psi - mu V) than
    the unbuckled path at the same time, and releases more of it as it grows (energy decreases along the
    followed path relative to the path it left)."""
    runs = {m: simulate(_branch(m), shared_tmp / m.replace(":", "").replace("+", "_"), comm, progress=False)
            for m in ("2:0", "0:2", "2:0+0:2")}
    flat = simulate(_branch(after_onset="fundamental"), shared_tmp / "flat", comm, progress=False)
    for s in runs.values():
        assert s["status"] == "buckled" and sorted(tuple(m["wave_vector"]) for m in s["critical"]["modes"][:2]) == \
            [(0, 2), (2, 0)] and s["critical"]["multiplicity"] == 2
    rows = {m: read_csv(shared_tmp / m.replace(":", "").replace("+", "_") / "history.csv") for m in runs}
    a, b = rows["2:0"], rows["0:2"]
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        for key in ("time", "energy", "fluid_volume", "amplitude_mm", "growth_mm"):
            assert abs(float(ra[key]) - float(rb[key])) <= 1e-9 * max(abs(float(ra[key])), 1e-12), key
    squares = runs["2:0+0:2"]["postbuckling"]["patterns"]
    assert len(squares) >= 3 and all(p["pattern"] == "squares" for p in squares)
    tf, gf = _grand_potential(read_csv(shared_tmp / "flat" / "history.csv"))
    for m, s in runs.items():
        t, g = _grand_potential(rows[m])
        t_switch = s["postbuckling"]["switches"][0]["time"]
        later = t > t_switch + 0.02
        release = np.interp(t[later], tf, gf) - g[later]
        assert (release > 0).all() and release[-1] > 10 * release[0], m
        end = s["postbuckling"]["end"]
        assert end["time"] == pytest.approx(1.0) and end["grand_potential"] < gf[-1]


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size != 2, reason="compares a 1-rank and a 2-rank run")
def test_a_plate_branch_on_one_and_two_ranks(shared_tmp, comm):
    """The same steps, crossings, history and patterns on the branch (measured: 2e-9 at worst); the Newton
    iteration and factorization counts on the branch are left out (measured: 14 of 26 branch steps differ by
    1-5 iterations, 202 against 212 factorizations: near the symmetric squares state the minimizer's line search
    and inertia correction react to roundoff, which the partition decides; the states they reach agree)."""
    cfg = _branch("2:0+0:2")
    world = simulate(cfg, shared_tmp / "two", comm, progress=False)
    one = on_rank0(simulate, cfg, shared_tmp / "one", MPI.COMM_SELF, progress=False)
    same_summary(one, world, 1e-8, counters=False)
    assert [p["pattern"] for p in one["postbuckling"]["patterns"]] == [p["pattern"] for p in world["postbuckling"]["patterns"]]
    assert world["postbuckling"]["end"]["grand_potential"] == pytest.approx(one["postbuckling"]["end"]["grand_potential"],
                                                                           rel=1e-8)
    same_rows(*([{k: v for k, v in r.items() if k != "newton_its"} for r in read_csv(shared_tmp / d / "history.csv")]
                for d in ("one", "two")), 1e-8)


@pytest.mark.slow
@long_physics
def test_a_plate_branch_resumes_like_an_uninterrupted_run(shared_tmp, comm):
    """Stopped on the branch (after the switch, step 50), resumed from its checkpoint: the same history,
    patterns and end energy."""
    cfg = _branch("2:0+0:2")
    cfg["output"]["checkpoint_every"] = 3
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    part = shared_tmp / "part"
    stopped = simulate(cfg, part, comm, progress=False, stop_after=50)
    assert stopped["status"] == "interrupted" and full["postbuckling"]["switches"][0]["time"] < stopped["final"]["time"]
    resumed = simulate(cfg, part, comm, progress=False, resume=checkpoint.check(part, cfg, comm))
    same_rows(read_csv(shared_tmp / "full" / "history.csv"), read_csv(part / "history.csv"), 1e-10)
    same_summary(full, resumed, 1e-10)
    assert [p["pattern"] for p in resumed["postbuckling"]["patterns"]] == \
        [p["pattern"] for p in full["postbuckling"]["patterns"]]
    assert resumed["postbuckling"]["end"]["grand_potential"] == pytest.approx(
        full["postbuckling"]["end"]["grand_potential"], rel=1e-10)


@pytest.mark.parametrize("kind, modes, says", [("bilayer", "2:0", "wave vectors pick a branch of a 3D"),
                                                ("plate", "2,0", "joined by '+'"), ("plate", "1+2", "joined by '+'")])
def test_branch_modes_are_wave_vectors_of_a_3d_kind(kind, modes, says):
    """stability.branch_modes: 'i:j' shapes joined by '+', on a 3D kind only; else a one-line ConfigError
    naming the key and what is allowed."""
    from app.schema import ConfigError

    with pytest.raises(ConfigError) as err:
        config.resolve({"geometry": {"kind": kind}, "stability": {"branch_modes": modes}}, [])
    assert "stability.branch_modes" in str(err.value.args[0]) + str(err.value) and says in str(err.value)
    assert config.resolve({"geometry": {"kind": "plate"}, "stability": {"branch_modes": "2:0+0:2"}}, [])


def test_a_3d_run_writes_the_whole_stress_and_its_smallest_principal_value(shared_tmp, comm):
    """fields.h5 of a plate: the six Cauchy stress components per cell, and stress_min_principal equal to the
    smallest eigenvalue numpy finds for them (the UFL closed form against LAPACK), in the swollen film."""
    import h5py

    out = shared_tmp / "fields3d"
    cfg = config.load(REPO / "configs" / "plate-branches.toml", ["time.end=0.5", "output.every=100",
                                                                   "output.plot=false", "reduced.beside_2d=false"])
    simulate(cfg, out, comm, progress=False)
    if comm.rank:
        return
    with h5py.File(out / "fields.h5", "r") as h5:
        def last(name):
            group = h5["Function"][name]
            return np.array(group[sorted(group, key=float)[-1]])[:, 0]

        assert set(h5["Function"]) == {"displacement", "fluid_content", "chemical_potential", "J", "flux",
                                       "stress_min_principal", *(f"stress_{c}" for c in ("xx", "yy", "zz", "xy", "xz",
                                                                                          "yz"))}
        S = np.zeros((len(last("stress_xx")), 3, 3))
        for (i, j), name in {(0, 0): "xx", (1, 1): "yy", (2, 2): "zz", (0, 1): "xy", (0, 2): "xz", (1, 2): "yz"}.items():
            S[:, i, j] = S[:, j, i] = last(f"stress_{name}")
        smallest = np.linalg.eigvalsh(S)[:, 0]
        assert abs(smallest).max() > 0 and np.abs(last("stress_min_principal") - smallest).max() <= 1e-7 * abs(smallest).max()


def test_a_3d_first_mode_that_is_not_the_1d_first_is_placed_in_the_1d_order():
    """The default plate's 1D order (computed): (5, 0), (0, 5), (3, 4), (4, 3) first; (3, 3) next, 0.64% later.
    A 3D run whose first mode is (3, 3) is told where that mode crosses in 1D and whether the gap lies within its
    error bar (the measured default plate: bar 0.4996 um, gap 0.0433 um, so not resolved); a 3D tube whose
    first mode has an axial wave is told that the 1D reduction does not cover it; agreeing modes say nothing."""
    from app.workflows import reduction

    red = reduction.compute(config.load(REPO / "configs" / "plate.toml"))
    red.pop("_estimate")
    assert sorted(map(tuple, red["wave_vectors"])) == [(0, 5), (3, 4), (4, 3), (5, 0)]
    later = next(m for m in red["mode_crossings"] if [3, 3] in m["wave_vectors"])
    first = red["mode_crossings"][0]  # the earliest crossing of the 1D base level: the 1D answer's modes
    assert sorted(map(tuple, first["wave_vectors"])) == sorted(map(tuple, red["wave_vectors"]))
    gap = later["growth_um"] - first["growth_um"]  # two crossings of one 1D level, not the extrapolated value
    assert 0 < gap < 0.01 * red["growth_um"]

    def run(wave, bar):
        return {"critical": {"growth_um": red["growth_um"] + 0.2, "modes": [{"wave_vector": wave}],
                             "discretization_error": {"total_um": bar} if bar else None}, "reduced": red}

    wide, narrow = reduction.mode_order(run([3, 3], 0.4996)), reduction.mode_order(run([3, 3], gap / 2))
    assert wide == {"wave_vector": [3, 3], "in_1d": True, "growth_um": later["growth_um"], "gap_um": gap,
                    "within_error_bar": True}
    assert narrow["within_error_bar"] is False and reduction.mode_order(run([3, 3], None))["within_error_bar"] is None
    assert "not resolved at this mesh" in reduction.compare(run([3, 3], 0.4996))
    assert "puts the wrong mode first" in reduction.compare(run([3, 3], gap / 2))
    assert reduction.mode_order(run([4, 3], 0.4996)) is None
    tube = {"critical": {"growth_um": 5.36, "modes": [{"wave_vector": [8, 1]}], "discretization_error": None},
            "reduced": {"growth_um": 5.13, "wave_vectors": [[10, 0]], "kind": "wrinkles",
                        "mode_crossings": [{"wave_vectors": [[10, 0]], "growth_um": 5.13}]}}
    assert reduction.mode_order(tube) == {"wave_vector": [8, 1], "in_1d": False}
    assert "an axial wave" in reduction.compare(tube)
