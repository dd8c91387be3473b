"""The CLI commands without tests of their own: converge, mesh, validate, study, sweep, bench; the mesh
options film_grading and the quadrature degrees; user .msh files with more materials; the scripts.

References: Richardson extrapolation of synthetic sequences g_h = g* + C h^p (exact g* and p); the
refinement rules of app/workflows/convergence.py written out (tolerance / 4, dt / 2, h / 2 and film layers x 2
per level) and the element sizes measured on the built meshes; each level's own summary.json (the
study tables must repeat it); meshes read back with gmsh; config round trips; a case run alone (1
rank) or on 2 ranks; the paper's trend of g_c with the modulus ratio; the geometric film heights of
film_grading; quadrature that is exact on rectangles; volumetric locking (higher g_c); and the
built-in bilayer as the reference of the same mesh read from a user .msh.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np
import pytest
from cases import TINY_BILAYER_TOML
from conftest import PYTHON, REPO, on_rank0, read_csv, read_json, run_child, run_to_end, write_on_rank0
from mpi4py import MPI

from app import cli, config, fem_utils, geometry
from app.model.material import chemical_potential
from app.workflows import studies
from app.workflows.convergence import refined_configs, richardson
from app.workflows.run import simulate

# A bilayer that buckles in about 0.4 s (0.15 mm wide, 15 x 2 film elements).
TINY = TINY_BILAYER_TOML + """
[time]
end = 1.0
dt_initial = 0.001
dt_max = 0.05
[stability]
error_estimate = false
[output]
fields = false
plot = false
"""
# The same as --set overrides of a study (whose own base config is the paper's 2 mm bilayer).
SHRINK = ["geometry.length=0.15", "geometry.substrate_thickness=0.15", "mesh.element_size=0.01",
          "mesh.film_layers=2", "mesh.substrate_grading=1.25", "reduced.beside_2d=false"]


def _sets(items):
    return [a for item in items for a in ("--set", item)]


def _mtime(path):
    return Path(path).stat().st_mtime_ns


# --- converge: Richardson extrapolation -----------------------------------------------------------


@pytest.mark.parametrize("p, ratio", [(1.0, 2.0), (1.7, 2.0), (2.0, 2.0), (3.0, 1.5), (1.2, 3.0)])
def test_richardson_recovers_limit_and_order_of_a_synthetic_sequence(p, ratio):
    """g_h = g* + C h^p on h = h0 / ratio^k: the observed order is p and the extrapolation g* to
    roundoff; each level's error is C h_k^p; only the last three values count."""
    g_star, C, h0 = 6.5, 0.3, 0.2
    h = [h0 / ratio ** k for k in range(4)]
    values = [g_star + C * hk ** p for hk in h]
    out = richardson(values, ratio)
    assert out["order"] == pytest.approx(p, rel=1e-9)
    assert out["converged"] == pytest.approx(g_star, rel=1e-13)
    assert out["errors"] == pytest.approx([C * hk ** p for hk in h], rel=1e-7, abs=1e-13)
    assert out["monotone"] is True and out["values"] == values
    # a wrong first value changes nothing (the last three levels decide)
    assert richardson([0.0] + values[1:], ratio)["converged"] == pytest.approx(g_star, rel=1e-13)


def test_richardson_two_levels_clamping_and_non_monotone_sequences():
    # two levels: order 1 assumed, exact for a first-order sequence: g* = g1 + (g1 - g0)/(r - 1)
    two = richardson([5.0 + 0.4, 5.0 + 0.2], 2.0)
    assert two["order"] is None or two["order"] == 1.0
    assert two["converged"] == pytest.approx(5.0, rel=1e-14)
    assert two["errors"] == pytest.approx([0.4, 0.2], rel=1e-12)
    # observed order 5 is reported, but the extrapolation uses at most p = 4:
    # g = 1 + h^5, h = 1, 1/2, 1/4 -> g_inf = g2 + (g2 - g1)/(2^4 - 1)
    g = [1 + h ** 5 for h in (1.0, 0.5, 0.25)]
    out = richardson(g, 2.0)
    assert out["order"] == pytest.approx(5.0, rel=1e-12)
    assert out["converged"] == pytest.approx(g[2] + (g[2] - g[1]) / 15, rel=1e-14)
    # oscillating: no order; the finest value with the largest change added to every error
    osc = richardson([1.0, 1.3, 1.1], 2.0)
    assert osc["order"] is None and osc["monotone"] is False
    assert osc["converged"] == 1.1
    assert osc["errors"] == pytest.approx([0.1 + 0.3, 0.2 + 0.3, 0.0 + 0.3])
    assert richardson([1.0, None, 2.0], 2.0)["converged"] is None


# --- converge: the level configs and their meshes -----------------------------------------------


