"""The iterative linear solver option gives the direct solver's answers; the stability screen falls back
to exact tests where the Newton solver has no LDL^T factor."""

import pytest
from conftest import small_bilayer, time_stepper

from app.workflows.run import simulate


def test_iterative_newton_solves_match_direct(shared_tmp, comm):
    runs = {}
    for linear in ("direct", "iterative"):
        cfg = small_bilayer(**{"solver.linear": linear, "time.end": 0.15, "stability.error_estimate": "false",
                               "stability.criterion": "undrained"})  # a criterion the Newton factor may screen
        runs[linear] = simulate(cfg, shared_tmp / linear, comm, progress=False)
    direct, iterative = runs["direct"], runs["iterative"]
    assert iterative["steps"] == direct["steps"]
    assert iterative["final"]["growth_mm"] == pytest.approx(direct["final"]["growth_mm"], rel=1e-7)
    assert iterative["linear_solver"]["krylov_iterations"] > iterative["steps"]
    # no factor to screen with: every step is tested exactly
    assert iterative["stability_tests"]["screened_steps"] == 0
    assert iterative["stability_tests"]["exact_tests"] >= iterative["steps"] + 1
    assert direct["stability_tests"]["screened_steps"] >= direct["steps"] - 1


def test_lu_factorization_falls_back_to_exact_stability_tests(shared_tmp, comm):
    cfg = small_bilayer(**{"solver.factorization": "lu", "time.end": 0.1, "stability.error_estimate": "false",
                           "stability.criterion": "undrained"})
    s = simulate(cfg, shared_tmp / "lu", comm, progress=False)
    assert s["stability_tests"]["screened_steps"] == 0
    assert s["stability_tests"]["exact_tests"] >= s["steps"] + 1


def test_solvers_leave_petsc_options_table_as_they_found_it(comm):
    """PETSc keeps at most 512 options per process: a study or a test session creates hundreds of
    solvers, so each must remove its own options once its linear solver is set up."""
    from petsc4py import PETSc

    from app import factory

    cfg = small_bilayer(**{"time.end": 0.02})
    p = factory.problem(cfg, comm)
    before = len(PETSc.Options().getAll())
    for linear in ("direct", "iterative") * 3:
        cfg["solver"]["linear"] = linear
        st = time_stepper(p, cfg)
        st.advance()
        assert len(PETSc.Options().getAll()) == before
        st.destroy()
