"""End to end through the CLI: result files, their consistency, and solver-failure reporting."""

import csv
import json

from cases import BUCKLING_STRIP_TOML
from mpi4py import MPI

from app import cli, config

TINY = """
[geometry]
length = 0.1
substrate_thickness = 0.05
[mesh]
film_layers = 2
substrate_grading = 1.3
[time]
end = 1.05
dt_initial = 0.01
dt_max = 0.1
[stability]
enabled = false
[output]
every = 2
"""


def _write(path, text):
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.barrier()


def test_run_writes_consistent_results(shared_tmp):
    cfg_path, out = shared_tmp / "tiny.toml", shared_tmp / "out"
    _write(cfg_path, TINY)
    assert cli.main(["run", str(cfg_path), "-o", str(out), "-q", "--set", "material.film.modulus_ratio=4"]) == 0
    resolved = config.load(out / "config.toml")
    assert resolved == config.load(cfg_path, ["material.film.modulus_ratio=4"])
    with open(out / "history.csv") as f:
        rows = list(csv.DictReader(f))
    # the stepper's columns, then the model's (app/model/history.py; no contact), no tracker's (stability off):
    # the order docs/outputs.md lists
    assert tuple(rows[0]) == ("step", "time", "dt", "newton_its", "inflow", "error_estimate", "growth_mm",
                              "mu_bar", "fluid_volume", "applied_strain", "amplitude_mm", "wrinkle_count", "energy")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["steps"] == len(rows) - 1
    assert summary["ranks"] == MPI.COMM_WORLD.size
    assert summary["final"]["time"] == float(rows[-1]["time"]) == 1.05
    assert summary["final"]["growth_mm"] == float(rows[-1]["growth_mm"]) > 0
    assert summary["materials"]["film"]["shear_modulus"] == 0.4
    assert "dolfinx" in summary["versions"] and summary["assumptions"]
    # the time grid respects the end of the ramp and mu_bar follows the ramp exactly
    times = [float(r["time"]) for r in rows]
    assert 1.0 in times
    mu0 = summary["materials"]["film"]["mu0"]
    for r in rows:
        t = float(r["time"])
        assert float(r["mu_bar"]) == mu0 + (0.0 - mu0) * min(t, 1.0)
    for name in ("fields.xdmf", "fields.h5", "history.png"):
        assert (out / name).stat().st_size > 0
    xdmf = (out / "fields.xdmf").read_text()
    for field in ("displacement", "fluid_content", "chemical_potential", "J", "flux"):
        assert f'Name="{field}"' in xdmf
    # the initial state, then every 2nd accepted step
    assert xdmf.count('<Attribute Name="displacement"') == 1 + (len(rows) - 1) // 2


def test_solver_failure_exits_1_and_keeps_history(shared_tmp):
    cfg_path, out = shared_tmp / "fail.toml", shared_tmp / "out"
    _write(cfg_path, TINY)
    code = cli.main(["run", str(cfg_path), "-o", str(out), "-q", "--set", "solver.max_it=1",
                     "--set", "time.dt_min=0.004"])
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert "dt_min" in summary["message"]
    with open(out / "history.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) >= 1 and float(rows[0]["time"]) == 0.0


BUCKLING = BUCKLING_STRIP_TOML + """
[time]
end = 1.0
dt_max = 0.05
[output]
fields = false
plot = false
"""


def test_run_reports_gc_with_its_discretization_error(shared_tmp):
    cfg_path, out = shared_tmp / "buckling.toml", shared_tmp / "out"
    _write(cfg_path, BUCKLING)
    assert cli.main(["run", str(cfg_path), "-o", str(out), "-q"]) == 0
    crit = json.loads((out / "summary.json").read_text())["critical"]
    est = crit["discretization_error"]
    companions = {}
    for study in ("time", "mesh"):
        s = json.loads((out / "error-estimate" / study / "summary.json").read_text())
        companions[study] = s["critical"]["growth_um"]
        assert est[f"{study}_companion_g_c_um"] == companions[study]
    # the companions really are coarser: time tolerance x4 (about half the steps), element size x2 and
    # half the film layers (about a quarter of the cells)
    base_cfg = config.load(out / "config.toml")
    tcfg = config.load(out / "error-estimate" / "time" / "config.toml")
    mcfg = config.load(out / "error-estimate" / "mesh" / "config.toml")
    assert tcfg["time"]["tolerance"] == 4 * base_cfg["time"]["tolerance"]
    for bound in ("dt_initial", "dt_max"):  # the step bounds coarsened with the steps (x2)
        assert tcfg["time"][bound] == 2 * base_cfg["time"][bound]
    assert tcfg["mesh"] == mcfg["mesh"]  # the time companion runs on the mesh companion's coarse mesh
    assert mcfg["mesh"]["element_size"] == 2 * base_cfg["mesh"]["element_size"]
    assert mcfg["mesh"]["film_layers"] * 2 == base_cfg["mesh"]["film_layers"]
    assert mcfg["time"] == base_cfg["time"]
    base = json.loads((out / "summary.json").read_text())
    tsum = json.loads((out / "error-estimate" / "time" / "summary.json").read_text())
    msum = json.loads((out / "error-estimate" / "mesh" / "summary.json").read_text())
    assert tsum["mesh"]["cells"] == msum["mesh"]["cells"] and tsum["steps"] < msum["steps"]
    assert 3.0 < base["mesh"]["cells"] / msum["mesh"]["cells"] < 5.0
    # time: order 1 -> |g_2h - g_2h,2dt| (on the coarse mesh); mesh: order 1.5 -> |g - g_2h| / (2^1.5 - 1)
    assert est["time_um"] == abs(companions["mesh"] - companions["time"])
    assert est["mesh_um"] == abs(crit["growth_um"] - companions["mesh"]) / (2 ** 1.5 - 1)
    assert est["total_um"] == est["time_um"] + est["mesh_um"] > 0
