"""MUMPS factorizations configured through PETSc options under a private prefix.

Every direct solve here (Newton's linear solves, the exact inertia test, the eigen-solve's
shift-invert) is a ``preonly`` KSP whose PC applies a MUMPS factorization. PETSc reads solver
options from one global table, so each solver sets its own under a prefix of its own (several solvers
coexist in one process) and removes them once they have been read: the table holds 512 entries per
process, which many solvers in one process would fill. MUMPS reads its controls at the first
(symbolic) factorization, so "read" means after the first factorization, not after setFromOptions.
"""

from __future__ import annotations

import itertools

from petsc4py import PETSc

# ICNTL(24) = 1: null-pivot detection; ICNTL(13) = 1: no ScaLAPACK on the root node, without which
# MUMPS cannot count negative pivots in parallel. Both are needed for an exact inertia.
INERTIA = {24: 1, 13: 1}

_ids = itertools.count()


def direct(factorization: str = "cholesky", icntl: dict | None = None, scope: str = "") -> dict:
    """Options of a KSP that only applies a MUMPS factorization: "cholesky" (LDL^T, valid also for an
    indefinite symmetric K) or "lu". ``scope`` is the sub-prefix of that KSP under the solver's own
    (e.g. "st_" for the KSP inside a SLEPc spectral transformation)."""
    opts = {"ksp_type": "preonly", "pc_type": factorization, "pc_factor_mat_solver_type": "mumps"}
    opts.update({f"mat_mumps_icntl_{k}": v for k, v in (INERTIA if icntl is None else icntl).items()})
    return {scope + key: value for key, value in opts.items()}


class PrefixedOptions:
    """Options in PETSc's table under a fresh prefix ``<stem><n>_``; :meth:`clear` removes them."""

    def __init__(self, stem: str, settings: dict):
        self.prefix = f"{stem}{next(_ids)}_"
        opts = PETSc.Options()
        for key, value in settings.items():
            opts[self.prefix + key] = value
        self._keys = [self.prefix + key for key in settings]

    def clear(self) -> None:
        """Remove the options (once every one has been read); safe to call again."""
        opts = PETSc.Options()
        for key in self._keys:
            if opts.hasName(key):
                opts.delValue(key)
        self._keys = []
