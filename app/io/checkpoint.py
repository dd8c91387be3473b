"""Checkpoints of a run (``output.checkpoint_every``) and what ``hydrobuckle run --resume`` reads.

A checkpoint is one file, ``checkpoint.npz`` in the result directory, written by rank 0 into
``checkpoint.npz.tmp`` (flushed to disk) and renamed over the previous one: a crash leaves the old or
the new checkpoint, never a torn one. It holds everything the run loop needs to go on as if never
stopped (docs/reliability.md, "Checkpoint and restart"):

- ``meta`` (JSON text as bytes): the format, the resolved config and the hash of its result-changing keys, the
  stepper's scalars (t, step, dt_next, dt_prev, history_valid, inflow, counters, the equilibrium
  test's volumes, Newton's residual scale), the onset tracker's state (negative-eigenvalue count,
  crossings so far, the screen's remembered states and counters) and the history.csv rows so far;
- ``u_key``, ``x``: each mesh node's index in the mesh's input (the gmsh model) and its coordinates;
- ``q_key``: each facet as the pair of its vertices' input indices (lo * 2^31 + hi); in 3D, as its three
  lowest vertex input indices (a, b, c: a * 2^42 + b * 2^21 + c, which names a quadrilateral face uniquely);
- ``a0``, ``a1``, ...: the state arrays (u and the accumulated flux Q_n of each remembered state, the
  predictor's rate_u and dQ_prev), in key order, each stored once;
- on a followed branch, ``profile_growth``, ``profile_time``, ``profile_position``, ``profile_value``: the
  surface profile of every branch step so far (profiles.npz of the continued run starts with them; they
  are gathered surface arrays sorted along the surface, the same on any number of ranks).

Each object writes and reads its own part of the meta: the stepper its counters and each snapshot's
scalars (``TimeStepper.counters``, ``Snapshot.scalars``; ``resume_from``, ``snapshot_of``), the tracker
its count, crossings and screen with snapshots referred to by number (``checkpoint_state``,
``restore_checkpoint``). This module stores the snapshots' arrays, the keys and the file; the keys are
:mod:`app.io.dof_layout`'s, what must match for a resume :mod:`app.io.result_identity`'s.

The arrays are stored independently of the mesh partition: displacement dofs keyed by the input node
index of their vertex, the RTCF flux dofs (one per facet) by their facet's vertex pair. A flux dof's
sign depends on the facet orientation dolfinx takes from the partition's global vertex numbering, so
the stored value is the flux along a canonical normal: the facet's tangent from its vertex with the
lower input index to the higher, turned by -90 degrees (in 3D: (X_b - X_a) x (X_c - X_a) of its three lowest
vertices). A restart may therefore use any number of
ranks; the mesh is rebuilt from the same config (gmsh on one rank: the same input nodes) and checked
against the stored coordinates.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app import config
from app.io import writes
from app.io.dof_layout import DofLayout, LayoutMismatch
from app.io.result_identity import first_difference, input_files, result_hash
from app.model.surface import SurfaceProfiles

FILE = "checkpoint.npz"
FORMAT = 1
# the branch's surface profiles (app.model.surface.SurfaceProfiles.arrays) and their members in the file
PROFILE_MEMBERS = {"growth_mm": "profile_growth", "time": "profile_time", "position": "profile_position",
                   "profile": "profile_value"}


class CheckpointError(config.ConfigError):
    """A checkpoint that cannot be resumed (one line; the CLI exits 2)."""

    def __init__(self, message: str):
        super().__init__("", message)


# --- writing ---------------------------------------------------------------------------------------


class _ZipWriter:
    """Rank 0's zip file; collects the first error instead of raising (the gathers must go on)."""

    def __init__(self, path: Path):
        self.error = None
        self.names: dict[str, str] = {}  # content digest -> member name
        self.zf = None
        try:
            self.zf = zipfile.ZipFile(path, "w", zipfile.ZIP_STORED, allowZip64=True)
        except OSError as err:
            self.error = err

    def put(self, name: str, array: np.ndarray) -> None:
        if self.error is None:
            try:
                with self.zf.open(name + ".npy", "w", force_zip64=True) as f:
                    np.lib.format.write_array(f, np.asarray(array), allow_pickle=False)
            except OSError as err:
                self.error = err

    def array(self, array: np.ndarray) -> str:
        """The member holding ``array`` (each content stored once)."""
        digest = hashlib.sha1(repr((array.dtype.str, array.shape)).encode() + array.tobytes()).hexdigest()
        if digest not in self.names:
            self.names[digest] = f"a{len(self.names)}"
            self.put(self.names[digest], array)
        return self.names[digest]

    def close(self) -> None:
        if self.zf is not None:
            try:
                self.zf.close()
            except OSError as err:
                self.error = self.error or err


