"""A result directory read back: :class:`Result` (what a run or the 1D reduction wrote: its summary, its
history's columns, its files, g_c with its error bar and N_c) and :class:`Study` (a study's or sweep's rows and
each case's result). :mod:`app.api` returns them.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


def _read_csv(path: Path) -> dict[str, Any]:
    """A CSV file's columns by name: numeric columns as float arrays (empty cells NaN), others as lists."""
    if not path.is_file():
        return {}
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return {}
    header, body = rows[0], rows[1:]
    columns: dict[str, Any] = {}
    for j, name in enumerate(header):
        cells = [r[j] if j < len(r) else "" for r in body]
        try:
            columns[name] = np.array([float(c) if c != "" else np.nan for c in cells])
        except ValueError:
            columns[name] = cells
    return columns


@dataclass(frozen=True, eq=False)
class Result:
    """What a run (or the 1D reduction) wrote into its result directory, read back.

    ``g_c_um`` is the critical growth in micrometres (None when the run found no onset), ``g_c_error_um``
    its estimated discretization error (the companion runs of ``stability.error_estimate``, or the 1D
    reduction's three levels), ``N_c`` the wrinkle count. ``summary`` is summary.json as a dict, ``history``
    history.csv's columns (numeric ones as numpy arrays), ``files`` every file of the directory by name."""

    outdir: Path
    summary: dict = field(repr=False)
    history: dict = field(repr=False)

    @classmethod
    def load(cls, outdir: str | Path) -> Result:
        """The result in ``outdir`` (a directory written by ``run``, ``reduced`` or their commands)."""
        outdir = Path(outdir)
        path = outdir / "summary.json"
        if not path.is_file():
            raise FileNotFoundError(f"{outdir} has no summary.json: not a finished hydrobuckle result")
        return cls(outdir, json.loads(path.read_text()), _read_csv(outdir / "history.csv"))

    # -- the answer -------------------------------------------------------------------------------------
    @property
    def status(self) -> str:
        """``buckled``, ``stable``, ``equilibrium``, ``failed``, ``interrupted``, or a postbuckling end."""
        return self.summary["status"]

    @property
    def solver(self) -> str:
        """``2d`` for a FEniCSx run, ``reduced-1d`` for the exact 1D reduction."""
        return self.summary.get("solver", "2d")

    @property
    def _onset(self) -> dict:
        if self.solver == "reduced-1d":
            return self.summary.get("reduced") or {}
        return self.summary.get("critical") or {}

    @property
    def g_c_um(self) -> float | None:
        """The critical growth g_c [um]: the increase of thickness when the film wrinkles."""
        return self._onset.get("growth_um")

    @property
    def g_c_error_um(self) -> float | None:
        """g_c's estimated discretization error [um] (None when not estimated)."""
        if self.solver == "reduced-1d":
            return self._onset.get("growth_error_um")
        est = self._onset.get("discretization_error") or {}
        if est.get("time_um") is None and est.get("mesh_um") is None:
            return None  # no companion gave an estimate (summary.json's discretization_error says why)
        return est.get("total_um")

    @property
    def N_c(self) -> float | None:  # noqa: N802 - the paper's name
        """The critical wrinkle count (wavelengths along the surface, to half a wave)."""
        return self._onset.get("wrinkle_count")

    @property
    def critical_time(self) -> float | None:
        """The time of the onset [s]."""
        return self._onset.get("time")

    @property
    def reduced(self) -> Result | None:
        """The exact 1D counterpart reported beside a 2D run (``reduced.beside_2d``), as a result of its
        own (no directory of its own: ``outdir`` is the run's, ``history`` empty); None when not computed."""
        block = self.summary.get("reduced")
        if self.solver == "reduced-1d" or not isinstance(block, dict) or "growth_um" not in block:
            return None
        status = "buckled" if block.get("kind") != "stable" else "stable"
        return Result(self.outdir, {"status": status, "solver": "reduced-1d", "reduced": block}, {})

    @property
    def files(self) -> dict[str, Path]:
        """Every file the result directory holds, by name (``summary.json``, ``history.csv``, ``fields.xdmf``,
        ``mode.png``, ...)."""
        return {p.name: p for p in sorted(self.outdir.iterdir()) if p.is_file() and not p.name.startswith(".")}

    def __str__(self) -> str:
        if self.g_c_um is None:
            return f"{self.status} ({self.outdir})"
        err = f" +- {self.g_c_error_um:.4f} um" if self.g_c_error_um is not None else ""
        n = f", N_c = {self.N_c:g}" if self.N_c is not None else ""
        return f"g_c = {self.g_c_um:.4f} um{err}{n} ({self.status}, {self.outdir})"


@dataclass(frozen=True, eq=False)
class Study:
    """A study's or sweep's answer: one row per case (as study.csv) and each case's :class:`Result`."""

    outdir: Path
    title: str
    parameter: str
    rows: list = field(repr=False)

    @property
    def complete(self) -> bool:
        """Whether every case ended complete (buckled, stable or at equilibrium)."""
        from app.workflows.studies import COMPLETE  # (lazy: reading a result needs no solver stack)

        return all(r["status"] in COMPLETE for r in self.rows)

    @property
    def results(self) -> list[Result | None]:
        """Each case's result, row by row (None for a case that wrote no summary: not run, or killed)."""
        out = []
        for r in self.rows:
            path = self.outdir / r["directory"]
            out.append(Result.load(path) if (path / "summary.json").is_file() else None)
        return out

    @property
    def files(self) -> dict[str, Path]:
        """The study's own files (study.csv, study.json, study.png, modes.png, isomodes.png)."""
        return {p.name: p for p in sorted(self.outdir.iterdir()) if p.is_file() and not p.name.startswith(".")}
