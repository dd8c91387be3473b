"""Every dolfinx-version-specific call hydrobuckle makes, in one place.

Two stacks are supported and tested: dolfinx 0.5 (Debian 12: UFL 2022 elements, ``FunctionSpace``,
``Function.vector``, adjacency-list dofmaps) and dolfinx 0.9 (Debian 13: ``basix.ufl`` elements,
``functionspace``, ``x.petsc_vec``, array dofmaps, ``alpha`` in lifting). Each difference is one
branch on :data:`MODERN` below; nothing else in hydrobuckle looks at the dolfinx version.
"""

from __future__ import annotations

import os

# PT-Scotch, dolfinx's graph partitioner on both stacks, partitions with threads, and with more than one
# thread the same mesh on the same ranks comes out with its parts given to the ranks in either order (measured
# on 2 ranks: 2 runs in 10 swapped), so the roundoff, and past an unstable state the branch taken, differed
# between identical runs. One thread makes the layout a function of the mesh and the rank count. Read when a
# mesh is partitioned; a user's own setting is kept.
os.environ.setdefault("SCOTCH_PTHREAD_NUMBER", "1")

import dolfinx  # noqa: E402
import numpy as np  # noqa: E402
import ufl  # noqa: E402
from dolfinx import fem  # noqa: E402
from dolfinx import mesh as dmesh  # noqa: E402
from dolfinx.fem import petsc as fem_petsc  # noqa: E402
from dolfinx.io import XDMFFile, gmshio  # noqa: E402  (gmshio must be imported explicitly in 0.5)
from petsc4py import PETSc  # noqa: E402

DOLFINX_VERSION = dolfinx.__version__
ScalarType = PETSc.ScalarType

#: dolfinx >= 0.7: elements from basix.ufl, ``fem.functionspace``, ndarray dofmaps, ``x.petsc_vec``.
MODERN = tuple(int(p) for p in DOLFINX_VERSION.split(".")[:2]) >= (0, 7)

if MODERN:
    import basix.ufl


def _element(family: str, cell, degree: int, shape=None):
    """A finite element of ``family`` on the UFL cell ``cell`` (a vector element with ``shape``)."""
    if MODERN:
        return basix.ufl.element(family, cell.cellname(), degree, shape=shape)
    if shape is not None:
        return ufl.VectorElement(family, cell, degree, dim=shape[0])
    return ufl.FiniteElement(family, cell, degree)


def _mixed(elements):
    return basix.ufl.mixed_element(elements) if MODERN else ufl.MixedElement(elements)


def _space(domain, element):
    return fem.functionspace(domain, element) if MODERN else fem.FunctionSpace(domain, element)


def cells_by_row(adjacency, n: int) -> np.ndarray:
    """A dofmap (an adjacency list in 0.5, an array in 0.9) as an (n, entries per cell) int64 array."""
    data = adjacency.array if hasattr(adjacency, "array") else adjacency
    return np.asarray(data, dtype=np.int64).reshape(n, -1)


def placeholder_domain():
    """An abstract UFL quadrilateral domain, for UFL expressions of Constants evaluated without a mesh."""
    return ufl.Mesh(_element("Lagrange", ufl.quadrilateral, 1, shape=(2,)))


# --- function spaces -------------------------------------------------------------------


#: the lowest-order Raviart-Thomas family by cell: UFL 2022 (dolfinx 0.5) names it RTCF on quadrilaterals and
#: NCF on hexahedra; basix.ufl (0.9) takes RTCF for both
_RT_FAMILY = {"quadrilateral": "RTCF", "hexahedron": "RTCF" if MODERN else "NCF"}


def _raviart_thomas(cell):
    return _element(_RT_FAMILY[cell.cellname()], cell, 1)


def _gdim(domain) -> int:
    return domain.geometry.dim


def mixed_displacement_flux_space(domain):
    """Vector Q1 displacement x lowest-order Raviart-Thomas flux (RTCF on quadrilaterals, its hexahedral
    counterpart in 3D: one flux dof per facet either way)."""
    cell = domain.ufl_cell()
    return _space(domain, _mixed([_element("Lagrange", cell, 1, shape=(_gdim(domain),)), _raviart_thomas(cell)]))


def mixed_displacement_content_space(domain):
    """Vector Q1 displacement x DG0 fluid content: the unknowns of the drained stability test
    (the fluid content per cell is what the divergence of an RTCF flux can change)."""
    cell = domain.ufl_cell()
    return _space(domain, _mixed([_element("Lagrange", cell, 1, shape=(_gdim(domain),)), _element("DG", cell, 0)]))


def mixed_lagrange_space(domain, degree: int, count: int):
    """``count`` scalar Lagrange fields of one degree in one mixed space (the 1D reduction's unknowns)."""
    el = _element("Lagrange", domain.ufl_cell(), degree)
    return _space(domain, _mixed([el] * count))


