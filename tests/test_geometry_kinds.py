"""Geometry kinds as a registry: every registered kind's keys and defaults are in the config schema, and a
kind registered from outside (a toy kind here) is accepted by config, validation, `hydrobuckle mesh`, the
problem and, with a cross-section, the exact 1D reduction, without a change anywhere else."""

import pytest
from conftest import rank_local
from mpi4py import MPI

from app import cli, config, geometry
from app.geometry import Drive, GeometryKind, GeometrySetup
from app.geometry.base import CrossSection
from app.geometry.bilayer import Bilayer
from app.schema import ConfigError, gt, key


def test_every_registered_kind_is_in_the_schema_with_its_defaults():
    assert geometry.KINDS.names() == ("bilayer", "tube", "elliptic-tube", "plate", "tube-3d", "elliptic-tube-3d",
                                      "msh", "msh-3d")
    table = config.schema()["geometry"]
    assert table["kind"].default == geometry.DEFAULT_KIND
    for kind in geometry.KINDS:
        assert config.kind_defaults()[kind.name] == {"geometry": kind.defaults(), "mesh": kind.mesh_defaults}
        for name, spec in kind.keys.items():
            assert name in table and table[name].type is spec.type and table[name].default is None
            assert spec.doc
        if kind.name in ("msh", "msh-3d"):
            continue  # needs a file
        cfg = config.resolve({"geometry": {"kind": kind.name}})
        assert {k: cfg["geometry"][k] for k in kind.keys} == kind.defaults()
        for name, value in kind.mesh_defaults.items():
            assert cfg["mesh"][name] == value
        unused = sorted(set(table) - set(kind.keys) - {"kind"})
        assert all(cfg["geometry"][k] is None for k in unused)


def _toy_model(width, depth, element_size, film_layers):
    """A toy builder: the bilayer's gmsh model under other groups' names (pure gmsh)."""
    from meshes import bilayer

    cells, facets, info = bilayer.add_model(width, depth, 0.01, element_size, film_layers, 1.2)
    return cells, facets, {**info, "toy": True}


class ToySlab(GeometryKind):
    name = "toy-slab"
    keys = {"span": key(float, 0.1, gt(0), "slab span [mm]", unit="mm"),
            "depth": key(float, 0.05, gt(0), "substrate depth [mm]", unit="mm")}
    mesh_defaults = {"element_size": 0.025, "film_layers": 1}
    film_element_fraction = None
    provides = frozenset()

    def validate(self, g):
        if g.mesh["element_size"] > g.geometry["span"] / 2:
            raise ConfigError("mesh.element_size", "is too coarse for the toy slab")

    def build(self, g, comm, msh_path=None):
        from app.geometry.tagged import mesh_from_builder

        g, m = g.geometry, g.mesh
        tm = mesh_from_builder(comm, "toy", _toy_model, g["span"], g["depth"], m["element_size"], m["film_layers"],
                               msh_path=msh_path)
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"},
                             {"left": "fixed", "right": "free", "bottom": "roller_y", "top": "permeable"},
                             drive=Drive("right", 0, g["span"]))


def _registered(kind):
    """The kind registered for one test, unregistered after it."""
    geometry.KINDS.register(kind)
    try:
        yield kind
    finally:
        geometry.KINDS.unregister(kind.name)


@pytest.fixture
def toy():
    yield from _registered(ToySlab())


def test_a_registered_kind_is_accepted_by_config(toy):
    assert "toy-slab" in geometry.KINDS.names()
    cfg = config.resolve({"geometry": {"kind": "toy-slab"}})
    assert cfg["geometry"]["span"] == 0.1 and cfg["mesh"]["element_size"] == 0.025
    assert cfg["geometry"]["length"] is None
    with pytest.raises(ConfigError, match="'geometry.length': is not used by geometry.kind = 'toy-slab'; its keys "
                                          "are: depth, span"):
        config.resolve({"geometry": {"kind": "toy-slab", "length": 1.0}})
    with pytest.raises(ConfigError, match="'geometry.span': = -1.0 is out of range; allowed: > 0"):
        config.resolve({"geometry": {"kind": "toy-slab", "span": -1.0}})
    with pytest.raises(ConfigError, match="too coarse for the toy slab"):
        config.resolve({"geometry": {"kind": "toy-slab", "span": 0.04}})
    # it provides no drive: compression is refused with the kinds that have one
    with pytest.raises(ConfigError, match="'compression' needs geometry.kind = 'bilayer' or 'plate'; allowed for "
                                          "'toy-slab': 'swelling'"):
        config.resolve({"geometry": {"kind": "toy-slab"}, "loading": {"kind": "compression"}})
    # the other kinds' keys are still theirs
    with pytest.raises(ConfigError, match="not used by geometry.kind = 'bilayer'"):
        config.resolve({"geometry": {"span": 0.2}})