def test_refined_and_coarsened_configs_follow_the_documented_factors():
    base = config.resolve({**_toml(TINY), "mesh": {**_toml(TINY)["mesh"], "film_layers": 4}})
    tol, h, nf = base["time"]["tolerance"], base["mesh"]["element_size"], base["mesh"]["film_layers"]
    for coarsen, sign in ((False, 1), (True, -1)):
        time_levels = refined_configs(base, "time", 3, 4.0, 2.0, coarsen)
        mesh_levels = refined_configs(base, "mesh", 3, 4.0, 2.0, coarsen)
        for k, ((label, value, c), (mlabel, mvalue, m)) in enumerate(zip(time_levels, mesh_levels)):
            assert (label, mlabel) == (f"time{k}", f"mesh{k}")
            assert c["time"]["tolerance"] == value == pytest.approx(tol / 4.0 ** (sign * k), rel=1e-14)
            assert c["mesh"] == base["mesh"]
            assert m["mesh"]["element_size"] == mvalue == pytest.approx(h / 2.0 ** (sign * k), rel=1e-14)
            assert m["mesh"]["film_layers"] == round(nf * 2.0 ** (sign * k))
            assert m["time"] == base["time"]
            for cc in (c, m):
                assert cc["stability"]["stop_at_onset"] is True and cc["output"]["fields"] is False
    # fixed steps: dt halves per refinement (and doubles per coarsening); dt_min/dt_max follow
    fixed = config.resolve(_toml(TINY), ["time.adaptive=false", "time.dt_initial=0.01", "time.dt_min=0.005"])
    for k, (_, value, c) in enumerate(refined_configs(fixed, "time", 3, 4.0, 2.0)):
        assert c["time"]["dt_initial"] == value == pytest.approx(0.01 / 2 ** k, rel=1e-14)
        assert c["time"]["dt_min"] == min(0.005, value)
    for k, (_, value, c) in enumerate(refined_configs(fixed, "time", 3, 4.0, 2.0, coarsen=True)):
        assert c["time"]["dt_initial"] == value == pytest.approx(0.01 * 2 ** k, rel=1e-14)
        assert c["time"]["dt_max"] == max(0.05, value)
    # 2 film layers cannot be halved twice
    with pytest.raises(config.ConfigError, match="film_layers"):
        refined_configs(config.resolve(_toml(TINY)), "mesh", 3, 4.0, 2.0, coarsen=True)


def _toml(text):
    import tomllib

    return tomllib.loads(text)


def _measured_mesh(cfg, comm):
    """(element length along the top, number of film element layers) measured on the built mesh."""
    tm = geometry.build(config.geometry_input(cfg), comm).tm
    x = tm.mesh.geometry.x
    H, w = cfg["geometry"]["substrate_thickness"], cfg["geometry"]["film_thickness"]
    pts = np.concatenate(comm.allgather(x[:, :2]))
    top = np.unique(np.round(pts[np.abs(pts[:, 1] - (H + w)) < 1e-12, 0], 12))
    left_film = np.unique(np.round(pts[(np.abs(pts[:, 0]) < 1e-12) & (pts[:, 1] >= H - 1e-12), 1], 12))
    return float(np.diff(top).max()), float(np.diff(top).min()), len(left_film) - 1


def test_level_meshes_have_the_element_sizes_of_their_configs(comm):
    base = config.resolve(_toml(TINY), ["mesh.film_layers=2", "mesh.element_size=0.015"])
    levels = refined_configs(base, "mesh", 2, 4.0, 2.0) + refined_configs(base, "mesh", 2, 4.0, 2.0, coarsen=True)[1:]
    expected = [(0.015, 2), (0.0075, 4), (0.03, 1)]
    for (_, _, c), (h, layers) in zip(levels, expected):
        hmax, hmin, nf = _measured_mesh(c, comm)
        assert hmax == pytest.approx(h, rel=1e-9) and hmin == pytest.approx(h, rel=1e-9)
        assert nf == layers


# --- converge: end to end -------------------------------------------------------------------------


def test_converge_time_two_levels_end_to_end(shared_tmp, comm, log_lines):
    cfg_path, out = write_on_rank0(shared_tmp / "tiny.toml", TINY), shared_tmp / "conv"
    assert cli.main(["converge", str(cfg_path), "--only", "time", "--levels", "2", "-o", str(out), "-q"]) == 0
    if comm.rank == 0:  # after each level: levels done of the total and the time left
        done = [line for line in log_lines if " levels done" in line]
        assert [line.split(";")[0] for line in done] == ["converge: 1/2 levels done", "converge: 2/2 levels done"]
        assert "left" in done[0] and done[1].endswith("none left")
    doc = read_json(out / "convergence.json")
    assert doc["direction"] == "refine" and list(doc["studies"]) == ["time"]
    base_cfg = config.load(cfg_path)
    tol = base_cfg["time"]["tolerance"]
    summaries = [read_json(out / d / "summary.json") for d in ("base", "time1")]
    assert config.load(out / "base" / "config.toml")["time"]["tolerance"] == tol
    assert config.load(out / "time1" / "config.toml")["time"]["tolerance"] == pytest.approx(tol / 4, rel=1e-14)
    assert not (out / "mesh1").exists()
    for row, s, level in zip(doc["rows"], summaries, (0, 1)):
        assert row["study"] == "time" and row["level"] == level
        assert row["parameter"] == pytest.approx(tol / 4 ** level, rel=1e-14)
        assert s["status"] == row["status"] == "buckled"
        assert row["g_c_um"] == s["critical"]["growth_um"]
        assert row["N_c"] == s["critical"]["wrinkle_count"] and row["t_c"] == s["critical"]["time"]
        assert (row["dofs"], row["steps"]) == (s["mesh"]["dofs"], s["steps"])
    assert summaries[1]["steps"] > summaries[0]["steps"]  # the finer tolerance takes more steps
    g0, g1 = (r["g_c_um"] for r in doc["rows"])
    st = doc["studies"]["time"]
    assert st["values"] == [g0, g1]
    g_inf = g1 + (g1 - g0) / (2 - 1)  # two levels: order 1, ratio 2
    assert st["converged"] == pytest.approx(g_inf, rel=1e-12)
    assert st["errors"] == pytest.approx([abs(g0 - g_inf), abs(g1 - g_inf)], rel=1e-9, abs=1e-15)
    b = doc["base"]
    assert b["g_c_um"] == g0
    assert b["converged_estimate_um"] == pytest.approx(g_inf, rel=1e-12)
    assert b["error_estimate_um"] == pytest.approx(abs(g0 - g_inf), rel=1e-9, abs=1e-15)
    table = read_csv(out / "convergence.csv")
    assert [float(r["g_c_um"]) for r in table] == [g0, g1]
    assert (out / "convergence.md").is_file() and (out / "convergence.png").stat().st_size > 0


