"""Solvers built from forms: Newton (SNES), time stepping, stability (inertia, SLEPc)."""
