"""Reader of user-supplied 2D gmsh ``.msh`` files: quadrilateral cells with named physical groups.

:func:`merge` loads a file into the current gmsh model (pure gmsh; see :mod:`meshes`) and returns
its (cell groups, facet groups) as name -> tag, or a sentence saying what is wrong with the file.
Cell groups name the layers and facet groups the boundaries; the config maps them to materials and
boundary roles (``geometry.layers``, ``geometry.boundaries``).
"""

from __future__ import annotations

from pathlib import Path

import gmsh

QUAD = 3  # gmsh element type of 4-node quadrilaterals


def merge(path: str | Path) -> tuple[dict[str, int], dict[str, int]] | str:
    """Merge the file into the current gmsh model: its (cell groups, facet groups), or a sentence
    saying what is wrong (missing, unreadable, no 2D physical groups, cells other than quadrilaterals)."""
    path = Path(path)
    if not path.is_file():
        return "does not exist"
    try:
        gmsh.merge(str(path))
    except Exception as err:  # gmsh reports every parse error as a bare Exception
        return "is not a readable gmsh mesh (" + " ".join(str(err).split()) + ")"
    names = physical_names()
    types = set(gmsh.model.mesh.getElementTypes(2))
    if not names[0]:
        return "has no 2D physical groups (cell groups name the layers)"
    if types - {QUAD}:
        return (f"contains non-quadrilateral cells (gmsh element types {sorted(types)}); "
                "hydrobuckle's RTCF flux needs quadrilaterals (recombine the mesh)")
    return names


def physical_names() -> tuple[dict[str, int], dict[str, int]]:
    """(cell groups, facet groups) of the current gmsh model as name -> tag."""
    cells, facets = {}, {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, tag) or f"group{tag}"
        if dim == 2:
            cells[name] = tag
        elif dim == 1:
            facets[name] = tag
    return cells, facets
