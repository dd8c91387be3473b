"""gmsh bilayer builder: layer areas, boundary lengths, element layers and grading."""

import numpy as np
import pytest
import ufl
from dolfinx import fem

from app import fem_utils
from app.geometry.bilayer import tagged_mesh
from meshes import bilayer


def _measure(tm, comm, dim_measure):
    one = fem.Constant(tm.mesh, 1.0)
    return fem_utils.assemble_scalar(fem.form(one * dim_measure), comm)


@pytest.mark.parametrize("grading", [1.0, 1.15, 1.4])
def test_bilayer_layers_and_boundaries(comm, grading):
    L, H, w = 0.4, 0.2, 0.012
    tm = tagged_mesh(comm, L, H, w, element_size=0.02, film_layers=3, grading=grading)
    dx = ufl.Measure("dx", domain=tm.mesh, subdomain_data=tm.cell_tags)
    ds = ufl.Measure("ds", domain=tm.mesh, subdomain_data=tm.facet_tags)
    assert _measure(tm, comm, dx(tm.cell_names["film"])) == pytest.approx(L * w, rel=1e-12)
    assert _measure(tm, comm, dx(tm.cell_names["substrate"])) == pytest.approx(L * H, rel=1e-12)
    for name, length in (("top", L), ("bottom", L), ("left", H + w), ("right", H + w)):
        assert _measure(tm, comm, ds(tm.facet_names[name])) == pytest.approx(length, rel=1e-12)
    assert fem_utils.num_global_cells(tm.mesh) == 20 * (3 + tm.info["substrate_layers"])
    assert tm.info["film_element_aspect"] == pytest.approx(0.02 / (w / 3))


def test_substrate_heights_are_graded_and_fill_the_substrate():
    h = bilayer.substrate_layer_heights(0.5, 0.0025 * 1.15, 1.15)
    assert h.sum() == pytest.approx(0.5, rel=1e-14)
    assert np.allclose(h[1:] / h[:-1], 1.15)
    assert h[0] == pytest.approx(0.0025 * 1.15, rel=0.1)
    uniform = bilayer.substrate_layer_heights(0.1, 0.01, 1.0)
    assert len(uniform) == 10 and np.allclose(uniform, 0.01)
