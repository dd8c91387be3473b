"""Extending hydrobuckle from outside app/: a stability criterion, a material law, a loading and a history
column, each registered by test code alone (no edit under app/), go through the config schema, validation and a
run. Each is checked against a built-in path that computes the same thing another way. A toy geometry kind is
tested the same way in tests/test_geometry_kinds.py."""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from cases import swelling_case
from conftest import read_csv, run_to_end, small_bilayer
from dolfinx import fem

from app import config, factory, fem_utils
from app.model import history, loading, material
from app.model.hydrogel import HydrogelLaw
from app.onset import criteria
from app.schema import ConfigError, gt, key
from app.workflows.run import simulate


class Fast(criteria.Criterion):
    """A toy criterion: K with the step stability.fast_tau, i.e. the built-in "rate" under a key of its own
    (and the Newton factor may never screen it)."""

    name = "fast"
    doc = "fast (K with stability.fast_tau)"
    keys = {"fast_tau": key(float, 1.0e-3, gt(0), "criterion = fast only: step of K [s]")}

    def operator(self, problem, params):
        return criteria.CRITERIA.get("rate").operator(problem, {"tau": params["fast_tau"]})


class SlowGel(HydrogelLaw):
    """A toy law: the hydrogel with every flux dissipating twice as much (mobility / 2 inside the law)."""

    name = "slow_gel"
    material_name = "SlowGel"

    def dissipation(self, dQ, C_n, s_n, tau, p):
        J0, M = p.preswelling, p.mobility
        return ufl.inner(C_n * dQ, dQ) / (2 * tau * J0 ** (1.0 / 3.0) * (M / 2) * s_n)


class RateSwelling(loading.Swelling):
    """A toy loading: the surface chemical potential rises at ``loading.mu_rate`` [MPa/s] from the surface
    material's mu0 until it reaches ``loading.chemical_potential``, then is held: the built-in swelling ramp
    with ramp_time = (chemical_potential - mu0) / mu_rate, written another way."""

    name = "rate_swelling"
    keys = {"chemical_potential": loading.RAMP_KEYS["chemical_potential"],
            "mu_rate": key(float, 1.0, gt(0), "rate_swelling only: d mu_bar / dt during the rise [MPa/s]")}

    def mu_bar(self, t: float) -> float:
        return min(self.mu_start + self.params["mu_rate"] * max(t, 0.0), self.params["chemical_potential"])

    def kinks(self) -> list[float]:
        return [(self.params["chemical_potential"] - self.mu_start) / self.params["mu_rate"]]


class SolidUptake:
    """A toy history column: the fluid the solid has taken up, from the displacement alone. Before wrinkling
    the bilayer swells laterally uniformly, and P_yy = 0 in each cell ties its content to its stretch:
    s(l) = l J0 - 1 + gamma/(eps J0) (J0^(2/3) l - 1/l) (tests/test_physics.py derives it); its integral never
    reads the flux dofs."""

    columns = ("solid_uptake_mm2",)

    def __init__(self):
        self.name, self.doc, self._forms = "solid_uptake", "fluid taken up, from the displacement", {}

    def applies(self, p) -> bool:
        return p.domain.geometry.dim == 2

    def values(self, p, t: float) -> dict:
        if id(p) not in self._forms:
            u_n, _ = ufl.split(p.state)
            F = ufl.Identity(2) + ufl.grad(u_n)
            m, lam = p.mat, F[1, 1]
            s = ufl.det(F) * m.preswelling - 1 + m.shear_modulus / (m.penalty * m.preswelling) * (
                m.preswelling ** (2 / 3) * lam - 1 / lam)
            self._forms[id(p)] = fem.form(s * p.dx_coupling)  # one point per cell, as the penalty
        return {"solid_uptake_mm2": fem_utils.assemble_scalar(self._forms[id(p)], p.comm)}


@pytest.fixture
def solid_uptake():
    group = history.HISTORY.register(SolidUptake())
    yield group
    history.HISTORY.unregister(group.name)


@pytest.fixture
def rate_swelling():
    kind = loading.LOADINGS.register(RateSwelling)
    yield kind
    loading.LOADINGS.unregister(kind.name)


@pytest.fixture
def fast():
    crit = criteria.CRITERIA.register(Fast())
    yield crit
    criteria.CRITERIA.unregister(crit.name)


@pytest.fixture
def slow_gel():
    law = material.LAWS.register(SlowGel())
    yield law
    material.LAWS.unregister(law.name)


