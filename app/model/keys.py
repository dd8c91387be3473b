"""The [mesh] table's quadrature keys: how the forms are integrated (app.model.problem.Discretization)."""

from __future__ import annotations

from app.schema import Key, in_closed, key

QUADRATURE: dict[str, Key] = {
    "quadrature_degree": key(int, 2, in_closed(1, 8), "quadrature degree of the cell integrals"),
    "coupling_quadrature_degree": key(int, 1, in_closed(0, 8),
                                      "quadrature degree of the volumetric penalty term (0/1 = one point: "
                                      "selective reduced integration)"),
}
