"""A film on a substrate over a rectangle, in 3D: the bilayer's section (:mod:`meshes.bilayer`, x along the
film, y up through substrate and film) extruded along z by the plate's width, into a structured hexahedral
mesh. Every x-y section of the plate is the 2D bilayer's mesh, node for node, so the plate one element wide
is the plane-strain bilayer extruded.

Physical groups: cells film, substrate; facets top (y = H + w, the permeable surface), bottom (y = 0),
left / right (x = 0 / L), front / back (z = 0 / width).

:func:`add_model` builds the mesh in the current gmsh model (pure gmsh; see :mod:`meshes`).
"""

from __future__ import annotations

import gmsh

from meshes import add_physical
from meshes.bilayer import add_section

CELLS = {"film": 1, "substrate": 2}
FACETS = {"bottom": 1, "top": 2, "left": 3, "right": 4, "front": 5, "back": 6}


def add_model(length: float, width: float, substrate_thickness: float, film_thickness: float,
              element_size: float, film_layers: int, grading: float, film_grading: float = 1.0,
              width_elements: int | None = None) -> tuple[dict, dict, dict]:
    """Mesh the plate in the current gmsh model: (cell groups, facet groups, info). Elements across the width
    have the size along the length unless ``width_elements`` says how many."""
    _, sub, film, info = add_section(length, substrate_thickness, film_thickness, element_size, film_layers,
                                     grading, film_grading)
    nz = width_elements if width_elements is not None else max(1, round(width / element_size))
    geo = gmsh.model.geo
    volumes = {}
    for name, surface in (("substrate", sub[1]), ("film", film[1])):
        out = geo.extrude([surface], 0, 0, width, numElements=[nz], recombine=True)
        volumes[name] = out[1][1]
    geo.synchronize()
    L, H, w = length, substrate_thickness, film_thickness
    tol = 1e-9 * max(L, width, H + w)
    where = {"bottom": lambda b: b[4] < tol, "top": lambda b: b[1] > H + w - tol,
             "left": lambda b: b[3] < tol, "right": lambda b: b[0] > L - tol,
             "front": lambda b: b[5] < tol, "back": lambda b: b[2] > width - tol}
    groups: dict[str, list[int]] = {name: [] for name in FACETS}
    for _, tag in gmsh.model.getBoundary([(3, v) for v in volumes.values()], combined=True, oriented=False):
        box = gmsh.model.getBoundingBox(2, abs(tag))
        for name, test in where.items():
            if test(box):
                groups[name].append(abs(tag))
    for name, tag in CELLS.items():
        add_physical(3, [volumes[name]], tag, name)
    for name, tag in FACETS.items():
        add_physical(2, groups[name], tag, name)
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(3)
    info = {**info, "elements_across_width": nz}
    return dict(CELLS), dict(FACETS), info
