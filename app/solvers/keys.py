"""The [time] and [solver] keys: the time stepper's step control (app.solvers.step_control.TimeSettings) and
Newton's tolerances and linear solves (app.solvers.newton.SolverSettings)."""

from __future__ import annotations

from app.schema import Key, ge, gt, in_closed, in_open, key, one_of

TIME: dict[str, Key] = {
    "end": key(float, 10.0, gt(0), "[s]"),
    "dt_initial": key(float, 1.0e-3, gt(0), "[s]"),
    "dt_max": key(float, 5.0, gt(0), "[s]"),
    "dt_min": key(float, 1.0e-9, gt(0), "smallest step before the run is declared failed [s]"),
    "tolerance": key(float, 5.0e-4, gt(0), "local error tolerance (fluid content) of the adaptive step"),
    "adaptive": key(bool, True, None, "false: fixed steps of dt_initial (cut back only on divergence)"),
    "controller": key(str, "predictive", one_of("predictive", "elementary"),
                      "the adaptive step's rule: elementary = dt 0.9 sqrt(tol/err); predictive = the same, "
                      "slowed by the growth of err/dt^2 over the last step while it grows (fewer rejected steps)"),
    "max_steps": key(int, 100000, ge(1), "stop after this many accepted steps (status 'failed', exit code 1)"),
    "stop_at_equilibrium": key(float, 0.0, ge(0.0),
                               "end the run (status equilibrium) once the relative fluid uptake rate "
                               "|dV/dt| t / |V - V(0)| after the last loading kink is below this; 0 = off"),
}

SOLVER: dict[str, Key] = {
    "rtol": key(float, 1.0e-9, in_open(0.0, 1.0), "Newton relative residual tolerance"),
    "atol": key(float, 1.0e-11, gt(0), "Newton absolute residual tolerance"),
    "max_it": key(int, 25, in_closed(1, 1000), "Newton iterations per step"),
    "factorization": key(str, "cholesky", one_of("cholesky", "lu"),
                         "direct solver of each Newton step (MUMPS LDL^T or LU)"),
    "linear": key(str, "direct", one_of("direct", "iterative"),
                  "Newton's linear solves: MUMPS factorization, or preconditioned Krylov (large meshes)"),
    "ksp_rtol": key(float, 1.0e-10, in_open(0.0, 1.0), "relative tolerance of the iterative linear solves"),
    "ksp_max_it": key(int, 2000, ge(1), "iterations per iterative linear solve"),
    "reuse": key(bool, True, None,
                 "keep a solve's LDL^T factor of K for its later Newton iterations while the residual falls "
                 "fast enough (modified Newton; direct solves); false: a factorization every iteration"),
    "reuse_rate": key(float, 0.03, in_open(0.0, 1.0),
                      "reuse only: a fresh factor once an iteration reduced the residual by less than this factor"),
}
