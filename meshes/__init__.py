"""Pure gmsh model builders for hydrobuckle's built-in geometries and the reader of user .msh files.

Nothing here knows about MPI, dolfinx or the rest of the app: a builder adds entities and named
physical groups to the *current* gmsh model, meshes it, and returns the name -> tag maps of its cell
and facet groups with a dict of facts about the mesh; the reader merges a file into the current
model and returns its groups, or a sentence saying what is wrong with it. Where gmsh runs (rank 0)
and how the model becomes a distributed mesh is :mod:`app.geometry`'s business.
"""

from __future__ import annotations

import gmsh


def add_physical(dim: int, tags: list[int], tag: int, name: str) -> None:
    """A named physical group of the current gmsh model."""
    gmsh.model.addPhysicalGroup(dim, list(tags), tag)
    gmsh.model.setPhysicalName(dim, tag, name)