def mixed_dg0_space(domain, count: int):
    """``count`` cell-wise constant scalar fields in one mixed space."""
    el = _element("DG", domain.ufl_cell(), 0)
    return _space(domain, _mixed([el] * count))


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


def global_indices(V, local: np.ndarray) -> np.ndarray:
    """Global numbers of local (owned or ghost) scalar dofs of V."""
    imap, bs = V.dofmap.index_map, V.dofmap.index_map_bs
    local = np.asarray(local, np.int64)
    return imap.local_to_global((local // bs).astype(np.int32)).astype(np.int64) * bs + local % bs


def matrix_csr(A):
    """(indptr, indices, values) of an assembled serial PETSc matrix."""
    return A.getValuesCSR()


def scalar_space(domain, family: str, degree: int):
    return _space(domain, _element(family, domain.ufl_cell(), degree))


def vector_space(domain, family: str, degree: int):
    """A vector-valued space with as many components as the mesh has dimensions."""
    return _space(domain, _element(family, domain.ufl_cell(), degree, shape=(_gdim(domain),)))


def rtcf_space(domain):
    """The flux space alone (lowest-order Raviart-Thomas on the mesh's cells)."""
    return _space(domain, _raviart_thomas(domain.ufl_cell()))


def collapse(subspace):
    """(collapsed space, indices of its dofs in the parent's local array)."""
    V, dofs = subspace.collapse()
    return V, np.asarray(dofs, dtype=np.int32)


def function_vector(f: fem.Function) -> PETSc.Vec:
    """The PETSc vector that shares memory with ``f.x.array``."""
    return f.x.petsc_vec if MODERN else f.vector


def scatter_forward(f: fem.Function) -> None:
    f.x.scatter_forward()


def owned_size(V) -> int:
    """Number of locally owned scalar dofs of V (block size included)."""
    return V.dofmap.index_map.size_local * V.dofmap.index_map_bs


def global_size(V) -> int:
    return V.dofmap.index_map.size_global * V.dofmap.index_map_bs


# --- mesh ----------------------------------------------------------------------------


def gmsh_model_to_mesh(model, comm, rank: int = 0, gdim: int = 2):
    """(mesh, cell_tags, facet_tags) from a gmsh model that lives on ``rank``."""
    if MODERN:  # 0.5's default: ghost cells across shared facets (interior-facet integrals need them)
        partitioner = dmesh.create_cell_partitioner(dmesh.GhostMode.shared_facet)
        return gmshio.model_to_mesh(model, comm, rank, gdim=gdim, partitioner=partitioner)
    return gmshio.model_to_mesh(model, comm, rank, gdim=gdim)


def num_owned_cells(domain) -> int:
    tdim = domain.topology.dim
    return domain.topology.index_map(tdim).size_local


def num_global_cells(domain) -> int:
    return domain.topology.index_map(domain.topology.dim).size_global


def rectangle_quads(comm, p0, p1, n):
    return dmesh.create_rectangle(comm, [np.asarray(p0, float), np.asarray(p1, float)], n,
                                  cell_type=dmesh.CellType.quadrilateral)


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


def cell_geometry_nodes(domain) -> np.ndarray:
    """Geometry node indices per cell (owned + ghost), shape (num_cells, nodes_per_cell)."""
    return cells_by_row(domain.geometry.dofmap, num_local_cells(domain))


def cell_dofs(V) -> np.ndarray:
    """The local dofs of each local cell (owned + ghost) of a (collapsed) space: (num_cells, dofs per cell)."""
    return cells_by_row(V.dofmap.list, num_local_cells(V.mesh))


def num_local_cells(domain) -> int:
    """Cells on this rank, owned and ghost."""
    imap = domain.topology.index_map(domain.topology.dim)
    return imap.size_local + imap.num_ghosts


def original_node_indices(domain) -> np.ndarray:
    """The index each local geometry node (owned + ghost) had in the mesh's input (the gmsh model's node
    order): the same for every partition and rank count of one input mesh."""
    return np.asarray(domain.geometry.input_global_indices, dtype=np.int64)


def node_coordinates(domain) -> np.ndarray:
    """Coordinates (x, y, and z in 3D) of the local geometry nodes."""
    return domain.geometry.x[:, :_gdim(domain)]


def exterior_facets(domain) -> np.ndarray:
    fdim = domain.topology.dim - 1
    domain.topology.create_connectivity(fdim, fdim + 1)
    return np.asarray(dmesh.exterior_facet_indices(domain.topology), dtype=np.int32)


def facets_with_tag(facet_tags, tag: int) -> np.ndarray:
    return facet_tags.indices[facet_tags.values == tag]


def cells_with_tag(cell_tags, tag: int) -> np.ndarray:
    return cell_tags.indices[cell_tags.values == tag]




# --- forms, assembly, boundary conditions (dolfinx.fem.form, Function and Constant are the same in 0.5 and 0.9:
# called directly) --------------------------------------------------------------------------------------------

def dirichlet_zero_on_facets(W_sub, facets: np.ndarray, fdim: int):
    """Homogeneous Dirichlet condition on a (possibly nested) sub-space of a mixed space.

    Works for Lagrange components and for RT flux spaces (where it fixes the normal flux
    moments on the given facets to zero)."""
    V, _ = W_sub.collapse()
    g = fem.Function(V)
    g.x.array[:] = 0.0
    dofs = fem.locate_dofs_topological((W_sub, V), fdim, facets)
    return fem.dirichletbc(g, dofs, W_sub), g


def dirichlet_function_on_facets(W_sub, facets: np.ndarray, fdim: int):
    """Dirichlet condition whose values come from a Function the caller updates in time."""
    return dirichlet_zero_on_facets(W_sub, facets, fdim)


def dirichlet_function_on_cells(W_sub, domain):
    """Dirichlet condition on every local cell's dofs of a (cell-wise, e.g. DG0) sub-space, its values from a
    Function the caller sets: (condition, function). dolfinx 0.9 locates dofs on cells only once the
    cell-to-cell connectivity exists (0.5 does not ask for it)."""
    tdim = domain.topology.dim
    domain.topology.create_connectivity(tdim, tdim)
    imap = domain.topology.index_map(tdim)
    cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    return dirichlet_zero_on_facets(W_sub, cells, tdim)


def locate_dofs_on_facets(V, fdim: int, facets: np.ndarray) -> np.ndarray:
    """Local dofs of a (collapsed) space V on the given facets."""
    return np.asarray(fem.locate_dofs_topological(V, fdim, facets), dtype=np.int32)


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


def set_dirichlet_values(x, bcs) -> None:
    """x[constrained dofs] = their prescribed values (owned entries)."""
    fem_petsc.set_bc(x, bcs)


def create_matrix(a):
    return fem_petsc.create_matrix(a)


def create_vector(L):
    return fem_petsc.create_vector(L)


def assemble_matrix_into(A, a, bcs, diagonal: float = 1.0):
    A.zeroEntries()
    fem_petsc.assemble_matrix(A, a, bcs=bcs, diagonal=diagonal)
    A.assemble()


def assemble_residual_into(b, L, a, bcs, x, lifting: bool = True):
    """b = L(x) with Dirichlet rows set to x_bc - g; with ``lifting`` also b += K (g - x) on the
    constrained columns (the standard Newton lifting; zero when x already meets the conditions)."""
    with b.localForm() as b_local:
        b_local.set(0.0)
    fem_petsc.assemble_vector(b, L)
    if lifting:
        if MODERN:
            fem_petsc.apply_lifting(b, [a], bcs=[bcs], x0=[x], alpha=-1.0)
        else:
            fem_petsc.apply_lifting(b, [a], bcs=[bcs], x0=[x], scale=-1.0)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    fem_petsc.set_bc(b, bcs, x, -1.0)


def assemble_vector(L) -> PETSc.Vec:
    b = fem_petsc.assemble_vector(L)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    return b


def assemble_scalar(M, comm) -> float:
    return comm.allreduce(fem.assemble_scalar(M), op=_mpi_sum())


def _mpi_sum():
    from mpi4py import MPI

    return MPI.SUM


def interpolate(target: fem.Function, source) -> None:
    """Interpolate a Function, an Expression or a callable into ``target``."""
    target.interpolate(source)


def form_signature(compiled) -> str:
    """The signature of a compiled form: equal signatures, the same generated kernel (one JIT-cache entry)."""
    import cffi

    return cffi.FFI().string(compiled.ufcx_form.signature).decode()


def expression(ufl_expr, V):
    """A compiled UFL expression evaluated at the interpolation points of V."""
    points = V.element.interpolation_points
    return fem.Expression(ufl_expr, points() if callable(points) else points)




# --- IO --------------------------------------------------------------------------------


def xdmf_writer(comm, path: str):
    return XDMFFile(comm, path, "w")


def xdmf_mesh_bytes(domain) -> int:
    """About the bytes XDMFFile.write_mesh puts into the .h5: node coordinates (3 x float64) and the
    cells' node lists (int64)."""
    nodes = domain.geometry.index_map().size_global
    tdim = domain.topology.dim
    cells = domain.topology.index_map(tdim).size_global
    return 8 * (3 * nodes + domain.ufl_cell().num_vertices() * cells)


def xdmf_function_bytes(f: fem.Function) -> int:
    """About the bytes XDMFFile.write_function puts into the .h5 for ``f``: its global values as float64,
    a 2D vector padded to 3 components."""
    im = f.function_space.dofmap.index_map
    bs = f.function_space.dofmap.index_map_bs
    return 8 * im.size_global * (3 if bs == 2 else bs)
