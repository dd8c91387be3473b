"""Geometry kind ``bilayer``: the paper's flat film on a substrate (Fig. "bi_geo"): u_x = 0 left and
right, u_y = 0 at the bottom (or u = 0: ``geometry.base = "clamped"``), fluid enters at the top; a
displacement loading moves the right edge."""

from __future__ import annotations

from typing import TYPE_CHECKING

from app.geometry.base import (CrossSection, Drive, GeometryInput, GeometryKind, GeometrySetup, base_key, base_role,
                                layer_keys, planar_cross_section, structured_size)
from app.schema import ConfigError, gt, key

if TYPE_CHECKING:
    from app.geometry.tagged import TaggedMesh


class Bilayer(GeometryKind):
    name = "bilayer"
    provides = frozenset({"drive"})  # a displacement loading moves the right edge
    creases = True  # a trial crease at the left edge (app.onset.creases)
    reduced_loadings = ("swelling", "compression")  # laterally uniform: the planar 1D section
    mesh_defaults = {"element_size": 0.004, "film_layers": 8}
    film_element_fraction = 0.4
    keys = {
        "length": key(float, 2.0, gt(0), "L [mm] (bilayer)", unit="mm"),
        **layer_keys(substrate=0.5, film=0.01),
        "base": base_key(),
    }

    def cross_section(self, geo: dict) -> CrossSection:
        return planar_cross_section(geo, drive=Drive("right", 0, geo["length"]))

    def validate(self, g: GeometryInput) -> None:
        geo, mesh = g.geometry, g.mesh
        if mesh["element_size"] > geo["length"] / 2:
            raise ConfigError("mesh.element_size",
                              f"= {mesh['element_size']:g} is too coarse; allowed: <= geometry.length/2 "
                              f"= {geo['length'] / 2:g}")
        if geo["base"] == "clamped" and g.loading == "compression":
            raise ConfigError("geometry.base", "= 'clamped' holds the base's u_x, which the compression moves at "
                              "the right edge; allowed with loading.kind = 'compression': 'rollers'")

    def estimate(self, g: GeometryInput) -> dict:
        from meshes.bilayer import film_interface_height, substrate_layer_count

        geo, mesh = g.geometry, g.mesh
        nx = max(1, round(geo["length"] / mesh["element_size"]))
        first = film_interface_height(geo["film_thickness"], mesh["film_layers"], mesh["film_grading"])
        ny = mesh["film_layers"] + substrate_layer_count(geo["substrate_thickness"], first * mesh["substrate_grading"],
                                                         mesh["substrate_grading"])
        return structured_size(nx, ny, closed=False, what="along the film")

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        geo, mesh = g.geometry, g.mesh
        tm = tagged_mesh(comm, geo["length"], geo["substrate_thickness"], geo["film_thickness"],
                         mesh["element_size"], mesh["film_layers"], mesh["substrate_grading"],
                         film_grading=mesh["film_grading"], msh_path=msh_path)
        return self._setup(tm, geo)

    def crease_setup(self, g: GeometryInput, comm, tip_size: float, tip_radius: float,
                     tip_depth: float = 0.0) -> GeometrySetup:
        """The bilayer meshed for a trial crease at its left edge (a symmetry line: u_x = 0), graded from
        ``tip_size`` within ``tip_radius`` of the top left corner, or of the left edge down to ``tip_depth``
        (a growing crease; :mod:`meshes.crease`)."""
        from app.geometry.tagged import mesh_from_builder
        from meshes import crease

        geo, mesh = g.geometry, g.mesh
        tm = mesh_from_builder(comm, "crease", crease.add_model, geo["length"], geo["substrate_thickness"],
                               geo["film_thickness"], mesh["element_size"], tip_size, tip_radius,
                               geo["film_thickness"] / mesh["film_layers"], tip_depth=tip_depth)
        return self._setup(tm, geo)

    def crease_line(self, g: GeometryInput) -> float:
        """x of the symmetry line a trial crease sits on (the left edge)."""
        return 0.0

    @staticmethod
    def _setup(tm, geo: dict) -> GeometrySetup:
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"},
                             {"left": "roller_x", "right": "roller_x", "bottom": base_role(geo), "top": "permeable"},
                             wrinkles="along", plot_band=6 * geo["film_thickness"],
                             drive=Drive("right", 0, geo["length"]))


def tagged_mesh(comm, length: float, substrate_thickness: float, film_thickness: float, element_size: float,
                film_layers: int, grading: float, rank: int = 0, msh_path: str | None = None,
                film_grading: float = 1.0) -> TaggedMesh:
    """The bilayer mesh of :func:`meshes.bilayer.add_model`, built on ``rank`` and distributed."""
    from app.geometry.tagged import mesh_from_builder
    from meshes import bilayer

    return mesh_from_builder(comm, "bilayer", bilayer.add_model, length, substrate_thickness, film_thickness,
                             element_size, film_layers, grading, film_grading=film_grading, msh_path=msh_path,
                             rank=rank)
