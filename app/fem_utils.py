"""Small conveniences on dolfinx objects that are the same on every supported version (the version
differences are :mod:`app.compat`): sizes and global numbers of dofs with their block size, the owned dofs
a set of conditions holds and their index set, assembly into existing PETSc objects with the ghost updates
and the MPI sum, collapsed sub-spaces with their dofs, cell and node counts, coordinates and midpoints, and a
graded interval mesh.
"""

from __future__ import annotations

import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from app import compat


def owned_size(V) -> int:
    """Number of locally owned scalar dofs of V (block size included)."""
    return V.dofmap.index_map.size_local * V.dofmap.index_map_bs


def global_size(V) -> int:
    return V.dofmap.index_map.size_global * V.dofmap.index_map_bs


def global_indices(V, local: np.ndarray) -> np.ndarray:
    """Global numbers of local (owned or ghost) scalar dofs of V."""
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    local = np.asarray(local, np.int64)
    return imap.local_to_global((local // bs).astype(np.int32)).astype(np.int64) * bs + local % bs


def bc_dof_indices(bc) -> np.ndarray:
    """Local (owned + ghost) indices in the parent space constrained by ``bc``."""
    idx, first_ghost = bc.dof_indices()
    return np.asarray(idx, dtype=np.int32)


def owned_bc_dofs(bcs, W) -> np.ndarray:
    """Owned indices (in the local array of W) constrained by any of ``bcs``."""
    n_owned = W.dofmap.index_map.size_local * W.dofmap.index_map_bs
    idx = np.concatenate([bc_dof_indices(bc) for bc in bcs]) if bcs else np.empty(0, np.int32)
    return np.unique(idx[idx < n_owned]).astype(np.int32)


def owned_index_set(W, local_indices: np.ndarray, comm) -> PETSc.IS:
    """PETSc index set of the global numbers of the given owned local indices of W."""
    start = W.dofmap.index_map.local_range[0] * W.dofmap.index_map_bs
    return PETSc.IS().createGeneral((start + np.sort(local_indices)).astype(PETSc.IntType), comm=comm)


def dirichlet_zero_on_facets(W_sub, facets: np.ndarray, fdim: int):
    """Homogeneous Dirichlet condition on a (possibly nested) sub-space of a mixed space.

    Works for Lagrange components and for RT flux spaces (where it fixes the normal flux
    moments on the given facets to zero)."""
    V, _ = W_sub.collapse()
    g = fem.Function(V)
    g.x.array[:] = 0.0
    dofs = fem.locate_dofs_topological((W_sub, V), fdim, facets)
    return fem.dirichletbc(g, dofs, W_sub), g


def dirichlet_function_on_cells(W_sub, domain):
    """Dirichlet condition on every local cell's dofs of a (cell-wise, e.g. DG0) sub-space, its values from a
    Function the caller sets: (condition, function). The cell-to-cell connectivity is created first: dolfinx
    0.9 locates dofs on cells only once it exists (0.5 does not ask for it, and is not hurt by it)."""
    tdim = domain.topology.dim
    domain.topology.create_connectivity(tdim, tdim)
    imap = domain.topology.index_map(tdim)
    cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    return dirichlet_zero_on_facets(W_sub, cells, tdim)


def assemble_matrix_into(A, a, bcs, diagonal: float = 1.0):
    A.zeroEntries()
    fem_petsc.assemble_matrix(A, a, bcs=bcs, diagonal=diagonal)
    A.assemble()


def assemble_vector(L) -> PETSc.Vec:
    b = fem_petsc.assemble_vector(L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return b


def assemble_scalar(M, comm) -> float:
    return comm.allreduce(fem.assemble_scalar(M), op=MPI.SUM)


def collapse(subspace):
    """(collapsed space, indices of its dofs in the parent's local array)."""
    V, dofs = subspace.collapse()
    return V, np.asarray(dofs, dtype=np.int32)


def dof_coordinates(V) -> np.ndarray:
    """x of each local dof of a scalar space (collapsed sub-spaces included)."""
    return V.tabulate_dof_coordinates()[:, 0].copy()


def dof_points(V) -> np.ndarray:
    """(x, y) of each local dof of a scalar space (collapsed sub-spaces included)."""
    return V.tabulate_dof_coordinates()[:, :2].copy()


def facet_midpoints(domain, facets: np.ndarray) -> np.ndarray:
    """(x, y) of the midpoint of each given local facet."""
    return dmesh.compute_midpoints(domain, domain.topology.dim - 1, facets)[:, :2]


def cell_midpoints(domain, cells: np.ndarray) -> np.ndarray:
    """(x, y) of the midpoint of each given local cell."""
    return dmesh.compute_midpoints(domain, domain.topology.dim, np.asarray(cells, np.int32))[:, :2]


def interval_mesh(comm, nodes: np.ndarray):
    """A 1D mesh whose vertices are the increasing coordinates ``nodes`` (a graded interval)."""
    nodes = np.asarray(nodes, dtype=float)
    domain = dmesh.create_interval(comm, len(nodes) - 1, [0.0, 1.0])
    x = domain.geometry.x
    # the uniform mesh's vertex at t = i/n moves to nodes[i]: an order-preserving map, so every cell
    # keeps its two vertices' neighbours
    t = x[:, 0].copy()
    x[:, 0] = np.interp(t, np.linspace(0.0, 1.0, len(nodes)), nodes)
    return domain


def num_owned_cells(domain) -> int:
    tdim = domain.topology.dim
    return domain.topology.index_map(tdim).size_local


def num_global_cells(domain) -> int:
    return domain.topology.index_map(domain.topology.dim).size_global


def num_local_cells(domain) -> int:
    """Cells on this rank, owned and ghost."""
    imap = domain.topology.index_map(domain.topology.dim)
    return imap.size_local + imap.num_ghosts


def cell_geometry_nodes(domain) -> np.ndarray:
    """Geometry node indices per cell (owned + ghost), shape (num_cells, nodes_per_cell)."""
    return compat.cells_by_row(domain.geometry.dofmap, num_local_cells(domain))


def cell_dofs(V) -> np.ndarray:
    """The local dofs of each local cell (owned + ghost) of a (collapsed) space: (num_cells, dofs per cell)."""
    return compat.cells_by_row(V.dofmap.list, num_local_cells(V.mesh))


def vertex_to_geometry(domain) -> np.ndarray:
    """Map from topological vertex index to geometry node index (they differ in dolfinx)."""
    tdim = domain.topology.dim
    domain.topology.create_connectivity(tdim, 0)
    c2v = domain.topology.connectivity(tdim, 0)
    n_vertices = domain.topology.index_map(0).size_local + domain.topology.index_map(0).num_ghosts
    out = np.full(n_vertices, -1, dtype=np.int64)
    nodes = cell_geometry_nodes(domain)
    for c in range(nodes.shape[0]):
        out[c2v.links(c)] = nodes[c, :len(c2v.links(c))]
    return out


def node_coordinates(domain) -> np.ndarray:
    """Coordinates (x, y, and z in 3D) of the local geometry nodes."""
    return domain.geometry.x[:, :domain.geometry.dim]


def exterior_facets(domain) -> np.ndarray:
    fdim = domain.topology.dim - 1
    domain.topology.create_connectivity(fdim, fdim + 1)
    return np.asarray(dmesh.exterior_facet_indices(domain.topology), dtype=np.int32)
