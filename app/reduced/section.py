"""The cross-section of a laterally uniform bilayer or an axisymmetric tube: layers along one coordinate,
where fluid enters, what is held, and the 1D mesh. Which geometry kinds have one, for which loadings, and its
layers: each kind says (:meth:`app.geometry.base.GeometryKind.cross_section`, ``reduced_loadings``); nothing
here names a kind.

Planar (``geometry.kind = "bilayer"``): Y from the substrate's base (Y = 0, roller: u_y = 0, or clamped: u = 0;
no flux) to
the film's permeable surface (Y = H + w). The 3D plate (``"plate"``) has the same section: its laterally
uniform state is the bilayer's, and a mode cos(m pi x / L) cos(n pi z / W) of its rollered rectangle reduces
to the planar one at |k| = pi sqrt((m/L)^2 + (n/W)^2) (the in-plane polarized part; the antiplane part is a
shear that stays stable), so its modes are the lattice of those |k|, numbered in increasing order.
Axisymmetric (``"tube"``): r from the passage (r = R - H - w, the film's permeable surface) to the rigid
impermeable wall (r = R: u = 0, no flux). The 3D tube (``"tube-3d"``, ends on rollers) has the same section
and the same axially uniform modes (n around, no axial wave: wave vector (n, 0)); its modes with axial waves
are the 3D run's alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from app import geometry
from app.model.loading import Loading
from app.model.material import Material

CRITERIA = ("drained", "undrained", "rate")  # the stability criteria with a 1D counterpart (modes.py)
LATTICE_WAVENUMBER = 40.0  # the plate's lattice of |k| is listed up to k w = this (above the tested maximum)


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
    width: float | None = None  # the 3D plate's width W along z (its modes: the lattice of |k|, see lattice())
    axial: bool = False  # the 3D tube: mode n is its axially uniform mode, wave vector (n, 0)
    clamped: bool = False  # planar: the base holds both displacement components (geometry.base = "clamped")

    @property
    def film_layer(self) -> Layer:
        return next(lay for lay in self.layers if lay.material == self.film)

    @property
    def film_thickness(self) -> float:
        return self.film_layer.thickness

    def wavenumber(self, n: float) -> float:
        """k of mode n: n pi / L along the bilayer (N = n/2 wrinkles); n around the tube; the plate's n-th
        distinct |k| of its lattice (n = 1, 2, ...)."""
        if self.width is not None:
            return float(self.lattice()[0][int(n) - 1])
        return n * math.pi / self.length if self.shape == "planar" else float(n)

    def wrinkle_count(self, n: int) -> float:
        """What the 2D runs report as N_c for mode n: half-waves / 2 along the bilayer, n around the tube,
        |k| L / (2 pi) on the plate (the bilayer's count for a stripe along x)."""
        if self.width is not None:
            return self.wavenumber(n) * self.length / (2 * math.pi)
        return n / 2 if self.shape == "planar" else float(n)

    def lattice(self) -> tuple[np.ndarray, list[list[tuple[int, int]]]]:
        """The plate's modes: the distinct |k| = pi sqrt((m/L)^2 + (n/W)^2) > 0 up to k w =
        LATTICE_WAVENUMBER in increasing order, and the half-wave pairs (m, n) of each (several where the
        sides allow equal |k|: (m, n) and (n, m) on a square)."""
        cached = _LATTICES.get((self.length, self.width, self.film_thickness))
        if cached is None:
            L, W = self.length, self.width
            k_max = LATTICE_WAVENUMBER / self.film_thickness
            m = np.arange(int(k_max * L / math.pi) + 1)
            n = np.arange(int(k_max * W / math.pi) + 1)
            mm, nn = np.meshgrid(m, n, indexing="ij")
            k2 = (mm / L) ** 2 + (nn / W) ** 2
            keep = (k2 > 0) & (k2 <= (k_max / math.pi) ** 2)
            mm, nn, k2 = mm[keep], nn[keep], k2[keep]
            order = np.lexsort((nn, mm, k2))
            mm, nn, k2 = mm[order], nn[order], k2[order]
            new = np.concatenate([[True], np.diff(k2) > 1e-12 * k2[1:]])  # equal |k| to roundoff: one mode
            starts = np.flatnonzero(new)
            ks = math.pi * np.sqrt(k2[starts])
            pairs = [list(zip(mm[a:b].tolist(), nn[a:b].tolist()))
                     for a, b in zip(starts, [*starts[1:], len(k2)])]
            cached = _LATTICES[(self.length, self.width, self.film_thickness)] = (ks, pairs)
        return cached

    def wave_vectors(self, n: int) -> list[tuple[int, int]] | None:
        """The plate's half-wave pairs (m, n) of mode n; the 3D tube's (n around, 0 along the axis); None
        for the 2D bilayer and tube."""
        if self.axial:
            return [(int(n), 0)]
        return self.lattice()[1][int(n) - 1] if self.width is not None else None

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


_LATTICES: dict = {}  # (L, W, w) -> Section.lattice()


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


def reducible(geometry_kind: str, loading_kind: str, criterion: str, extra_layers=()) -> str:
    """'' when a config of this geometry kind, loading and stability criterion, with these materials besides
    film and substrate (``material.layers``), has an exact 1D reduction; else the reason, naming the key
    (:func:`app.config.reducible` reads them from a config)."""
    kind = geometry.KINDS.get(geometry_kind) if geometry_kind in geometry.KINDS else None
    if kind is None or not kind.reduced_loadings:
        able = ", ".join(k.name for k in geometry.KINDS if k.reduced_loadings)
        return (f"geometry.kind = {geometry_kind!r}: the 1D reduction covers the laterally uniform bilayer and the "
                f"circular tube ({able})")
    if loading_kind not in kind.reduced_loadings:
        return (f"loading.kind = {loading_kind!r}: the 1D reduction of a {geometry_kind} covers "
                f"{', '.join(kind.reduced_loadings)}")
    if criterion not in CRITERIA:
        return f"stability.criterion = {criterion!r}: the 1D reduction covers {', '.join(CRITERIA)}"
    if set(extra_layers):
        return "material.layers: the 1D reduction covers the two-layer film/substrate section only"
    return ""
