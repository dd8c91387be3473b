"""Time stepping (app/solvers/stepping.py) and crossings located within one step (app/onset/crossing.py,
app/onset/tracker.py).

References: the fixed time grid written out by hand; the step-size controller's formula
dt_next = dt * clamp(0.9 sqrt(tol/err), 0.2, 2) (docs/model.md, "Time stepping"); the documented cut-back
factor 4; a run without Newton failures (the same final state within the error tolerance); and, for
several eigenvalues crossing in one step, the ordering and bracket width that the onset bisection
promises (every bracket inside the step, narrower than stability.tolerance).
"""

import csv
import json
import math

import numpy as np
import pytest
import ufl
from conftest import run_to_end, small_bilayer
from dolfinx import fem
from mpi4py import MPI

from app import cli, compat, config, factory, fem_utils
from app.solvers.step_control import CUTBACK, GROW_MAX, SAFETY, SHRINK_MIN
from app.workflows.run import simulate


def _write(path, text):
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(text)
    MPI.COMM_WORLD.barrier()


def _history(outdir):
    with open(outdir / "history.csv") as f:
        return list(csv.DictReader(f))


def cell_fluid_content(p) -> np.ndarray:
    """Cell averages of s = s0 - Div Q_n on the owned cells (an independent DG0 projection)."""
    V0 = compat.scalar_space(p.domain, "DG", 0)
    v0 = ufl.TestFunction(V0)
    _, Q = ufl.split(p.state)
    num = fem_utils.assemble_vector(fem.form((p.mat.s0 - ufl.div(Q)) * v0 * ufl.dx))
    area = fem_utils.assemble_vector(fem.form(v0 * ufl.dx))
    n = fem_utils.num_owned_cells(p.domain)
    out = (num.array / area.array)[:n].copy()
    num.destroy()
    area.destroy()
    return out


def test_fixed_steps_follow_the_grid_and_stop_at_the_ramp_end(comm):
    """time.adaptive = false: steps of exactly dt_initial, clipped once at the end of the ramp (1 s)
    and at time.end, never rejected (the error estimate is recorded but not used)."""
    dt = 0.3
    cfg = small_bilayer(**{"time.adaptive": "false", "time.dt_initial": dt, "time.dt_max": dt, "time.end": 2.0,
                           "time.tolerance": 1e-9, "stability.enabled": "false"})
    _, st, rows = run_to_end(cfg, comm)
    expected = [0.3, 0.6, 0.9, 1.0, 1.3, 1.6, 1.9, 2.0]  # by hand: k*dt, the kink at 1.0, the end at 2.0
    assert [r.time for r in rows[1:]] == pytest.approx(expected, abs=1e-12)
    assert [r.dt for r in rows[1:]] == pytest.approx([0.3, 0.3, 0.3, 0.1, 0.3, 0.3, 0.3, 0.1], abs=1e-12)
    assert st.rejected == 0 and st.failed_solves == 0
    # with a tolerance of 1e-9 an adaptive run would have rejected these steps: the estimate is above it
    assert max(r.error_estimate for r in rows[1:] if math.isfinite(r.error_estimate)) > 1e-9


def test_max_steps_stops_the_run_as_a_failure(shared_tmp):
    """time.max_steps = 3: exactly three steps are kept, the run ends with status "failed" naming the
    key, exit code 1 (docs/running.md: solver failure)."""
    cfg_path, out = shared_tmp / "c.toml", shared_tmp / "out"
    _write(cfg_path, "[geometry]\nlength = 0.1\nsubstrate_thickness = 0.05\n[mesh]\nelement_size = 0.01\n"
                     "film_layers = 2\n[time]\nend = 1.0\ndt_initial = 0.01\n[stability]\nenabled = false\n"
                     "[output]\nfields = false\nplot = false\n")
    assert cli.main(["run", str(cfg_path), "-o", str(out), "-q", "--set", "time.max_steps=3"]) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "failed"
    assert "time.max_steps = 3" in summary["message"]
    rows = _history(out)
    assert summary["steps"] == 3 and [int(r["step"]) for r in rows] == [0, 1, 2, 3]
    assert summary["final"]["time"] == float(rows[-1]["time"]) < 1.0


@pytest.mark.parametrize("controller", ["predictive", "elementary"])
def test_error_control_rejects_steps_and_bounds_every_accepted_error(comm, controller):
    """A tiny tolerance forces rejections; every accepted step's estimate is within the tolerance
    (only the first step has none), and each accepted step is at most the controller's proposal of the step
    before: dt * clamp(f, 0.2, 2), f = 0.9 sqrt(tol/err), divided by sqrt(rho) for the predictive rule while
    the error constant err/dt^2 grew by rho > 1 over the step (docs/model.md, Time stepping), written out here from
    the history's columns. Smaller only after a rejection, or when clipped at the end."""
    tol = 1e-6
    cfg = small_bilayer(**{"time.tolerance": tol, "time.dt_initial": 0.01, "time.end": 0.5,
                           "stability.enabled": "false", "time.controller": controller})
    _, st, rows = run_to_end(cfg, comm)
    assert st.rejected > 0
    errs = [r.error_estimate for r in rows[1:]]
    assert math.isnan(errs[0])  # no history for the predictor yet
    assert all(math.isfinite(e) and 0 <= e <= tol for e in errs[1:])
    assert rows[-1].time == pytest.approx(0.5, abs=1e-12)
    smaller = 0
    dt_max = cfg["time"]["dt_max"]
    for before, a, b in zip(rows[0:-2], rows[1:-1], rows[2:]):
        if not math.isfinite(a.error_estimate):
            continue
        f = SAFETY * math.sqrt(tol / a.error_estimate)
        if controller == "predictive" and math.isfinite(before.error_estimate) and before.error_estimate > 0:
            rho = (a.error_estimate / a.dt**2) / (before.error_estimate / before.dt**2)
            f /= math.sqrt(max(rho, 1.0))
        proposal = min(dt_max, a.dt * min(GROW_MAX, max(SHRINK_MIN, f)))
        assert b.dt <= proposal * (1 + 1e-12)
        smaller += b.dt < proposal * (1 - 1e-12)
    assert smaller <= st.rejected + 1  # + the last step, clipped at time.end
    # the documented constants themselves
    assert (SAFETY, SHRINK_MIN, GROW_MAX, CUTBACK) == (0.9, 0.2, 2.0, 0.25)


