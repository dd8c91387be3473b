"""The drained (and undrained) onset of a homogeneous swelling gel layer against its linear stability
theory (Kang & Huang 2010's problem for this free energy; app.model.theory, derived in
docs/theory/drained-onset.md without the FE code).

A laterally constrained layer on a roller base swells quasi-statically: the mobility is raised so that
diffusion is fast against the ramp of the surface chemical potential (only the product ramp_time x
mobility matters, checked in docs/validation.md), so the state is homogeneous and its thickness stretch
l = 1 + growth/H is that of the theory. The layer loses surface stability at the stretch where the
half-space's zero-speed surface wave exists for the drained (or undrained) incremental moduli.

Tolerances come from the convergence study in docs/validation.md ("Surface instability of a swelling
layer"): on this mesh (h = H/20) the FE onset lies above the theory by 0.77% (drained; undrained 0.94%) and converges to it
from above as h -> 0 (0.14% at H/40, 0.003% at H/80); the quasi-static error at ramp_time x mobility = 1e4
is below 1e-4. So: theory <= FE <= theory (1 + 1.5%).
"""

import pytest

from app import config
from app.model import theory
from app.factory import layer_materials
from app.workflows.run import simulate

H, W = 0.1, 0.01


def layer(h: float, *overrides, chi: float = 0.1) -> dict:
    user = {"geometry": {"length": 0.1, "substrate_thickness": H - W, "film_thickness": W},
            "mesh": {"element_size": h, "film_layers": max(1, round(W / h)), "substrate_grading": 1.0},
            "material": {"mobility": 1.0, "interaction": chi, "film": {"modulus_ratio": 1.0}},
            "loading": {"ramp_time": 1.0e4, "chemical_potential": 0.0},
            "time": {"end": 1.0e4, "dt_initial": 0.1, "dt_max": 200.0},
            "output": {"fields": False, "plot": False}, "stability": {"error_estimate": False}}
    return config.resolve(user, list(overrides))


def onset_stretch(summary: dict) -> float:
    return 1.0 + summary["critical"]["growth_mm"] / H


@pytest.mark.parametrize("criterion", ["drained", "undrained"])
def test_onset_stretch_of_a_swelling_layer_matches_the_surface_instability_theory(shared_tmp, comm, criterion):
    cfg = layer(0.005, f"stability.criterion={criterion}")
    r = simulate(cfg, shared_tmp / criterion, comm, progress=False)
    mat = layer_materials(cfg, ["substrate"])["substrate"]
    lam_c = theory.surface_critical_stretch(mat, drained=criterion == "drained")
    assert r["status"] == "buckled"
    assert lam_c <= onset_stretch(r) <= lam_c * 1.015


def test_a_layer_that_is_drained_unstable_but_undrained_stable(shared_tmp, comm):
    """chi = 0.5: the drained onset (l = 2.94) lies before the equilibrium stretch (3.24), the undrained one
    (3.36) beyond it. The default criterion finds the onset; the undrained test never does, and the
    drained run says that the undrained test is still stable there."""
    runs = {c: simulate(layer(0.005, f"stability.criterion={c}", chi=0.5), shared_tmp / c, comm, progress=False)
            for c in ("drained", "undrained")}
    mat = layer_materials(layer(0.005, chi=0.5), ["substrate"])["substrate"]
    lam_d, lam_u = theory.surface_critical_stretch(mat), theory.surface_critical_stretch(mat, drained=False)
    lam_eq = theory.constrained_layer_stretch(mat, 0.0)
    assert lam_d < lam_eq < lam_u  # the premise, from the theory alone
    assert runs["drained"]["status"] == "buckled"
    assert lam_d <= onset_stretch(runs["drained"]) <= lam_d * 1.015
    assert runs["drained"]["critical"]["other_limits"]["undrained_negative_eigenvalues"] == 0
    assert runs["undrained"]["status"] == "stable"
    assert 1 + runs["undrained"]["final"]["growth_mm"] / H == pytest.approx(lam_eq, rel=1e-3)
