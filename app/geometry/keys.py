"""The [mesh] keys of the meshing: what the geometry kinds and app.geometry.msh's refinement read (a kind's own
defaults: GeometryKind.mesh_defaults). The table ends with the quadrature keys of app.model.keys."""

from __future__ import annotations

from app.schema import Key, gt, in_closed, key

MESH: dict[str, Key] = {
    "element_size": key(float, None, gt(0), "element length along the film surface [mm]", optional=True),
    "film_layers": key(int, None, in_closed(1, 200), "element layers through the film", optional=True),
    "substrate_grading": key(float, 1.15, in_closed(1.0, 3.0),
                             "element-height ratio away from the film; 1 = uniform"),
    "film_grading": key(float, 1.0, in_closed(1.0, 4.0),
                        "film element-height ratio towards the permeable surface; 1 = uniform"),
    "refinements": key(int, 0, in_closed(0, 4),
                       "geometry.kind = 'msh' and 'msh-3d' only: split every cell of the file into 4 "
                       "(quadrilaterals) or 8 (hexahedra) this many times (gmsh's uniform refinement; physical "
                       "groups kept, new nodes on the file's straight edges)"),
}
