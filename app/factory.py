"""Where a resolved config becomes hydrobuckle's objects: each layer's material under the config's law, the
discrete problem (geometry, materials, loading, discretization) and the 1D cross-section of the exact
reduction. Above config.py (it reads the config through it) and below io/ and the workflows; model/ and
reduced/ take these objects and never see a config dict's structure."""

from __future__ import annotations

from app import config, geometry
from app.model.loading import Loading
from app.model.material import Material
from app.model.problem import Discretization, Problem
from app.reduced.section import Layer, NotReducible, Section, drive, reducible


def layer_materials(cfg: dict, names=("film", "substrate")) -> dict[str, Material]:
    """Parameters of each named material (film, substrate, [material.layers.*]) under the config's law."""
    law = config.law(cfg)
    return {name: law.material(config.layer_parameters(cfg, name)) for name in names}


def problem(cfg: dict, comm, setup: geometry.GeometrySetup | None = None) -> Problem:
    """The problem of a resolved config: the geometry (built unless given), each layer's material, the loading
    (its surface ramp starting at the mu0 of the material under the permeable surface) and the
    discretization settings."""
    setup = setup if setup is not None else geometry.build(cfg, comm)
    materials = layer_materials(cfg, sorted(set(setup.layers.values())))
    surface = setup.material_under("permeable", comm)
    loading = Loading.from_config(cfg, mu_start=materials[surface].mu0, drive=setup.drive)
    return Problem(comm, setup, materials, loading, Discretization.from_config(cfg))


def section(cfg: dict) -> Section:
    """The cross-section of a reducible config (:func:`app.reduced.section.reducible`; else NotReducible
    naming the key)."""
    why = reducible(cfg)
    if why:
        raise NotReducible(why)
    geo = cfg["geometry"]
    materials = layer_materials(cfg)
    loading = Loading.from_config(cfg, mu_start=materials["film"].mu0, drive=drive(cfg))
    H, w = geo["substrate_thickness"], geo["film_thickness"]
    if geo["kind"] == "bilayer":
        layers = (Layer("substrate", 0.0, H), Layer("film", H, H + w))
        return Section("planar", layers, H + w, 0.0, geo["length"], materials, loading)
    R = geo["outer_radius"]
    a = R - H - w
    layers = (Layer("film", a, a + w), Layer("substrate", a + w, R))
    return Section("axisymmetric", layers, a, R, None, materials, loading)
