"""Results pinned before the restructure (tests/pinned_cases.py): the default bilayer's g_c, N_c and
history on a coarse mesh, the tube's, and the mechanical compression case, serially and on 2 ranks.
Equal to 1e-10 relative (the eigenvalues near zero to 1e-8 of the largest reported one)."""

import json

import numpy as np
import pytest
from pinned_cases import CASES, PINNED, compute


@pytest.mark.parametrize("name", sorted(CASES))
def test_results_are_the_pinned_ones(name, shared_tmp, comm):
    ref = json.loads(PINNED.read_text())[name]
    got = compute(name, shared_tmp / name, comm)
    assert got["status"] == ref["status"] and got["steps"] == ref["steps"]
    for key in ("wrinkle_count", "first_mode_wrinkle_count"):
        assert got["critical"][key] == ref["critical"][key], key
    for key in ("time", "growth_mm", "lambda_min_before", "lambda_min_after"):
        assert got["critical"][key] == pytest.approx(ref["critical"][key], rel=1e-10), key
    assert got["critical"]["bracket"] == pytest.approx(ref["critical"]["bracket"], rel=1e-12)
    scale = max(abs(v) for v in ref["modes"])
    assert np.allclose(got["modes"], ref["modes"], rtol=1e-8, atol=1e-8 * scale)
    for col, values in ref["history"].items():
        a, b = np.array(got["history"][col]), np.array(values)
        assert a.shape == b.shape, col
        assert np.allclose(a, b, rtol=1e-10, atol=1e-10 * max(np.abs(b).max(), 1e-300)), col