def test_converge_fixed_steps_halve_the_step_the_runs_take(shared_tmp, comm):
    """With time.adaptive = false the time study halves the fixed step: every step of each level's
    history (the onset, about 0.9 s, comes before the end of the ramp) has exactly that size."""
    cfg_path, out = write_on_rank0(shared_tmp / "tiny.toml", TINY), shared_tmp / "conv"
    assert cli.main(["converge", str(cfg_path), "--only", "time", "--levels", "2", "-o", str(out), "-q",
                     *_sets(["time.adaptive=false", "time.dt_initial=0.04", "time.dt_max=0.04"])]) == 0
    doc = read_json(out / "convergence.json")
    for level, d in enumerate(("base", "time1")):
        dts = {round(float(r["dt"]), 15) for r in read_csv(out / d / "history.csv")[1:]}
        assert dts == {0.04 / 2 ** level}
        assert doc["rows"][level]["parameter"] == 0.04 / 2 ** level
        assert read_json(out / d / "summary.json")["critical"]["time"] < 1.0


def test_converge_coarsened_mesh_end_to_end(shared_tmp, comm):
    """--coarsen: level 1 has twice the element size and half the film layers; the base (the finest)
    gets the extrapolated error."""
    cfg_path, out = write_on_rank0(shared_tmp / "tiny.toml", TINY), shared_tmp / "conv"
    assert cli.main(["converge", str(cfg_path), "--only", "mesh", "--levels", "2", "--coarsen", "-o", str(out),
                     "-q"]) == 0
    doc = read_json(out / "convergence.json")
    assert doc["direction"] == "coarsen"
    fine, coarse = read_json(out / "base" / "summary.json"), read_json(out / "mesh1" / "summary.json")
    c1 = config.load(out / "mesh1" / "config.toml")
    assert c1["mesh"]["element_size"] == 0.02 and c1["mesh"]["film_layers"] == 1
    assert coarse["mesh"]["cells"] < fine["mesh"]["cells"]
    g0, g1 = fine["critical"]["growth_um"], coarse["critical"]["growth_um"]
    st = doc["studies"]["mesh"]
    assert st["values"] == [g0, g1]
    g_inf = g0 + (g0 - g1) / (2 - 1)
    assert st["converged"] == pytest.approx(g_inf, rel=1e-12)
    assert st["errors"] == pytest.approx([abs(g0 - g_inf), abs(g1 - g_inf)], rel=1e-9)
    assert doc["base"]["error_estimate_um"] == pytest.approx(abs(g1 - g0), rel=1e-9)


def test_converge_rejects_bad_input_without_running(shared_tmp):
    cfg_path = write_on_rank0(shared_tmp / "tiny.toml", TINY)
    out = shared_tmp / "never"
    assert cli.main(["converge", str(cfg_path), "--levels", "7", "-o", str(out), "-q"]) == 2
    assert cli.main(["converge", str(cfg_path), "--only", "mesh", "--coarsen", "--levels", "3", "-o", str(out)]) == 2
    assert cli.main(["converge", str(cfg_path), "--set", "stability.enabled=false", "-o", str(out)]) == 2
    assert not out.exists()


# --- mesh and validate --------------------------------------------------------------------------

TINY_TUBE = """
[geometry]
kind = "tube"
outer_radius = 0.3
substrate_thickness = 0.06
film_thickness = 0.01
[mesh]
element_size = 0.01
film_layers = 2
substrate_grading = 1.3
[material.film]
modulus_ratio = 10.0
[time]
end = 1.0
[stability]
error_estimate = false
[output]
fields = false
plot = false
"""


def _msh_contents(path):
    """Physical groups of a .msh file read with gmsh: {(dim, name): (element types, element count)}."""
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(path))
        out = {}
        for dim, tag in gmsh.model.getPhysicalGroups():
            types, count = set(), 0
            for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
                t, e, _ = gmsh.model.mesh.getElements(dim, ent)
                types |= {int(x) for x in t}
                count += sum(len(x) for x in e)
            out[(dim, gmsh.model.getPhysicalName(dim, tag))] = (sorted(types), count)
        return out
    finally:
        gmsh.finalize()


