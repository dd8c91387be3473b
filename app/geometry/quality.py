"""Element quality of quadrilateral meshes."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from app import fem_utils


def scaled_jacobians(domain) -> np.ndarray:
    """Per owned cell, the minimum over its corners of sin(angle between the two edges at the corner)
    (the scaled Jacobian: 1 for rectangles, -> 0 for degenerate cells, < 0 for inverted ones)."""
    x = domain.geometry.x[:, :2]
    n = fem_utils.num_owned_cells(domain)
    cells = fem_utils.cell_geometry_nodes(domain)[:n]
    if n == 0:
        return np.empty(0)
    # dolfinx quadrilateral node order is tensor-product: (0,1,3,2) walks the boundary
    ring = x[cells[:, [0, 1, 3, 2]]]
    out = np.full(n, np.inf)
    for k in range(4):
        p, nxt, prv = ring[:, k], ring[:, (k + 1) % 4], ring[:, (k - 1) % 4]
        e1, e2 = nxt - p, prv - p
        cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        out = np.minimum(out, cross / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)))
    # orientation-independent: a consistently clockwise mesh has all values negative
    return out if np.median(out) >= 0 else -out


def min_scaled_jacobian(domain) -> float:
    local = scaled_jacobians(domain)
    return domain.comm.allreduce(float(local.min()) if local.size else np.inf, op=MPI.MIN)