def write(outdir, cfg: dict, layout: DofLayout, stepper, tracker, rows: list, profiles=None, contact=None) -> float:
    """Write the checkpoint of the run's current state (collective; between steps). Returns its size in
    bytes on rank 0 (0 elsewhere); an OSError on every rank if rank 0 could not write it (the previous
    checkpoint is then left as it was). ``profiles``: the branch's :class:`SurfaceProfiles` so far;
    ``contact``: the problem's :class:`~app.model.penalty.PenaltyContact` (its penalty, raised on the way)."""
    comm = layout.comm
    rank0 = comm.rank == 0
    final = Path(outdir) / FILE
    tmp = final.with_name(FILE + ".tmp")
    sink = _ZipWriter(tmp) if rank0 else None
    stored = layout.keys()
    if rank0:
        for name, a in zip(("u_key", "x", "q_key"), stored):
            sink.put(name, a)

    snaps: list = []  # unique Snapshot objects (by identity), in order of first reference

    def ref(snap) -> int:
        for i, s in enumerate(snaps):
            if s is snap:
                return i
        snaps.append(snap)
        return len(snaps) - 1

    current = ref(stepper.snapshot())
    tracker_meta = tracker.checkpoint_state(ref)  # refers to snapshots by number; None without a tracker
    snap_meta = []
    for s in snaps:
        u, q = layout.mixed_parts(s.state)
        members = {}
        for field, kind, owned in (("state_u", "u", u), ("state_q", "q", q), ("rate_u", "u", layout.u_part(s.rate_u)),
                                   ("dQ_prev", "q", layout.q_part(s.dQ_prev))):
            full = layout.gather(kind, owned)
            members[field] = sink.array(full) if rank0 else None
        snap_meta.append({**s.scalars(), **members})
    size = 0.0
    error = None
    if rank0:
        try:  # nothing rank 0 does alone may raise: the other ranks wait for its verdict below
            if profiles:
                for name, a in profiles.arrays().items():
                    sink.put(PROFILE_MEMBERS[name], a)
            meta = {"format": FORMAT, "result_hash": result_hash(cfg), "inputs": input_files(cfg), "config": cfg,
                    "ranks": comm.size, "t": stepper.t, "step": stepper.step, "snapshots": snap_meta,
                    "current": current, "stepper": stepper.counters(), "tracker": tracker_meta, "rows": rows,
                    "profiles_closed": bool(profiles.closed) if profiles else False,
                    "contact": {"kappa": contact.kappa, "raised": contact.raised} if contact is not None else None}
            sink.put("meta", np.frombuffer(writes.json_text(meta, exact=True, indent=None).encode(), dtype=np.uint8))
        except (TypeError, ValueError) as err:
            sink.error = sink.error or err
        sink.close()
        if sink.error is None:
            try:
                writes.commit(tmp, final)
                size = float(final.stat().st_size)
            except OSError as err:
                sink.error = err
        if sink.error is not None:
            tmp.unlink(missing_ok=True)
            error = f"{type(sink.error).__name__}: {sink.error}"
    error = comm.bcast(error, root=0)
    if error:
        raise OSError(f"checkpoint not written: {error}")
    return size


def remove(outdir, comm) -> None:
    """Delete the checkpoint (collective; after a run that ended normally)."""
    if comm.rank == 0:
        for name in (FILE, FILE + ".tmp"):
            (Path(outdir) / name).unlink(missing_ok=True)
    comm.barrier()


# --- reading ---------------------------------------------------------------------------------------


