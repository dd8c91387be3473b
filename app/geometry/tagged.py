"""The MPI/dolfinx side of a geometry: gmsh runs on one rank, its model becomes a distributed
:class:`TaggedMesh` (through :mod:`app.compat`), and facts about tagged boundaries.

The builders themselves (:mod:`meshes`) are plain gmsh; :func:`mesh_from_builder` runs one on the gmsh
rank, sends its groups and info (or its error) to every rank and distributes the mesh.
"""

from __future__ import annotations

import contextlib
import pickle
from dataclasses import dataclass, field

import gmsh
import numpy as np

from app import compat, fem_utils


@dataclass
class TaggedMesh:
    """A distributed mesh with named cell regions (layers) and named boundary facets."""

    mesh: object
    cell_tags: object
    facet_tags: object
    cell_names: dict[str, int] = field(default_factory=dict)
    facet_names: dict[str, int] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def cells(self, name: str) -> np.ndarray:
        return self.cell_tags.indices[self.cell_tags.values == self.cell_names[name]]

    def facets(self, name: str) -> np.ndarray:
        return self.facet_tags.indices[self.facet_tags.values == self.facet_names[name]]


@contextlib.contextmanager
def gmsh_session(comm, name: str, rank: int = 0):
    """Initialize gmsh on ``rank`` only (quiet, all-quad settings); finalize afterwards."""
    active = comm.rank == rank
    if active:
        gmsh.initialize()
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(name)
    try:
        yield active
    finally:
        if active:
            gmsh.finalize()


def on_gmsh_rank(comm, rank: int, active: bool, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` on the gmsh rank; its result on every rank, or its exception raised on
    every rank (so an error there never leaves the other ranks waiting)."""
    if active:
        try:
            outcome = (True, fn(*args, **kwargs))
        except Exception as err:  # noqa: BLE001 - handed to every rank, then re-raised
            outcome = (False, _portable(err))
    else:
        outcome = None
    ok, value = comm.bcast(outcome, root=rank)
    if not ok:
        raise value
    return value


def _portable(err: Exception) -> Exception:
    try:
        return pickle.loads(pickle.dumps(err))
    except Exception:  # noqa: BLE001 - an exception that cannot travel is sent as its text
        return RuntimeError(f"{type(err).__name__}: {err}")


def mesh_from_builder(comm, name: str, builder, *args, msh_path: str | None = None, rank: int = 0,
                      **kwargs) -> TaggedMesh:
    """Run a :mod:`meshes` builder (``builder(*args, **kwargs) -> (cell groups, facet groups, info)``)
    in a gmsh session on ``rank`` and distribute its mesh; with ``msh_path`` also write the .msh."""
    with gmsh_session(comm, name, rank) as active:
        cells, facets, info = on_gmsh_rank(comm, rank, active, builder, *args, **kwargs)
        return to_dolfinx(comm, rank, cells, facets, info, msh_path)


def to_dolfinx(comm, rank: int, cell_names: dict, facet_names: dict, info: dict,
               msh_path: str | None = None) -> TaggedMesh:
    """Distribute the current gmsh model (on ``rank``) to all ranks as a TaggedMesh."""
    if comm.rank == rank and msh_path:
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(msh_path))
    dim = comm.bcast(gmsh.model.getDimension() if comm.rank == rank else None, root=rank)  # 2 or 3
    mesh, ct, ft = compat.gmsh_model_to_mesh(gmsh.model, comm, rank, gdim=dim)
    from app.geometry.quality import min_scaled_jacobian

    info = {**info, "min_scaled_jacobian": min_scaled_jacobian(mesh)}
    return TaggedMesh(mesh, ct, ft, dict(cell_names), dict(facet_names), info)


def boundary_points(tm: TaggedMesh, groups: list[str]) -> np.ndarray:
    """Endpoints (2 per facet, gathered on every rank, duplicates from ghosts removed) of the facets in
    ``groups``: shape (n_facets, 2, 2)."""
    domain = tm.mesh
    fdim = domain.topology.dim - 1
    domain.topology.create_connectivity(fdim, 0)
    f2v = domain.topology.connectivity(fdim, 0)
    x = domain.geometry.x[:, :2]
    v_to_geom = fem_utils.vertex_to_geometry(domain)
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


def facet_nodes(tm: TaggedMesh, groups: list[str]) -> np.ndarray:
    """Coordinates (N, gdim) of the mesh nodes on the facets of ``groups``, gathered on every rank, each node
    once."""
    domain = tm.mesh
    fdim = domain.topology.dim - 1
    domain.topology.create_connectivity(fdim, 0)
    f2v = domain.topology.connectivity(fdim, 0)
    v_to_geom = fem_utils.vertex_to_geometry(domain)
    gdim = domain.geometry.dim
    nodes = [v_to_geom[f2v.links(f)] for g in groups for f in tm.facets(g)]
    local = domain.geometry.x[np.unique(np.concatenate(nodes)), :gdim] if nodes else np.zeros((0, gdim))
    xyz = np.concatenate(domain.comm.allgather(local))
    _, keep = np.unique(np.round(xyz, 12), axis=0, return_index=True)
    return xyz[np.sort(keep)]


def is_closed(tm: TaggedMesh, groups: list[str]) -> bool:
    """True if the facets of ``groups`` form closed curves (every endpoint shared by two facets)."""
    segs = boundary_points(tm, groups)
    if len(segs) == 0:
        return False
    pts = np.round(segs.reshape(-1, 2), 10)
    _, counts = np.unique(pts, axis=0, return_counts=True)
    return bool(np.all(counts == 2))
