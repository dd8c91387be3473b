"""The exact 1D reduction (app/reduced, docs/reduction.md) against closed forms, and the 2D runs against it.

- the laterally constrained steady state of each layer (app.model.theory, written independently of the
  FE code) and the growth it implies;
- the short-wave limit of the surface (a half-space in the local state) against Kang & Huang's condition
  for this free energy (docs/theory/drained-onset.md, drained and undrained);
- in a transient, P_yy = 0 through the whole section, so the surface's state lies on the constrained-layer
  curve and its short-wave crossing must come at the homogeneous layer's critical stretch;
- a stiff film in compression against the film-on-substrate formula;
- the default bilayer and tube: the 2D onset and the reduced one within each other's error bars.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess

import numpy as np
import pytest
import ufl
from conftest import EXE, child_env, child_jobs, long_physics, on_rank0, rank_local
from dolfinx import fem
from mpi4py import MPI
from scipy.optimize import brentq

from app import compat, config, factory, fem_utils
from app.factory import layer_materials
from app.model import theory
from app.model.hydrogel import HYDROGEL
from app.reduced.halfspace import HalfSpace
from app.reduced.onset import Screen, Stability, margin_curve, mode_grid
from app.reduced.solve import n_max
from app.reduced.transient import LayeredModel, Resolution, Transient
from app.workflows import reduction


def _gel(gamma):
    return HYDROGEL.material({"shear_modulus": gamma, "mixing_modulus": 24.2, "penalty": 10.0, "mobility": 1e-4,
                              "preswelling": 1.01, "interaction": 0.1})


@pytest.mark.parametrize("gamma", [0.1, 0.8])
@pytest.mark.parametrize("criterion", ["drained", "undrained"])
def test_short_wave_limit_is_the_homogeneous_layers_surface_condition(gamma, criterion):
    """The half-space of the reduction (its own discretization of the mode equations, from the law's UFL)
    against the closed-form zero-speed surface-wave condition with the drained / undrained volumetric
    stiffness (theory.surface_critical_stretch: 3.1410 / 3.3607 for gamma = 0.1). Measured to 1e-7."""
    mat = _gel(gamma)
    hs = HalfSpace(mat, criterion)

    def margin(lam):
        return hs.margin(((1.0, 0.0), (0.0, lam)), theory.constrained_layer_fluid(mat, lam))

    lam = brentq(margin, 2.0, theory.BIOT_CUBIC_RATIO - 1e-3, xtol=1e-12)
    assert lam == pytest.approx(theory.surface_critical_stretch(mat, drained=criterion == "drained"), rel=1e-6)


def test_steady_state_is_the_laterally_constrained_equilibrium():
    """A thin bilayer (ratio 8) swollen to equilibrium with mu_bar = 0: each layer at the closed-form stretch
    and fluid content of a laterally constrained layer, and the growth their sum. Measured 3e-10."""
    cfg = config.resolve({"geometry": {"length": 1.0, "substrate_thickness": 0.02, "film_thickness": 0.01}})
    sec = factory.section(cfg)
    m = LayeredModel(sec, Resolution(dt_max=100.0))
    tr = Transient(m)
    tr.run(2000.0)
    V0 = compat.scalar_space(m.domain, "DG", 0)
    u, q = ufl.split(m.state)
    lam, s = fem.Function(V0), fem.Function(V0)
    lam.interpolate(compat.expression(1.0 + u.dx(0), V0))
    s.interpolate(compat.expression(m.mat.s0 - m.div(q), V0))
    mid = fem_utils.dof_coordinates(V0)
    growth = 0.0
    for lay in sec.layers:
        mat = sec.materials[lay.material]
        l_eq = theory.constrained_layer_stretch(mat, 0.0)
        inside = (mid > lay.start) & (mid < lay.end)
        assert np.max(np.abs(lam.x.array[inside] - l_eq)) < 1e-8 * l_eq
        assert np.max(np.abs(s.x.array[inside] - theory.constrained_layer_fluid(mat, l_eq))) < 1e-8 * l_eq
        growth += (l_eq - 1.0) * lay.thickness
    assert tr.steps[-1].growth == pytest.approx(growth, rel=1e-8)


@pytest.mark.parametrize("criterion, ratio", [("drained", 8.0), ("undrained", 1.0)])
def test_surface_crossing_comes_at_the_homogeneous_critical_stretch(criterion, ratio):
    """In the default bilayer's transient P_yy = 0 everywhere (a traction-free top, no lateral variation),
    so the surface state is that of a constrained layer at its own stretch, and the surface's short-wave
    crossing must come when that stretch reaches the film's critical one (drained 2.5277 for gamma_f = 0.8;
    undrained 3.3607 for gamma_f = 0.1: a film of 0.8 swells to 2.59 only, short of its undrained 3.21),
    however inhomogeneous the section is below. The stretch is interpolated at the
    crossing time through the three steps around it: measured within 2e-5."""
    cfg = config.load("configs/bilayer.toml", [f"stability.criterion={criterion}",
                                               f"material.film.modulus_ratio={ratio}"])
    sec = factory.section(cfg)
    st = reduction.settings(cfg)
    m = LayeredModel(sec, st.resolution)
    stab = Stability(m, criterion)
    screen = Screen(stab, mode_grid(8, 8), 20.0)  # a few modes: the surface limit is what is tested
    tr = Transient(m)
    tr.run(3.0, stop=lambda snap, i: screen(snap, i) or (None in screen.first_unstable))
    curve = margin_curve(stab, tr.steps, screen)
    c = curve.short_wave
    assert c is not None
    i = screen.first_unstable[None]
    near = tr.steps[i - 2:i + 1]
    ts, ls = [s.t for s in near], [stab.surface_state(s)[1] for s in near]
    lam = float(np.polyval(np.polyfit(ts, ls, 2), c.time))  # interpolated as the crossing is
    film = layer_materials(cfg)["film"]
    assert lam == pytest.approx(theory.surface_critical_stretch(film, drained=criterion == "drained"), rel=5e-5)
    # and the surface state is on the constrained-layer curve
    lt, ln, s = stab.surface_state(tr.steps[i])
    assert lt == pytest.approx(1.0, abs=1e-12)
    assert s == pytest.approx(theory.constrained_layer_fluid(film, ln), rel=1e-6)


@rank_local
def test_stiff_film_in_compression_wrinkles_at_the_film_on_substrate_strain():
    """Undrained compression of a film 50 times stiffer than its deep substrate (the case of
    test_stability's 2D check): the applied strain at the onset within 2.5% of (1/4)(3 Es/Ef)^(2/3)
    (measured -2.2%: the film's nonlinearity and the finite substrate, which the formula leaves out), a
    wrinkle count theory cannot tell from its optimum, and a wavelength within 10% of 2 pi h (Ef/3Es)^(1/3)."""
    L = 1.5
    cfg = config.resolve({
        "geometry": {"length": L, "substrate_thickness": 0.5, "film_thickness": 0.01},
        "material": {"film": {"modulus_ratio": 50.0}},
        "loading": {"kind": "compression", "compression_strain": 0.07},
        "stability": {"criterion": "undrained"},
        "time": {"end": 1.0, "dt_initial": 0.05, "dt_max": 0.05}})
    block = reduction.compute(cfg)
    mats = layer_materials(cfg)
    eps_c = theory.film_wrinkling_strain(mats["film"], mats["substrate"])
    l_c = theory.film_wrinkling_wavelength(mats["film"], mats["substrate"], 0.01)
    assert block["kind"] == "wrinkles"
    strain = 0.07 * block["time"] / cfg["time"]["end"]
    assert strain == pytest.approx(eps_c, rel=0.025)

    def strain_ratio(n):
        k = n * l_c / L
        return k ** 2 / 3 + 2 / (3 * k)

    assert strain_ratio(block["wrinkle_count"]) <= 1.01
    assert block["wavelength_mm"] == pytest.approx(l_c, rel=0.1)


@rank_local
def test_error_bar_covers_a_finer_computation():
    """The reduced answer of the default bilayer with its steps halved again (step_change / 2) and its mesh
    refined (film cells x 2): within the default answer's error bar, which is under 0.1% of g_c."""
    cfg = config.load("configs/bilayer.toml")
    a = reduction.compute(cfg)
    b = reduction.compute(config.load("configs/bilayer.toml", ["reduced.step_change=0.005", "reduced.film_cells=24"]))
    assert a["kind"] == b["kind"] == "wrinkles"
    assert a["wrinkle_count"] == b["wrinkle_count"] == 19
    assert a["growth_error_um"] < 1e-3 * a["growth_um"]
    assert abs(a["growth_um"] - b["growth_um"]) <= a["growth_error_um"]
    assert abs(a["time"] - b["time"]) <= a["time_error"]


@long_physics
@pytest.mark.parametrize("name", ["bilayer", "tube"])
def test_2d_default_onset_and_the_reduction_lie_within_each_others_error_bars(name, shared_tmp, comm):
    """The paper's default bilayer and tube in 2D (their own error estimate) and their exact 1D counterparts,
    reported in the same summary: the same wrinkle count, and the 1D value inside the 2D error bar (a test of
    the 2D answer and of its error estimate). Measured: bilayer 2D - 1D = -0.004 um against a bar of 0.129 um,
    tube +0.041 um against 0.18 um."""
    from app.workflows.pipeline import run_case

    cfg = config.load(f"configs/{name}.toml", ["output.fields=false", "output.plot=false"])
    s = run_case(cfg, shared_tmp / name, comm, progress=False)
    red, c = s["reduced"], s["critical"]
    assert red["solver"] == "reduced-1d" and red["kind"] == "wrinkles"
    assert red["wrinkle_count"] == c["wrinkle_count"]
    err2 = c["discretization_error"]["total_um"]
    assert abs(c["growth_um"] - red["growth_um"]) <= err2
    assert red["growth_error_um"] < 0.1 * err2  # the reduction is the sharper reference
    on_disk = json.loads((shared_tmp / name / "summary.json").read_text())
    assert on_disk["reduced"] == red


@child_jobs
def test_reduced_command_writes_its_result_and_refuses_what_it_cannot_reduce(shared_tmp):
    def run():
        out = shared_tmp / "red"
        p = subprocess.run([EXE, "reduced", "configs/tube.toml", "-o", str(out)], capture_output=True, text=True,
                           env=child_env())
        bad = subprocess.run([EXE, "reduced", "configs/elliptic-tube.toml", "-o", str(shared_tmp / "bad")],
                             capture_output=True, text=True, env=child_env())
        return p.returncode, p.stdout + p.stderr, bad.returncode, bad.stderr, (shared_tmp / "bad").exists(), \
            json.loads((out / "summary.json").read_text()), (out / "margin.csv").read_text().splitlines()

    code, text, bad_code, bad_err, bad_dir, summary, margin = on_rank0(run)
    assert code == 0, text
    red = summary["reduced"]
    assert "result: 1D reduction (drained): g_c = " in text and f"N_c = {red['wrinkle_count']:g}" in text
    # the margin curve: its minimum is the answer's mode
    rows = [r.split(",") for r in margin[1:] if r.split(",")[0]]
    best = min(rows, key=lambda r: float(r[3]))
    assert int(best[0]) == red["mode_number"] == red["wrinkle_count"]  # around the tube: n = N
    assert bad_code == 2 and not bad_dir
    lines = [ln for ln in bad_err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "geometry.kind" in lines[0] and "bilayer, tube" in lines[0]


def test_mode_count_of_the_screen_reaches_the_largest_wavenumber():
    cfg = config.load("configs/bilayer.toml")
    sec = factory.section(cfg)
    n = n_max(sec, cfg["reduced"]["max_wavenumber"])
    assert sec.wavenumber(n) * sec.film_thickness >= cfg["reduced"]["max_wavenumber"]
    assert sec.wavenumber(n - 1) * sec.film_thickness < cfg["reduced"]["max_wavenumber"]
    assert sec.wrinkle_count(38) == 19 and sec.local_wavenumber(38) == pytest.approx(2 * math.pi / (2 * 2.0 / 38))


@rank_local
@pytest.mark.parametrize("sets", [[], ["geometry.film_thickness=0.05"]])
def test_answer_does_not_depend_on_the_largest_wavenumber_screened(sets):
    """Screening modes up to k w = 80 instead of 20: the same answer (a finite mode, or the surface's
    short-wave limit, which covers every wave beyond the screened ones), and the same first finite
    wavelength: convergence in the largest n tested."""
    a = reduction.compute(config.load("configs/bilayer.toml", sets))
    b = reduction.compute(config.load("configs/bilayer.toml", [*sets, "reduced.max_wavenumber=80"]))
    assert b["tested_mode_numbers"][1] >= 4 * a["tested_mode_numbers"][1] - 4
    assert (a["kind"], a["mode_number"]) == (b["kind"], b["mode_number"])
    assert b["growth_um"] == pytest.approx(a["growth_um"], rel=1e-9)
    fa, fb = a["first_finite_wavelength"], b["first_finite_wavelength"]
    assert (fa is None) == (fb is None)
    if fa:
        assert fa["mode_number"] == fb["mode_number"] and fb["growth_um"] == pytest.approx(fa["growth_um"], rel=1e-9)


def test_the_reduction_beside_a_run_is_computed_once_and_reaches_every_rank(shared_tmp, comm):
    """reduced.beside_2d on the small swelling bilayer on every rank count (the long default bilayer and tube,
    compared with their 2D onsets, run in the serial session only): the 1D block is computed on rank 0, and
    every rank's summary holds the same one, equal to the reduction computed alone for this config (but for
    its wall time)."""
    from cases import swelling_case

    from app.workflows.pipeline import run_case

    cfg = swelling_case("reduced.beside_2d=true", "stability.error_estimate=false")
    s = run_case(cfg, shared_tmp / "run", comm, progress=False)
    def timeless(d):  # the block without its wall times (those of the levels too)
        if isinstance(d, dict):
            return {k: timeless(v) for k, v in d.items() if k not in ("seconds", "_estimate")}
        return [timeless(v) for v in d] if isinstance(d, list) else d

    block = timeless(s["reduced"])
    assert len({json.dumps(b, sort_keys=True) for b in comm.allgather(block)}) == 1
    assert block == on_rank0(lambda: timeless(reduction.compute(cfg)))
    assert block["solver"] == "reduced-1d" and block["kind"] not in ("failed", "interrupted"), block


def test_study_by_the_reduction_matches_single_computations_and_reruns_nothing(shared_tmp, comm, capsys):
    """``study bilayer-modulus-ratio --reduced`` (two values): each row is the single reduced computation
    of its case (solver column reduced-1d, the same g and N_c), a rerun keeps every case, and a study the
    reduction does not cover is refused with one line naming the case, exit 2, nothing created."""
    from app import cli
    from app.workflows import studies

    out = shared_tmp / "rstudy"
    assert cli.main(["study", "bilayer-modulus-ratio", "--reduced", "--values", "4,8", "-o", str(out), "-q"]) == 0
    rows = on_rank0(lambda: list(csv.DictReader(open(out / "study.csv"))))
    assert [r["solver"] for r in rows] == ["reduced-1d"] * 2 and [r["onset"] for r in rows] == ["wrinkles"] * 2
    _, cases = studies.study_cases("bilayer-modulus-ratio", out, "8", [])
    single = reduction.compute(cases[0].cfg) if comm.rank == 0 else None
    single = comm.bcast(None if single is None else {k: v for k, v in single.items() if k != "_estimate"}, root=0)
    assert float(rows[1]["g_c_um"]) == pytest.approx(single["growth_um"], rel=1e-12)
    assert float(rows[1]["N_c"]) == single["wrinkle_count"] == 19
    stamp = on_rank0(lambda: (out / "modulus_ratio=8" / "summary.json").stat().st_mtime_ns)
    assert cli.main(["study", "bilayer-modulus-ratio", "--reduced", "--values", "4,8", "-o", str(out), "-q"]) == 0
    assert on_rank0(lambda: (out / "modulus_ratio=8" / "summary.json").stat().st_mtime_ns) == stamp
    bad = shared_tmp / "rbad"
    capsys.readouterr()
    assert cli.main(["study", "tube-aspect-ratio", "--reduced", "-o", str(bad)]) == 2
    assert not on_rank0(bad.exists)
    if comm.rank == 0:  # one line, naming the key and the case once
        line, = capsys.readouterr().err.strip().splitlines()
        assert line.startswith("hydrobuckle: error: ") and "--reduced" in line, line
        assert line.count("case ") == 1 and "case aspect_ratio=" in line, line


@pytest.mark.parametrize("criterion", ["drained", "undrained"])
def test_mode_operator_of_a_homogeneous_layer_at_short_waves_is_the_surface_condition(criterion):
    """The finite-mode operator (app/reduced/modes.py, not the half-space) of a homogeneous gel (ratio 1)
    in the homogeneous constrained state of stretch lambda, at k = 500 /mm (waves 12.6 um on a 0.51 mm
    layer): it loses definiteness at the closed-form short-wave critical stretch (3.1410 drained, 3.3607
    undrained). Measured 1e-6 / 8e-6."""
    cfg = config.load("configs/bilayer.toml", ["material.film.modulus_ratio=1"])
    sec = factory.section(cfg)
    m = LayeredModel(sec, reduction.settings(cfg).resolution)
    stab = Stability(m, criterion)
    gel = sec.materials["film"]
    k = 500.0

    def margin(lam):
        s = theory.constrained_layer_fluid(gel, lam)
        state = np.zeros_like(m.state.x.array)
        state[m.v_dofs] = (lam - 1.0) * m.x_v
        state[m.q_dofs] = (gel.s0 - s) * m.x_q  # s = s0 - Q'
        stab.base.x.array[:] = state
        m.lam_x.value = 1.0
        return stab.op.polynomial().margin(k)

    lam = brentq(margin, 2.5, theory.BIOT_CUBIC_RATIO - 1e-3, xtol=1e-10)
    assert lam == pytest.approx(theory.surface_critical_stretch(gel, drained=criterion == "drained"), rel=3e-5)


def test_the_crossover_bisection_finds_where_the_onset_meets_a_time(monkeypatch, capsys):
    """``hydrobuckle reduced --crossover KEY LO HI TIME``: the value of KEY at which the 1D onset time equals
    TIME, by bisection to 1e-3 of the value. With an onset time 1/r of the key r (a stand-in for the 1D runs)
    and TIME 0.4 the answer is r = 2.5 within its own error bar, and that bar is at most 1e-3 of it; a TIME
    no value in the range reaches gives no value. Bad input (LO >= HI, a TIME beyond time.end, an unknown
    key) exits 2 with one line naming it, before any 1D run."""
    from app import cli

    cfg = config.load("configs/bilayer-creases.toml")
    key = "material.film.modulus_ratio"
    monkeypatch.setattr(reduction, "onset_time",
                        lambda c: (1.0 / c["material"]["film"]["modulus_ratio"], "N = 2"))
    found = reduction.crossover(cfg, key, 1.0, 5.0, 0.4, lambda msg: None)
    assert abs(found["value"] - 2.5) <= found["error"] <= 1e-3 * 2.5
    assert reduction.crossover(cfg, key, 1.0, 2.0, 0.4, lambda msg: None)["value"] is None
    path = "configs/bilayer-creases.toml"
    rank0 = MPI.COMM_WORLD.rank == 0  # the one rank that prints
    for bad, word in ((["5", "1", "0.4"], "LO < HI"), (["1", "x", "0.4"], "numbers"), (["1", "5", "2"], "time.end")):
        capsys.readouterr()
        assert cli.main(["reduced", path, "--crossover", key, *bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert not rank0 or (len(err) == 1 and "--crossover" in err[0] and word in err[0])
    assert cli.main(["reduced", path, "--crossover", "material.film.nope", "1", "5", "0.4"]) == 2
    assert not rank0 or "material.film.nope" in capsys.readouterr().err
