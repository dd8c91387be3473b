"""fields.xdmf and mode.xdmf open as one dataset: one grid per output time carrying every field,
times equal to history.csv's output steps, and values equal to the solver's fields (checked against
independent computations from the file's own mesh and data), serially and on 2 ranks; a field registered
from test code (app/model/fields.py) is written like the built-in ones."""

import csv
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import ufl
from conftest import small_bilayer

from app import factory
from app.model.fields import FIELDS, Field
from app.workflows.run import simulate

h5py = pytest.importorskip("h5py")


def _grids(path):
    domain = ET.parse(path).getroot().find("Domain")
    top = domain.findall("Grid")
    assert len(top) == 1 and top[0].get("CollectionType") == "Temporal"  # one dataset, not a multiblock
    return top[0].findall("Grid")


def _data(h5, item):
    name = item.find("DataItem").text.split(":", 1)[1]
    return np.asarray(h5[name])


def _quad_centre_jacobians(X, cells):
    """d(x)/d(xi, eta) at the centre of each counter-clockwise quadrilateral: shape (cells, 2, 2)."""
    x = X[cells]  # (cells, 4, 2)
    d_xi = 0.25 * (-x[:, 0] + x[:, 1] + x[:, 2] - x[:, 3])
    d_eta = 0.25 * (-x[:, 0] - x[:, 1] + x[:, 2] + x[:, 3])
    return np.stack([d_xi, d_eta], axis=2)


def _areas(X, cells):
    x, y = X[cells][..., 0], X[cells][..., 1]
    return 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))


def test_fields_and_mode_are_one_dataset_with_the_solver_values(shared_tmp, comm):
    every = 3
    cfg = small_bilayer(**{"time.end": 1.0, "output.fields": "true", "output.every": every, "stability.modes": 2})
    out = shared_tmp / "xdmf"
    problem = factory.problem(cfg, comm)
    summary = simulate(cfg, out, comm, problem=problem, progress=False)
    assert summary["status"] == "buckled"
    with open(out / "history.csv") as f:
        history = list(csv.DictReader(f))
    # every 3rd step, and the final state also where its step is not one of them
    output_rows = [r for r in history if int(r["step"]) % every == 0 or r is history[-1]]
    assert float(output_rows[-1]["time"]) == summary["final"]["time"]

    grids = _grids(out / "fields.xdmf")
    assert len(grids) == len(output_rows)
    names = ["displacement", "fluid_content", "chemical_potential", "J", "flux", "stress_xx", "stress_yy", "stress_xy",
             "stress_min_principal"]  # docs/outputs.md
    with h5py.File(out / "fields.h5", "r") as h5:
        for grid, row in zip(grids, output_rows):
            assert float(grid.find("Time").get("Value")) == pytest.approx(float(row["time"]), rel=1e-14, abs=1e-300)
            attrs = {a.get("Name"): a for a in grid.findall("Attribute")}
            assert sorted(attrs) == sorted(names)
            X = _data(h5, grid.find("Geometry"))
            cells = _data(h5, grid.find("Topology"))
            area = _areas(X, cells)
            # fluid content per cell, summed over the reference cells, is history's fluid volume
            s = _data(h5, attrs["fluid_content"])[:, 0]
            assert np.sum(s * area) == pytest.approx(float(row["fluid_volume"]), rel=1e-12)
            # J per cell equals det F at the cell centre from the file's own nodal displacement
            u = _data(h5, attrs["displacement"])[:, :2]
            dX = _quad_centre_jacobians(X, cells)
            du = _quad_centre_jacobians(u, cells)
            F = np.eye(2) + du @ np.linalg.inv(dX)
            assert np.allclose(_data(h5, attrs["J"])[:, 0], np.linalg.det(F), rtol=1e-12, atol=0)
            sxx, syy, sxy, smin = (_data(h5, attrs[k])[:, 0]
                                   for k in ("stress_xx", "stress_yy", "stress_xy", "stress_min_principal"))
            # the smaller principal stress of [[sxx, sxy], [sxy, syy]]
            assert np.allclose(smin, np.linalg.eigvalsh(np.stack([np.stack([sxx, sxy], 1),
                                                                  np.stack([sxy, syy], 1)], 1))[:, 0], atol=1e-12)
            if float(row["time"]) == 0.0:  # every layer starts stress-free in its own preswollen state
                assert np.abs(np.stack([sxx, syy, sxy])).max() < 1e-10
        # the last output time against the solver's final state, node by node (this rank's nodes)
        last = grids[-1]
        attrs = {a.get("Name"): a for a in last.findall("Attribute")}
        X = _data(h5, last.find("Geometry"))
        u_file = _data(h5, attrs["displacement"])[:, :2]
    assert int(output_rows[-1]["step"]) == summary["steps"]
    V = problem.V_u
    coords = V.tabulate_dof_coordinates()[:, :2]
    u_solver = problem.state.x.array[problem.u_dofs].reshape(-1, 2)
    order = {tuple(np.round(x, 12)): i for i, x in enumerate(X)}
    idx = np.array([order[tuple(np.round(x, 12))] for x in coords])
    assert np.allclose(u_file[idx], u_solver, rtol=0, atol=1e-14 * np.abs(u_solver).max())
    # the top's mean vertical displacement from the file is the history's growth (uniform top nodes)
    top = np.isclose(X[:, 1], X[:, 1].max())
    assert u_file[top, 1].mean() == pytest.approx(float(output_rows[-1]["growth_mm"]), rel=1e-2)

    (grid,) = _grids(out / "mode.xdmf")
    crit = json.loads((out / "summary.json").read_text())["critical"]
    assert float(grid.find("Time").get("Value")) == pytest.approx(crit["time"], rel=1e-14)
    attrs = {a.get("Name"): a for a in grid.findall("Attribute")}
    assert sorted(attrs) == ["critical_displacement", "mode"]
    with h5py.File(out / "mode.h5", "r") as h5:
        mode = _data(h5, attrs["mode"])
        assert np.abs(mode).max() == pytest.approx(1.0, rel=1e-14)  # normalized to max |u| = 1
        assert np.abs(_data(h5, attrs["critical_displacement"])).max() > 0