@dataclass
class Resume:
    """A checked checkpoint: its path, its meta and the branch's surface profiles so far (on every rank)."""

    path: Path
    meta: dict
    profile_arrays: dict | None = None  # PROFILE_MEMBERS' keys -> arrays; None before a branch

    def profiles(self):
        """The followed branch's :class:`~app.model.surface.SurfaceProfiles` up to the checkpoint."""
        if not self.profile_arrays:
            return SurfaceProfiles()
        return SurfaceProfiles.from_arrays(self.profile_arrays, self.meta.get("profiles_closed", False))

    @property
    def rows(self) -> list:
        return self.meta["rows"]

    @property
    def crossings(self) -> int:
        return len((self.meta["tracker"] or {}).get("crossings", ()))


def _read(path: Path, cfg: dict) -> tuple[dict, dict | None]:
    """Rank 0: the meta of a checkpoint file and its surface profiles (None if it has none), after
    reading every member (a corrupt file fails here)."""
    where = f"--resume '{path.parent}'"
    if not path.parent.is_dir():
        raise CheckpointError(f"{where}: no such directory")
    if not path.is_file():
        raise CheckpointError(f"{where}: no checkpoint in it ({FILE}; a run writes one every "
                              "output.checkpoint_every accepted steps and when interrupted)")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(z["meta"].tobytes().decode())
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise ValueError(f"format {meta.get('format') if isinstance(meta, dict) else '?'}, not {FORMAT}")
            arrays = {name: z[name] for name in z.files if name != "meta"}  # reads all: CRC checked
        n, m = arrays["u_key"].size, arrays["q_key"].size
        d = arrays["x"].shape[1] if arrays["x"].ndim == 2 else 0
        if arrays["x"].shape != (n, d) or d not in (2, 3):
            raise ValueError("node coordinates do not match the node keys")
        for s in meta["snapshots"]:
            for field, shape in (("state_u", (n, d)), ("state_q", (m,)), ("rate_u", (n, d)), ("dQ_prev", (m,))):
                if arrays[s[field]].shape != shape:
                    raise ValueError(f"array {s[field]} has shape {arrays[s[field]].shape}, not {shape}")
        for key in ("result_hash", "inputs", "t", "step", "current", "stepper", "tracker", "rows"):
            meta[key]  # noqa: B018 - every key must be there
        float(meta["config"]["time"]["end"])
        profiles = None
        if PROFILE_MEMBERS["time"] in arrays:
            profiles = {name: arrays[member] for name, member in PROFILE_MEMBERS.items()}
            steps = profiles["time"].shape
            # position: (steps, nodes) along a curve, (steps, nodes, 2) over a 3D surface
            if (profiles["growth_mm"].shape != steps or profiles["position"].ndim not in (2, 3)
                    or profiles["position"].shape[0] != steps[0]
                    or profiles["profile"].shape != profiles["position"].shape[:2]):
                raise ValueError("the surface profiles' arrays do not match")
    except (OSError, ValueError, KeyError, TypeError, IndexError, EOFError, zipfile.BadZipFile) as err:
        reason = f"{type(err).__name__}: {err}".replace("\n", " ")
        raise CheckpointError(f"{where}: the checkpoint {FILE} is unreadable ({reason[:200]})") from None
    if meta["result_hash"] != result_hash(cfg):
        diff = first_difference(meta["config"], cfg) or "the result-changing keys' hash"
        raise CheckpointError(f"{where}: the config differs from the checkpoint's in a key that changes the "
                              f"result: {diff}")
    for key, digest in input_files(cfg).items():
        if meta["inputs"].get(key) != digest:
            raise CheckpointError(f"{where}: the file {key} = '{cfg['geometry']['file']}' changed since the "
                                  "checkpoint (another sha256)")
    end, old_end, t = cfg["time"]["end"], meta["config"]["time"]["end"], meta["t"]
    if end != old_end:  # a step is clipped only to reach time.end: states before it do not depend on it
        if t >= old_end * (1 - 1e-12):
            raise CheckpointError(f"{where}: the checkpoint is at its run's end (t = time.end = {old_end:g} s): "
                                  f"time.end = {end:g} needs a new run")
        if end <= t * (1 + 1e-12):
            raise CheckpointError(f"{where}: time.end = {end:g} is not after the checkpoint's time t = {t:.6g} s")
    return meta, profiles


