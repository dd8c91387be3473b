"""Geometry kinds ``msh`` and ``msh-3d``: the user's own gmsh ``.msh`` file, 2D (quadrilaterals) or 3D
(hexahedra), whose physical groups the config maps to materials (``geometry.layers``) and boundary roles
(``geometry.boundaries``).

The file is read on rank 0 (:func:`meshes.msh.merge`) and distributed; a file that is missing, unreadable
or lacks a named group is a ConfigError on every rank, found before anything runs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from app.geometry.base import BOUNDARY_ROLES, GeometryInput, GeometryKind, GeometrySetup
from app.schema import ConfigError, key, one_of

WRINKLE_MEASURES = ("auto", "along", "around")
SHAPES_3D = ("auto", "plane", "cylinder")

if TYPE_CHECKING:
    from app.geometry.tagged import TaggedMesh


class UserMsh(GeometryKind):
    name = "msh"
    keys = {
        "file": key(str, None, None, "msh: path of a 2D gmsh .msh file (quadrilaterals)", optional=True),
        "layers": key(dict, None, None, "msh: cell physical group -> material name", optional=True),
        "boundaries": key(dict, None, None, "msh: facet physical group -> boundary role", optional=True),
        "wrinkles": key(str, "auto", one_of(*WRINKLE_MEASURES), "msh: how wrinkles are counted"),
    }
    exportable = False
    not_exportable_because = "already is a .msh file"
    named_materials = True
    uniform_refinement = True
    dim = 2  # the file's cells: quadrilaterals (2) or hexahedra (3)

    def validate(self, g: GeometryInput) -> None:
        geo = g.geometry
        if not geo.get("file"):
            raise ConfigError("geometry.file", f"must name a .msh file for geometry.kind = '{self.name}'")
        layers, boundaries = geo.get("layers"), geo.get("boundaries")
        if not layers:
            raise ConfigError("geometry.layers", "must map cell physical groups to materials, e.g. "
                              "{ film = \"film\", substrate = \"substrate\" }")
        known = {"film", "substrate"} | set(g.layers)
        for group, mat in layers.items():
            if mat not in known:
                raise ConfigError(f"geometry.layers.{group}", f"= {mat!r} is not a material; allowed: "
                                  + ", ".join(sorted(known)) + " (define more under [material.layers.NAME])")
        if not boundaries:
            raise ConfigError("geometry.boundaries", "must map facet physical groups to roles: "
                              + ", ".join(BOUNDARY_ROLES))
        for group, role in boundaries.items():
            if role not in BOUNDARY_ROLES:
                raise ConfigError(f"geometry.boundaries.{group}", f"= {role!r}; allowed: " + ", ".join(BOUNDARY_ROLES))
        if "permeable" not in boundaries.values():
            raise ConfigError("geometry.boundaries", "needs at least one 'permeable' boundary (where fluid enters)")

    def check_input(self, g: GeometryInput, comm) -> None:
        """The file must exist and be a readable quadrilateral gmsh mesh with every cell group given a
        material and every named group present."""
        geo = g.geometry
        cells, facets = physical_groups(comm, geo["file"], dim=self.dim)
        _check_groups(geo, cells, facets)

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        geo = g.geometry
        from app.geometry.tagged import is_closed

        tm = read(comm, geo["file"], refinements=g.mesh["refinements"])
        _check_groups(geo, tm.cell_names, tm.facet_names)
        wrinkles = geo.get("wrinkles") or "auto"
        if wrinkles == "auto":
            wrinkles = "around" if is_closed(tm, [g for g, r in geo["boundaries"].items()
                                                  if r == "permeable"]) else "along"
        return GeometrySetup(tm, dict(geo["layers"]), dict(geo["boundaries"]), wrinkles=wrinkles)

    def refined(self, g: GeometryInput, exponent: int, factor: float) -> tuple[float, dict]:
        """A file has no element size to scale: level ``exponent`` splits every cell of the file
        ``mesh.refinements + exponent`` times (a negative exponent undoes refinements the config asked
        for). The parameter is the element size relative to the file's."""
        if factor != 2:
            raise ConfigError("mesh.refinements", f"a .msh mesh is refined by uniform splitting (factor 2); "
                              f"a refinement factor of {factor:g} is not possible")
        level = g.mesh["refinements"] + exponent
        if level < 0:
            raise ConfigError("mesh.refinements", f"= {g.mesh['refinements']} cannot be coarsened "
                              f"{-exponent} time(s): a .msh mesh is only refined (every cell split into "
                              f"{2 ** self.dim}); "
                              f"allowed: mesh.refinements >= {-exponent}, or refine instead of coarsening")
        return 2.0 ** -level, {"mesh.refinements": level}  # the schema checks the upper bound (variant)


