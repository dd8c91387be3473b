"""Solvers own their work data: the stability analyzer tests the problem's converged state on
coefficients of its own (it never writes the problem's unknown or step size), and its K is the one
assembled from the problem's own forms at zero increment, bit for bit (the same compiled kernel)."""

import numpy as np
from conftest import run_to_end, small_bilayer
from dolfinx.fem import petsc as fem_petsc

from app import fem_utils
from app.onset.criteria import CRITERIA


def _form_signature(compiled) -> str:
    """The signature of a compiled form: equal signatures, the same generated kernel (one JIT-cache entry)."""
    import cffi

    return cffi.FFI().string(compiled.ufcx_form.signature).decode()


def test_analyzer_k_is_the_problems_k_and_leaves_the_problem_alone(comm):
    cfg = small_bilayer(**{"time.end": 0.05, "stability.enabled": "false"})
    p, _, _ = run_to_end(cfg, comm)  # a state with displacement and fluid
    tau = 0.01
    analyzer = CRITERIA.get("rate").analyzer(p, {"tau": tau})
    # the coefficients are the analyzer's own, the compiled kernel the problem's (no second JIT compile)
    assert _form_signature(analyzer.op.k.form) == _form_signature(p.forms.hessian)
    w, step_tau = p.w.x.array.copy(), float(p.tau.value)
    assert step_tau != tau
    nneg = analyzer.inertia()[0]
    analyzer.eigenpairs(2)
    assert np.array_equal(p.w.x.array, w) and float(p.tau.value) == step_tau
    assert nneg == 0

    # the reference: the problem's own Hessian form at zero increment with the stability tau
    p.w.x.array[:] = 0.0
    p.w.x.array[p.u_dofs] = p.state.x.array[p.u_dofs]
    p.tau.value = tau
    A = fem_petsc.create_matrix(p.forms.hessian)
    fem_utils.assemble_matrix_into(A, p.forms.hessian, p.bcs)
    analyzer.assemble()
    A.axpy(-1.0, analyzer.op.A)
    assert A.norm() == 0.0
    A.destroy()
    analyzer.destroy()
