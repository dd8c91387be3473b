"""Result directory: resolved config, history.csv, summary.json, fields.xdmf and plots.

Rank 0 writes the text files; the XDMF field file is written collectively. A run first removes
any ``summary.json`` left in the directory, so a directory holds a summary only once the run that
wrote it has ended (``status`` says how). A file that cannot be written (a full disk) does not stop
the writer with an exception: it records the first :class:`~app.io.writes.ResultWriteError` (the same
on every rank) in :attr:`ResultWriter.error`, goes on writing what it can, and the run loop stops.
"""

from __future__ import annotations

import csv
import io
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from app import compat, config, fem_utils, timing
from app.io import writes
from app.io.writes import ResultWriteError
from app.io.xdmf import FieldSeries, ballast_path
from app.model.fields import fields_for, state_of
from app.model.surface import boundary_displacement, shape_of

MODE_FILES = ("mode.xdmf", "mode.h5", "mode.png", "mode_surface.csv")  # written at the first crossing
CHECKPOINT_FILES = ("checkpoint.npz", "checkpoint.npz.tmp")  # app.io.checkpoint
RESULT_FILES = ("summary.json", "history.csv", "config.toml", "fields.xdmf", "fields.h5", "history.png",
                "mode.xdmf", "mode.h5", "mode.png", "mode_surface.csv")
# left by a run killed while writing: the space kept aside for closing an XDMF file, a file written aside
SCRATCH_FILES = (ballast_path("fields.xdmf").name, ballast_path("mode.xdmf").name, writes.SPACE_PROBE,
                 "history.csv.tmp", "fields.xdmf.tmp", "mode.xdmf.tmp",
                 *(writes.aside(name).name for name in ("config.toml", "summary.json", "history.png", "mode.png",
                                                         "mode_surface.csv")))


def versions() -> dict:
    import dolfinx
    import gmsh
    from petsc4py import PETSc
    from slepc4py import SLEPc

    from app.version import __version__

    def v(mod):
        return ".".join(str(x) for x in mod.Sys.getVersion())

    try:  # the barrier self-contact's library (scripts/requirements.txt)
        import ipctk

        ipc = ipctk.__version__
    except ImportError:
        ipc = "not installed"
    return {"hydrobuckle": __version__, "dolfinx": dolfinx.__version__, "petsc": v(PETSc),
            "slepc": v(SLEPc), "gmsh": gmsh.__version__, "ipctk": ipc}


def rewrite_summary(outdir, comm, summary: dict) -> None:
    """Write summary.json (rank 0, atomically); collective, so every rank may read it afterwards. A
    :class:`~app.io.writes.ResultWriteError` on every rank if it cannot be written."""
    path = Path(outdir) / "summary.json"
    writes.on_rank0(comm, path, writes.write_json, path, summary)


@dataclass(frozen=True)
class OutputSettings:
    """The [output] table: which result files a run writes besides history and summary."""

    fields: bool = True  # fields.xdmf
    every: int = 1  # fields every n accepted steps
    plot: bool = True  # history.png, mode.png
    checkpoint_every: int = 10  # checkpoint.npz every n accepted steps (0: none; app.io.checkpoint)

    @classmethod
    def from_config(cls, cfg: dict) -> OutputSettings:
        o = cfg["output"]
        return cls(o["fields"], o["every"], o["plot"], o["checkpoint_every"])


