"""gmsh geometry builders for hydrobuckle: tagged all-quadrilateral meshes, built on rank 0.

Each builder returns a :class:`app.geometry.tagged.TaggedMesh` holding the distributed dolfinx mesh,
its cell and facet tags, and the name -> tag maps of the physical groups.
"""

from app.geometry.tagged import TaggedMesh  # noqa: F401
