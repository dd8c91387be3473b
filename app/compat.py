"""Every dolfinx-version-specific call hydrobuckle makes, in one place, and nothing else.

Two stacks are supported and tested: dolfinx 0.5 (Debian 12: UFL 2022 elements, ``FunctionSpace``,
``Function.vector``, adjacency-list dofmaps) and dolfinx 0.9 (Debian 13: ``basix.ufl`` elements,
``functionspace``, ``x.petsc_vec``, array dofmaps, ``alpha`` in lifting). Each difference is one
branch on :data:`MODERN` below, and each function here says which versions it bridges; nothing else in
hydrobuckle looks at the dolfinx version. Calls that are the same on both are made directly, or through
:mod:`app.fem_utils` where hydrobuckle adds a convention (block sizes, ghost updates, MPI sums).
"""

from __future__ import annotations

import dolfinx
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from dolfinx.io import gmshio  # (gmshio must be imported explicitly in 0.5)
from petsc4py import PETSc

DOLFINX_VERSION = dolfinx.__version__

#: dolfinx >= 0.7: elements from basix.ufl, ``fem.functionspace``, ndarray dofmaps, ``x.petsc_vec``.
MODERN = tuple(int(p) for p in DOLFINX_VERSION.split(".")[:2]) >= (0, 7)

if MODERN:
    import basix.ufl


def _element(family: str, cell, degree: int, shape=None):
    """A finite element of ``family`` on the UFL cell ``cell`` (a vector element with ``shape``): basix.ufl in 0.9,
    UFL 2022's element classes in 0.5."""
    if MODERN:
        return basix.ufl.element(family, cell.cellname(), degree, shape=shape)
    if shape is not None:
        return ufl.VectorElement(family, cell, degree, dim=shape[0])
    return ufl.FiniteElement(family, cell, degree)


def _mixed(elements):
    """A mixed element: basix.ufl.mixed_element in 0.9, ufl.MixedElement in 0.5."""
    return basix.ufl.mixed_element(elements) if MODERN else ufl.MixedElement(elements)


def _space(domain, element):
    """fem.functionspace in 0.9, fem.FunctionSpace in 0.5."""
    return fem.functionspace(domain, element) if MODERN else fem.FunctionSpace(domain, element)


def placeholder_domain():
    """An abstract UFL quadrilateral domain, for UFL expressions of Constants evaluated without a mesh (its
    coordinate element is versioned)."""
    return ufl.Mesh(_element("Lagrange", ufl.quadrilateral, 1, shape=(2,)))


# --- function spaces (their elements are versioned) --------------------------------------


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


def scalar_space(domain, family: str, degree: int):
    return _space(domain, _element(family, domain.ufl_cell(), degree))


def vector_space(domain, family: str, degree: int):
    """A vector-valued space with as many components as the mesh has dimensions."""
    return _space(domain, _element(family, domain.ufl_cell(), degree, shape=(_gdim(domain),)))


# --- dofmaps, vectors, meshes, lifting, expressions ----------------------------------------


def cells_by_row(adjacency, n: int) -> np.ndarray:
    """A dofmap (an adjacency list in 0.5, an array in 0.9) as an (n, entries per cell) int64 array."""
    data = adjacency.array if hasattr(adjacency, "array") else adjacency
    return np.asarray(data, dtype=np.int64).reshape(n, -1)


def function_vector(f: fem.Function) -> PETSc.Vec:
    """The PETSc vector that shares memory with ``f.x.array``: ``x.petsc_vec`` in 0.9, ``vector`` in 0.5."""
    return f.x.petsc_vec if MODERN else f.vector


def gmsh_model_to_mesh(model, comm, rank: int = 0, gdim: int = 2):
    """(mesh, cell_tags, facet_tags) from a gmsh model that lives on ``rank``; 0.9 is asked for the ghost mode
    that is 0.5's default."""
    if MODERN:  # 0.5's default: ghost cells across shared facets (interior-facet integrals need them)
        partitioner = dmesh.create_cell_partitioner(dmesh.GhostMode.shared_facet)
        return gmshio.model_to_mesh(model, comm, rank, gdim=gdim, partitioner=partitioner)
    return gmshio.model_to_mesh(model, comm, rank, gdim=gdim)


def assemble_residual_into(b, L, a, bcs, x, lifting: bool = True):
    """b = L(x) with Dirichlet rows set to x_bc - g; with ``lifting`` also b += K (g - x) on the
    constrained columns (the standard Newton lifting; zero when x already meets the conditions). The lifting's
    factor is ``alpha`` in 0.9, ``scale`` in 0.5."""
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


def expression(ufl_expr, V):
    """A compiled UFL expression evaluated at the interpolation points of V (a method in 0.9, a property in 0.5)."""
    points = V.element.interpolation_points
    return fem.Expression(ufl_expr, points() if callable(points) else points)
