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
from app.geometry.tagged import TaggedMesh, gmsh_session, to_dolfinx

QUAD = 3  # gmsh element type of 4-node quadrilaterals


class MshError(ValueError):
    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(message)


def read(comm, path: str | Path, rank: int = 0) -> TaggedMesh:
    """The mesh of a .msh file, distributed; MshError (key ``geometry.file``) on every rank if the
    file is missing, unreadable, has no 2D physical groups or cells other than quadrilaterals."""
    path = Path(path)
    with gmsh_session(comm, "user-msh", rank) as active:
        cells, facets = _open(comm, path, rank, active)
        tm = to_dolfinx(comm, rank, cells, facets, {"file": str(path)})
    return tm


def physical_groups(comm, path: str | Path, rank: int = 0) -> tuple[dict[str, int], dict[str, int]]:
    """(cell groups, facet groups) of a .msh file as name -> tag on every rank, with the same checks
    as :func:`read` but without building the mesh (for input checks before anything runs)."""
    with gmsh_session(comm, "user-msh-groups", rank) as active:
        return _open(comm, Path(path), rank, active)


def _open(comm, path: Path, rank: int, active: bool):
    """Merge the file into the gmsh session on ``rank``; its groups, or MshError on every rank."""
    result = _merge(path) if active else None
    result = comm.bcast(result, root=rank)
    if isinstance(result, str):
        raise MshError("geometry.file", f"= '{path}' {result}")
    return result


def _merge(path: Path):
    """On the gmsh rank: the file's (cell groups, facet groups), or a sentence saying what is wrong."""
    if not path.is_file():
        return "does not exist"
    try:
        gmsh.merge(str(path))
    except Exception as err:  # gmsh reports every parse error as a bare Exception
        return "is not a readable gmsh mesh (" + " ".join(str(err).split()) + ")"
    names = _physical_names()
    types = set(gmsh.model.mesh.getElementTypes(2))
    if not names[0]:
        return "has no 2D physical groups (cell groups name the layers)"
    if types - {QUAD}:
        return (f"contains non-quadrilateral cells (gmsh element types {sorted(types)}); "
                "hydrobuckle's RTCF flux needs quadrilaterals (recombine the mesh)")
    return names


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
