"""The bilayered tube in 3D: the tube's cross-section (:mod:`meshes.tube`, a film lining the passage, the
substrate out to the wall) extruded along the axis z by a length, into a structured hexahedral mesh. Every
cross-section z = const is the 2D tube's mesh node for node, so the tube one element long is the plane-strain
tube extruded.

Physical groups: cells film, substrate; facets inner (the passage surface), outer (the wall), front / back
(the ends z = 0 / length).

:func:`add_model` builds the mesh in the current gmsh model (pure gmsh; see :mod:`meshes`).
"""

from __future__ import annotations

import gmsh

from meshes import add_physical
from meshes.tube import CELLS, add_section

FACETS = {"inner": 1, "outer": 2, "front": 3, "back": 4}


def add_model(outer_radius: float, substrate_thickness: float, film_thickness: float, element_size: float,
              film_layers: int, grading: float, length: float, aspect_ratio: float = 1.0, film_grading: float = 1.0,
              axial_elements: int | None = None) -> tuple[dict, dict, dict]:
    """Mesh the 3D tube in the current gmsh model: (cell groups, facet groups, info); GeometryError for an
    impossible tube. Elements along the axis have the size around the passage unless ``axial_elements`` says
    how many."""
    film_s, sub_s, _, _, info = add_section(outer_radius, substrate_thickness, film_thickness, element_size,
                                            film_layers, grading, aspect_ratio, film_grading)
    nz = axial_elements if axial_elements is not None else max(1, round(length / element_size))
    geo = gmsh.model.geo
    volumes: dict[str, list[int]] = {"film": [], "substrate": []}
    for name, surfaces in (("film", film_s), ("substrate", sub_s)):
        for s in surfaces:
            out = geo.extrude([(2, s)], 0, 0, length, numElements=[nz], recombine=True)
            volumes[name].append(out[1][1])
    geo.synchronize()
    R, tol = outer_radius, 1e-9 * max(outer_radius, length)
    passage = info["semi_major"]  # the farthest the passage reaches from the axis; the wall is at R
    groups: dict[str, list[int]] = {name: [] for name in FACETS}
    every = [(3, v) for vs in volumes.values() for v in vs]
    for _, tag in gmsh.model.getBoundary(every, combined=True, oriented=False):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, abs(tag))
        if z1 < tol:
            groups["front"].append(abs(tag))
        elif z0 > length - tol:
            groups["back"].append(abs(tag))
        elif max(abs(x0), abs(x1), abs(y0), abs(y1)) < 0.5 * (passage + R):
            groups["inner"].append(abs(tag))
        else:
            groups["outer"].append(abs(tag))
    for name, tag in CELLS.items():
        add_physical(3, volumes[name], tag, name)
    for name, tag in FACETS.items():
        add_physical(2, groups[name], tag, name)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(3)
    info = {**info, "length": length, "elements_along_axis": nz}
    return dict(CELLS), dict(FACETS), info