class ResultWriter:
    """Writes one run's results into ``outdir``: what ``settings`` asks for, and the resolved ``cfg``
    as config.toml (the record of the run).

    Only the constructor raises a :class:`~app.io.writes.ResultWriteError` (nothing is computed yet);
    later a file that cannot be written is recorded in :attr:`error` (the first one, the same on every
    rank) and the writer goes on with the others: history.csv keeps its whole rows, a field file that
    failed is not written to again."""

    def __init__(self, outdir: str | Path, comm, cfg: dict, settings: OutputSettings, columns=None,
                 resume_rows: list | None = None, keep_mode: bool = False):
        """``resume_rows``: a run resumed from its checkpoint (``run --resume``): history.csv is rewritten
        with these rows (the checkpoint's) and continued; the other result files are removed as for a new
        run (fields.xdmf restarts at the resumed step), except the mode files with ``keep_mode`` (the
        checkpoint is past the first crossing, whose mode they hold). A new run also removes the
        directory's checkpoint."""
        self.outdir = Path(outdir)
        self.comm = comm
        self.cfg = cfg
        self.settings = settings
        self.rank0 = comm.rank == 0
        self.columns = list(columns) if columns else None
        self._history = None  # rank 0: the open history.csv (writes.RowFile)
        self._header = True  # history.csv still needs its header line
        self._history_failed = False
        self._xdmf = None
        self._fields_step = None  # the accepted step whose fields were written last
        self.error: ResultWriteError | None = None
        self.rows: list[dict] = []
        keep = set() if resume_rows is None else {"history.csv", *(MODE_FILES if keep_mode else ())}
        writes.on_rank0(comm, self.outdir, self._prepare, keep, resume_rows is None)
        text = "# hydrobuckle resolved configuration (every key, defaults filled in)\n" + config.dumps(cfg)
        writes.on_rank0(comm, self.outdir / "config.toml", writes.write_text, self.outdir / "config.toml", text)
        if resume_rows is not None:
            writes.on_rank0(comm, self.outdir / "history.csv", self._rewrite_history, resume_rows)
            self.rows = list(resume_rows)

    def _prepare(self, keep: set, new_run: bool) -> None:
        """Rank 0: the directory, without the result files of an earlier run (and its checkpoint)."""
        self.outdir.mkdir(parents=True, exist_ok=True)
        for name in RESULT_FILES + SCRATCH_FILES:
            if name not in keep:
                (self.outdir / name).unlink(missing_ok=True)
        shutil.rmtree(self.outdir / "error-estimate", ignore_errors=True)
        if new_run:
            for name in CHECKPOINT_FILES:
                (self.outdir / name).unlink(missing_ok=True)

    def _record(self, err: ResultWriteError) -> None:
        if self.error is None:
            self.error = err

    def _rewrite_history(self, rows: list) -> None:
        """Rank 0: history.csv holding exactly ``rows`` (written aside, then renamed), open for appending."""
        path = self.outdir / "history.csv"
        tmp = path.with_name("history.csv.tmp")
        self._header = True
        aside = writes.RowFile(tmp, new=True)
        try:
            for row in rows:
                aside.append(self._row_text(row))
            aside.close()
            writes.commit(tmp, path)
        except BaseException:
            aside.close()
            tmp.unlink(missing_ok=True)
            raise
        self._history = writes.RowFile(path, new=False)

    # --- history ---------------------------------------------------------------------------

    def history_row(self, row: dict) -> None:
        """Append one accepted step to history.csv (whole, straight to the file; collective: every rank
        learns whether it was written). After a failed row no further row is written: the file keeps
        every row up to the last one written, each whole."""
        with timing.timed("output"):
            self.rows.append(row)
            if self._history_failed:
                return
            path = self.outdir / "history.csv"
            try:
                writes.on_rank0(self.comm, path, self._append_row, row)
            except ResultWriteError as err:
                self._history_failed = True
                self._record(err)

    def _append_row(self, row: dict) -> None:
        if self._history is None:
            self._history, self._header = writes.RowFile(self.outdir / "history.csv", new=True), True
        self._history.append(self._row_text(row))

    def _row_text(self, row: dict) -> str:
        """One CSV row (the header line before the first one)."""
        buf = io.StringIO()
        self.columns = self.columns or list(row)
        w = csv.DictWriter(buf, fieldnames=self.columns, extrasaction="ignore")
        if self._header:
            w.writeheader()
        w.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()})
        text = buf.getvalue()
        self._header = False
        return text

    # --- fields ----------------------------------------------------------------------------

    def setup_fields(self, problem) -> None:
        """Compile the post-processing expressions once (:mod:`app.model.fields`), if fields are written."""
        if not self.settings.fields or self.error is not None:
            return
        domain = problem.domain
        try:
            self._xdmf = FieldSeries(self.comm, self.outdir / "fields.xdmf", domain, "fields")
        except ResultWriteError as err:
            self._record(err)
            return
        self._fields = []
        for name, space, expr in field_expressions(problem):
            f = fem.Function(space)
            f.name = name
            self._fields.append((f, compat.expression(expr, space)))
        if problem.contact is not None:  # the self-contact's traction on the surface nodes [MPa]
            f = fem.Function(compat.vector_space(domain, "Lagrange", 1))  # the displacement's output space
            f.name = "contact_traction"
            on_u = fem.Function(problem.V_u)  # the traction where the solver's dofs are, then interpolated

            def fill(target, state=problem.state, contact=problem.contact):
                contact.traction_into(on_u, state.x.array)
                target.interpolate(on_u)

            self._fields.append((f, _ComputedField(fill)))

    def write_fields(self, t: float, step: int = 0, last: bool = False) -> None:
        """The fields at time t, if they are written at accepted step number ``step`` (every
        ``output.every`` steps; with ``last``, the run's final state, unless that step was written)."""
        if self._xdmf is None or (step % self.settings.every if not last else step == self._fields_step):
            return
        self._fields_step = step
        with timing.timed("output"):
            for f, expr in self._fields:
                if isinstance(expr, _ComputedField):  # a field that is not a UFL expression (the contact traction)
                    expr.fill(f)
                else:
                    f.interpolate(expr)
            try:
                self._xdmf.write([f for f, _ in self._fields], t)
            except ResultWriteError as err:
                self._record(err)
                self._close_fields()  # no further output time (the file stays valid up to the last one)

    def _close_fields(self) -> None:
        if self._xdmf is not None:
            xdmf, self._xdmf = self._xdmf, None
            try:
                xdmf.close()
            except ResultWriteError as err:
                self._record(err)

    # --- buckling mode ---------------------------------------------------------------------

    def write_mode(self, problem, crossing) -> None:
        """mode.xdmf (mode displacement normalized to max |u| = 1, and the state it buckles from)
        and mode.png (the deformed surface region with the mode superposed)."""
        Vu, u_dofs = problem.V_u, problem.u_dofs
        mode = fem.Function(Vu)
        mode.name = "mode"
        mode.x.array[:] = crossing.mode[u_dofs]
        peak = self.comm.allreduce(float(abs(mode.x.array).max()) if mode.x.array.size else 0.0, op=_max())
        if peak > 0:
            mode.x.array[:] /= peak
        base = fem.Function(Vu)
        base.name = "critical_displacement"
        base.x.array[:] = crossing.state[u_dofs]
        try:
            with FieldSeries(self.comm, self.outdir / "mode.xdmf", problem.domain, "mode") as f:
                f.write([base, mode], crossing.time)
        except ResultWriteError as err:
            self._record(err)
        three_d = problem.domain.geometry.dim == 3
        polys = None if three_d else _gather_cells(problem, base.x.array, mode.x.array)
        groups = problem.geo.facets_with_role("permeable")
        coords, disp = boundary_displacement(problem, crossing.mode, groups)
        _, state_disp = boundary_displacement(problem, crossing.state, groups)
        surface = self.outdir / "mode_surface.csv"  # the surface data the study galleries draw from
        axes = "xyz"[:coords.shape[1]]
        header = ",".join([*axes, *(f"mode_u{a}" for a in axes), *(f"state_u{a}" for a in axes)])
        try:
            writes.on_rank0(self.comm, surface, writes.replace_file, surface, lambda tmp: np.savetxt(
                tmp, np.column_stack([coords, disp, state_disp]), delimiter=",", header=header, comments=""))
        except ResultWriteError as err:
            self._record(err)
        shape = shape_of(problem)
        position, normal = shape.plotted(coords, disp)
        profile = (position, normal / (np.abs(normal).max() or 1.0), shape.position_label, "normal mode displacement")
        if self.settings.plot:
            from app.io.plots import mode_map_plot, mode_plot

            png = self.outdir / "mode.png"
            try:
                if three_d:  # the surface from above: its normal mode displacement as a colour map
                    writes.on_rank0(self.comm, png, writes.replace_file, png,
                                    lambda tmp: mode_map_plot(profile, crossing, tmp, shape.map_axes, shape.wave_label))
                else:
                    writes.on_rank0(self.comm, png, writes.replace_file, png,
                                    lambda tmp: mode_plot(polys, profile, problem.geo, crossing, tmp))
            except ResultWriteError as err:
                self._record(err)

    # --- summary and plot ------------------------------------------------------------------

    def summary(self, data: dict) -> None:
        """summary.json (a failure is recorded in :attr:`error`)."""
        try:
            rewrite_summary(self.outdir, self.comm, data)
        except ResultWriteError as err:
            self._record(err)

    def plot_history(self, critical: dict | None = None) -> None:
        """history.png, if plots are written; ``critical`` (the summary's block) marks the onset (t_c, g_c)."""
        if not self.rows or not self.settings.plot:
            return
        from app.io.plots import history_plot

        png = self.outdir / "history.png"
        try:
            writes.on_rank0(self.comm, png, writes.replace_file, png,
                            lambda tmp: history_plot(self.rows, tmp, critical))
        except ResultWriteError as err:
            self._record(err)

    def plot_branch(self, profiles, critical: dict | None, shape=None, patterns: list | None = None) -> None:
        """After a followed branch: the surface profiles themselves, profiles.npz (growth, time, position and
        profile of every step on the branch; :class:`app.model.surface.SurfaceProfiles`), and wrinkles.png
        and amplitude.png if plots are written (collective, like :meth:`plot_history`). In 3D (``shape``: a
        surface, with ``patterns``, :func:`app.model.patterns.branch_patterns`) pattern.png replaces
        wrinkles.png: the surface from above at those states."""
        if not profiles:
            return
        from app.io.plots import amplitude_plot, pattern_plot, wrinkles_plot

        def save_npz(tmp):
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **profiles.arrays())

        outputs = [("profiles.npz", save_npz)]
        if self.settings.plot:
            creases = {float(r["time"]): int(r["creases"]) for r in self.rows if r.get("creases") not in (None, "")}
            if shape is not None and shape.surface_dim == 2:
                outputs.append(("pattern.png", lambda tmp: pattern_plot(profiles, patterns or [], shape, tmp)))
            else:
                outputs.append(("wrinkles.png", lambda tmp: wrinkles_plot(profiles.tuples(), critical, profiles.closed,
                                                                          tmp, creases=creases)))
            outputs.append(("amplitude.png", lambda tmp: amplitude_plot(self.rows, critical, tmp)))

        def files():
            for name, write in outputs:
                path = self.outdir / name
                writes.at(path, writes.replace_file, path, write)

        try:
            writes.on_rank0(self.comm, self.outdir, files)
        except ResultWriteError as err:
            self._record(err)

    def close(self) -> None:
        self._close_fields()
        if self._history is not None:
            self._history.close()
            self._history = None


