"""Bilayered tube cross-sections (seed paper Figs. "tu_geo" and "tu_pbgeo"): circular or elliptical passage.

A film of uniform thickness w lines the passage; the substrate fills the space up to the outer
circle of radius R (held by a rigid, impermeable wall). The passage is an ellipse with semi-minor
axis b along x and semi-major axis a along y, a/b = ``aspect_ratio`` and a b = r^2 with
r = R - H - w (same area as the circle of radius r; aspect ratio 1 is the circular tube). The
film's outer edge is the offset curve of the ellipse (uniform thickness), not a scaled ellipse.

Structured all-quadrilateral mesh in four quadrants: nodes along the passage are uniform in arc
length (``element_size`` apart, a multiple of 4 in total); each film node sits on the normal of its
passage node; substrate nodes lie on the segment from the offset point radially out to the wall,
graded away from the film like the bilayer's. Physical groups: cells film, substrate; facets
inner (the passage surface), outer (the wall).

:func:`check_geometry` rejects impossible tubes (plain numpy, usable before any mesh exists);
:func:`add_model` builds the mesh in the current gmsh model (pure gmsh; see :mod:`meshes`).
"""

from __future__ import annotations

import math

import gmsh
import numpy as np

from meshes import add_physical
from meshes.bilayer import film_layer_heights, substrate_layer_heights

CELLS = {"film": 1, "substrate": 2}
FACETS = {"inner": 1, "outer": 2}


