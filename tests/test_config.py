"""Config schema, overrides and bad input: one clear line naming the key, exit code 2, no result dir."""

import subprocess
import sys

import pytest
from conftest import child_env, on_rank0
from mpi4py import MPI

from app import cli, config, geometry


def test_defaults_are_the_documented_paper_case():
    cfg = config.resolve({})
    geo = {k: v for k, v in cfg["geometry"].items() if v is not None}
    assert geo == {"kind": "bilayer", "length": 2.0, "substrate_thickness": 0.5, "film_thickness": 0.01,
                   "base": "rollers"}  # the paper: u_y = 0 at the base
    tube = config.resolve({"geometry": {"kind": "tube"}})["geometry"]
    assert (tube["outer_radius"], tube["substrate_thickness"], tube["film_thickness"]) == (1.0, 0.2, 0.02)
    assert cfg["material"]["film"]["modulus_ratio"] == 8.0
    film = config.film_overrides(config.resolve({}))
    assert film["shear_modulus"] == pytest.approx(0.8)


def test_overrides_are_typed_and_dotted():
    cfg = config.resolve({}, ["material.film.modulus_ratio=20", "loading.kind=compression", "output.fields=false"])
    assert cfg["material"]["film"]["modulus_ratio"] == 20.0
    assert cfg["loading"]["kind"] == "compression"
    assert cfg["output"]["fields"] is False


def test_dumps_round_trips(tmp_path):
    cfg = config.resolve({"material": {"film": {"modulus_ratio": 3.5}}})
    path = tmp_path / "c.toml"
    path.write_text(config.dumps(cfg))
    assert config.load(path) == cfg


BAD = [
    ("[geometry]\nfilm_thickness = -0.01\n", "geometry.film_thickness", "> 0"),
    ("[geometry]\nlenght = 2.0\n", "geometry.lenght", "unknown key"),
    ("[mesh]\nfilm_layers = 0\n", "mesh.film_layers", "in [1, 200]"),
    ("[material.film]\nmodulus_ratio = 0\n", "material.film.modulus_ratio", "> 0"),
    ("[material.film]\nmodulus_ratio = -2.0\n", "material.film.modulus_ratio", "> 0"),
    ("[material]\npreswelling = 1.0\n", "material.preswelling", "in (1, 100)"),
    ("[material]\npreswelling = 0.9\n", "material.preswelling", "in (1, 100)"),
    ("[time]\nend = 0\n", "time.end", "> 0"),
    ("[time]\nend = -1.0\n", "time.end", "> 0"),
    ("[mesh]\nfilm_layers = 2.5\n", "mesh.film_layers", "integer"),
    ("[geometry]\nlength = \"long\"\n", "geometry.length", "number"),
    ("[loading]\nkind = \"heating\"\n", "loading.kind", "one of"),
    ("[material.film]\nmodulus_ratio = 2.0\nshear_modulus = 0.2\n", "material.film.shear_modulus", "not both"),
    ("[geometry]\nlength = 0.005\n", "mesh.element_size", "<= geometry.length/2"),
    ("geometry = 3\n", "geometry", "table"),
    ("[geometry]\nkind = \"tube\"\nlength = 2.0\n", "geometry.length", "not used by geometry.kind = 'tube'"),
    ("[geometry]\nkind = \"tube\"\nsubstrate_thickness = 0.99\n", "geometry.substrate_thickness",
     "allowed: < 0.98"),
    ("[geometry]\nkind = \"elliptic-tube\"\naspect_ratio = 0.5\n", "geometry.aspect_ratio", "in [1, 10]"),
    ("[geometry]\nkind = \"tube\"\n[loading]\nkind = \"compression\"\n", "loading.kind", "'swelling'"),
    ("[geometry]\nkind = \"msh\"\n", "geometry.file", "must name a .msh file"),
    ("[geometry]\nkind = \"msh\"\nfile = \"a.msh\"\nlayers = { film = \"glass\" }\n",
     "geometry.layers.film", "allowed: film, substrate"),
    ("[geometry]\nkind = \"msh\"\nfile = \"a.msh\"\nlayers = { film = \"film\" }\n"
     "boundaries = { top = \"open\" }\n", "geometry.boundaries.top", "allowed: permeable"),
]


def _one_line_on_rank0(err: str, *needles: str) -> None:
    """Bad input: rank 0 prints exactly one line (containing ``needles``), every other rank nothing."""
    lines = err.strip().splitlines()
    if MPI.COMM_WORLD.rank == 0:
        assert len(lines) == 1, err
        assert all(n in lines[0] for n in needles), err
    else:
        assert lines == [], err


@pytest.mark.parametrize("text,key,allowed", BAD)
def test_bad_config_exits_2_with_one_line_and_no_result_dir(shared_tmp, capsys, text, key, allowed):
    comm = MPI.COMM_WORLD
    cfg_path = shared_tmp / "bad.toml"
    out = shared_tmp / "results"
    if comm.rank == 0:
        cfg_path.write_text(text)
    comm.barrier()
    code = cli.main(["run", str(cfg_path), "-o", str(out)])
    assert code == 2
    assert not out.exists()
    _one_line_on_rank0(capsys.readouterr().err, f"'{key}'", allowed)


