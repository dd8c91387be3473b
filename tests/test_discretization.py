"""The Q1 x RTCF mixed discretization: divergence theorem, mixed vs plain RTCF, symmetric Hessian,
and the stress-free preswollen reference state (zero residual at t = 0)."""

import numpy as np
import pytest
import ufl
from conftest import small_bilayer
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from app import compat, factory, fem_utils


def distorted_mesh(comm, n=6):
    """Unit square of quads mapped by a smooth nonlinear map: cells are general (non-affine) quads."""
    domain = dmesh.create_rectangle(comm, [np.array([0, 0], float), np.array([1, 1], float)], [n, n], cell_type=dmesh.CellType.quadrilateral)
    x = domain.geometry.x
    X, Y = x[:, 0].copy(), x[:, 1].copy()
    x[:, 0] = X + 0.06 * np.sin(np.pi * X) * np.sin(2 * np.pi * Y) + 0.1 * X * Y
    x[:, 1] = Y + 0.05 * np.sin(2 * np.pi * X) * np.sin(np.pi * Y) - 0.08 * X * Y * Y
    return domain


def _field(x):
    return np.vstack([np.sin(2 * x[0]) + x[1] ** 2, np.cos(3 * x[1]) * x[0] + 0.3])


def test_rtcf_in_mixed_space_satisfies_divergence_theorem(comm):
    domain = distorted_mesh(comm)
    W = compat.mixed_displacement_flux_space(domain)
    w = fem.Function(W)
    _, q_dofs = fem_utils.collapse(W.sub(1))
    rng = np.random.default_rng(7 + comm.rank)
    w.x.array[q_dofs] = rng.standard_normal(len(q_dofs))
    w.x.scatter_forward()
    _, Q = ufl.split(w)
    n = ufl.FacetNormal(domain)
    lhs = fem_utils.assemble_scalar(fem.form(ufl.div(Q) * ufl.dx), comm)
    rhs = fem_utils.assemble_scalar(fem.form(ufl.dot(Q, n) * ufl.ds), comm)
    assert abs(lhs - rhs) < 1e-11 * max(1.0, abs(rhs))
    # cell-wise too: int_K div Q = int_dK Q.n for every cell K. Testing with the DG0 indicator v0 of
    # each cell, the boundary side collects every facet of K with K's own trace and outward normal
    # (interior facets from both sides, '+' and '-'; ghosted facets are summed by the reverse scatter).
    V0 = compat.scalar_space(domain, "DG", 0)
    v0 = ufl.TestFunction(V0)
    vol = fem_utils.assemble_vector(fem.form(ufl.div(Q) * v0 * ufl.dx))
    surf = fem_utils.assemble_vector(fem.form(
        ufl.dot(Q, n) * v0 * ufl.ds
        + (ufl.dot(Q("+"), n("+")) * v0("+") + ufl.dot(Q("-"), n("-")) * v0("-")) * ufl.dS))
    n_owned = V0.dofmap.index_map.size_local
    vol, surf = vol.array[:n_owned], surf.array[:n_owned]
    assert n_owned > 0 and np.abs(vol).min() > 1e-3  # random fluxes: no cell is trivially balanced
    assert np.abs(vol - surf).max() < 1e-12 * np.abs(surf).max()  # measured 1.3e-15 abs (values ~3)
    # and the normal component is continuous (H(div)): Q.n seen from both sides cancels on every
    # interior facet (measured jump^2 integral 1e-29 against 3e2 for (Q.n)^2)
    jump = fem_utils.assemble_scalar(fem.form((ufl.dot(Q("+"), n("+")) + ufl.dot(Q("-"), n("-"))) ** 2 * ufl.dS),
                                  comm)
    size = fem_utils.assemble_scalar(fem.form(ufl.dot(Q("+"), n("+")) ** 2 * ufl.dS), comm)
    assert jump < 1e-24 * size


def test_mixed_rtcf_matches_plain_rtcf(comm):
    """Interpolating the same field into RTCF alone and into the mixed space gives the same flux."""
    domain = distorted_mesh(comm)
    W = compat.mixed_displacement_flux_space(domain)
    w = fem.Function(W)
    w.sub(1).interpolate(_field)
    w.x.scatter_forward()
    V = compat.scalar_space(domain, "RTCF", 1)
    q = fem.Function(V)
    q.interpolate(_field)
    _, Qm = ufl.split(w)
    n = ufl.FacetNormal(domain)
    # Fixed quadrature: UFL's degree estimate differs between the mixed and the plain element, and
    # on non-affine cells the integrands are rational, so estimates would not compare like with like.
    dx = ufl.dx(metadata={"quadrature_degree": 8})
    for expr in (lambda Q: ufl.dot(Q, Q) * dx, lambda Q: ufl.div(Q) ** 2 * dx,
                 lambda Q: ufl.dot(Q, n) * ufl.ds):
        a = fem_utils.assemble_scalar(fem.form(expr(Qm)), comm)
        b = fem_utils.assemble_scalar(fem.form(expr(q)), comm)
        assert a == pytest.approx(b, rel=1e-12, abs=1e-14)
    # mass matrices agree up to the dof permutation: compare permutation-invariant norms
    Mm = fem_petsc.create_matrix(fem.form(ufl.dot(ufl.TrialFunction(W), ufl.TestFunction(W)) * ufl.dx))
    fem_utils.assemble_matrix_into(Mm, fem.form(ufl.dot(ufl.split(ufl.TrialFunction(W))[1],
                                                        ufl.split(ufl.TestFunction(W))[1]) * ufl.dx), [])
    Mp = fem_petsc.create_matrix(fem.form(ufl.dot(ufl.TrialFunction(V), ufl.TestFunction(V)) * ufl.dx))
    fem_utils.assemble_matrix_into(Mp, fem.form(ufl.dot(ufl.TrialFunction(V), ufl.TestFunction(V)) * ufl.dx), [])
    assert Mm.norm(PETSc.NormType.FROBENIUS) == pytest.approx(Mp.norm(PETSc.NormType.FROBENIUS), rel=1e-12)
    # and the interpolant converges to the field (L2 error falls with h) on distorted meshes
    errs = []
    for nref in (4, 8, 16):
        d = distorted_mesh(comm, nref)
        Vr = compat.scalar_space(d, "RTCF", 1)
        qr = fem.Function(Vr)
        qr.interpolate(_field)
        x = ufl.SpatialCoordinate(d)
        exact = ufl.as_vector([ufl.sin(2 * x[0]) + x[1] ** 2, ufl.cos(3 * x[1]) * x[0] + 0.3])
        errs.append(np.sqrt(fem_utils.assemble_scalar(fem.form(ufl.dot(qr - exact, qr - exact) * ufl.dx), comm)))
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert (rates > 0.8).all(), rates


