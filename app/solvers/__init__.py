"""Solvers built from forms, boundary conditions and their own work data: Newton (SNES), MUMPS options,
step-size control, time stepping, stability (inertia, SLEPc)."""