def _global_facets(tm, name, comm):
    """Number of facets of a group over all ranks (owned facets: each counted once)."""
    domain = tm.mesh
    fdim = domain.topology.dim - 1
    n_owned = domain.topology.index_map(fdim).size_local
    return comm.allreduce(int(np.sum(tm.facets(name) < n_owned)))


@pytest.mark.parametrize("text, cells, facets", [
    (TINY, ["film", "substrate"], ["bottom", "left", "right", "top"]),
    (TINY_TUBE, ["film", "substrate"], ["inner", "outer"]),
], ids=["bilayer", "tube"])
def test_mesh_command_writes_the_builtin_mesh(shared_tmp, comm, capsys, text, cells, facets):
    cfg_path, msh = write_on_rank0(shared_tmp / "g.toml", text), shared_tmp / "sub" / "g.msh"
    assert cli.main(["mesh", str(cfg_path), "-o", str(msh)]) == 0
    if comm.rank == 0:
        assert f"wrote {msh}" in capsys.readouterr().out
    builtin = geometry.build(config.geometry_input(config.load(cfg_path)), comm).tm
    n_cells = fem_utils.num_global_cells(builtin.mesh)
    contents = on_rank0(_msh_contents, msh)
    assert sorted(n for d, n in contents if d == 2) == cells
    assert sorted(n for d, n in contents if d == 1) == facets
    assert sum(contents[(2, n)][1] for n in cells) == n_cells
    assert all(contents[(2, n)][0] == [3] for n in cells)  # 4-node quadrilaterals only
    for name in facets:
        assert contents[(1, name)] == ([1], _global_facets(builtin, name, comm))
    # read back as a user mesh: the same cells and facet groups
    from app.geometry import msh as mshmod

    tm = mshmod.read(comm, msh)
    assert fem_utils.num_global_cells(tm.mesh) == n_cells
    for name in cells:
        assert comm.allreduce(int(np.sum(tm.cells(name) < fem_utils.num_owned_cells(tm.mesh)))) == \
            comm.allreduce(int(np.sum(builtin.cells(name) < fem_utils.num_owned_cells(builtin.mesh))))
    for name in facets:
        assert _global_facets(tm, name, comm) == _global_facets(builtin, name, comm)


def test_mesh_command_rejects_a_msh_config(shared_tmp):
    cfg_path = write_on_rank0(shared_tmp / "m.toml", '[geometry]\nkind = "msh"\nfile = "x.msh"\n'
                              'layers = { a = "film" }\nboundaries = { b = "permeable" }\n')
    assert cli.main(["mesh", str(cfg_path), "-o", str(shared_tmp / "x.msh")]) == 2
    assert not (shared_tmp / "x.msh").exists()


MSH_CONFIG = """
[geometry]
kind = "msh"
file = "layers.msh"
layers = { film = "film", coating = "coat", substrate = "substrate" }
boundaries = { top = "permeable", left = "roller_x", right = "roller_x", bottom = "roller_y" }
[material.film]
modulus_ratio = 10.0
[material.layers.coat]
modulus_ratio = 3.0
mobility = 2e-4
"""


@pytest.mark.parametrize("text, overrides", [(TINY, ["material.film.modulus_ratio=20", "time.end=3.5"]),
                                             (TINY_TUBE, []), (MSH_CONFIG, ["geometry.wrinkles=along"])],
                         ids=["bilayer", "tube", "msh"])
def test_validate_prints_a_resolved_config_that_round_trips(shared_tmp, capsys, text, overrides):
    cfg_path = write_on_rank0(shared_tmp / "v.toml", text)
    capsys.readouterr()
    assert cli.main(["validate", str(cfg_path), *_sets(overrides)]) == 0
    printed = capsys.readouterr().out
    again = shared_tmp / f"printed{MPI.COMM_WORLD.rank}.toml"
    again.write_text(printed)
    assert config.load(again) == config.resolve(_toml(text), overrides) == config.load(cfg_path, overrides)
    # fully resolved: every key of the schema is written, with its value
    resolved = _toml(printed)
    assert resolved["time"]["dt_min"] == 1e-9 and resolved["mesh"]["quadrature_degree"] == 2


def test_validate_round_trips_a_material_table_without_keys(shared_tmp, capsys):
    """[material.layers.coat] with no keys (the substrate's values under another name) must survive
    validate's printout, or the printed config (and every result's config.toml) no longer loads."""
    text = MSH_CONFIG.replace("modulus_ratio = 3.0\nmobility = 2e-4\n", "")
    assert text.rstrip().endswith("[material.layers.coat]")
    cfg_path = write_on_rank0(shared_tmp / "v.toml", text)
    capsys.readouterr()
    assert cli.main(["validate", str(cfg_path)]) == 0
    again = shared_tmp / f"printed{MPI.COMM_WORLD.rank}.toml"
    again.write_text(capsys.readouterr().out)
    assert config.load(again) == config.load(cfg_path)
    assert config.load(again)["material"]["layers"] == {"coat": {}}


# --- study and sweep ------------------------------------------------------------------------------


def test_study_list_names_every_study_with_its_values(capsys):
    assert cli.main(["study", "--list"]) == 0
    out = capsys.readouterr().out
    for name, spec in studies.STUDIES.items():
        assert name in out
        assert f"{spec.param} = " + ", ".join(f"{v:g}" for v in spec.values) in out
    assert cli.main(["study"]) == 2  # no name: the list, and exit 2