def _hessian(problem):
    A = fem_petsc.create_matrix(problem.forms.hessian)
    fem_utils.assemble_matrix_into(A, problem.forms.hessian, problem.bcs)
    return A


def test_hessian_is_symmetric_at_a_general_state(comm):
    p = factory.problem(small_bilayer(), comm)
    rng = np.random.default_rng(3 + comm.rank)
    p.state.x.array[p.u_dofs] = 1e-3 * rng.standard_normal(len(p.u_dofs))
    p.state.x.array[p.q_dofs] = 1e-5 * rng.standard_normal(len(p.q_dofs))
    p.w.x.array[p.u_dofs] = 2e-3 * rng.standard_normal(len(p.u_dofs))
    p.w.x.array[p.q_dofs] = 1e-6 * rng.standard_normal(len(p.q_dofs))
    p.state.x.scatter_forward()
    p.w.x.scatter_forward()
    p.set_time(0.3, 0.01)
    A = _hessian(p)
    At = A.duplicate(copy=True)
    At.transpose()
    At.axpy(-1.0, A)
    assert At.norm(PETSc.NormType.FROBENIUS) <= 1e-12 * A.norm(PETSc.NormType.FROBENIUS)


def _residual(problem):
    b = fem_petsc.create_vector(problem.forms.residual)
    x = compat.function_vector(problem.w)
    compat.assemble_residual_into(b, problem.forms.residual, problem.forms.hessian, problem.bcs, x)
    return b


def _block_norms(problem, b):
    W = problem.W
    n_owned = fem_utils.owned_size(W)
    arr = b.array
    u_mask = problem.u_dofs[problem.u_dofs < n_owned]
    q_mask = problem.q_dofs[problem.q_dofs < n_owned]
    nu = np.sqrt(problem.comm.allreduce(float(np.sum(arr[u_mask] ** 2))))
    nq = np.sqrt(problem.comm.allreduce(float(np.sum(arr[q_mask] ** 2))))
    return nu, nq


@pytest.mark.parametrize("ratio", [1.0, 8.0])
def test_residual_vanishes_in_the_reference_state(comm, ratio):
    """t = 0: u = 0, dQ = 0, each layer at its own s0 and mu_bar = film mu0.

    The mechanical residual vanishes for every modulus ratio (each layer is stress-free); the flux
    residual vanishes for a homogeneous gel and, for a bilayer, equals the jump of mu0 across the
    interface (the initial chemical mismatch between layers; docs/model.md, "Each layer has its own
    reference state")."""
    cfg = small_bilayer(**{"material.film.modulus_ratio": ratio})
    p = factory.problem(cfg, comm)
    p.set_time(0.0, 0.01)
    nu, nq = _block_norms(p, _residual(p))
    scale = p.materials["substrate"].shear_modulus * cfg["geometry"]["film_thickness"]
    assert nu < 1e-10 * scale
    jump = abs(p.materials["film"].mu0 - p.materials["substrate"].mu0)
    if ratio == 1.0:
        assert nq < 1e-10
    else:
        # An RTCF basis function carries a total flux of +-1 through its facet (contravariant Piola),
        # so each interface facet's row is +-jump; the norm over all interface facets follows.
        n_facets = round(cfg["geometry"]["length"] / cfg["mesh"]["element_size"])
        assert nq == pytest.approx(jump * np.sqrt(n_facets), rel=1e-8)


def test_residual_lifting_vanishes_once_the_iterate_meets_the_dirichlet_values(comm):
    """The Newton solver skips the lifting term K (g - x) when x meets the Dirichlet values: the
    residual is then the same with and without it; where x misses them the term matters."""
    p = factory.problem(small_bilayer(), comm)
    rng = np.random.default_rng(5 + comm.rank)
    p.w.x.array[p.u_dofs] = 1e-4 * rng.standard_normal(len(p.u_dofs))
    p.w.x.array[p.q_dofs] = 1e-7 * rng.standard_normal(len(p.q_dofs))
    p.w.x.scatter_forward()
    p.set_time(0.3, 0.01)
    x = compat.function_vector(p.w)

    def residuals():
        out = []
        for lifting in (True, False):
            b = fem_petsc.create_vector(p.forms.residual)
            compat.assemble_residual_into(b, p.forms.residual, p.forms.hessian, p.bcs, x, lifting=lifting)
            out.append(b)
        return out

    with_lift, without = residuals()  # x misses the (zero) Dirichlet values
    without.axpy(-1.0, with_lift)
    assert without.norm() > 1e-3 * with_lift.norm()
    fem_petsc.set_bc(x, p.bcs)
    x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    with_lift, without = residuals()
    without.axpy(-1.0, with_lift)
    assert without.norm() <= 1e-14 * with_lift.norm()
