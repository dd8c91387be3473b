"""Checkpoints and ``run --resume`` (docs/reliability.md, "Checkpoint and restart").

References, never tuned values: an uninterrupted run of the same config in the same test (history rows,
g_c, crossings, counters) on the same number of ranks, to 1e-10 relative; across rank counts (written
on 1 rank and resumed on 2, and the reverse) to 1e-8 (the partitions change roundoff only: uninterrupted
runs on 1 and 2 ranks agree to about 5e-12 here). The stored state is checked against a known field:
written on one layout and read on another, compared with the same field interpolated on the reading
layout (UFL integrals of the difference and of its flux through every facet), and the stored facet
fluxes against fluxes worked out by hand from the stored node coordinates. Subprocesses: SIGKILL of a
running ``hydrobuckle run`` (serially, and of every process of an ``mpirun -n 2`` job: compared with an
uninterrupted 2-rank launch to 1e-8, as two 2-rank launches partition the mesh differently), SIGTERM,
and SIGINT of a ``sweep``, then ``--resume``. (``converge`` and ``bench``: tests/test_resume_commands.py.)
"""

from __future__ import annotations

import copy
import json
import math
import os
import shutil
import signal
import time
import zipfile

import numpy as np
import pytest
import ufl
from cases import LONG, TINY_BILAYER_TOML, swelling_case
from conftest import (
    EXE,
    MPIRUN,
    child_jobs,
    finish,
    kill_session,
    on_rank0,
    read_csv,
    read_json,
    run_child,
    same_rows,
    same_summary,
    session_processes,
    start,
    time_stepper,
    valid_history,
    wait_rows,
    write_on_rank0,
)
from dolfinx import fem
from mpi4py import MPI

from app import config, factory, fem_utils
from app.cli import main
from app.io import checkpoint, result_identity
from app.io.dof_layout import KEY_BASE, DofLayout
from app.onset.tracker import NoStabilityTest
from app.workflows.run import simulate

EVERY = ("output.checkpoint_every=3", "stability.error_estimate=false")
CROSS_RANK = 1e-8  # see the module docstring