def _study(out, *extra):
    return cli.main(["study", "bilayer-modulus-ratio", "-o", str(out), "-q", *_sets(SHRINK), *extra])


def test_study_runs_skips_complete_cases_and_reruns_them_with_force(shared_tmp, comm):
    out = shared_tmp / "study"
    assert _study(out, "--values", "4,20") == 0
    rows = read_csv(out / "study.csv")
    assert [float(r["value"]) for r in rows] == [4.0, 20.0]
    assert [r["status"] for r in rows] == ["buckled", "buckled"]
    dirs = [out / r["directory"] for r in rows]
    for d, v in zip(dirs, (4.0, 20.0)):
        c = config.load(d / "config.toml")
        assert c["material"]["film"]["modulus_ratio"] == v and c["geometry"]["length"] == 0.15
        assert float(rows[[4.0, 20.0].index(v)]["g_c_um"]) == read_json(d / "summary.json")["critical"]["growth_um"]
    g = [float(r["g_c_um"]) for r in rows]
    assert g[0] > g[1]  # the paper's trend: g_c falls as the film gets stiffer
    for name in ("study.png", "modes.png", "study.json"):
        assert (out / name).stat().st_size > 0
    stamps = [_mtime(d / "summary.json") for d in dirs]
    comm.barrier()
    assert _study(out, "--values", "4,20") == 0  # complete: skipped
    assert [_mtime(d / "summary.json") for d in dirs] == stamps
    assert _study(out, "--values", "4,20", "--force") == 0
    assert all(_mtime(d / "summary.json") != s for d, s in zip(dirs, stamps))
    assert [float(r["g_c_um"]) for r in read_csv(out / "study.csv")] == pytest.approx(g, rel=1e-12)


def test_study_error_estimate_runs_coarser_companions(shared_tmp, comm):
    out = shared_tmp / "est"
    assert _study(out, "--values", "8", "--error-estimate") == 0
    row = read_csv(out / "study.csv")[0]
    case = out / row["directory"]
    s = read_json(case / "summary.json")
    crit, cfg = s["critical"], config.load(case / "config.toml")
    est = crit["discretization_error"]
    assert cfg["stability"]["error_estimate"] is True
    comp = {}
    for study in ("time", "mesh"):
        d = case / "error-estimate" / study
        comp[study] = (read_json(d / "summary.json"), config.load(d / "config.toml"))
        assert comp[study][0]["status"] == "buckled"
        assert est[f"{study}_companion_g_c_um"] == comp[study][0]["critical"]["growth_um"]
    t_cfg, m_cfg = comp["time"][1], comp["mesh"][1]
    # the mesh companion: the run's steps on a coarser mesh; the time companion: that coarse mesh, coarser steps
    assert m_cfg["mesh"]["element_size"] == pytest.approx(2 * cfg["mesh"]["element_size"], rel=1e-14)
    assert m_cfg["mesh"]["film_layers"] * 2 == cfg["mesh"]["film_layers"]
    assert m_cfg["time"] == cfg["time"]
    assert t_cfg["time"]["tolerance"] == pytest.approx(4 * cfg["time"]["tolerance"], rel=1e-14)
    assert t_cfg["mesh"] == m_cfg["mesh"] and est["time_companion_mesh"] == "coarsened"
    assert comp["mesh"][0]["mesh"]["cells"] < s["mesh"]["cells"]
    assert comp["time"][0]["mesh"]["cells"] == comp["mesh"][0]["mesh"]["cells"]
    assert comp["time"][0]["steps"] < comp["mesh"][0]["steps"]
    g = crit["growth_um"]
    assert est["time_um"] == pytest.approx(
        abs(est["mesh_companion_g_c_um"] - est["time_companion_g_c_um"]) / (2 ** 1 - 1), rel=1e-12)
    assert est["mesh_um"] == pytest.approx(abs(g - est["mesh_companion_g_c_um"]) / (2 ** 1.5 - 1), rel=1e-12)
    assert est["total_um"] == pytest.approx(est["time_um"] + est["mesh_um"], rel=1e-12)
    assert float(row["g_c_error_um"]) == pytest.approx(est["total_um"], rel=1e-12)


def test_study_isomodes_record_later_crossings(shared_tmp, comm):
    out = shared_tmp / "iso"
    assert _study(out, "--values", "8", "--isomodes", "--set", "stability.max_crossings=3") == 0
    row = read_csv(out / "study.csv")[0]
    s = read_json(out / row["directory"] / "summary.json")
    assert config.load(out / row["directory"] / "config.toml")["stability"]["stop_at_onset"] is False
    crossings = s["crossings"]
    assert len(crossings) == 3 and crossings[0] == {k: s["critical"][k] for k in crossings[0]}
    g = [c["growth_um"] for c in crossings]
    assert g == sorted(g)
    assert [c["time"] for c in crossings] == sorted(c["time"] for c in crossings)
    cells = [c.split("@") for c in row["crossings"].split(";")]
    assert [float(n) for n, _ in cells] == [c["first_mode_wrinkle_count"] for c in crossings]
    assert [float(x) for _, x in cells] == pytest.approx(g, rel=1e-4)  # written with 5 digits
    assert (out / "isomodes.png").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size < 2, reason="rank groups need 2 ranks")
