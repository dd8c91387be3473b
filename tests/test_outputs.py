"""Result files (app/io/output.py ResultWriter) and the closed-form references (app/model/theory.py).

References: the files an earlier run left in the directory (a new run must remove its result files
and nothing else); mode.xdmf/mode.h5 read back through PETSc's HDF5 viewer (mode_surface.csv must
hold the same mode, up to one positive normalization factor, and the same critical state); the mesh
of the surface written out by hand; the growth (mean u_y of the top, exact trapezoid rule for Q1);
and the plane-strain modulus of the linearized undrained hydrogel worked out by hand.
"""

import csv
import json
import math
import re

import numpy as np
import pytest
from mpi4py import MPI

from app import config
from app.model.hydrogel import Hydrogel
from app.io.output import RESULT_FILES, OutputSettings, ResultWriter
from app.workflows.run import simulate
from app.model.theory import film_wrinkling_strain, film_wrinkling_wavelength, plane_strain_modulus

SWELLING = {
    "geometry": {"length": 0.3, "substrate_thickness": 0.15, "film_thickness": 0.01},
    "mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
    "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
    "stability": {"error_estimate": False},
    "output": {"fields": False, "plot": False},
}


def _on_rank0(fn):
    comm = MPI.COMM_WORLD
    value = fn() if comm.rank == 0 else None
    return comm.bcast(value, root=0)


def test_a_new_run_removes_the_stale_results_of_an_earlier_one(shared_tmp, comm):
    """Run 1 (buckles; fields, plots, mode files) then, in the same directory, run 2 without the
    stability test, fields or plots: once run 2's writer exists, no result file of run 1 is left
    (summary.json last of all: a directory without it holds an unfinished run) and error-estimate/
    is gone; files that are not results stay. After run 2 only its own files exist."""
    out = shared_tmp / "run"
    first = config.resolve(SWELLING, ["geometry.length=0.15", "mesh.element_size=0.01", "output.fields=true",
                                      "output.plot=true"])
    assert simulate(first, out, comm, progress=False)["status"] == "buckled"
    produced = {name for name in RESULT_FILES if (out / name).is_file()}
    assert produced == set(RESULT_FILES)  # run 1 wrote every kind of result file
    if comm.rank == 0:
        (out / "error-estimate" / "time").mkdir(parents=True)
        (out / "error-estimate" / "time" / "summary.json").write_text("{}")
        (out / "notes.txt").write_text("mine")
    comm.barrier()

    second = config.resolve(SWELLING, ["geometry.length=0.15", "mesh.element_size=0.01", "time.end=0.2",
                                       "stability.enabled=false"])
    writer = ResultWriter(out, comm, second, OutputSettings.from_config(second))
    left = {name for name in RESULT_FILES if (out / name).exists()}
    assert left == {"config.toml"}
    assert config.load(out / "config.toml") == second
    assert not (out / "error-estimate").exists()
    assert (out / "notes.txt").read_text() == "mine"
    writer.close()

    s = simulate(second, out, comm, progress=False)
    assert s["status"] == "completed"
    assert {name for name in RESULT_FILES if (out / name).exists()} == {"summary.json", "history.csv", "config.toml"}
    assert json.loads((out / "summary.json").read_text())["status"] == "completed"
    with open(out / "history.csv") as f:
        header = next(csv.reader(f))
    assert "negative_eigenvalues" not in header  # run 2's columns, not run 1's


def _read_h5(path, name):
    """A dataset of a dolfinx HDF5 file through PETSc's HDF5 viewer (no h5py needed)."""
    from petsc4py import PETSc

    viewer = PETSc.Viewer().createHDF5(str(path), "r", comm=PETSc.COMM_SELF)
    vec = PETSc.Vec().create(PETSc.COMM_SELF)
    vec.setName(name)
    vec.load(viewer)
    data = vec.array.copy()
    vec.destroy()
    viewer.destroy()
    return data