class UserMsh3D(UserMsh):
    """``msh-3d``: a hexahedral 3D mesh. Its modes are described on the permeable surface, which must be flat
    (a film's top: ``plane``, the half-waves along its two in-plane axes) or a cylinder about the z axis (a
    tube's passage: ``cylinder``, waves around and half-waves along the axis), with its nodes on a tensor grid
    of those two coordinates (a transfinite or extruded mesh); ``auto`` tells the two apart."""

    name = "msh-3d"
    dim = 3
    three_d = True
    keys = {
        "file": key(str, None, None, "msh-3d: path of a 3D gmsh .msh file (hexahedra)", optional=True),
        "layers": UserMsh.keys["layers"],
        "boundaries": UserMsh.keys["boundaries"],
        "surface": key(str, "auto", one_of(*SHAPES_3D), "msh-3d: the permeable surface on which modes are "
                       "described: plane (flat, across a coordinate axis), cylinder (about the z axis) or auto"),
    }

    def check_input(self, g: GeometryInput, comm) -> None:
        """As the 2D kind's, and the permeable surface must be one on which 3D modes are described
        (:func:`surface_shape_of`), read from the file before anything runs."""
        from app.geometry.tagged import gmsh_session, on_gmsh_rank
        from meshes import msh

        geo = g.geometry
        with gmsh_session(comm, "user-msh-groups", 0) as active:
            cells, facets = _merge(comm, Path(geo["file"]), 0, active, self.dim)
            _check_groups(geo, cells, facets)
            permeable = [g for g, r in geo["boundaries"].items() if r == "permeable"]
            xyz = on_gmsh_rank(comm, 0, active, msh.facet_group_coordinates, facets, permeable)
        surface_shape_of(xyz, geo.get("surface") or "auto", geo["file"])

    def build(self, g: GeometryInput, comm, msh_path: str | None = None) -> GeometrySetup:
        from app.geometry.tagged import facet_nodes

        geo = g.geometry
        tm = read(comm, geo["file"], refinements=g.mesh["refinements"], dim=3)
        _check_groups(geo, tm.cell_names, tm.facet_names)
        permeable = [g for g, r in geo["boundaries"].items() if r == "permeable"]
        shape = surface_shape_of(facet_nodes(tm, permeable), geo.get("surface") or "auto", geo["file"])
        return GeometrySetup(tm, dict(geo["layers"]), dict(geo["boundaries"]), wrinkles=shape,
                             growth="mean_radial" if shape == "cylinder" else "mean_normal")


