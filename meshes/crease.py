"""The bilayer of :mod:`meshes.bilayer` meshed for a trial crease at its left edge: unstructured
quadrilaterals, graded by a gmsh size field from ``tip_size`` around the top left corner (the crease's tip
and walls, within ``tip_radius``) to ``element_size``, the element size growing by ``grading`` times the
distance beyond that radius (a crease's strain field decays over a few crease lengths: the grading, not the
far field's element size, decides how well it is resolved), and no coarser than ``film_size`` in the film.
With ``tip_depth`` > 0 the fine zone is the band within ``tip_radius`` of the left edge from the top down to
``tip_depth`` + ``tip_radius`` (a crease that grows along its symmetry line: its walls and its tip wherever
it ends). The same physical groups as the structured bilayer: cells film, substrate; facets top, bottom,
left, right.

:func:`add_model` builds the mesh in the current gmsh model (pure gmsh; see :mod:`meshes`).
"""

from __future__ import annotations

import gmsh

from meshes import add_physical
from meshes.bilayer import CELLS, FACETS

# gmsh 4.10 renamed the size fields' options (gmsh 4.8 on Debian 12 knows the old names only)
_NEW_NAMES = tuple(int(v) for v in gmsh.__version__.split(".")[:2]) >= (4, 10)
GRADING = 0.25  # the element size's growth per unit distance from the fine zone

_OPTION = {"points": "PointsList" if _NEW_NAMES else "NodesList", "in": "InField" if _NEW_NAMES else "IField",
           "min": "SizeMin" if _NEW_NAMES else "LcMin", "max": "SizeMax" if _NEW_NAMES else "LcMax",
           "curves": "CurvesList" if _NEW_NAMES else "EdgesList",
           "sampling": "Sampling" if _NEW_NAMES else "NumPointsPerCurve"}


def add_model(length: float, substrate_thickness: float, film_thickness: float, element_size: float,
              tip_size: float, tip_radius: float, film_size: float | None = None,
              grading: float = GRADING, tip_depth: float = 0.0) -> tuple[dict, dict, dict]:
    """Mesh the bilayer [0, L] x [0, H + w] in the current gmsh model: (cell groups, facet groups, info)."""
    L, H, w = length, substrate_thickness, film_thickness
    geo = gmsh.model.geo
    p = [geo.addPoint(0, 0, 0), geo.addPoint(L, 0, 0), geo.addPoint(L, H, 0), geo.addPoint(0, H, 0),
         geo.addPoint(L, H + w, 0), geo.addPoint(0, H + w, 0)]
    bottom, right_s, interface, left_s = (geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2]),
                                          geo.addLine(p[2], p[3]), geo.addLine(p[3], p[0]))
    right_f, top, left_f = geo.addLine(p[2], p[4]), geo.addLine(p[4], p[5]), geo.addLine(p[5], p[3])
    substrate = geo.addPlaneSurface([geo.addCurveLoop([bottom, right_s, interface, left_s])])
    film = geo.addPlaneSurface([geo.addCurveLoop([-interface, right_f, top, left_f])])
    geo.synchronize()

    field = gmsh.model.mesh.field

    def graded(distance: int, radius: float) -> int:
        """tip_size within ``radius`` of the distance field's entities, growing by ``grading`` beyond it."""
        size = field.add("Threshold")
        field.setNumber(size, _OPTION["in"], distance)
        field.setNumber(size, _OPTION["min"], tip_size)
        field.setNumber(size, _OPTION["max"], element_size)
        field.setNumber(size, "DistMin", radius)
        field.setNumber(size, "DistMax", radius + max(element_size - tip_size, 0.0) / grading)
        return size

    corner = field.add("Distance")
    field.setNumbers(corner, _OPTION["points"], [p[5]])
    tip = graded(corner, tip_radius + tip_depth)
    if tip_depth > 0:  # fine where near the left edge and within tip_depth (+ radius) of the top
        edge = field.add("Distance")
        field.setNumbers(edge, _OPTION["curves"], [left_f, left_s])
        field.setNumber(edge, _OPTION["sampling"], int((H + w) / tip_size) + 2)
        band = field.add("Max")
        field.setNumbers(band, "FieldsList", [tip, graded(edge, tip_radius)])
        tip = band
    sizes = [tip]
    if film_size is not None and film_size < element_size:
        box = field.add("Box")
        for name, value in (("VIn", film_size), ("VOut", element_size), ("XMin", 0.0), ("XMax", L),
                            ("YMin", H), ("YMax", H + w)):
            field.setNumber(box, name, value)
        sizes.append(box)
    smallest = field.add("Min")
    field.setNumbers(smallest, "FieldsList", sizes)
    field.setAsBackgroundMesh(smallest)
    for name, value in (("Mesh.MeshSizeExtendFromBoundary", 0), ("Mesh.MeshSizeFromPoints", 0),
                        ("Mesh.MeshSizeFromCurvature", 0),
                        ("Mesh.Algorithm", 6),  # Frontal-Delaunay
                        ("Mesh.RecombineAll", 1), ("Mesh.RecombinationAlgorithm", 2)):  # all quadrilaterals
        gmsh.option.setNumber(name, value)
    add_physical(2, [film], CELLS["film"], "film")
    add_physical(2, [substrate], CELLS["substrate"], "substrate")
    add_physical(1, [bottom], FACETS["bottom"], "bottom")
    add_physical(1, [top], FACETS["top"], "top")
    add_physical(1, [left_s, left_f], FACETS["left"], "left")
    add_physical(1, [right_s, right_f], FACETS["right"], "right")
    gmsh.model.mesh.generate(2)
    types, tags, _ = gmsh.model.mesh.getElements(2)
    cells = {gmsh.model.mesh.getElementProperties(t)[0]: len(e) for t, e in zip(types, tags)}
    return dict(CELLS), dict(FACETS), {"tip_size": tip_size, "tip_radius": tip_radius, "tip_depth": tip_depth,
                                       "cells_by_type": cells}