@pytest.fixture
def stretch_field():
    field = FIELDS.register(Field("stretch_trace", "tr(F^T F), per cell", "cell scalar",
                                  lambda st: ufl.tr(st.F.T * st.F)))
    yield field
    FIELDS.unregister(field.name)


def test_a_registered_field_is_written_with_the_others(stretch_field, shared_tmp, comm):
    """A field registered from test code (no edit of app/) is on every grid of fields.xdmf beside the
    built-in ones, with the value of its expression: tr(F^T F) at each cell centre, computed here from the
    file's own nodal displacement (as J is above)."""
    cfg = small_bilayer(**{"time.end": 0.5, "output.fields": "true", "output.every": 4,
                           "stability.enabled": "false"})
    out = shared_tmp / "toy-field"
    simulate(cfg, out, comm, progress=False)
    grids = _grids(out / "fields.xdmf")
    assert len(grids) >= 2
    with h5py.File(out / "fields.h5", "r") as h5:
        for grid in grids:
            attrs = {a.get("Name"): a for a in grid.findall("Attribute")}
            assert "stretch_trace" in attrs and "J" in attrs and len(attrs) == 10
            X, cells = _data(h5, grid.find("Geometry")), _data(h5, grid.find("Topology"))
            u = _data(h5, attrs["displacement"])[:, :2]
            F = np.eye(2) + _quad_centre_jacobians(u, cells) @ np.linalg.inv(_quad_centre_jacobians(X, cells))
            expected = np.einsum("cij,cij->c", F, F)
            assert np.allclose(_data(h5, attrs["stretch_trace"])[:, 0], expected, rtol=1e-12, atol=0)
        assert np.abs(expected - 2.0).max() > 1e-3  # the last grid is deformed: the check is not 2 = 2
