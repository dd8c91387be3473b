"""The mesh size estimate of the built-in kinds (from the keys, without meshing) against the cells
and dofs of the built meshes, and the refusal of absurd meshes by run and validate unless --force
(docs/reliability.md)."""

from __future__ import annotations

import time

import pytest
from conftest import REPO

from app import cli, config, geometry
from app.geometry.base import MAX_CELLS
from app import factory

SMALL = {
    "bilayer": {"geometry": {"length": 0.3, "substrate_thickness": 0.15, "film_thickness": 0.01},
                "mesh": {"element_size": 0.01, "film_layers": 3, "substrate_grading": 1.25, "film_grading": 1.5}},
    "elliptic-tube": {"geometry": {"kind": "elliptic-tube", "aspect_ratio": 1.5, "outer_radius": 0.3,
                                   "substrate_thickness": 0.06, "film_thickness": 0.01},
                      "mesh": {"element_size": 0.01, "film_layers": 2, "substrate_grading": 1.3}},
}
BILAYER = str(REPO / "configs" / "bilayer.toml")
ABSURD = ["--set", "mesh.element_size=1e-6"]  # L = 2 mm: 2,000,000 elements along the film


@pytest.mark.parametrize("name", list(SMALL))
def test_estimate_matches_the_built_mesh(name, comm):
    cfg = config.resolve(SMALL[name], [])
    est = geometry.kind_of(cfg["geometry"]["kind"]).estimate(config.geometry_input(cfg))
    problem = factory.problem(cfg, comm)
    # the counting follows the builders exactly; the brief allows a few %
    assert est["cells"] == pytest.approx(problem.cells(), rel=0.02)
    assert est["dofs"] == pytest.approx(problem.dofs(), rel=0.02)
    assert (est["cells"], est["dofs"]) == (problem.cells(), problem.dofs())


def test_user_msh_has_no_estimate():
    assert geometry.KINDS.get("msh").estimate(geometry.GeometryInput("msh", {}, {})) is None


def test_validate_prints_the_estimate(shared_tmp, capsys, comm):
    assert cli.main(["validate", BILAYER]) == 0
    out = capsys.readouterr().out
    first = out.splitlines()[0]
    assert first == "# mesh estimate: 18,000 cells (500 elements along the film x 36 layers), 73,610 dofs, " \
                    "about 0.5 GB (serial)", first
    printed = shared_tmp / f"printed{comm.rank}.toml"
    printed.write_text(out)
    assert config.load(printed) == config.load(BILAYER)  # still a loadable config


@pytest.mark.parametrize("command", ["run", "validate"])
def test_absurd_mesh_is_refused_at_once(command, shared_tmp, capsys, comm):
    out = shared_tmp / "absurd"
    argv = [command, BILAYER, *ABSURD] + (["-o", str(out)] if command == "run" else [])
    t0 = time.perf_counter()
    assert cli.main(argv) == 2
    assert time.perf_counter() - t0 < 10  # no meshing (gmsh would not come back)
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    if comm.rank == 0:
        assert len(lines) == 1, captured.err
        line = lines[0]
        assert line.startswith("hydrobuckle: error: config key 'mesh.element_size': = 1e-06 ")
        assert "72,000,000 cells" in line and f"limit of {MAX_CELLS:,} cells" in line and "--force" in line
    else:
        assert lines == []
    assert not out.exists()


def test_force_lets_validate_accept_an_absurd_mesh(capsys):
    assert cli.main(["validate", BILAYER, *ABSURD, "--force"]) == 0
    assert capsys.readouterr().out.startswith("# mesh estimate: 72,000,000 cells (2,000,000 elements along")


def test_limit_is_on_the_cell_count(capsys):
    """Just below and just above the limit: 5,000,000 cells exactly pass, one row more is refused."""
    # 100 layers through (film 8 + substrate 92 with grading 1): 50,000 elements along L give 5,000,000
    sets = ["--set", "geometry.substrate_thickness=0.115", "--set", "mesh.substrate_grading=1.0"]
    cfg = config.load(BILAYER, [s for s in sets if s != "--set"] + ["mesh.element_size=4e-5"])
    est = geometry.kind_of(cfg["geometry"]["kind"]).estimate(config.geometry_input(cfg))
    assert est["cells"] == MAX_CELLS, est
    assert cli.main(["validate", BILAYER, *sets, "--set", "mesh.element_size=4e-5"]) == 0
    assert cli.main(["validate", BILAYER, *sets, "--set", "mesh.element_size=3.99e-5"]) == 2
    capsys.readouterr()


MULTI = {  # the commands that run several meshes: each case, level or size is estimated before anything runs
    "study": ["study", "bilayer-modulus-ratio", "--values", "8,10", *ABSURD],
    "sweep": ["sweep", BILAYER, "--param", "material.film.modulus_ratio", "--values", "8,10", *ABSURD],
    "converge": ["converge", BILAYER, "--set", "mesh.element_size=2e-5"],  # its base passes, level mesh1 does not
    "bench": ["bench", "--sizes", "coarse", *ABSURD],
}
LABELS = {"study": "(case modulus_ratio=8)", "sweep": "(case modulus_ratio=8)", "converge": "(converge level mesh1)",
          "bench": "(bench size coarse)"}


@pytest.mark.parametrize("command", list(MULTI))
def test_commands_running_several_meshes_refuse_an_absurd_one(command, shared_tmp, capsys, comm):
    """study, sweep, converge and bench apply the limit to every mesh they would build (converge's refined
    levels too): one line naming the key and the case, exit 2, no result directory, at once."""
    out = shared_tmp / command
    t0 = time.perf_counter()
    assert cli.main(MULTI[command] + ["-o", str(out)]) == 2
    assert time.perf_counter() - t0 < 10
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    if comm.rank == 0:
        assert len(lines) == 1, captured.err
        assert lines[0].startswith("hydrobuckle: error: config key 'mesh.element_size': = ")
        assert LABELS[command] in lines[0] and f"limit of {MAX_CELLS:,} cells" in lines[0], lines[0]
    else:
        assert lines == []
    assert not out.exists()