def test_mode_surface_csv_holds_the_mode_and_state_of_mode_xdmf(shared_tmp, comm):
    out = shared_tmp / "mode"
    cfg = config.resolve(SWELLING)
    s = simulate(cfg, out, comm, progress=False)
    assert s["status"] == "buckled"
    crit = s["critical"]
    L, H, w = 0.3, 0.15, 0.01

    def read():
        with open(out / "mode_surface.csv") as f:
            header = f.readline().strip()
        data = np.loadtxt(out / "mode_surface.csv", delimiter=",", skiprows=1, ndmin=2)
        xdmf = (out / "mode.xdmf").read_text()
        names = dict(re.findall(r'Attribute Name="(\w+)".*?mode\.h5:(/Function/\w+/[\w.]+)', xdmf, re.S))
        mesh_path = re.search(r"mode\.h5:(/Mesh/[\w/]+/geometry)", xdmf).group(1)
        geometry = _read_h5(out / "mode.h5", mesh_path).reshape(-1, 2)
        mode = _read_h5(out / "mode.h5", names["mode"]).reshape(-1, 3)[:, :2]
        state = _read_h5(out / "mode.h5", names["critical_displacement"]).reshape(-1, 3)[:, :2]
        return header, data, geometry, mode, state

    header, data, X, mode, state = _on_rank0(read)
    assert header == "x,y,mode_ux,mode_uy,state_ux,state_uy"
    # the surface nodes of the top, each once: y = H + w, x = k h for k = 0..L/h (h = 0.005)
    nx = round(L / 0.005)
    assert data.shape == (nx + 1, 6)
    assert np.allclose(data[:, 1], H + w, atol=1e-12)
    assert np.allclose(np.sort(data[:, 0]), np.linspace(0, L, nx + 1), atol=1e-12)
    # the same nodes in mode.h5
    idx = [int(np.argmin(np.linalg.norm(X - p, axis=1))) for p in data[:, :2]]
    assert np.abs(X[idx] - data[:, :2]).max() < 1e-12
    # mode.xdmf: normalized to max |u| = 1; the csv: the same mode up to one positive factor
    assert np.abs(mode).max() == pytest.approx(1.0, rel=1e-14)
    surf = mode[idx]
    k = int(np.argmax(np.abs(surf)))
    factor = data[:, 2:4].flat[k] / surf.flat[k]
    assert factor > 0
    assert np.abs(data[:, 2:4] - factor * surf).max() <= 1e-10 * np.abs(data[:, 2:4]).max()
    # the critical state: identical displacements
    assert np.abs(data[:, 4:6] - state[idx]).max() <= 1e-14
    # the state is the unstable end of the bracket: its growth (mean u_y of the top, trapezoid rule,
    # exact for Q1) is g_c or slightly more, by at most the growth over the bracket width
    order = np.argsort(data[:, 0])
    x, uy = data[order, 0], data[order, 5]
    g_hi = float(np.sum(0.5 * (uy[1:] + uy[:-1]) * np.diff(x)) / L)
    with open(out / "history.csv") as f:
        rows = list(csv.DictReader(f))
    rate = max((float(b["growth_mm"]) - float(a["growth_mm"])) / (float(b["time"]) - float(a["time"]))
               for a, b in zip(rows[:-1], rows[1:]))
    lo, hi = crit["bracket"]
    assert crit["growth_mm"] <= g_hi * (1 + 1e-12)
    assert g_hi - crit["growth_mm"] <= 2 * rate * (hi - lo)
    # the mode's normal displacement along the top: its sign changes (k half-waves give k - 1 to
    # k + 1 of them) agree with the summary's wrinkle count of this mode (half-waves / 2)
    my = data[order, 3]
    changes = int(np.sum(np.sign(my[1:]) * np.sign(my[:-1]) < 0))
    assert abs(changes - 2 * crit["first_mode_wrinkle_count"]) <= 1


# --- theory.plane_strain_modulus --------------------------------------------------------------------
#
# Linearize P = dpsi/dF (plane strain, fluid content frozen at s0) about the stress-free reference
# F = 1, s = s0:
#   network  gamma/(2 J0) (J0^(2/3) F:F - 2 ln J):   d2/dF2 = gamma/J0 (J0^(2/3) d_ik d_jl + d_il d_jk)
#   coupling eps/(2 J0) (J J0 - 1 - s)^2:           d2/dF2 = eps J0 d_ij d_kl + eps (J0 - 1 - s0)(d_ij d_kl - d_il d_jk)
# With eq. 3.5, eps (J0 - 1 - s0) = -gamma (J0^(-1/3) - 1/J0), the tangent is isotropic with
#   mu = gamma J0^(-1/3),   lambda = eps J0 - gamma (J0^(-1/3) - 1/J0),
# and uniaxial in-plane stress (sigma_yy = 0, eps_zz = 0) gives E_bar = 4 mu (lambda + mu) / (lambda + 2 mu)
# (= 2 mu/(1 - nu) with nu = lambda / (2 (lambda + mu))).
# Default substrate (gamma = 0.1, eps = 10, J0 = 1.01): mu = 0.0996689, lambda = 10.09934,
# E_bar = 4 * 0.0996689 * 10.19901 / 10.29868 = 0.394817 MPa.


def _hand_modulus(gamma, eps, J0):
    mu = gamma * J0 ** (-1 / 3)
    lam = eps * J0 - gamma * (J0 ** (-1 / 3) - 1 / J0)
    return 4 * mu * (lam + mu) / (lam + 2 * mu)


@pytest.mark.parametrize("gamma, eps, J0", [(0.1, 10.0, 1.01), (0.8, 10.0, 1.01), (0.1, 1.0, 1.5), (2.0, 0.5, 3.0)])
def test_plane_strain_modulus_matches_the_hand_calculation(gamma, eps, J0):
    mat = Hydrogel(shear_modulus=gamma, mixing_modulus=24.2, penalty=eps, mobility=1e-4, preswelling=J0,
                   interaction=0.1)
    assert plane_strain_modulus(mat) == pytest.approx(_hand_modulus(gamma, eps, J0), rel=1e-8)  # measured 2e-10


def test_default_substrate_modulus_and_the_film_theory_by_hand():
    assert _hand_modulus(0.1, 10.0, 1.01) == pytest.approx(0.394817, abs=1e-6)
    sub = Hydrogel(0.1, 24.2, 10.0, 1e-4, 1.01, 0.1)
    film = Hydrogel(5.0, 24.2, 10.0, 1e-4, 1.01, 0.1)  # ratio 50
    Es, Ef = _hand_modulus(0.1, 10.0, 1.01), _hand_modulus(5.0, 10.0, 1.01)
    assert film_wrinkling_strain(film, sub) == pytest.approx(0.25 * (3 * Es / Ef) ** (2 / 3), rel=1e-8)
    assert film_wrinkling_wavelength(film, sub, 0.01) == pytest.approx(
        2 * math.pi * 0.01 * (Ef / (3 * Es)) ** (1 / 3), rel=1e-8)
    # nearly incompressible (eps / gamma = 1e4): E_bar -> 4 mu, here 4 mu (1 - mu/lambda + ...), mu/lambda = 1e-5
    stiff = Hydrogel(0.1, 24.2, 1e3, 1e-4, 1.01, 0.1)
    assert plane_strain_modulus(stiff) == pytest.approx(4 * 0.1 * 1.01 ** (-1 / 3), rel=1e-4)
