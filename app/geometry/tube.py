"""Geometry kinds ``tube`` and ``elliptic-tube``: a film lining the passage of a tube held by a rigid,
impermeable outer wall (paper Figs. "tu_geo" and "tu_pbgeo"); fluid enters through the passage."""

from __future__ import annotations

from typing import TYPE_CHECKING

from app.geometry.base import CrossSection, GeometryInput, GeometryKind, GeometrySetup, layer_keys, structured_size
from app.schema import ConfigError, gt, in_closed, key

if TYPE_CHECKING:
    from app.geometry.tagged import TaggedMesh


class Tube(GeometryKind):
    """Circular passage of radius r = R - H - w."""

    name = "tube"
    keys = {
        "outer_radius": key(float, 1.0, gt(0), "R [mm] (tubes)", unit="mm"),
        **layer_keys(substrate=0.2, film=0.02),
    }
    mesh_defaults = {"element_size": 0.01, "film_layers": 4}
    film_element_fraction = 0.5
    reduced_loadings = ("swelling",)  # axisymmetric: the polar 1D section

    def cross_section(self, geo: dict) -> CrossSection:
        """r from the passage (r = R - H - w, the film's permeable surface) to the rigid wall at R; a 3D tube's
        modes with this section are its axially uniform ones."""
        R, w = geo["outer_radius"], geo["film_thickness"]
        a = R - geo["substrate_thickness"] - w
        return CrossSection("axisymmetric", (("film", a, a + w), ("substrate", a + w, R)), a, R, axial=self.three_d)

    def aspect_ratio(self, geo: dict) -> float:
        return 1.0

    def validate(self, g: GeometryInput) -> None:
        geo, mesh = g.geometry, g.mesh
        R, H, w = geo["outer_radius"], geo["substrate_thickness"], geo["film_thickness"]
        if H + w >= R:
            raise ConfigError("geometry.substrate_thickness",
                              f"= {H:g}: substrate + film ({H + w:g} mm) must be thinner than "
                              f"geometry.outer_radius = {R:g} mm; allowed: < {R - w:g}")
        if mesh["element_size"] > (R - H - w) / 2:
            raise ConfigError("mesh.element_size", f"= {mesh['element_size']:g} is too coarse; allowed: "
                              f"<= passage radius/2 = {(R - H - w) / 2:g}")
        from meshes.tube import GeometryError, check_geometry

        try:
            check_geometry(R, H, w, self.aspect_ratio(geo))
        except GeometryError as err:
            raise ConfigError(err.key, str(err)) from None

    def section_size(self, g: GeometryInput) -> tuple[int, int]:
        """(elements around the passage, element layers through film and substrate), as meshes.tube meshes."""
        from meshes.bilayer import film_interface_height, substrate_layer_count
        from meshes.tube import ellipse_perimeter, semi_axes

        geo, mesh = g.geometry, g.mesh
        R, H, w = geo["outer_radius"], geo["substrate_thickness"], geo["film_thickness"]
        a, b = semi_axes(R - H - w, self.aspect_ratio(geo))
        m = max(2, round(ellipse_perimeter(a, b) / mesh["element_size"] / 4))  # as meshes.tube.add_section
        first = film_interface_height(w, mesh["film_layers"], mesh["film_grading"])
        grading = mesh["substrate_grading"]
        ny = mesh["film_layers"] + substrate_layer_count(H, first * grading, grading)
        return 4 * m, ny

    def estimate(self, g: GeometryInput) -> dict:
        return structured_size(*self.section_size(g), closed=True, what="around the passage")

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        from meshes.tube import GeometryError

        geo, mesh = g.geometry, g.mesh
        try:
            tm = tagged_mesh(comm, geo["outer_radius"], geo["substrate_thickness"], geo["film_thickness"],
                             mesh["element_size"], mesh["film_layers"], mesh["substrate_grading"],
                             aspect_ratio=self.aspect_ratio(geo), film_grading=mesh["film_grading"],
                             msh_path=msh_path)
        except GeometryError as err:
            raise ConfigError(err.key, str(err)) from None
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"}, {"inner": "permeable", "outer": "fixed"},
                             growth="mean_radial", wrinkles="around")


class EllipticTube(Tube):
    """Elliptic passage, a/b = aspect_ratio with a b = r^2 (same area), semi-minor axis b along x; growth is
    the inward displacement of the minor-axis vertex (b, 0), the paper's g_c,x."""

    name = "elliptic-tube"
    keys = {**Tube.keys, "aspect_ratio": key(float, 1.0, in_closed(1.0, 10.0), "a/b of the elliptic passage")}
    reduced_loadings = ()  # the passage is not axisymmetric

    def aspect_ratio(self, geo: dict) -> float:
        return geo["aspect_ratio"]

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        return grown_at_minor_vertex(super().build(g, comm, msh_path))


def grown_at_minor_vertex(setup: GeometrySetup) -> GeometrySetup:
    """An elliptic passage's growth: the inward displacement of its minor-axis vertex (b, 0) (in 3D the vertex
    line along the axis), the paper's g_c,x."""
    setup.growth = "vertex"
    setup.growth_point = (setup.tm.info["semi_minor"], 0.0)
    setup.growth_direction = (-1.0, 0.0)
    return setup


def tagged_mesh(comm, outer_radius: float, substrate_thickness: float, film_thickness: float, element_size: float,
                film_layers: int, grading: float, aspect_ratio: float = 1.0, rank: int = 0,
                msh_path: str | None = None, film_grading: float = 1.0) -> TaggedMesh:
    """The tube mesh of :func:`meshes.tube.add_model`, built on ``rank`` and distributed; GeometryError on
    every rank for an impossible tube."""
    from app.geometry.tagged import mesh_from_builder
    from meshes import tube

    tube.check_geometry(outer_radius, substrate_thickness, film_thickness, aspect_ratio)  # on every rank
    return mesh_from_builder(comm, "tube", tube.add_model, outer_radius, substrate_thickness, film_thickness,
                             element_size, film_layers, grading, aspect_ratio=aspect_ratio,
                             film_grading=film_grading, msh_path=msh_path, rank=rank)