def test_study_ranks_per_case_two_equals_one(shared_tmp, comm):
    """--ranks-per-case 1 on 2 ranks runs the cases side by side on one rank each; 2 runs each case on
    both ranks: the same g_c and N_c."""
    g = {}
    for k in (1, 2):
        out = shared_tmp / f"rpc{k}"
        assert _study(out, "--values", "4,20", "--ranks-per-case", str(k)) == 0
        rows = read_csv(out / "study.csv")
        g[k] = [(float(r["g_c_um"]), float(r["N_c"])) for r in rows]
        ranks = [read_json(out / r["directory"] / "summary.json")["ranks"] for r in rows]
        assert ranks == [k, k]
    for (g1, n1), (g2, n2) in zip(g[1], g[2]):
        assert g2 == pytest.approx(g1, rel=1e-8)  # measured 2e-14
        assert n1 == n2
    assert cli.main(["study", "bilayer-modulus-ratio", "--ranks-per-case", "3", "-o", str(shared_tmp / "x")]) == 2


def test_sweep_cli_cases_equal_the_same_config_run_alone(shared_tmp, comm):
    cfg_path, out = write_on_rank0(shared_tmp / "tiny.toml", TINY), shared_tmp / "sweep"
    assert cli.main(["sweep", str(cfg_path), "--param", "material.film.modulus_ratio", "--values", "6,12",
                     "-o", str(out), "-q"]) == 0
    rows = read_csv(out / "study.csv")
    assert [float(r["value"]) for r in rows] == [6.0, 12.0] and rows[0]["parameter"] == "material.film.modulus_ratio"
    for r, v in zip(rows, (6.0, 12.0)):
        alone = config.load(cfg_path, [f"material.film.modulus_ratio={v}"])
        alone["output"]["fields"] = False
        assert config.load(out / r["directory"] / "config.toml") == alone
        ref = simulate(alone, shared_tmp / f"alone{comm.rank}-{v:g}", MPI.COMM_SELF, progress=False)
        assert float(r["g_c_um"]) == pytest.approx(ref["critical"]["growth_um"], rel=1e-12)
        assert float(r["N_c"]) == ref["critical"]["wrinkle_count"]
    assert float(rows[0]["g_c_um"]) > float(rows[1]["g_c_um"])


# --- bench --ranks ------------------------------------------------------------------------------


def _bench_one_rank(out):
    cmd = [PYTHON, "-m", "app", "bench", "--ranks", "1", "--sizes", "coarse", "-o", str(out), "-q", "--set",
           "geometry.length=0.2"]
    return run_child(cmd, cwd=REPO, timeout=600)


def test_bench_ranks_launches_its_own_mpirun(shared_tmp):
    """`hydrobuckle bench --ranks 1` starts `mpirun -n 1` itself (from rank 0 when the test runs under
    mpirun: the child gets an environment without the parent's MPI variables); its g_c is that of
    the same config run here on one rank."""
    from app.workflows import bench

    out = shared_tmp / "bench"
    proc = on_rank0(_bench_one_rank, out)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    doc = read_json(out / "bench.json")
    assert list(doc["runs"]) == ["1"] and doc["speedup"] == {}
    run = doc["runs"]["1"]["sizes"]["coarse"]
    assert run["ranks"] == 1 and len(run["peak_rss_mb_per_rank"]) == 1
    cfg = bench.size_config("coarse", ["geometry.length=0.2"])
    ref = on_rank0(lambda: simulate(cfg, shared_tmp / "ref", MPI.COMM_SELF, progress=False)["critical"])
    assert run["g_c_um"] == pytest.approx(ref["growth_um"], rel=1e-12)
    assert run["dofs"] == read_json(out / "run-coarse-np1" / "summary.json")["mesh"]["dofs"]
    assert "| 1 | coarse |" in (out / "bench.md").read_text()


# --- mesh options ---------------------------------------------------------------------------------


@pytest.mark.parametrize("grading", [1.0, 1.5, 2.0])
def test_film_grading_makes_film_heights_geometric_towards_the_surface(comm, grading):
    """Bilayer: the film's element heights from the interface to the top shrink by 1/grading each
    and add up to w; tube: along the x axis (normal to the passage there) they grow by grading from
    the passage outwards."""
    cfg = config.resolve(_toml(TINY), ["mesh.film_layers=3", f"mesh.film_grading={grading}"])
    _, _, nf = _measured_mesh(cfg, comm)
    assert nf == 3
    tm = geometry.build(config.geometry_input(cfg), comm).tm
    pts = np.concatenate(comm.allgather(tm.mesh.geometry.x[:, :2]))
    H, w = 0.15, 0.01
    y = np.unique(np.round(pts[(np.abs(pts[:, 0]) < 1e-12) & (pts[:, 1] >= H - 1e-12), 1], 13))
    heights = np.diff(y)  # interface -> top
    assert heights.sum() == pytest.approx(w, rel=1e-10)
    assert heights[1:] / heights[:-1] == pytest.approx([1 / grading] * 2, rel=1e-8)
    tube_cfg = config.resolve(_toml(TINY_TUBE), ["mesh.film_layers=3", f"mesh.film_grading={grading}"])
    tm = geometry.build(config.geometry_input(tube_cfg), comm).tm
    pts = np.concatenate(comm.allgather(tm.mesh.geometry.x[:, :2]))
    r = 0.3 - 0.06 - 0.01
    x = np.unique(np.round(pts[(np.abs(pts[:, 1]) < 1e-12) & (pts[:, 0] > 0) & (pts[:, 0] <= r + 0.01 + 1e-12), 0],
                           13))
    heights = np.diff(x)  # passage -> interface
    assert x[0] == pytest.approx(r, rel=1e-12) and heights.sum() == pytest.approx(0.01, rel=1e-10)
    assert heights[1:] / heights[:-1] == pytest.approx([grading] * 2, rel=1e-6)


