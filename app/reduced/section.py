"""The cross-section of a laterally uniform bilayer or an axisymmetric tube: layers along one coordinate,
where fluid enters, what is held, and the 1D mesh.

Planar (``geometry.kind = "bilayer"``): Y from the substrate's base (Y = 0, roller: u_y = 0, no flux) to
the film's permeable surface (Y = H + w). Axisymmetric (``"tube"``): r from the passage (r = R - H - w,
the film's permeable surface) to the rigid impermeable wall (r = R: u = 0, no flux).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app.model.loading import Loading
from app.model.material import Material

KINDS = ("bilayer", "tube")
CRITERIA = ("drained", "undrained", "rate")  # the stability criteria with a 1D counterpart (modes.py)
LOADINGS = {"bilayer": ("swelling", "compression"), "tube": ("swelling",)}


class NotReducible(ValueError):
    """The config has no exact 1D counterpart (the reason says which key)."""


@dataclass(frozen=True)
class Layer:
    material: str
    start: float
    end: float

    @property
    def thickness(self) -> float:
        return self.end - self.start


@dataclass(frozen=True)
class Section:
    shape: str  # "planar" or "axisymmetric"
    layers: tuple[Layer, ...]  # in increasing coordinate
    surface: float  # coordinate of the permeable surface
    base: float  # coordinate of the held boundary
    length: float | None  # planar: the bilayer's length L (wavenumber k = n pi / L)
    materials: dict[str, Material]
    loading: Loading
    film: str = "film"

    @property
    def film_layer(self) -> Layer:
        return next(lay for lay in self.layers if lay.material == self.film)

    @property
    def film_thickness(self) -> float:
        return self.film_layer.thickness

    def wavenumber(self, n: float) -> float:
        """k of mode n: n pi / L along the bilayer (N = n/2 wrinkles); n around the tube."""
        return n * math.pi / self.length if self.shape == "planar" else float(n)

    def wrinkle_count(self, n: int) -> float:
        """What the 2D runs report as N_c for mode n: half-waves / 2 along the bilayer, n around the tube."""
        return n / 2 if self.shape == "planar" else float(n)

    def local_wavenumber(self, n: float) -> float:
        """The wavenumber along the permeable surface [1/mm] (around the tube: n / passage radius)."""
        return self.wavenumber(n) if self.shape == "planar" else n / self.surface

    def nodes(self, film_cells: int, grading: float, surface_grading: float = 1.0) -> np.ndarray:
        """Vertices of the 1D mesh: ``film_cells`` cells through the film, each ``surface_grading`` times
        the one nearer the permeable surface (where the state has a diffusion boundary layer); away from the
        film each cell ``grading`` times the one before, from the film's cell at the interface."""
        film = self.film_layer
        toward_start = self.surface == film.start  # the permeable surface at the film's start (the tube)
        q = surface_grading
        sizes = q ** np.arange(film_cells)  # from the surface inwards
        sizes *= film.thickness / sizes.sum()
        x = np.concatenate([[0.0], np.cumsum(sizes)])
        x[-1] = film.thickness
        pts = [film.start + x if toward_start else film.end - x[::-1]]
        h = sizes[-1]  # the film's cell at the interface
        for lay in self.layers:
            if lay is film:
                continue
            pts.append(_graded(lay.thickness, h * grading, grading, from_start=lay.start == film.end) + lay.start)
        return np.unique(np.round(np.concatenate(pts), 15))


def _graded(length: float, first: float, ratio: float, from_start: bool) -> np.ndarray:
    """Vertices of [0, length] whose cells grow by ``ratio`` from ``first`` (at 0, or at ``length``),
    the sizes scaled so the last cell ends exactly at the far end."""
    sizes = [first]
    while sum(sizes) < length:
        sizes.append(sizes[-1] * ratio)
    if len(sizes) > 1 and sum(sizes) - length > 0.5 * sizes[-1]:
        sizes.pop()
    sizes = np.array(sizes) * (length / sum(sizes))
    x = np.concatenate([[0.0], np.cumsum(sizes)])
    x[-1] = length
    return x if from_start else length - x[::-1]


def drive(cfg: dict):
    from app.geometry.base import Drive

    geo = cfg["geometry"]
    return Drive("right", 0, geo["length"]) if geo["kind"] == "bilayer" else None


def reducible(cfg: dict) -> str:
    """'' when the config has an exact 1D reduction, else the reason (naming the key)."""
    geo, lo = cfg["geometry"], cfg["loading"]
    if geo["kind"] not in KINDS:
        return (f"geometry.kind = {geo['kind']!r}: the 1D reduction covers the laterally uniform bilayer and the "
                f"circular tube ({', '.join(KINDS)})")
    if lo["kind"] not in LOADINGS[geo["kind"]]:
        return (f"loading.kind = {lo['kind']!r}: the 1D reduction of a {geo['kind']} covers "
                f"{', '.join(LOADINGS[geo['kind']])}")
    criterion = cfg["stability"]["criterion"]
    if criterion not in CRITERIA:
        return f"stability.criterion = {criterion!r}: the 1D reduction covers {', '.join(CRITERIA)}"
    extra = set(cfg["material"].get("layers", {}) or {})
    if extra:
        return "material.layers: the 1D reduction covers the two-layer film/substrate section only"
    return ""
