"""Extending hydrobuckle from outside app/: a stability criterion and a material law, each registered by
test code alone (no edit under app/), go through the config schema, validation, the run and summary.json.
Each is checked against a built-in path that computes the same thing another way. A toy geometry kind is
tested the same way in tests/test_geometry_kinds.py."""

from __future__ import annotations

import pytest
import ufl
from cases import swelling_case

from app import config
from app.model import material
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