def test_quadrature_degree_exact_on_rectangles_small_on_curved_cells(shared_tmp, comm):
    """On the bilayer's axis-aligned rectangles the laterally homogeneous state has a constant F per
    cell and K's integrands are polynomials of degree <= 2 per direction: 2x2 Gauss (degree 2) is
    exact, so degree 4 gives the same g_c to roundoff. On the tube's curved cells it is not: degree 4
    changes the growth, but only by the small quadrature error (measured 3e-7 relative)."""
    g = {}
    for q in (2, 4):
        cfg = config.load(write_on_rank0(shared_tmp / "tiny.toml", TINY), [f"mesh.quadrature_degree={q}"])
        g[q] = simulate(cfg, shared_tmp / f"q{q}", comm, progress=False)["critical"]["growth_mm"]
    assert g[4] == pytest.approx(g[2], rel=1e-10)
    growth = {}
    for q in (2, 4):
        cfg = config.resolve(_toml(TINY_TUBE), [f"mesh.quadrature_degree={q}", "time.end=0.5", "time.dt_initial=0.01",
                                                "time.dt_max=0.1", "stability.enabled=false"])
        _, _, rows = run_to_end(cfg, comm)
        growth[q] = rows[-1].growth_mm
    assert growth[4] != growth[2]  # the option reaches the forms
    assert growth[4] == pytest.approx(growth[2], rel=1e-5)


def test_coupling_quadrature_two_points_lock_and_raise_gc(shared_tmp, comm):
    """The volumetric penalty with 2x2 points per cell locks the Q1 film in bending: a stiffer
    response, higher g_c; degrees 0 and 1 are the same one-point rule."""
    g = {}
    for q in (0, 1, 2):
        cfg = config.load(write_on_rank0(shared_tmp / "tiny.toml", TINY), [f"mesh.coupling_quadrature_degree={q}"])
        g[q] = simulate(cfg, shared_tmp / f"c{q}", comm, progress=False)["critical"]["growth_mm"]
    assert g[0] == pytest.approx(g[1], rel=1e-12)
    assert g[2] > 1.05 * g[1]  # measured +34% on this mesh (docs/model.md: +25% on the paper-like mesh)


# --- user .msh: more materials, wrinkle direction ------------------------------------------------


def _split_substrate(src, dst, y_cut):
    """Rewrite a bilayer .msh with the substrate split at y_cut into 'coating' (above) and 'substrate'
    (below), keeping every node, cell and facet group."""
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.open(str(src))
        tags, coords, _ = gmsh.model.mesh.getNodes()
        xyz = dict(zip(tags, coords.reshape(-1, 3)))
        groups = []
        for dim, ptag in gmsh.model.getPhysicalGroups():
            name = gmsh.model.getPhysicalName(dim, ptag)
            entities = gmsh.model.getEntitiesForPhysicalGroup(dim, ptag)
            nodes = [gmsh.model.mesh.getElements(dim, e)[2][0] for e in entities]
            groups.append((dim, name, np.concatenate(nodes)))
        gmsh.model.add("split")
        holder = gmsh.model.addDiscreteEntity(2)
        gmsh.model.mesh.addNodes(2, holder, tags, coords)
        pieces = []
        for dim, name, nodes in groups:
            if name == "substrate":
                quads = nodes.reshape(-1, 4)
                above = np.array([np.mean([xyz[n][1] for n in q]) > y_cut for q in quads])
                pieces += [(2, "coating", quads[above].ravel()), (2, "substrate", quads[~above].ravel())]
            else:
                pieces.append((dim, name, nodes))
        count = {1: 0, 2: 0}
        for dim, name, nodes in pieces:
            ent = holder if (dim == 2 and count[2] == 0) else gmsh.model.addDiscreteEntity(dim)
            count[dim] += 1
            gmsh.model.mesh.addElementsByType(ent, 3 if dim == 2 else 1, [], nodes)
            gmsh.model.addPhysicalGroup(dim, [ent], count[dim])
            gmsh.model.setPhysicalName(dim, count[dim], name)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(dst))
    finally:
        gmsh.finalize()


def _layers_msh(shared_tmp, comm):
    cfg_path = write_on_rank0(shared_tmp / "bilayer.toml", TINY)
    assert cli.main(["mesh", str(cfg_path), "-o", str(shared_tmp / "bilayer.msh")]) == 0
    on_rank0(_split_substrate, shared_tmp / "bilayer.msh", shared_tmp / "layers.msh", 0.1)
    return cfg_path