def test_newton_failure_is_cut_back_and_the_run_recovers(shared_tmp, comm):
    """solver.max_it = 3: the first step at dt = 0.1 needs 4 Newton iterations (measured 4 with the
    default max_it) and fails; it is retried at dt/4, which needs 3, and the run completes. Its final
    state equals that of a run without failures within the error tolerance on the fluid content."""
    base = {"time.dt_initial": 0.1, "time.dt_max": 0.2, "time.end": 0.6, "stability.enabled": "false"}
    results = {}
    for max_it in (25, 3):
        cfg = small_bilayer(**base, **{"solver.max_it": max_it})
        p = factory.problem(cfg, comm)
        s = simulate(cfg, shared_tmp / f"it{max_it}", comm, problem=p, progress=False)
        results[max_it] = (s, cell_fluid_content(p), _history(shared_tmp / f"it{max_it}"))
    ref, cut = results[25][0], results[3][0]
    assert ref["failed_solves"] == 0 and int(results[25][2][1]["newton_its"]) > 3  # the reference needs 4
    assert cut["failed_solves"] >= 1
    assert cut["status"] == ref["status"] == "completed"
    first = results[3][2][1]
    assert float(first["dt"]) == pytest.approx(0.1 * CUTBACK, rel=1e-12)  # cut back by 4, once
    assert float(first["time"]) == pytest.approx(0.025, rel=1e-12)
    assert cut["final"]["time"] == ref["final"]["time"] == pytest.approx(0.6, abs=1e-12)
    ds = comm.allreduce(float(np.abs(results[3][1] - results[25][1]).max()), op=MPI.MAX)
    tol = small_bilayer()["time"]["tolerance"]
    assert ds <= tol  # measured 7.4e-5 (tolerance 5e-4)
    assert cut["final"]["growth_mm"] == pytest.approx(ref["final"]["growth_mm"], rel=1e-2)


SWELLING = {
    "geometry": {"length": 0.3, "substrate_thickness": 0.15, "film_thickness": 0.01},
    "mesh": {"element_size": 0.005, "film_layers": 2, "substrate_grading": 1.25},
    "time": {"end": 1.0, "dt_initial": 0.001, "dt_max": 0.05},
    "output": {"fields": False, "plot": False},
}


def test_several_crossings_in_one_step_are_each_located_in_order(shared_tmp, comm):
    """Fixed steps of 0.05 s across the onset: one step gains several negative eigenvalues (the
    bilayer's wrinkle counts become critical within a fraction of a millisecond). With
    stop_at_onset = false every new one is bisected on its own: the crossings are ordered in time
    and growth, their counts are 1, 2, 3, and every bracket lies inside that one step and is
    narrower than stability.tolerance, with K positive definite at its stable end (lambda > 0) and
    indefinite at the other (lambda < 0)."""
    tol = 1e-3
    cfg = config.resolve(SWELLING, ["time.adaptive=false", "time.dt_initial=0.05", "stability.stop_at_onset=false",
                                    "stability.max_crossings=3", f"stability.tolerance={tol}",
                                    "stability.error_estimate=false"])
    out = shared_tmp / "multi"
    s = simulate(cfg, out, comm, progress=False)
    assert s["status"] == "buckled"
    rows = _history(out)
    counts = [int(r["negative_eigenvalues"]) for r in rows]
    jumps = [(k, counts[k] - counts[k - 1]) for k in range(1, len(rows)) if counts[k] > counts[k - 1]]
    k, gained = jumps[0]
    assert gained >= 3, jumps  # measured 7 in one step
    t_lo, t_hi = float(rows[k - 1]["time"]), float(rows[k]["time"])
    crossings = s["crossings"]
    assert len(crossings) == 3  # stability.max_crossings
    assert crossings[0] == {k: s["critical"][k] for k in crossings[0]}
    assert [c["negative_eigenvalues"] for c in crossings] == [1, 2, 3]
    times = [c["time"] for c in crossings]
    assert times == sorted(times) and len(set(times)) == 3
    growths = [c["growth_mm"] for c in crossings]
    assert growths == sorted(growths)
    for c in crossings:
        lo, hi = c["bracket"]
        assert t_lo <= lo <= c["time"] <= hi <= t_hi
        assert hi - lo <= tol * hi
        assert c["lambda_min_before"] > 0 > c["lambda_min_after"]
    # the run stopped at that step: the crossings limit was reached there
    assert len(rows) == k + 1
