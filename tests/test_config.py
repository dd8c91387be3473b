"""Config schema, overrides and bad input: one clear line naming the key, exit code 2, no result dir."""

import subprocess
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

from app import cli, config


def test_defaults_are_the_documented_paper_case():
    cfg = config.resolve({})
    geo = {k: v for k, v in cfg["geometry"].items() if v is not None}
    assert geo == {"kind": "bilayer", "length": 2.0, "substrate_thickness": 0.5, "film_thickness": 0.01}
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
    err = capsys.readouterr().err.strip()
    if comm.rank == 0:
        assert len(err.splitlines()) == 1
        assert f"'{key}'" in err and allowed in err


def test_bad_override_and_missing_file(shared_tmp, capsys):
    assert cli.main(["validate", str(shared_tmp / "nope.toml")]) == 2
    assert "does not exist" in capsys.readouterr().err
    good = shared_tmp / "good.toml"
    if MPI.COMM_WORLD.rank == 0:
        good.write_text("")
    MPI.COMM_WORLD.barrier()
    assert cli.main(["validate", str(good), "--set", "material.film.modulus_rati=3"]) == 2
    assert "material.film.modulus_rati" in capsys.readouterr().err
    assert cli.main(["validate", str(good), "--set", "mesh.film_layers=true"]) == 2


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="spawns a fresh interpreter")
def test_console_entry_point_exit_code(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[geometry]\nsubstrate_thickness = -1\n")
    proc = subprocess.run([sys.executable, "-m", "app", "run", str(cfg), "-o", str(tmp_path / "r")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "geometry.substrate_thickness" in proc.stderr
    assert not (tmp_path / "r").exists()
    ver = subprocess.run([sys.executable, "-m", "app", "version"], capture_output=True, text=True)
    assert ver.returncode == 0 and "dolfinx 0.5" in ver.stdout
    assert Path(cfg).exists()


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
