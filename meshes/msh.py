"""User-supplied 2D gmsh ``.msh`` files: quadrilateral cells with named physical groups.

The file is read on rank 0 and distributed. Cell groups name the layers and facet groups the
boundaries; the config maps them to materials and boundary roles (``geometry.layers``,
``geometry.boundaries``).
"""

from __future__ import annotations

from pathlib import Path

import gmsh
import numpy as np

from app import compat
from meshes.tagged import TaggedMesh, gmsh_session, to_dolfinx

QUAD = 3  # gmsh element type of 4-node quadrilaterals


class MshError(ValueError):
    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(message)


def read(comm, path: str | Path, rank: int = 0) -> TaggedMesh:
    path = Path(path)
    problem = None
    if comm.rank == rank and not path.is_file():
        problem = f"= '{path}' does not exist"
    problem = comm.bcast(problem, root=rank)
    if problem:
        raise MshError("geometry.file", problem)
    with gmsh_session(comm, "user-msh", rank) as active:
        names = None
        if active:
            gmsh.merge(str(path))
            names = _physical_names()
            types = set(gmsh.model.mesh.getElementTypes(2))
            if not names[0]:
                names = ("no 2D physical groups (cell groups name the layers)",)
            elif types - {QUAD}:
                names = (f"contains non-quadrilateral cells (gmsh element types {sorted(types)}); "
                         "hydrobuckle's RTCF flux needs quadrilaterals (recombine the mesh)",)
        names = comm.bcast(names, root=rank)
        if len(names) == 1:
            raise MshError("geometry.file", f"= '{path}' {names[0]}")
        cells, facets = names
        tm = to_dolfinx(comm, rank, cells, facets, {"file": str(path)})
    return tm


def _physical_names():
    cells, facets = {}, {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, tag) or f"group{tag}"
        if dim == 2:
            cells[name] = tag
        elif dim == 1:
            facets[name] = tag
    return cells, facets


def boundary_points(tm: TaggedMesh, groups: list[str]) -> np.ndarray:
    """Endpoints (2 per facet, gathered on every rank, duplicates from ghosts removed) of the facets in
    ``groups``: shape (n_facets, 2, 2)."""
    domain = tm.mesh
    fdim = domain.topology.dim - 1
    domain.topology.create_connectivity(fdim, 0)
    f2v = domain.topology.connectivity(fdim, 0)
    x = domain.geometry.x[:, :2]
    v_to_geom = compat.vertex_to_geometry(domain)
    segs = []
    for g in groups:
        for f in tm.facets(g):
            v = f2v.links(f)
            segs.append(x[v_to_geom[v]])
    segs = np.array(segs).reshape(-1, 2, 2)
    allsegs = np.concatenate(domain.comm.allgather(segs))
    mid = np.round(allsegs.mean(axis=1), 12)
    _, keep = np.unique(mid, axis=0, return_index=True)
    return allsegs[np.sort(keep)]


def is_closed(tm: TaggedMesh, groups: list[str]) -> bool:
    """True if the facets of ``groups`` form closed curves (every endpoint shared by two facets)."""
    segs = boundary_points(tm, groups)
    if len(segs) == 0:
        return False
    pts = np.round(segs.reshape(-1, 2), 10)
    _, counts = np.unique(pts, axis=0, return_counts=True)
    return bool(np.all(counts == 2))