def test_a_registered_criterion_runs_like_the_matrix_it_uses(fast, shared_tmp, comm):
    """stability.criterion = fast with fast_tau = 0.02 s finds the onset of rate with tau = 0.02 s (the same
    matrix built through the registry): the same bracket and g_c (bit for bit serially); summary.json names
    it with its key."""
    schema = config.schema()["stability"]
    assert "fast" in schema["criterion"].doc and "fast_tau" in schema
    with pytest.raises(ConfigError, match="stability.fast_tau"):
        swelling_case("stability.criterion=fast", "stability.fast_tau=-1")
    toy = simulate(swelling_case("stability.criterion=fast", "stability.fast_tau=0.02", "stability.screening=exact",
                                 "stability.error_estimate=false"), shared_tmp / "fast", comm, progress=False)
    ref = simulate(swelling_case("stability.criterion=rate", "stability.tau=0.02", "stability.screening=exact",
                                 "stability.error_estimate=false"), shared_tmp / "rate", comm, progress=False)
    assert toy["status"] == ref["status"] == "buckled"
    assert toy["critical"]["criterion"] == {"name": "fast", "fast_tau": 0.02}
    # bit for bit serially; on 2 ranks MUMPS' parallel factorization leaves run-to-run roundoff (measured on
    # Debian 13: brackets 1e-15 apart between two runs; tests/test_screening.py saw up to 2.7e-10)
    tight = 0.0 if comm.size == 1 else 1e-9
    assert toy["critical"]["bracket"] == pytest.approx(ref["critical"]["bracket"], rel=tight, abs=0.0)
    assert toy["critical"]["growth_mm"] == pytest.approx(ref["critical"]["growth_mm"], rel=tight, abs=0.0)


def test_a_registered_law_runs_like_the_law_it_restates(slow_gel, shared_tmp, comm):
    """material.law = slow_gel at mobility M is the hydrogel at mobility M/2 (the same equations written
    another way): the same onset time and growth, to the roundoff of two compiled kernels."""
    with pytest.raises(ConfigError, match="material.law"):
        swelling_case("material.law=no_such_law")
    m = swelling_case()["material"]["mobility"]
    toy = simulate(swelling_case("material.law=slow_gel", "stability.error_estimate=false"), shared_tmp / "toy",
                   comm, progress=False)
    ref = simulate(swelling_case(f"material.mobility={m / 2}", "stability.error_estimate=false"),
                   shared_tmp / "ref", comm, progress=False)
    assert toy["status"] == ref["status"] == "buckled"
    assert toy["critical"]["time"] == pytest.approx(ref["critical"]["time"], rel=1e-6)
    assert toy["critical"]["growth_mm"] == pytest.approx(ref["critical"]["growth_mm"], rel=1e-6)


def test_a_registered_loading_runs_like_the_ramp_it_restates(rate_swelling, comm):
    """loading.kind = rate_swelling at mu_rate = (0 - mu0) / 0.8 s is the built-in swelling with ramp_time =
    0.8 s: the same kink, and at each (fixed) step the same growth, fluid volume and inflow at each, to the
    roundoff of the two ways mu_bar(t) is written."""
    with pytest.raises(ConfigError, match="loading.mu_rate"):
        swelling_case("loading.kind=rate_swelling", "loading.mu_rate=0")
    base = ("stability.enabled=false", "time.end=1.2", "time.adaptive=false", "time.dt_initial=0.02")
    mu0 = factory.layer_materials(swelling_case(*base))["film"].mu0
    assert mu0 < 0.0
    _, _, toy = run_to_end(swelling_case(*base, "loading.kind=rate_swelling", f"loading.mu_rate={-mu0 / 0.8!r}"),
                           comm)
    _, _, ref = run_to_end(swelling_case(*base, "loading.ramp_time=0.8"), comm)
    # fixed steps: with adaptive ones the proposals read error estimates that carry the roundoff of mu_bar, and
    # the step ends drift apart (measured: 5e-12 past the kink, 2e-10 at t = 1.2 s)
    assert [r.time for r in toy] == [r.time for r in ref]
    assert any(r.time == pytest.approx(0.8, rel=1e-12) for r in toy)  # the toy's kink is a step's end
    assert len(toy) > 20 and toy[-1].growth_mm > 0.0
    for column in ("growth_mm", "fluid_volume", "inflow", "mu_bar"):
        got, want = [getattr(r, column) for r in toy], [getattr(r, column) for r in ref]
        scale = max(abs(v) for v in want)  # measured serially: at most 5.2e-15 of the column's largest value
        assert got == pytest.approx(want, rel=0.0, abs=1e-12 * scale), column


def test_a_registered_history_column_is_written_like_the_balance_it_restates(solid_uptake, shared_tmp, comm):
    """A history column registered from test code appears in history.csv after the built-in model columns and
    before the onset tracker's, and its values obey the fluid balance: the uptake computed from the
    displacement alone minus its initial value equals the stepper's inflow through the top, step by step
    (tests/test_physics.py measured 3.7e-14 of the final inflow)."""
    out = shared_tmp / "uptake"
    summary = simulate(small_bilayer(**{"time.end": 1.2, "stability.enabled": "true"}), out, comm, progress=False)
    assert summary["status"] == "buckled"  # it stops at the onset: every state before it is laterally uniform
    rows = read_csv(out / "history.csv")
    names = list(rows[0])
    assert names.index("energy") < names.index("solid_uptake_mm2") < names.index("negative_eigenvalues")
    uptake = np.array([float(r["solid_uptake_mm2"]) for r in rows])
    inflow = np.array([float(r["inflow"]) for r in rows])
    fluid = np.array([float(r["fluid_volume"]) for r in rows])
    assert uptake[0] == pytest.approx(fluid[0], rel=2e-14)  # the stress-free reference: s(1) = s0 in every cell
    assert inflow[-1] > 10 * fluid[0]  # fluid really entered
    assert np.abs((uptake - uptake[0]) - inflow).max() < 1e-13 * inflow[-1]