def check(outdir, cfg: dict, comm) -> Resume:
    """The checkpoint of ``outdir`` if ``cfg`` may resume it (read and checked on rank 0), or a
    :class:`CheckpointError` on every rank: no checkpoint, a corrupt one, a result-changing key changed."""
    path = Path(outdir) / FILE
    result = None
    if comm.rank == 0:
        try:
            result = _read(path, cfg)
        except CheckpointError as err:
            result = str(err)
    result = comm.bcast(result, root=0)
    if isinstance(result, str):
        raise CheckpointError(result)
    return Resume(path, *result)


def restore(resume: Resume, problem, stepper, tracker) -> DofLayout:
    """Put the checkpoint's state into a freshly built problem, stepper and tracker (collective, on any
    number of ranks): the stored snapshots are rebuilt on this layout, then the stepper and the tracker
    take their own parts of the meta (``resume_from``, ``restore_checkpoint``). Returns the layout (for
    later checkpoints)."""
    layout = DofLayout(problem)
    comm, meta = layout.comm, resume.meta
    z = np.load(resume.path, allow_pickle=False) if comm.rank == 0 else None
    try:
        try:
            layout.locate((z["u_key"], z["x"], z["q_key"]) if z is not None else None)
        except LayoutMismatch as err:  # on every rank alike
            raise CheckpointError(str(err)) from None
        n_total = comm.allreduce(layout.nu), comm.allreduce(layout.nq)
        if z is not None and n_total != (z["u_key"].size, z["q_key"].size):
            problem_text = f"{n_total} (nodes, facets) now, {(z['u_key'].size, z['q_key'].size)} in the checkpoint"
        else:
            problem_text = None
        problem_text = comm.bcast(problem_text, root=0)
        if problem_text:
            raise CheckpointError(f"the checkpoint does not fit the mesh this config builds: {problem_text}")
        cache: dict[str, np.ndarray] = {}

        def local(name: str, kind: str) -> np.ndarray:
            if name not in cache:
                cache[name] = layout.scatter(kind, z[name] if z is not None else None)
            return cache[name]

        snaps = [stepper.snapshot_of(layout.mixed(local(s["state_u"], "u"), local(s["state_q"], "q")),
                                     local(s["rate_u"], "u").ravel().copy(), local(s["dQ_prev"], "q") * layout.q_sign,
                                     s) for s in meta["snapshots"]]
    finally:
        if z is not None:
            z.close()
    stepper.resume_from(snaps[meta["current"]], meta["stepper"])
    if meta.get("contact") and problem.contact is not None:  # the penalty as the run had raised it
        problem.contact.set_kappa(meta["contact"]["kappa"])
        problem.contact.raised = [tuple(r) for r in meta["contact"]["raised"]]
    if meta["tracker"] is not None:
        tracker.restore_checkpoint(meta["tracker"], snaps)
    comm.barrier()
    return layout


class Checkpoints:
    """The run loop's checkpoints: every ``every`` accepted steps and on request (an interrupt)."""

    def __init__(self, outdir, cfg: dict, every: int, log=None):
        self.outdir, self.cfg, self.every = Path(outdir), cfg, every
        self.log = log or (lambda msg: None)
        self.layout = None
        self.last_step = None  # the step of the last checkpoint written (or resumed from)
        self.sizes: list[float] = []

    def resumed(self, layout: DofLayout, step: int) -> None:
        self.layout, self.last_step = layout, step

    def due(self, step: int) -> bool:
        return bool(self.every) and step % self.every == 0 and step != self.last_step

    def write(self, problem, stepper, tracker, rows, profiles=None) -> None:
        if not self.every or stepper.step == self.last_step:
            return
        if self.layout is None:
            self.layout = DofLayout(problem)
        try:
            size = write(self.outdir, self.cfg, self.layout, stepper, tracker, rows, profiles,
                         getattr(problem, "contact", None))
        except OSError as err:  # the run goes on; the previous checkpoint stays
            self.log(f"hydrobuckle: warning: {err}")
            return
        self.last_step = stepper.step
        self.sizes.append(size)

    def remove(self, comm) -> None:
        remove(self.outdir, comm)
