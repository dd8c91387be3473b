"""Constitutive model against the closed forms of the paper (eqs. 3.4-3.6), and the material law
interface: mu and P derived by UFL equal finite differences of psi; float values from the same
derivatives; the law's one parameter declaration feeds the config, the Material record, the per-cell
fields and the summary."""

import dataclasses
import math

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from scipy.optimize import brentq

from app import config, fem_utils
from app.model.hydrogel import HYDROGEL, Hydrogel
from app.model.material import LAWS, chemical_potential, first_piola, free_energy
from app.model.theory import _undrained_pxx, constrained_layer_fluid, constrained_layer_stretch

PAPER = dict(mixing_modulus=24.2, penalty=10.0, mobility=1e-4, preswelling=1.01, interaction=0.1)


def _evaluate(expr_of, mat, F_values, s_value):
    """Evaluate a UFL expression of (mat, F, s) with UFL-differentiable variables on a 1-cell mesh."""
    domain = dmesh.create_rectangle(MPI.COMM_SELF, [np.array([0, 0], float), np.array([1, 1], float)], [1, 1], cell_type=dmesh.CellType.quadrilateral)
    F = ufl.variable(ufl.as_matrix([[fem.Constant(domain, float(v)) for v in row] for row in F_values]))
    s = ufl.variable(fem.Constant(domain, float(s_value)))
    return fem_utils.assemble_scalar(fem.form(expr_of(mat, F, s) * ufl.dx(domain=domain)), MPI.COMM_SELF)


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
    assert np.abs(first_piola(mat, np.eye(2), mat.s0)).max() < 1e-12 * gamma


def test_chemical_potential_matches_the_hand_derivative_away_from_reference():
    """mu = dpsi/ds of eq. 3.4 written out (eq. 2.6) against the law's UFL derivative, as floats and
    assembled."""
    mat = Hydrogel(shear_modulus=0.3, **PAPER)
    a, e, J0, chi = mat.mixing_modulus, mat.penalty, mat.preswelling, mat.interaction
    Fv = [[1.05, 0.1], [-0.02, 1.7]]
    J = np.linalg.det(Fv)
    for s in (0.05, 0.7, 3.0):
        by_hand = a / J0 * (math.log(s / (1 + s)) + 1 / (1 + s) + chi / (1 + s) ** 2) - e / J0 * (J * J0 - 1 - s)
        assert chemical_potential(mat, Fv, s) == pytest.approx(by_hand, rel=1e-12)
        assembled = _evaluate(lambda m, F, s_: chemical_potential(m, F, s_), mat, Fv, s)
        assert assembled == pytest.approx(by_hand, rel=1e-12)


def _psi(mat, F, s) -> float:
    """psi as a float: the law's UFL expression on a 1-cell mesh of unit area."""
    return _evaluate(lambda m, F_, s_: free_energy(m, F_, s_), mat, F, s)


@pytest.mark.parametrize("Fv,s", [([[1.05, 0.1], [-0.02, 1.7]], 0.7), ([[0.9, 0.0], [0.03, 1.2]], 0.15),
                                  ([[1.0, 0.0], [0.0, 1.0]], 0.0135)])
def test_ufl_derived_mu_and_piola_equal_finite_differences_of_psi(Fv, s):
    """The derivatives the forms, the fields and mu0 use (ufl.diff of the law's psi) against central
    differences of psi itself (step 1e-5: truncation ~1e-10, roundoff ~1e-11 relative)."""
    mat = Hydrogel(shear_modulus=0.3, **PAPER)
    h = 1e-5
    Fv = np.array(Fv, dtype=float)
    mu_fd = (_psi(mat, Fv, s + h) - _psi(mat, Fv, s - h)) / (2 * h)
    assert chemical_potential(mat, Fv, s) == pytest.approx(mu_fd, rel=1e-7)
    P = first_piola(mat, Fv, s)
    scale = np.abs(P).max()
    for i in range(2):
        for j in range(2):
            dF = np.zeros((2, 2))
            dF[i, j] = h
            P_fd = (_psi(mat, Fv + dF, s) - _psi(mat, Fv - dF, s)) / (2 * h)
            assert P[i, j] == pytest.approx(P_fd, abs=1e-7 * scale), (i, j)


def test_theory_piola_equals_the_law_derivative():
    """theory.py writes P out for F = diag(a, l) (an independent reference); it equals the law's UFL P."""
    for gamma, eps in ((0.1, 10.0), (5.0, 10.0), (0.1, 1e3)):
        mat = Hydrogel(gamma, 24.2, eps, 1e-4, 1.01, 0.1)
        for e in (1e-5, -0.03, 0.1):
            pxx = _undrained_pxx(mat, e)  # at the l with P_yy = 0
            a = 1 + e

            def pyy(l_, mat=mat, a=a):
                return first_piola(mat, np.diag([a, l_]), mat.s0)[1, 1]

            lam = brentq(pyy, 0.2, 5.0, xtol=1e-15, rtol=1e-15)
            P = first_piola(mat, np.diag([a, lam]), mat.s0)
            assert pxx == pytest.approx(P[0, 0], rel=1e-9, abs=1e-13)  # the same root, found twice
            assert abs(P[0, 1]) < 1e-14 and abs(P[1, 0]) < 1e-14


def test_constrained_layer_reference_value():
    """l = 4.887 at mu_bar = 0 for gamma = 0.1 (docs/validation.md, section 1: closed form of eqs. 3.3-3.4
    with F = diag(1, l)); zero traction and mu = mu_bar there."""
    mat = Hydrogel(shear_modulus=0.1, **PAPER)
    lam = constrained_layer_stretch(mat, 0.0)
    assert lam == pytest.approx(4.887, abs=5e-4)
    s = constrained_layer_fluid(mat, lam)
    Pyy = _evaluate(lambda m, F, s_: ufl.diff(free_energy(m, F, s_), F)[1, 1], mat, [[1, 0], [0, lam]], s)
    assert abs(Pyy) < 1e-10
    assert abs(first_piola(mat, np.diag([1.0, lam]), s)[1, 1]) < 1e-10
    assert chemical_potential(mat, np.diag([1.0, lam]), s) == pytest.approx(0.0, abs=1e-9)


def test_one_parameter_declaration_feeds_config_record_and_summary():
    """The law's params are config's material keys (defaults, ranges, film overrides), the fields of its
    Material record, and what the summary lists per material."""
    assert LAWS.get("hydrogel") is HYDROGEL
    cfg = config.resolve({})
    assert cfg["material"]["law"] is None and config.law(cfg) is HYDROGEL  # unset: the default law
    assert config.law(config.resolve({"material": {"law": "hydrogel"}})) is HYDROGEL
    for name, key in HYDROGEL.params.items():
        assert config.schema()["material"][name] is key
        assert cfg["material"][name] == key.default
        assert config.schema()["material"]["film"][name].default is None
        assert key.doc and key.check is not None
    assert [f.name for f in dataclasses.fields(Hydrogel)] == list(HYDROGEL.params)
    mat = HYDROGEL.material(config.substrate_parameters(cfg))
    assert mat == Hydrogel(**{k: cfg["material"][k] for k in HYDROGEL.params})
    assert list(mat.as_dict()) == list(HYDROGEL.params)
    with pytest.raises(config.ConfigError, match="material.preswelling"):
        config.resolve({"material": {"preswelling": 1.0}})
    with pytest.raises(config.ConfigError, match="material.law"):
        config.resolve({"material": {"law": "rubber"}})