def _msh_user(shared_tmp, coat: dict, wrinkles="auto"):
    user = _toml(TINY)
    user["geometry"] = {"kind": "msh", "file": str(shared_tmp / "layers.msh"), "wrinkles": wrinkles,
                        "layers": {"film": "film", "coating": "coat", "substrate": "substrate"},
                        "boundaries": {"top": "permeable", "left": "roller_x", "right": "roller_x",
                                       "bottom": "roller_y"}}
    user["material"] = {"layers": {"coat": coat}}
    return user


def test_user_msh_with_a_third_material(shared_tmp, comm):
    """A bilayer from `hydrobuckle mesh` with its substrate split into two groups, the upper one
    ('coating') mapped to a material of [material.layers]: with the substrate's values it reproduces
    the built-in bilayer; with its own values every coating cell carries them and the summary lists
    the material with s0 and mu0 of eqs. 3.5/3.6."""
    cfg_path = _layers_msh(shared_tmp, comm)
    builtin = config.load(cfg_path, ["stability.enabled=false", "time.end=0.3"])
    same = config.resolve(_msh_user(shared_tmp, {}), ["stability.enabled=false", "time.end=0.3"])
    _, _, ref = run_to_end(builtin, comm)
    p, _, rows = run_to_end(same, comm)
    assert p.geo.wrinkles == "along"  # auto: the open top surface
    assert sorted(p.materials) == ["coat", "film", "substrate"]
    assert len(rows) == len(ref)
    for a, b in zip(rows, ref):
        assert a.time == b.time
        assert a.growth_mm == pytest.approx(b.growth_mm, rel=1e-9)
        assert a.fluid_volume == pytest.approx(b.fluid_volume, rel=1e-12)

    cfg = config.resolve(_msh_user(shared_tmp, {"modulus_ratio": 3.0, "mobility": 2e-4}),
                         ["stability.enabled=false", "time.end=0.05"])
    from app import factory

    p = factory.problem(cfg, comm)
    for group, value in (("film", 0.8), ("coating", 0.3), ("substrate", 0.1)):
        assert p.mat.shear_modulus.x.array[p.tm.cells(group)] == pytest.approx(value, rel=1e-15)
    assert np.all(p.mat.mobility.x.array[p.tm.cells("coating")] == 2e-4)
    assert np.all(p.mat.mobility.x.array[p.tm.cells("substrate")] == 1e-4)
    s = simulate(cfg, shared_tmp / "run", comm, problem=p, progress=False)
    coat = s["materials"]["coat"]
    gamma, eps, J0, alpha, chi = 0.3, 10.0, 1.01, 24.2, 0.1
    assert coat["shear_modulus"] == pytest.approx(0.3, rel=1e-15) and coat["mobility"] == 2e-4
    s0 = gamma / eps * (J0 ** (-1 / 3) - 1 / J0) + J0 - 1  # eq. 3.5
    mu0 = alpha / J0 * (math.log(s0 / (1 + s0)) + 1 / (1 + s0) + chi / (1 + s0) ** 2) - eps / J0 * (J0 - 1 - s0)
    assert coat["s0"] == pytest.approx(s0, rel=1e-14)
    assert coat["mu0"] == pytest.approx(mu0, rel=1e-12)
    assert coat["mu0"] == pytest.approx(chemical_potential(p.materials["coat"], np.eye(2), s0), rel=1e-14)
    # the ramp starts at the mu0 of the film, the material under the permeable top
    first = read_csv(shared_tmp / "run" / "history.csv")[0]
    assert float(first["mu_bar"]) == s["materials"]["film"]["mu0"]


def test_auto_wrinkles_around_a_closed_msh_surface(shared_tmp, comm):
    tube_cfg = write_on_rank0(shared_tmp / "tube.toml", TINY_TUBE)
    assert cli.main(["mesh", str(tube_cfg), "-o", str(shared_tmp / "tube.msh")]) == 0
    user = {"geometry": {"kind": "msh", "file": str(shared_tmp / "tube.msh"),
                         "layers": {"film": "film", "substrate": "substrate"},
                         "boundaries": {"inner": "permeable", "outer": "fixed"}}}
    assert geometry.build(config.geometry_input(config.resolve(user)), comm).wrinkles == "around"
    user["geometry"]["wrinkles"] = "along"  # an explicit choice wins
    assert geometry.build(config.geometry_input(config.resolve(user)), comm).wrinkles == "along"
    # an open permeable surface: the bilayer's top
    bil = write_on_rank0(shared_tmp / "b.toml", TINY)
    assert cli.main(["mesh", str(bil), "-o", str(shared_tmp / "b.msh")]) == 0
    open_user = {"geometry": {"kind": "msh", "file": str(shared_tmp / "b.msh"),
                              "layers": {"film": "film", "substrate": "substrate"},
                              "boundaries": {"top": "permeable", "bottom": "fixed"}}}
    assert geometry.build(config.geometry_input(config.resolve(open_user)), comm).wrinkles == "along"


# --- scripts --------------------------------------------------------------------------------------


def test_every_shell_script_parses():
    scripts = sorted((REPO / "scripts").glob("*.sh")) + [REPO / ".ci" / "run"]
    assert len(scripts) >= 8
    for path in scripts:
        proc = subprocess.run(["bash", "-n", str(path)], capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, f"{path}: {proc.stderr}"