def test_unregistered_kind_leaves_the_schema(toy):
    geometry.KINDS.unregister(toy.name)
    try:
        assert "span" not in config.schema()["geometry"]
        with pytest.raises(ConfigError, match="geometry.kind"):
            config.resolve({"geometry": {"kind": "toy-slab"}})
    finally:
        geometry.KINDS.register(toy)


def test_a_registered_kind_is_written_by_the_mesh_command_and_builds_a_problem(toy, shared_tmp, capsys):
    from app.geometry import msh as user_msh
    from app import factory

    comm = MPI.COMM_WORLD
    cfg_path, out = shared_tmp / "toy.toml", shared_tmp / "toy.msh"
    if comm.rank == 0:
        cfg_path.write_text('[geometry]\nkind = "toy-slab"\nspan = 0.1\n')
    comm.barrier()
    assert cli.main(["mesh", str(cfg_path), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    if comm.rank == 0:
        assert f"wrote {out}" in printed and "'toy': True" in printed
    cells, facets = user_msh.physical_groups(comm, out)
    assert sorted(cells) == ["film", "substrate"] and sorted(facets) == ["bottom", "left", "right", "top"]
    p = factory.problem(config.load(cfg_path), comm)
    assert p.tm.info["toy"] is True and p.loading.kind == "swelling"
    assert p.loading.mu_bar(0.0) == p.materials["film"].mu0


def test_the_mesh_command_asks_the_kind_whether_it_can_be_exported(shared_tmp, capsys):
    comm = MPI.COMM_WORLD
    cfg_path = shared_tmp / "m.toml"
    if comm.rank == 0:
        cfg_path.write_text('[geometry]\nkind = "msh"\nfile = "x.msh"\nlayers = { a = "film" }\n'
                            'boundaries = { b = "permeable" }\n')
    comm.barrier()
    assert cli.main(["mesh", str(cfg_path), "-o", str(shared_tmp / "x.msh")]) == 2
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert "'msh' already is a .msh file; allowed here: bilayer, tube, elliptic-tube" in err


class ToyStrip(Bilayer):
    """A toy kind with a 1D counterpart: the bilayer under another name, its cross-section written out here (the
    film on its substrate from the base to the permeable top) and only swelling reducible."""

    name = "toy-strip"
    reduced_loadings = ("swelling",)

    def cross_section(self, geo):
        H, w = geo["substrate_thickness"], geo["film_thickness"]
        return CrossSection("planar", (("substrate", 0.0, H), ("film", H, H + w)), H + w, 0.0, geo["length"])


@pytest.fixture
def toy_strip():
    yield from _registered(ToyStrip())


@rank_local
def test_a_registered_kinds_cross_section_gives_its_1d_reduction(toy_strip, toy):
    """A kind's 1D counterpart comes from the kind alone (one class, one registration; no edit of factory or
    app/reduced): the toy strip's section is the bilayer's, so its exact 1D onset is the bilayer's, bit for bit;
    a loading outside its reduced_loadings and a kind without any are reported as not reducible, naming the key."""
    from cases import swelling_case

    from app.workflows import reduction

    ref = reduction.compute(swelling_case())
    got = reduction.compute(swelling_case("geometry.kind=toy-strip"))
    assert got["kind"] == ref["kind"] == "wrinkles"
    for name in ("time", "growth_um", "wrinkle_count", "mu_bar"):
        assert got[name] == ref[name], name
    why = config.reducible(swelling_case("geometry.kind=toy-strip", "loading.kind=compression"))
    assert why.startswith("loading.kind = 'compression'") and why.endswith("covers swelling")
    why = config.reducible(config.resolve({"geometry": {"kind": "toy-slab"}}))
    assert why.startswith("geometry.kind = 'toy-slab'") and "toy-strip" in why and "elliptic" not in why