def test_bad_override_and_missing_file(shared_tmp, capsys):
    assert cli.main(["validate", str(shared_tmp / "nope.toml")]) == 2
    _one_line_on_rank0(capsys.readouterr().err, "does not exist")
    good = shared_tmp / "good.toml"
    if MPI.COMM_WORLD.rank == 0:
        good.write_text("")
    MPI.COMM_WORLD.barrier()
    assert cli.main(["validate", str(good), "--set", "material.film.modulus_rati=3"]) == 2
    _one_line_on_rank0(capsys.readouterr().err, "'material.film.modulus_rati'")
    assert cli.main(["validate", str(good), "--set", "mesh.film_layers=true"]) == 2
    _one_line_on_rank0(capsys.readouterr().err, "'mesh.film_layers'")


MSH_LAYERS = '{ film = "film", substrate = "substrate" }'
MSH_BOUNDARIES = '{ top = "permeable", left = "roller_x", right = "roller_x", bottom = "roller_y" }'
# (file, layers, boundaries) -> the key named and what the message says
BAD_MSH = [
    ("nope.msh", MSH_LAYERS, MSH_BOUNDARIES, "geometry.file", "does not exist"),
    ("garbage.msh", MSH_LAYERS, MSH_BOUNDARIES, "geometry.file", "is not a readable gmsh mesh"),
    ("good.msh", '{ film = "film", coat = "substrate" }', MSH_BOUNDARIES, "geometry.layers.coat",
     "is not a cell physical group"),
    ("good.msh", MSH_LAYERS, MSH_BOUNDARIES.replace("top", "roof"), "geometry.boundaries.roof",
     "is not a facet physical group"),
    ("good.msh", '{ film = "film" }', MSH_BOUNDARIES, "geometry.layers", "gives no material to the cell group(s) "
     "substrate"),
]


@pytest.mark.parametrize("file,layers,boundaries,key,message", BAD_MSH,
                         ids=["missing", "unreadable", "cell-group", "facet-group", "unassigned-group"])
def test_bad_msh_exits_2_with_one_line_and_no_result_dir(shared_tmp, capfd, file, layers, boundaries, key,
                                                         message):
    """A .msh that is missing, unreadable or lacks a group the config names is bad input for every
    command that builds geometry: exit 2, one line naming the key on rank 0 (nothing on the others,
    no traceback), no result directory; checked before anything runs."""
    from app.geometry import bilayer

    comm = MPI.COMM_WORLD
    good = shared_tmp / "good.msh"
    bilayer.tagged_mesh(comm, 0.1, 0.05, 0.01, 0.01, 2, 1.3, msh_path=str(good))
    cfg_path = shared_tmp / "bad.toml"
    if comm.rank == 0:
        (shared_tmp / "garbage.msh").write_text("this is not a mesh\n")
        cfg_path.write_text(f'[geometry]\nkind = "msh"\nfile = "{shared_tmp / file}"\nlayers = {layers}\n'
                            f'boundaries = {boundaries}\n')
    comm.barrier()
    # the same config with the good file and the right groups passes the check
    good_cfg = config.resolve({"geometry": {"kind": "msh", "file": str(good),
                                            "layers": {"film": "film", "substrate": "substrate"},
                                            "boundaries": {"top": "permeable", "bottom": "roller_y"}}})
    geometry.check(config.geometry_input(good_cfg), comm)
    capfd.readouterr()
    out = shared_tmp / "results"
    for command in (["run", str(cfg_path), "-o", str(out)],
                    ["sweep", str(cfg_path), "--param", "material.film.modulus_ratio", "--values", "4,8", "-o",
                     str(out)],
                    ["converge", str(cfg_path), "--only", "time", "-o", str(out)]):
        assert cli.main(command) == 2, command
        assert not out.exists(), command
        _one_line_on_rank0(capfd.readouterr().err, f"'{key}'", message)


def test_python_m_app_entry_point_exit_code(shared_tmp):
    """`python -m app` (app/__main__.py; the console script is tests/test_console.py's) passes main()'s
    exit code on: bad input exits 2 with one line and no result directory. Started by rank 0 from /."""
    cfg, out = shared_tmp / "bad.toml", shared_tmp / "r"
    if MPI.COMM_WORLD.rank == 0:
        cfg.write_text("[geometry]\nsubstrate_thickness = -1\n")
    MPI.COMM_WORLD.barrier()
    proc = on_rank0(subprocess.run, [sys.executable, "-m", "app", "run", str(cfg), "-o", str(out)], cwd="/",
                    env=child_env(), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "'geometry.substrate_thickness'" in lines[0], proc.stderr
    assert not out.exists()


def test_msh_layers_and_boundaries_from_file_and_set():
    user = {"geometry": {"kind": "msh", "file": "x.msh", "layers": {"f": "film", "s": "substrate", "c": "coating"},
                         "boundaries": {"top": "impermeable"}},
            "material": {"layers": {"coating": {"modulus_ratio": 3.0, "mobility": 2e-4}}}}
    cfg = config.resolve(user, ["geometry.boundaries.top=permeable", "geometry.boundaries.base=fixed"])
    assert cfg["geometry"]["boundaries"] == {"top": "permeable", "base": "fixed"}
    coating = config.layer_parameters(cfg, "coating")
    assert coating["shear_modulus"] == pytest.approx(0.3) and coating["mobility"] == 2e-4
    assert config.layer_parameters(cfg, "substrate")["mobility"] == 1e-4
    with pytest.raises(config.ConfigError, match="material.layers.coating.stiffness"):
        config.resolve({**user, "material": {"layers": {"coating": {"stiffness": 1.0}}}},
                       ["geometry.boundaries.top=permeable"])