def _listing(d) -> dict:
    """Every file below ``d`` with its bytes and modification time."""
    return {str(p.relative_to(d)): (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(d.rglob("*"))
            if p.is_file()}


def _one_error_line(capsys, comm, *words) -> None:
    err = capsys.readouterr().err
    if comm.rank == 0:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("hydrobuckle: error: "), err
        for w in words:
            assert w in lines[0], (w, lines[0])
    else:
        assert err == ""


# --- the stored state is the field, on any layout --------------------------------------------------


def _u(x):
    return np.vstack([0.1 * x[0] * x[1] + 0.01, 0.05 * x[0] - 0.2 * x[1] ** 2])


def _q(x):
    return np.vstack([1.0 + 2.0 * x[0] + x[1], 0.5 - x[0] + 3.0 * x[1]])


def _ru(x):
    return np.vstack([x[1] ** 2, -x[0]])


def _dq(x):
    return np.vstack([-0.3 + x[1], 2.0 * x[0] + 0.7])


def _interpolated(V, fn) -> np.ndarray:
    f = fem.Function(V)
    f.interpolate(fn)
    f.x.scatter_forward()
    return f.x.array.copy()


def _known(p) -> dict:
    state = np.zeros_like(p.state.x.array)
    state[p.u_dofs] = _interpolated(p.V_u, _u)
    state[p.q_dofs] = _interpolated(p.V_q, _q)
    return {"state": state, "rate_u": _interpolated(p.V_u, _ru), "dQ_prev": _interpolated(p.V_q, _dq)}


LAYOUT_CASE = ("geometry.length=0.15", "mesh.element_size=0.01")


def _save_known(path, comm) -> None:
    cfg = swelling_case(*LAYOUT_CASE)
    p = factory.problem(cfg, comm)
    st = time_stepper(p, cfg)
    k = _known(p)
    p.state.x.array[:] = k["state"]
    st.rate_u[:], st.dQ_prev[:] = k["rate_u"], k["dQ_prev"]
    st.t, st.step = 0.25, 7
    if comm.rank == 0:
        path.mkdir(parents=True, exist_ok=True)
    comm.barrier()
    checkpoint.write(path, cfg, DofLayout(p), st, NoStabilityTest(), rows=[{"step": 0}])
    st.destroy()


def _flux_mismatch(p, a: np.ndarray, b: np.ndarray) -> float:
    """sqrt of (sum over facets of (flux of a - b)^2 + volume L2 of a - b) over the same of b: every
    facet's flux, through UFL (interior facets from both sides' normals, boundary facets)."""
    e, r = fem.Function(p.V_q), fem.Function(p.V_q)
    e.x.array[:] = a - b
    r.x.array[:] = b
    n = ufl.FacetNormal(p.domain)

    def size(f):
        form = ((ufl.dot(f("+"), n("+"))) ** 2 * ufl.dS + ufl.dot(f, n) ** 2 * ufl.ds + ufl.dot(f, f) * ufl.dx)
        return fem_utils.assemble_scalar(fem.form(form), p.comm)

    return math.sqrt(size(e) / size(r))


def _load_and_compare(path, comm) -> None:
    cfg = swelling_case(*LAYOUT_CASE)
    resume = checkpoint.check(path, cfg, comm)
    p = factory.problem(cfg, comm)
    st = time_stepper(p, cfg)
    checkpoint.restore(resume, p, st, NoStabilityTest())
    k = _known(p)  # the same fields interpolated on this layout
    s = p.state.x.array
    du = np.abs(s[p.u_dofs] - k["state"][p.u_dofs]).max(initial=0.0)
    dr = np.abs(st.rate_u - k["rate_u"]).max(initial=0.0)
    assert comm.allreduce(max(du, dr), op=MPI.MAX) < 1e-14
    assert _flux_mismatch(p, s[p.q_dofs], k["state"][p.q_dofs]) < 1e-12
    assert _flux_mismatch(p, st.dQ_prev, k["dQ_prev"]) < 1e-12
    assert (st.t, st.step) == (0.25, 7)
    st.destroy()


def _stored_fluxes_by_hand(path) -> None:
    """The stored flux of a facet is the flux of Q through it along the canonical normal: the tangent
    from its vertex of lower input index to the higher, turned by -90 degrees (exact for linear Q with
    the midpoint value); the stored displacement is u at the stored node."""
    with np.load(path / checkpoint.FILE) as z:
        meta = json.loads(z["meta"].tobytes().decode())
        s = meta["snapshots"][meta["current"]]
        uk, x, qk = z["u_key"], z["x"], z["q_key"]
        lo, hi = x[np.searchsorted(uk, qk // KEY_BASE)], x[np.searchsorted(uk, qk % KEY_BASE)]
        t = hi - lo
        normal = np.column_stack([t[:, 1], -t[:, 0]])
        for name, fn in (("state_q", _q), ("dQ_prev", _dq)):
            expected = np.einsum("ij,ji->i", normal, fn((0.5 * (lo + hi)).T))
            assert np.abs(z[s[name]] - expected).max() < 1e-12 * np.abs(expected).max(), name
        for name, fn in (("state_u", _u), ("rate_u", _ru)):
            assert np.abs(z[s[name]] - fn(x.T).T).max() < 1e-14, name


def test_stored_state_is_the_field_on_any_layout(shared_tmp, comm):
    """A known (u, Q) state written on one layout is the same field on another: 1 rank <-> 2 ranks in the
    2-rank session (dolfinx numbers and orients the facets differently there), 1 rank serially."""
    combos = [("world", "world")] + ([("self", "world"), ("world", "self")] if comm.size > 1 else [])
    for save, load in combos:
        path = shared_tmp / f"{save}-{load}"
        if save == "self":
            on_rank0(_save_known, path, MPI.COMM_SELF)
        else:
            _save_known(path, comm)
        on_rank0(_stored_fluxes_by_hand, path)
        if load == "self":
            on_rank0(_load_and_compare, path, MPI.COMM_SELF)
        else:
            _load_and_compare(path, comm)


# --- resumed runs against uninterrupted ones ----------------------------------------------------------

AFTER_CROSSINGS = ("stability.stop_at_onset=false", "stability.max_crossings=8")
# fixed steps of 0.01 s: the onset near 0.91 s, stopped at 1.0 s on the branch
ON_BRANCH = ("stability.after_onset=branch", "time.end=1.3", "time.adaptive=false", "time.dt_initial=0.01")


# adaptive steps on the branch: stopped 5 steps after the switch
ON_BRANCH_ADAPTIVE = ("stability.after_onset=branch", "time.end=1.3")


@pytest.mark.parametrize("extra, stop", [((), 8), (AFTER_CROSSINGS, "crossings"), (ON_BRANCH, 100),
                                         (ON_BRANCH_ADAPTIVE, "switch")],
                         ids=["before-onset", "after-crossings", "on-a-branch", "on-a-branch-adaptive"])
def test_resume_continues_like_an_uninterrupted_run(extra, stop, shared_tmp, comm):
    """Stopped after ``stop`` steps (as an interrupt stops it: a checkpoint of that step), resumed: the same
    history.csv, onset, crossings and counters as the run never stopped. after-crossings: stopped past
    the step where the uninterrupted run has counted three crossings or more (its mode files the resumed
    directory keeps); on-a-branch-adaptive: 5 steps past the branch switch. Both taken from the uninterrupted
    run, so that any change of the step sizes keeps the stop where it is meant to be."""
    cfg = swelling_case(*EVERY, *extra)
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    rows = read_csv(shared_tmp / "full" / "history.csv")
    crossed = 0
    if stop == "switch":
        switch = full["postbuckling"]["switches"][0]["time"]
        stop = 5 + max(int(r["step"]) for r in rows if float(r["time"]) <= switch + 1e-12)
    elif stop == "crossings":
        stop, crossed = next((int(r["step"]), int(r["negative_eigenvalues"])) for r in rows
                             if int(r["negative_eigenvalues"]) >= 3)
    assert full["status"] == "buckled" and full["steps"] > stop + 3
    part = shared_tmp / "part"
    stopped = simulate(cfg, part, comm, progress=False, stop_after=stop)
    assert stopped["status"] == "interrupted" and stopped["steps"] == stop
    resume = checkpoint.check(part, cfg, comm)
    assert resume.meta["step"] == stop and len(resume.rows) == stop + 1
    if extra is AFTER_CROSSINGS:
        assert resume.crossings == crossed and (part / "mode_surface.csv").is_file()
    if extra in (ON_BRANCH, ON_BRANCH_ADAPTIVE):  # stopped on the branch: the minimizing solver and switch resumed
        assert resume.meta["stepper"]["minimizing"] and resume.meta["tracker"]["branch"]["switches"]
    resumed = simulate(cfg, part, comm, progress=False, resume=resume)
    ref, got = read_csv(shared_tmp / "full" / "history.csv"), read_csv(part / "history.csv")
    tol = 1e-10
    if extra in (ON_BRANCH, ON_BRANCH_ADAPTIVE) and comm.size > 1:
        # on 2 ranks the factorization is not bitwise reproducible (two uninterrupted 2-rank runs differ too),
        # and the minimizer's energy line search decides at roundoff: the states agree to Newton's tolerance
        # but not always with the same iteration counts or polishes (the minimizer's counters). Measured since
        # the minimizer's polish fix, adaptive steps, 4 runs: growth and amplitude 2e-12, dt 5e-11, the local
        # error estimate (a difference of nearly equal contents) 7e-10; fixed steps likewise
        for r in ref + got:
            r.pop("newton_its")
        tol = 1e-8
    same_rows(ref, got, tol)
    same_summary(full, resumed, tol, counters=tol == 1e-10)  # iteration counters: see above
    if extra is AFTER_CROSSINGS:  # the first crossing's mode files, written before the checkpoint, are kept
        _same_mode_surface(shared_tmp / "full" / "mode_surface.csv", part / "mode_surface.csv")
    if extra in (ON_BRANCH, ON_BRANCH_ADAPTIVE):  # profiles.npz: the whole branch, before the stop from the checkpoint
        _same_profiles(shared_tmp / "full" / "profiles.npz", part / "profiles.npz", tol)
    assert not (part / checkpoint.FILE).exists()  # the run ended normally: nothing left to resume


def _same_profiles(ref, got, tol: float) -> None:
    """Two profiles.npz files: the same steps (growth, time) and the same surface profiles, relative to the
    largest profile value. The times to 1e-12 where the runs are bitwise reproducible (tol 1e-10, one
    rank); on 2 ranks to ``tol`` like history.csv's: there the adaptive steps differ at roundoff, and their
    sum grows with the steps (measured 1.6e-12 of t after 60 steps on Debian 13, with factor reuse before
    the onset)."""
    time_tol = 1e-12 if tol <= 1e-10 else tol
    with np.load(ref) as a, np.load(got) as b:
        assert set(a.files) == set(b.files) == {"growth_mm", "time", "position", "profile"}
        assert a["time"].size >= 20 and a["profile"].shape == b["profile"].shape
        assert np.abs(a["time"] - b["time"]).max() <= time_tol * a["time"].max()
        for name in ("growth_mm", "position", "profile"):
            scale = np.abs(a[name]).max()
            assert np.abs(a[name] - b[name]).max() <= tol * scale, name


def _same_mode_surface(ref, got) -> None:
    """Two mode_surface.csv files: the same surface nodes (rows in the partition's order: sorted here),
    the same critical state, and the same mode up to its sign (an eigenvector's sign is arbitrary: it
    flips between two uninterrupted 2-rank runs). The mode is SLEPc's eigenvector, converged to 1e-10 in
    its residual, so 1e-8 (measured between two uninterrupted 2-rank runs: 2e-12)."""
    a, b = (np.loadtxt(f, delimiter=",", skiprows=1) for f in (ref, got))
    a, b = (m[np.lexsort((m[:, 1], m[:, 0]))] for m in (a, b))
    assert a.shape == b.shape and np.abs(a[:, :2] - b[:, :2]).max() < 1e-12
    state = np.abs(a[:, 4:] - b[:, 4:]).max() / np.abs(a[:, 4:]).max()
    sign = np.sign(np.sum(a[:, 2:4] * b[:, 2:4]))
    mode = np.abs(a[:, 2:4] - sign * b[:, 2:4]).max() / np.abs(a[:, 2:4]).max()
    assert state <= 1e-10 and mode <= 1e-8, (state, mode)


@pytest.mark.slow
@pytest.mark.skipif(MPI.COMM_WORLD.size != 2, reason="writes on 1 rank and resumes on 2 (and the reverse)")
def test_resume_on_another_rank_count(shared_tmp, comm):
    cfg = swelling_case(*EVERY)
    self_ = MPI.COMM_SELF
    full_world = simulate(cfg, shared_tmp / "full2", comm, progress=False)
    full_self = on_rank0(simulate, cfg, shared_tmp / "full1", self_, progress=False)
    # written on 1 rank, resumed on 2
    on_rank0(simulate, cfg, shared_tmp / "from1", self_, progress=False, stop_after=8)
    resumed = simulate(cfg, shared_tmp / "from1", comm, progress=False,
                       resume=checkpoint.check(shared_tmp / "from1", cfg, comm))
    assert resumed["ranks"] == 2
    for ref, d in ((full_world, "full2"), (full_self, "full1")):
        same_summary(ref, resumed, CROSS_RANK)
        same_rows(read_csv(shared_tmp / d / "history.csv"), read_csv(shared_tmp / "from1" / "history.csv"), CROSS_RANK)
    # written on 2 ranks, resumed on 1
    simulate(cfg, shared_tmp / "from2", comm, progress=False, stop_after=8)
    resumed = on_rank0(lambda: simulate(cfg, shared_tmp / "from2", self_, progress=False,
                                        resume=checkpoint.check(shared_tmp / "from2", cfg, self_)))
    assert resumed["ranks"] == 1
    for ref, d in ((full_world, "full2"), (full_self, "full1")):
        same_summary(ref, resumed, CROSS_RANK)
        same_rows(read_csv(shared_tmp / d / "history.csv"), read_csv(shared_tmp / "from2" / "history.csv"), CROSS_RANK)


def test_cli_resume_after_a_failed_run_cuts_history_back(shared_tmp, comm, capsys):
    """`run` stopped by time.max_steps = 8 (exit 1; checkpoints at steps 3 and 6, none when a run fails),
    then `run --resume` without that limit (time.max_steps may change): history.csv is cut back to the
    checkpoint's 7 rows and continued; the result is the uninterrupted run's."""
    cfg = swelling_case(*EVERY)
    toml = shared_tmp / "case.toml"
    write_on_rank0(toml, config.dumps(cfg))
    out = shared_tmp / "out"
    assert main(["run", str(toml), "-o", str(out), "-q", "--set", "time.max_steps=8"]) == 1
    assert len(read_csv(out / "history.csv")) == 9
    resume = checkpoint.check(out, cfg, comm)
    assert resume.meta["step"] == 6 and len(resume.rows) == 7
    assert main(["run", str(toml), "--resume", str(out), "-q"]) == 0
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    same_rows(read_csv(shared_tmp / "full" / "history.csv"), read_csv(out / "history.csv"), 1e-10)
    same_summary(full, read_json(out / "summary.json"), 1e-10)
    assert config.load(out / "config.toml") == cfg  # the resumed run's config (max_steps back to its default)
    capsys.readouterr()


def test_time_end_may_change_on_resume(shared_tmp, comm):
    """A state before time.end never depended on it (a step is clipped only to reach it): resumed with a
    later time.end, the run is the uninterrupted run to that time."""
    base = ("stability.enabled=false",) + EVERY
    short, long_ = swelling_case(*base, "time.end=0.4"), swelling_case(*base, "time.end=0.6")
    simulate(short, shared_tmp / "part", comm, progress=False, stop_after=10)
    resumed = simulate(long_, shared_tmp / "part", comm, progress=False,
                       resume=checkpoint.check(shared_tmp / "part", long_, comm))
    full = simulate(long_, shared_tmp / "full", comm, progress=False)
    same_rows(read_csv(shared_tmp / "full" / "history.csv"), read_csv(shared_tmp / "part" / "history.csv"), 1e-10)
    same_summary(full, resumed, 1e-10)


def _rewrite_npz(src, dst, change) -> None:
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    with open(dst, "wb") as f:
        np.savez(f, **arrays)


def test_resume_refusals_leave_the_directory_as_it_was(shared_tmp, comm, capsys):
    """Exit 2, one line on rank 0 (nothing on the others), the directory untouched: a result-changing key
    changed (named, with both values), time.end before the checkpoint, no checkpoint, no directory, a
    truncated or corrupted file, -o elsewhere, and a checkpoint that does not fit the rebuilt mesh
    (detected after meshing, before the directory is touched). Keys that change no result pass."""
    cfg = swelling_case(*EVERY)
    toml = shared_tmp / "case.toml"
    write_on_rank0(toml, config.dumps(cfg))
    out = shared_tmp / "out"
    simulate(cfg, out, comm, progress=False, stop_after=4)
    before = on_rank0(_listing, out)

    def refused(argv, *words, where=out, listing=None):
        assert main(argv + ["-q"]) == 2
        _one_error_line(capsys, comm, *words)
        assert on_rank0(_listing, where) == (listing or before)

    refused(["run", str(toml), "--resume", str(out), "--set", "material.film.modulus_ratio=9"],
            "material.film.modulus_ratio = 8.0 in the checkpoint, 9.0 now")
    refused(["run", str(toml), "--resume", str(out), "--set", "mesh.element_size=0.006"], "mesh.element_size")
    refused(["run", str(toml), "--resume", str(out), "--set", "time.end=0.002"], "time.end = 0.002",
            "not after the checkpoint's time")
    refused(["run", str(toml), "--resume", str(out), "-o", str(shared_tmp / "elsewhere")], "--resume")
    assert not (shared_tmp / "elsewhere").exists()
    # output.*, time.end (later), time.max_steps and stability.error_estimate change no result
    changed = copy.deepcopy(cfg)
    changed["output"].update(fields=True, checkpoint_every=7)
    changed["time"].update(end=2.0, max_steps=50)
    changed["stability"]["error_estimate"] = True
    assert checkpoint.check(out, changed, comm).meta["step"] == 4

    empty = shared_tmp / "empty"
    on_rank0(lambda: (empty.mkdir(), (empty / "history.csv").write_text("step\n0\n")))
    refused(["run", str(toml), "--resume", str(empty)], "no checkpoint", where=empty,
            listing=on_rank0(_listing, empty))
    missing = shared_tmp / "missing"
    assert main(["run", str(toml), "--resume", str(missing), "-q"]) == 2
    _one_error_line(capsys, comm, "no such directory")
    assert not missing.exists()

    def damaged(name, damage):
        d = shared_tmp / name
        on_rank0(lambda: (shutil.copytree(out, d), damage(d / checkpoint.FILE)))
        return d, on_rank0(_listing, d)

    def truncate(f):
        data = f.read_bytes()
        f.write_bytes(data[: len(data) // 2])

    def flip(f):  # one byte inside the first state array: its CRC no longer matches
        with zipfile.ZipFile(f) as z:
            info = z.getinfo("a0.npy")
        data = bytearray(f.read_bytes())
        data[info.header_offset + 1000] ^= 0xFF  # past the headers (under 300 bytes), inside the data
        f.write_bytes(bytes(data))

    for name, damage in (("truncated", truncate), ("flipped", flip)):
        d, listing = damaged(name, damage)
        refused(["run", str(toml), "--resume", str(d)], "is unreadable", where=d, listing=listing)

    def moved(f):  # a well-formed file whose nodes are not the mesh's
        _rewrite_npz(f, f, lambda a: a["x"].__setitem__((5, 0), a["x"][5, 0] + 1e-3))

    d, listing = damaged("moved", moved)
    refused(["run", str(toml), "--resume", str(d)], "does not fit the mesh", where=d, listing=listing)


# --- signals: SIGKILL, SIGTERM, an interrupted sweep -----------------------------------------------

@pytest.fixture(scope="module")
def long_case(tmp_path_factory):
    """(config file, the uninterrupted run's history rows and summary), run once on rank 0."""
    comm = MPI.COMM_WORLD
    d = comm.bcast(str(tmp_path_factory.mktemp("long")) if comm.rank == 0 else None, root=0)

    def reference():
        from pathlib import Path

        toml = Path(d) / "long.toml"
        toml.write_text(LONG)
        s = simulate(config.load(toml), Path(d) / "reference", MPI.COMM_SELF, progress=False)
        return toml, read_csv(Path(d) / "reference" / "history.csv"), s

    return on_rank0(reference)


def _kill_and_resume(toml, out):
    proc = start([EXE, "run", str(toml), "-o", str(out)])
    wait_rows(proc, out / "history.csv", 25, also=out / checkpoint.FILE)
    proc.send_signal(signal.SIGKILL)
    code, _, _ = finish(proc)
    killed = valid_history(out / "history.csv")
    assert not (out / "summary.json").exists()  # a killed run writes no summary
    step = checkpoint.check(out, config.load(toml), MPI.COMM_SELF).meta["step"]
    resumed = run_child([EXE, "run", str(toml), "--resume", str(out)])
    return code, len(killed), step, resumed


@child_jobs
def test_sigkill_loses_at_most_the_steps_since_the_last_checkpoint(long_case, shared_tmp):
    """SIGKILL to a serial `hydrobuckle run` once a checkpoint exists: history.csv is valid CSV, the last
    checkpoint is at most output.checkpoint_every steps behind it; `run --resume` then gives the
    uninterrupted run's history and summary."""
    toml, ref_rows, ref = long_case
    out = shared_tmp / "killed"
    code, rows, step, resumed = on_rank0(_kill_and_resume, toml, out)
    assert code == -signal.SIGKILL
    assert step % 10 == 0 and 0 <= (rows - 1) - step <= 10, (rows, step)
    assert resumed.returncode == 0, resumed.stdout[-2000:] + resumed.stderr[-2000:]
    assert f"resumed from {out / checkpoint.FILE} at step {step}," in resumed.stdout
    same_rows(ref_rows, read_csv(out / "history.csv"), 1e-10)
    same_summary(ref, read_json(out / "summary.json"), 1e-10)
    assert not (out / checkpoint.FILE).exists()


def _kill_mpirun_and_resume(toml, out, reference):
    ref = run_child([*MPIRUN, EXE, "run", str(toml), "-o", str(reference), "-q"])
    assert ref.returncode == 0, ref.stderr[-2000:]
    proc = start([*MPIRUN, EXE, "run", str(toml), "-o", str(out)])
    wait_rows(proc, out / "history.csv", 25, also=out / checkpoint.FILE)
    killed = kill_session(proc, signal.SIGKILL)  # mpirun and both ranks (each in a process group of its own)
    code, _, _ = finish(proc)
    t0 = time.monotonic()
    while session_processes(proc) and time.monotonic() - t0 < 10:
        time.sleep(0.05)
    left = session_processes(proc)
    rows = len(valid_history(out / "history.csv"))
    summary = (out / "summary.json").exists()
    meta = checkpoint.check(out, config.load(toml), MPI.COMM_SELF).meta
    resumed = run_child([*MPIRUN, EXE, "run", str(toml), "--resume", str(out)])
    return code, len(killed), left, rows, summary, meta, resumed


@child_jobs
def test_sigkill_of_an_mpirun_job_loses_at_most_the_steps_since_the_last_checkpoint(long_case, shared_tmp):
    """SIGKILL to every process of a running `mpirun -n 2 hydrobuckle run` (mpirun and its two ranks, as
    a node failure or `kill -9` of the job) once a checkpoint exists: history.csv is valid CSV, the
    checkpoint (written on 2 ranks) is at most output.checkpoint_every steps behind it, and `mpirun -n
    2 ... run --resume` completes with the history and onset of an uninterrupted 2-rank run, to the
    cross-layout tolerance (every 2-rank launch partitions the mesh anew)."""
    toml, _, _ = long_case
    out = shared_tmp / "killed2"
    code, n_killed, left, rows, summary, meta, resumed = on_rank0(_kill_mpirun_and_resume, toml, out,
                                                                 shared_tmp / "reference2")
    assert code == -signal.SIGKILL and n_killed >= 3 and left == [], (code, n_killed, left)
    assert not summary  # a killed run writes no summary
    step = meta["step"]
    assert meta["ranks"] == 2 and step % 10 == 0 and 0 <= (rows - 1) - step <= 10, (rows, step)
    assert resumed.returncode == 0, resumed.stdout[-2000:] + resumed.stderr[-2000:]
    assert f"resumed from {out / checkpoint.FILE} at step {step}," in resumed.stdout
    ref = read_json(shared_tmp / "reference2" / "summary.json")
    same_rows(read_csv(shared_tmp / "reference2" / "history.csv"), read_csv(out / "history.csv"), CROSS_RANK)
    same_summary(ref, read_json(out / "summary.json"), CROSS_RANK)
    assert read_json(out / "summary.json")["resumed_from"] == {"step": step, "time": meta["t"], "ranks": 2}
    assert not (out / checkpoint.FILE).exists()


def _term_and_resume(toml, out):
    proc = start([EXE, "run", str(toml), "-o", str(out)])
    wait_rows(proc, out / "history.csv", 15)
    proc.send_signal(signal.SIGTERM)
    code, _, _ = finish(proc)
    summary = read_json(out / "summary.json")
    meta = checkpoint.check(out, config.load(toml), MPI.COMM_SELF).meta
    resumed = run_child([EXE, "run", str(toml), "--resume", str(out)])
    return code, summary, meta["step"], len(meta["rows"]), resumed


@child_jobs
def test_sigterm_writes_a_checkpoint_to_resume_from(long_case, shared_tmp):
    """SIGTERM: exit 143, status "interrupted", and a checkpoint of the very step the run stopped at
    (not only the last periodic one); --resume continues to the uninterrupted run's result."""
    toml, ref_rows, ref = long_case
    out = shared_tmp / "termed"
    code, summary, step, rows, resumed = on_rank0(_term_and_resume, toml, out)
    assert code == 143 and summary["status"] == "interrupted"
    assert step == summary["steps"] and rows == step + 1
    assert resumed.returncode == 0, resumed.stdout[-2000:] + resumed.stderr[-2000:]
    same_rows(ref_rows, read_csv(out / "history.csv"), 1e-10)
    same_summary(ref, read_json(out / "summary.json"), 1e-10)


def _interrupt_sweep(toml, out):
    argv = ["sweep", str(toml), "--param", "material.film.modulus_ratio", "--values", "1.0,1.2", "-o", str(out)]
    proc = start([EXE, *argv])
    wait_rows(proc, out / "modulus_ratio=1" / "history.csv", 20)
    proc.send_signal(signal.SIGINT)
    code, first_out, _ = finish(proc)
    listing = sorted(p.name for p in out.iterdir())
    again = run_child([EXE, *argv])
    return code, first_out, listing, again


@child_jobs
def test_interrupted_sweep_stops_after_the_current_case_and_resumes_it(long_case, shared_tmp):
    """SIGINT during the first case of a sweep: it stops after that case (exit 130; before, each later
    case still built its mesh and wrote an "interrupted" directory), which keeps a checkpoint; the rerun
    resumes that case from it and runs the other; the resumed case equals the uninterrupted run."""
    toml, ref_rows, ref = long_case
    out = shared_tmp / "sweep"
    code, first_out, listing, again = on_rank0(_interrupt_sweep, toml, out)
    assert code == 130, first_out[-2000:]
    assert "modulus_ratio=1.2" not in listing and "modulus_ratio=1" in listing, listing
    assert "not started" in first_out
    assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
    assert "study: modulus_ratio=1: resuming at step" in again.stdout
    assert "study: modulus_ratio=1.2: running" in again.stdout
    same_rows(ref_rows, read_csv(out / "modulus_ratio=1" / "history.csv"), 1e-10)
    same_summary(ref, read_json(out / "modulus_ratio=1" / "summary.json"), 1e-10)
    assert os.path.isfile(out / "modulus_ratio=1.2" / "summary.json")


MSH_CASE = """
[geometry]
kind = "msh"
file = "{file}"
wrinkles = "along"
layers = {{ film = "film", substrate = "substrate" }}
boundaries = {{ top = "permeable", bottom = "roller_y", left = "roller_x", right = "roller_x" }}
[time]
end = 0.3
dt_initial = 0.001
dt_max = 0.05
[stability]
error_estimate = false
[output]
fields = false
plot = false
checkpoint_every = 2
"""
MSH_MESH = TINY_BILAYER_TOML


def test_user_msh_resumes_and_an_edited_file_is_refused(shared_tmp, comm, capsys):
    """A user .msh (input node order: the file's): stopped by time.max_steps, resumed = uninterrupted.
    The same config over an edited file (one byte appended) is refused: the file's sha256 is stored."""
    on_rank0((shared_tmp / "mesh.toml").write_text, MSH_MESH)
    msh = shared_tmp / "user.msh"
    assert main(["mesh", str(shared_tmp / "mesh.toml"), "-o", str(msh)]) == 0
    toml = shared_tmp / "case.toml"
    on_rank0(toml.write_text, MSH_CASE.format(file=msh))
    cfg = config.load(toml)
    out = shared_tmp / "out"
    assert main(["run", str(toml), "-o", str(out), "-q", "--set", "time.max_steps=5"]) == 1
    assert checkpoint.check(out, cfg, comm).meta["step"] == 4
    edited = shared_tmp / "edited"
    on_rank0(shutil.copytree, out, edited)
    assert main(["run", str(toml), "--resume", str(out), "-q"]) == 0
    full = simulate(cfg, shared_tmp / "full", comm, progress=False)
    same_rows(read_csv(shared_tmp / "full" / "history.csv"), read_csv(out / "history.csv"), 1e-10)
    same_summary(full, read_json(out / "summary.json"), 1e-10)
    on_rank0(lambda: msh.write_bytes(msh.read_bytes() + b"\n"))
    listing = on_rank0(_listing, edited)
    assert main(["run", str(toml), "--resume", str(edited), "-q"]) == 2
    _one_error_line(capsys, comm, "geometry.file", "changed since the checkpoint")
    assert on_rank0(_listing, edited) == listing


def test_a_checkpoint_from_before_mesh_refinements_still_resumes(shared_tmp, comm):
    """mesh.refinements came after checkpoints did: a checkpoint whose stored config lacks it (at 0, what
    its absence meant) has the same result-changing keys, and one with the key at 1 differs (named)."""
    cfg = swelling_case(*EVERY)
    old = copy.deepcopy(cfg)
    del old["mesh"]["refinements"]
    assert result_identity.result_hash(old) == result_identity.result_hash(cfg)
    refined = copy.deepcopy(cfg)
    refined["mesh"]["refinements"] = 1
    assert result_identity.first_difference(old, refined) == "mesh.refinements = '<unset>' in the checkpoint, 1 now"