class GeometryError(ValueError):
    """An impossible or badly shaped geometry; ``key`` names the config key to change."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(message)

    def __reduce__(self):  # picklable, so a builder's error can be sent to every MPI rank
        return type(self), (self.key, str(self))


def semi_axes(passage_radius: float, aspect_ratio: float) -> tuple[float, float]:
    """(a, b): semi-major (y) and semi-minor (x) axes with a/b = aspect_ratio and a b = r^2."""
    a = passage_radius * math.sqrt(aspect_ratio)
    return a, passage_radius / math.sqrt(aspect_ratio)


def ellipse_point(a: float, b: float, phi):
    return np.stack([b * np.cos(phi), a * np.sin(phi)], axis=-1)


def ellipse_normal(a: float, b: float, phi):
    """Unit normal pointing out of the passage (into the film)."""
    n = np.stack([np.cos(phi) / b, np.sin(phi) / a], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def ellipse_perimeter(a: float, b: float, samples: int = 20001) -> float:
    phi = np.linspace(0, 2 * np.pi, samples)
    trapezoid = getattr(np, "trapezoid", None) or np.trapz  # numpy 2 renamed it (Debian 13), 1.x has trapz only
    return float(trapezoid(np.hypot(b * np.sin(phi), a * np.cos(phi)), phi))


def quadrant_parameters(a: float, b: float, m: int) -> np.ndarray:
    """m + 1 parameters on [0, pi/2] equally spaced in arc length (first quadrant)."""
    phi = np.linspace(0, np.pi / 2, 4001)
    ds = np.hypot(b * np.sin(phi), a * np.cos(phi))
    s = np.concatenate([[0.0], np.cumsum(0.5 * (ds[1:] + ds[:-1]) * np.diff(phi))])
    out = np.interp(np.linspace(0, s[-1], m + 1), s, phi)
    out[0], out[-1] = 0.0, np.pi / 2
    return out


def passage_parameters(a: float, b: float, m: int) -> np.ndarray:
    """4m parameters around the ellipse, mirror-symmetric about both axes, uniform in arc length."""
    q = quadrant_parameters(a, b, m)
    quads = [q[:-1], np.pi - q[::-1][:-1], np.pi + q[:-1], 2 * np.pi - q[::-1][:-1]]
    return np.concatenate(quads)


def layer_points(a, b, w, R, phi):
    """Passage points P, film offset points Q = P + w n, wall points C = R Q/|Q|."""
    P = ellipse_point(a, b, phi)
    Q = P + w * ellipse_normal(a, b, phi)
    C = R * Q / np.linalg.norm(Q, axis=-1, keepdims=True)
    return P, Q, C


def check_geometry(outer_radius: float, substrate_thickness: float, film_thickness: float,
                   aspect_ratio: float = 1.0, min_substrate_fraction: float = 0.5) -> dict:
    """Reject passages that are inverted, or where the film or substrate would be too thin."""
    R, H, w = outer_radius, substrate_thickness, film_thickness
    r = R - H - w
    if r <= 0:
        raise GeometryError("geometry.substrate_thickness",
                            f"passage radius R - H - w = {r:.4g} mm must be > 0; allowed: "
                            f"substrate_thickness + film_thickness < outer_radius = {R:g}")
    a, b = semi_axes(r, aspect_ratio)
    # The outward offset of a convex curve never folds, so the film is always valid; the substrate
    # between the offset curve and the wall is what can become thin.
    phi = np.linspace(0, np.pi / 2, 2001)
    _, Q, _ = layer_points(a, b, w, R, phi)
    thickness = R - np.linalg.norm(Q, axis=-1)
    t_min = float(thickness.min())
    limit = min_substrate_fraction * w
    if t_min < limit:
        # largest admissible aspect ratio, for the message
        lo, hi = 1.0, aspect_ratio
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            am, bm = semi_axes(r, mid)
            _, Qm, _ = layer_points(am, bm, w, R, phi)
            if (R - np.linalg.norm(Qm, axis=-1)).min() >= limit:
                lo = mid
            else:
                hi = mid
        raise GeometryError("geometry.aspect_ratio",
                            f"= {aspect_ratio:g} leaves a substrate only {t_min:.4g} mm thick (< {limit:.3g} mm, "
                            f"half the film) where the passage comes closest to the wall; allowed: aspect_ratio "
                            f"<= {lo:.4f} for these radii (the passage keeps the area of a circle of radius "
                            f"{r:g} mm)")
    return {"passage_radius": r, "semi_major": a, "semi_minor": b, "min_substrate_thickness": t_min}


def add_section(outer_radius: float, substrate_thickness: float, film_thickness: float, element_size: float,
                film_layers: int, grading: float, aspect_ratio: float = 1.0, film_grading: float = 1.0):
    """The tube's cross-section in the current gmsh model, transfinite and recombined but not meshed:
    (film surfaces, substrate surfaces, passage curves, wall curves, info); GeometryError for an impossible
    tube. :func:`add_model` meshes it in 2D; :mod:`meshes.tube3d` extrudes it along the axis."""
    R, H, w = outer_radius, substrate_thickness, film_thickness
    info = check_geometry(R, H, w, aspect_ratio)
    a, b = info["semi_major"], info["semi_minor"]
    m = max(2, round(ellipse_perimeter(a, b) / element_size / 4))  # elements per quadrant
    film_hs = film_layer_heights(w, film_layers, film_grading)
    sub_h = substrate_layer_heights(H, film_hs[0] * grading, grading)
    info.update({"elements_around": 4 * m, "film_layers": film_layers, "substrate_layers": len(sub_h),
                 "aspect_ratio": aspect_ratio})
    phi = passage_parameters(a, b, m)
    P, Q, C = layer_points(a, b, w, R, phi)
    n = len(phi)
    geo = gmsh.model.geo
    pP = [geo.addPoint(*p, 0) for p in P]
    pQ = [geo.addPoint(*q, 0) for q in Q]
    pC = [geo.addPoint(*c, 0) for c in C]
    radial_film, radial_sub = [], []
    for k in range(4):
        i = k * m
        lf = geo.addLine(pP[i], pQ[i])
        ls = geo.addLine(pQ[i], pC[i])
        radial_film.append(lf)
        radial_sub.append(ls)
    inner, mid, outer, film_s, sub_s = [], [], [], [], []
    for k in range(4):
        idx = [(k * m + j) % n for j in range(m + 1)]
        ci = geo.addSpline([pP[j] for j in idx])
        cm = geo.addSpline([pQ[j] for j in idx])
        co = geo.addSpline([pC[j] for j in idx])
        inner.append(ci)
        mid.append(cm)
        outer.append(co)
        k1 = (k + 1) % 4
        for c in (ci, cm, co):
            geo.mesh.setTransfiniteCurve(c, m + 1)
        lf0, lf1 = radial_film[k], radial_film[k1]
        ls0, ls1 = radial_sub[k], radial_sub[k1]
        loop_f = geo.addCurveLoop([ci, lf1, -cm, -lf0])
        loop_s = geo.addCurveLoop([cm, ls1, -co, -ls0])
        film_s.append(geo.addPlaneSurface([loop_f]))
        sub_s.append(geo.addPlaneSurface([loop_s]))
    # Connectors run outwards (passage -> interface -> wall): film layers thicken towards
    # the interface by film_grading, substrate layers towards the wall by grading. Set on the geo kernel (not
    # the model) so that they survive a later synchronize, e.g. after meshes.tube3d's extrusion.
    for lf in radial_film:
        geo.mesh.setTransfiniteCurve(lf, film_layers + 1, "Progression", film_grading)
    for ls in radial_sub:
        geo.mesh.setTransfiniteCurve(ls, len(sub_h) + 1, "Progression", grading)
    for s in film_s + sub_s:
        geo.mesh.setTransfiniteSurface(s)
        geo.mesh.setRecombine(2, s)
    geo.synchronize()
    return film_s, sub_s, inner, outer, info


def add_model(outer_radius: float, substrate_thickness: float, film_thickness: float, element_size: float,
              film_layers: int, grading: float, aspect_ratio: float = 1.0,
              film_grading: float = 1.0) -> tuple[dict, dict, dict]:
    """Mesh the tube in the current gmsh model: (cell groups, facet groups, info); GeometryError for an
    impossible tube."""
    film_s, sub_s, inner, outer, info = add_section(outer_radius, substrate_thickness, film_thickness, element_size,
                                                    film_layers, grading, aspect_ratio, film_grading)
    add_physical(2, film_s, CELLS["film"], "film")
    add_physical(2, sub_s, CELLS["substrate"], "substrate")
    add_physical(1, inner, FACETS["inner"], "inner")
    add_physical(1, outer, FACETS["outer"], "outer")
    gmsh.model.mesh.generate(2)
    return dict(CELLS), dict(FACETS), info
