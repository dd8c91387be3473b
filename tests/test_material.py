"""Constitutive model against the closed forms of the paper (eqs. 3.4-3.6)."""

import math

import numpy as np
import pytest
import ufl
from mpi4py import MPI

from app import compat
from app.model.material import (
    Hydrogel,
    chemical_potential,
    constrained_layer_fluid,
    constrained_layer_stretch,
    free_energy,
)

PAPER = dict(mixing_modulus=24.2, penalty=10.0, mobility=1e-4, preswelling=1.01, interaction=0.1)


def _evaluate(expr_of, mat, F_values, s_value):
    """Evaluate a UFL expression of (mat, F, s) with UFL-differentiable variables on a 1-cell mesh."""
    domain = compat.rectangle_quads(MPI.COMM_SELF, (0, 0), (1, 1), (1, 1))
    F = ufl.variable(ufl.as_matrix([[compat.Constant(domain, float(v)) for v in row] for row in F_values]))
    s = ufl.variable(compat.Constant(domain, float(s_value)))
    return compat.assemble_scalar(compat.form(expr_of(mat, F, s) * ufl.dx(domain=domain)), MPI.COMM_SELF)


@pytest.mark.parametrize("gamma,J0", [(0.1, 1.01), (0.8, 1.01), (0.1, 1.5), (2.0, 1.2)])
def test_s0_mu0_match_eqs_3_5_and_3_6(gamma, J0):
    mat = Hydrogel(shear_modulus=gamma, **{**PAPER, "preswelling": J0})
    eps, alpha, chi = PAPER["penalty"], PAPER["mixing_modulus"], PAPER["interaction"]
    s0 = gamma / eps * (J0 ** (-1 / 3) - 1 / J0) + J0 - 1
    mu0 = -eps / J0 * (J0 - 1 - s0) + alpha / J0 * (math.log(s0 / (1 + s0)) + 1 / (1 + s0) + chi / (1 + s0) ** 2)
    assert mat.s0 == pytest.approx(s0, rel=1e-14)
    assert mat.mu0 == pytest.approx(mu0, rel=1e-14)
    # mu0 is dpsi/ds of the UFL free energy at the reference state
    dpsi_ds = _evaluate(lambda m, F, s: ufl.diff(free_energy(m, F, s), s), mat, np.eye(2), s0)
    assert dpsi_ds == pytest.approx(mu0, rel=1e-12)


@pytest.mark.parametrize("gamma,J0", [(0.1, 1.01), (0.8, 1.3)])
def test_reference_state_is_stress_free(gamma, J0):
    mat = Hydrogel(shear_modulus=gamma, **{**PAPER, "preswelling": J0})
    for i in range(2):
        for j in range(2):
            Pij = _evaluate(lambda m, F, s, i=i, j=j: ufl.diff(free_energy(m, F, s), F)[i, j], mat, np.eye(2), mat.s0)
            assert abs(Pij) < 1e-12 * gamma


def test_chemical_potential_matches_derivative_away_from_reference():
    mat = Hydrogel(shear_modulus=0.3, **PAPER)
    Fv = [[1.05, 0.1], [-0.02, 1.7]]
    J = np.linalg.det(Fv)
    for s in (0.05, 0.7, 3.0):
        dpsi_ds = _evaluate(lambda m, F, s_: ufl.diff(free_energy(m, F, s_), s_), mat, Fv, s)
        assert dpsi_ds == pytest.approx(float(chemical_potential(mat, J, s)), rel=1e-12)


def test_constrained_layer_reference_value():
    """l = 4.887 at mu_bar = 0 for gamma = 0.1 (docs/validation.md, section 1: closed form of eqs. 3.3-3.4
    with F = diag(1, l)); zero traction and mu = mu_bar there."""
    mat = Hydrogel(shear_modulus=0.1, **PAPER)
    lam = constrained_layer_stretch(mat, 0.0)
    assert lam == pytest.approx(4.887, abs=5e-4)
    s = constrained_layer_fluid(mat, lam)
    Pyy = _evaluate(lambda m, F, s_: ufl.diff(free_energy(m, F, s_), F)[1, 1], mat, [[1, 0], [0, lam]], s)
    assert abs(Pyy) < 1e-10
    assert float(chemical_potential(mat, lam, s)) == pytest.approx(0.0, abs=1e-9)