class _ComputedField:
    """A field computed outside UFL: ``fill(f)`` writes it into the Function f."""

    def __init__(self, fill):
        self.fill = fill


def field_expressions(problem):
    """(name, space, UFL expression) of every registered field (:mod:`app.model.fields`) that the problem's
    mesh gets, from the converged state."""
    state = state_of(problem)
    domain = problem.domain
    spaces = {"nodal vector": lambda: compat.vector_space(domain, "Lagrange", 1),
              "cell scalar": lambda: compat.scalar_space(domain, "DG", 0),
              "cell vector": lambda: compat.vector_space(domain, "DG", 0)}
    made = {}
    out = []
    for field in fields_for(state.dim):
        if field.space not in made:
            made[field.space] = spaces[field.space]()
        out.append((field.name, made[field.space], field.expression(state)))
    return out


def _max():
    return MPI.MAX


def _gather_cells(problem, base: np.ndarray, mode: np.ndarray):
    """On rank 0: (vertex coordinates, base displacement, mode) per owned cell, polygon-ordered."""
    V = problem.V_u
    X = V.tabulate_dof_coordinates()[:, :2]
    n_cells = fem_utils.num_owned_cells(problem.domain)
    cells = np.array([V.dofmap.cell_dofs(c) for c in range(n_cells)], dtype=np.int64).reshape(n_cells, -1)
    cells = cells[:, [0, 1, 3, 2]]  # tensor-product vertex order -> polygon order
    layer = np.zeros(n_cells, dtype=np.int32)
    ct = problem.tm.cell_tags
    owned = ct.indices < n_cells
    layer[ct.indices[owned]] = ct.values[owned]
    data = (X[cells], base.reshape(-1, 2)[cells], mode.reshape(-1, 2)[cells], layer)
    gathered = problem.comm.gather(data, root=0)
    if problem.comm.rank != 0:
        return None
    return tuple(np.concatenate([g[i] for g in gathered]) for i in range(4))
