"""Where each dof of hydrobuckle's spaces sits on the mesh: the geometry node of each first-order Lagrange dof,
the facet of each lowest-order Raviart-Thomas dof and the normal it measures, the two nodes of each facet.
The checkpoints key their values by these (input node numbers and facet node pairs are the same for every
partition of one input mesh), and the surface check maps displacement dofs to surface nodes with them.
The version-specific accessors (dofmap layout, geometry nodes) are in :mod:`app.compat`."""

from __future__ import annotations

import numpy as np
from dolfinx import fem

from app import compat, fem_utils


def lagrange1_dof_nodes(V) -> np.ndarray:
    """The geometry node of each local dof (block) of a first-order Lagrange space V on a first-order mesh.

    Both dofmaps list a cell's entries in the reference cell's vertex order, so the k-th dof of a cell
    sits on the cell's k-th geometry node; checked here against the dof coordinates."""
    domain = V.mesh
    n = fem_utils.num_local_cells(domain)
    dofs = compat.cells_by_row(V.dofmap.list, n)
    nodes = fem_utils.cell_geometry_nodes(domain)
    if dofs.shape != nodes.shape:
        raise RuntimeError(f"{dofs.shape[1]} dofs per cell but {nodes.shape[1]} geometry nodes: not P1 on a P1 mesh")
    size = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    out = np.full(size, -1, dtype=np.int64)
    out[dofs.ravel()] = nodes.ravel()
    X = V.tabulate_dof_coordinates()[:, :domain.geometry.dim]
    if (out < 0).any() or not np.allclose(X, fem_utils.node_coordinates(domain)[out], rtol=0.0,
                                          atol=1e-12 * max(1.0, float(np.abs(X).max(initial=0.0)))):
        raise RuntimeError("P1 dofs and geometry nodes do not coincide")
    return out


def facet_of_dofs(V) -> np.ndarray:
    """The facet of each local dof of a lowest-order facet space (RTCF1: one dof per facet), from the
    cells' dofmaps and their facets in reference order."""
    domain = V.mesh
    tdim = domain.topology.dim
    domain.topology.create_connectivity(tdim, tdim - 1)
    n = fem_utils.num_local_cells(domain)
    c2f = np.asarray(domain.topology.connectivity(tdim, tdim - 1).array, dtype=np.int64).reshape(n, -1)
    dofs = compat.cells_by_row(V.dofmap.list, n)
    size = V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts
    out = np.full(size, -1, dtype=np.int64)
    layout = V.dofmap.dof_layout
    for i in range(c2f.shape[1]):
        local = list(layout.entity_dofs(tdim - 1, i))
        if len(local) != 1:
            raise RuntimeError(f"{len(local)} dofs on facet {i} of the reference cell: not a lowest-order facet space")
        out[dofs[:, local[0]]] = c2f[:, i]
    if (out < 0).any():
        raise RuntimeError("a facet-space dof on no local cell")
    return out


def facet_dof_normals(V) -> np.ndarray:
    """(n_x, n_y[, n_z]) per local dof of a lowest-order Raviart-Thomas space: the dofs of the constant
    fields e_x, e_y (and e_z), i.e. the (size-scaled) normal each dof measures the flux along. Its sign follows
    the facet's orientation, which dolfinx takes from the partition's global vertex numbering."""
    f = fem.Function(V)
    d = V.mesh.geometry.dim
    out = []
    for comp in range(d):
        f.interpolate(lambda x, c=comp: np.vstack([np.full(x.shape[1], float(c == k)) for k in range(d)]))
        f.x.scatter_forward()
        out.append(f.x.array.copy())
    return np.column_stack(out)


def facet_nodes(domain) -> np.ndarray:
    """The geometry nodes (vertices) of each local facet, shape (num_facets, 2) on a 2D mesh, (num_facets, 4)
    on a hexahedral one."""
    tdim = domain.topology.dim
    domain.topology.create_connectivity(tdim - 1, 0)
    domain.topology.create_connectivity(tdim, 0)
    f2v = np.asarray(domain.topology.connectivity(tdim - 1, 0).array, dtype=np.int64).reshape(-1, 2 ** (tdim - 1))
    c2v = np.asarray(domain.topology.connectivity(tdim, 0).array, dtype=np.int64)
    c2v = c2v.reshape(fem_utils.num_local_cells(domain), -1)
    v2g = np.full(domain.topology.index_map(0).size_local + domain.topology.index_map(0).num_ghosts, -1, np.int64)
    v2g[c2v] = fem_utils.cell_geometry_nodes(domain)[:, : c2v.shape[1]]  # a first-order cell's nodes are its vertices
    return v2g[f2v]