def surface_shape_of(xyz, asked: str, path) -> str:
    """The 3D surface shape (``plane`` or ``cylinder``) on which a user mesh's modes are described, checked on
    the permeable surface's node coordinates ``xyz`` (all ranks'): flat across a coordinate axis, or at one
    radius about the z axis, with the nodes on a tensor grid of the two surface coordinates (as
    :class:`app.model.shapes3d.PlaneSurface` and ``CylinderSurface`` read them: in-plane coordinates, or the angle
    around and z). ConfigError naming
    geometry.surface (or geometry.file) otherwise."""
    import numpy as np

    if len(xyz) == 0:
        raise ConfigError("geometry.boundaries", f"the 'permeable' group(s) of '{path}' have no surface elements: "
                          "fluid enters nowhere; name a facet group with elements")
    size = float(np.ptp(xyz, axis=0).max()) or 1.0
    flat = float(np.ptp(xyz, axis=0).min()) <= 1e-9 * size
    radius = np.linalg.norm(xyz[:, :2], axis=1)
    round_ = radius.min() > 0 and float(np.ptp(radius)) <= 0.05 * float(radius.mean())  # chords of a refined file
    shape = asked if asked != "auto" else "plane" if flat else "cylinder" if round_ else None
    if shape is None or (shape == "plane" and not flat) or (shape == "cylinder" and not round_):
        found = "flat" if flat else "a cylinder about the z axis" if round_ else "neither flat nor a cylinder about z"
        raise ConfigError("geometry.surface", f"= {asked!r}, but the permeable surface of '{path}' is {found}; "
                          "allowed: plane (a flat surface across a coordinate axis) or cylinder (at one radius "
                          "about the z axis, x = y = 0), the surfaces on which 3D modes are described")
    if shape == "plane":
        a, b = (xyz[:, k] for k in range(3) if k != int(np.argmin(np.ptp(xyz, axis=0))))
        digits = (12, 12)
    else:
        a, b = np.mod(np.arctan2(xyz[:, 1], xyz[:, 0]), 2 * np.pi), xyz[:, 2]
        a[a > 2 * np.pi - 1e-9] = 0.0
        digits = (9, 12)
        angles = np.unique(np.round(a, 9))
        gaps = np.diff(np.concatenate([angles, [angles[0] + 2 * np.pi]]))
        if len(angles) < 3 or gaps.max() > 1.5 * np.median(gaps):  # the passage's modes wrap around 2 pi
            raise ConfigError("geometry.surface", f"= {asked!r}: the permeable surface of '{path}' does not go all "
                              f"the way around the z axis (a gap of {np.degrees(gaps.max()):.3g} degrees); a "
                              "cylinder's modes are waves around the whole passage: mesh the whole tube")
    if len(np.unique(np.round(a, digits[0]))) * len(np.unique(np.round(b, digits[1]))) != len(xyz):
        raise ConfigError("geometry.file", f"= '{path}': the nodes of its permeable surface are not a tensor grid "
                          f"of the surface's two coordinates ({shape}); 3D modes are described on such a grid: mesh "
                          "the body transfinite or by extrusion")
    return shape


def read(comm, path: str | Path, rank: int = 0, refinements: int = 0, dim: int = 2) -> TaggedMesh:
    """The mesh of a .msh file, split uniformly ``refinements`` times, distributed; ConfigError (key
    ``geometry.file``) on every rank if the file is missing, unreadable, not of dimension ``dim``, has no
    physical groups of cells or cells other than quadrilaterals (2D) or hexahedra (3D)."""
    from app.geometry.tagged import gmsh_session, on_gmsh_rank, to_dolfinx
    from meshes import msh

    path = Path(path)
    with gmsh_session(comm, "user-msh", rank) as active:
        cells, facets = _merge(comm, path, rank, active, dim)
        if refinements:
            on_gmsh_rank(comm, rank, active, msh.refine, refinements)
        return to_dolfinx(comm, rank, cells, facets, {"file": str(path), "refinements": int(refinements)})


def physical_groups(comm, path: str | Path, rank: int = 0, dim: int = 2) -> tuple[dict[str, int], dict[str, int]]:
    """(cell groups, facet groups) of a .msh file as name -> tag on every rank, with the same checks as
    :func:`read` but without building the mesh (for input checks before anything runs)."""
    from app.geometry.tagged import gmsh_session

    with gmsh_session(comm, "user-msh-groups", rank) as active:
        return _merge(comm, Path(path), rank, active, dim)


def _merge(comm, path: Path, rank: int, active: bool, dim: int = 2):
    from app.geometry.tagged import on_gmsh_rank
    from meshes import msh

    result = on_gmsh_rank(comm, rank, active, msh.merge, path, dim)
    if isinstance(result, str):
        raise ConfigError("geometry.file", f"= '{path}' {result}")
    return result


def _check_groups(geo: dict, cells, facets) -> None:
    for group in geo["layers"]:
        if group not in cells:
            raise ConfigError(f"geometry.layers.{group}", "is not a cell physical group of "
                              f"{geo['file']}; its groups: " + ", ".join(sorted(cells)))
    for group in geo["boundaries"]:
        if group not in facets:
            raise ConfigError(f"geometry.boundaries.{group}", "is not a facet physical group of "
                              f"{geo['file']}; its groups: " + (", ".join(sorted(facets)) or "none"))
    missing = sorted(set(cells) - set(geo["layers"]))
    if missing:
        raise ConfigError("geometry.layers", "gives no material to the cell group(s) " + ", ".join(missing))
