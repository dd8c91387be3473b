"""What a geometry kind means for the problem: mesh, layer materials, boundary roles, and how growth
and wrinkles are measured.

Boundary roles (mechanics + chemistry):

- ``permeable``: traction-free; chemical potential prescribed (the ramp), fluid enters here;
- ``impermeable`` / ``free``: traction-free, zero normal flux;
- ``fixed``: u = 0, zero normal flux (a rigid impermeable wall);
- ``roller_x`` / ``roller_y``: u_x = 0 / u_y = 0, zero normal flux (symmetry or sliding support).

Growth: ``mean_normal`` is the mean displacement of the permeable surface along the body's outward
normal there (bilayer: mean u_y of the top; tube: mean inward radial displacement of the passage);
``mean_radial`` (tubes) is the mean inward radial displacement of the passage's nodes;
``vertex`` is the inward displacement of one surface point (the elliptic passage's minor-axis vertex,
the paper's g_c,x). Wrinkles are counted ``along`` an open surface (half-waves) or ``around`` a
closed one (integer wavenumber).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from app import config


@dataclass
class GeometrySetup:
    tm: object  # meshes.TaggedMesh
    layers: dict[str, str]  # cell group -> material name
    boundaries: dict[str, str]  # facet group -> role
    growth: str = "mean_normal"  # or "vertex"
    growth_point: tuple[float, float] | None = None
    growth_direction: tuple[float, float] | None = None  # inward unit vector at growth_point
    wrinkles: str = "along"  # or "around"
    plot_band: float | None = None  # bilayer: plot only this depth under the surface [mm]
    info: dict = field(default_factory=dict)

    def facets_with_role(self, *roles: str) -> list[str]:
        return [name for name, role in self.boundaries.items() if role in roles]


def build(cfg: dict, comm, msh_path: str | None = None) -> GeometrySetup:
    """The geometry of ``cfg``; with ``msh_path`` the built-in builders also write their gmsh mesh."""
    geo, mesh = cfg["geometry"], cfg["mesh"]
    kind = geo["kind"]
    if kind == "bilayer":
        from meshes import bilayer

        tm = bilayer.build(comm, geo["length"], geo["substrate_thickness"], geo["film_thickness"],
                           mesh["element_size"], mesh["film_layers"], mesh["substrate_grading"],
                           film_grading=mesh["film_grading"], msh_path=msh_path)
        return GeometrySetup(tm, {"film": "film", "substrate": "substrate"},
                             {"left": "roller_x", "right": "roller_x", "bottom": "roller_y", "top": "permeable"},
                             wrinkles="along", plot_band=6 * geo["film_thickness"])
    if kind in ("tube", "elliptic-tube"):
        from meshes import tube

        ar = geo.get("aspect_ratio") or 1.0
        try:
            tm = tube.build(comm, geo["outer_radius"], geo["substrate_thickness"], geo["film_thickness"],
                            mesh["element_size"], mesh["film_layers"], mesh["substrate_grading"], aspect_ratio=ar,
                            film_grading=mesh["film_grading"], msh_path=msh_path)
        except tube.GeometryError as err:
            raise config.ConfigError(err.key, str(err)) from None
        setup = GeometrySetup(tm, {"film": "film", "substrate": "substrate"}, {"inner": "permeable", "outer": "fixed"},
                              growth="mean_radial", wrinkles="around")
        if kind == "elliptic-tube":
            setup.growth = "vertex"
            setup.growth_point = (tm.info["semi_minor"], 0.0)
            setup.growth_direction = (-1.0, 0.0)
        return setup
    if kind == "msh":
        from meshes import msh

        try:
            tm = msh.read(comm, geo["file"])
        except msh.MshError as err:
            raise config.ConfigError(err.key, str(err)) from None
        _check_msh_groups(geo, tm.cell_names, tm.facet_names)
        wrinkles = geo.get("wrinkles") or "auto"
        if wrinkles == "auto":
            wrinkles = "around" if msh.is_closed(tm, [g for g, r in geo["boundaries"].items()
                                                      if r == "permeable"]) else "along"
        return GeometrySetup(tm, dict(geo["layers"]), dict(geo["boundaries"]), wrinkles=wrinkles)
    raise config.ConfigError("geometry.kind", f"unsupported kind {kind!r}")


def check(cfg: dict, comm) -> None:
    """Raise ConfigError (on every rank) for input errors only the geometry's file can show, without
    building a mesh: for geometry.kind = 'msh' the file must exist and be a readable quadrilateral
    gmsh mesh with every cell group given a material and every named group present. Built-in kinds
    are fully checked by ``config.validate``. Commands call this before they create any result."""
    geo = cfg["geometry"]
    if geo["kind"] != "msh":
        return
    from meshes import msh

    try:
        cells, facets = msh.physical_groups(comm, geo["file"])
    except msh.MshError as err:
        raise config.ConfigError(err.key, str(err)) from None
    _check_msh_groups(geo, cells, facets)


def _check_msh_groups(geo: dict, cells, facets) -> None:
    for group in geo["layers"]:
        if group not in cells:
            raise config.ConfigError(f"geometry.layers.{group}", "is not a cell physical group of "
                                     f"{geo['file']}; its groups: " + ", ".join(sorted(cells)))
    for group in geo["boundaries"]:
        if group not in facets:
            raise config.ConfigError(f"geometry.boundaries.{group}", "is not a facet physical group of "
                                     f"{geo['file']}; its groups: " + (", ".join(sorted(facets)) or "none"))
    missing = sorted(set(cells) - set(geo["layers"]))
    if missing:
        raise config.ConfigError("geometry.layers", "gives no material to the cell group(s) " + ", ".join(missing))
