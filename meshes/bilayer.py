"""Flat film-substrate bilayer (seed paper Fig. "bi_geo"): a structured quadrilateral mesh.

The substrate [0, L] x [0, H] lies under the film [0, L] x [H, H + w]. Elements along x have
the user's size; the film has ``film_layers`` uniform element layers; substrate element heights
grow geometrically away from the film by ``grading`` starting one ratio above the film's.
Physical groups: cells film, substrate; facets top, bottom, left, right.

:func:`add_model` builds the mesh in the current gmsh model (pure gmsh; see :mod:`meshes`).
"""

from __future__ import annotations

import math

import gmsh
import numpy as np

from meshes import add_physical

CELLS = {"film": 1, "substrate": 2}
FACETS = {"bottom": 1, "top": 2, "left": 3, "right": 4}


def substrate_layer_heights(H: float, first: float, grading: float) -> np.ndarray:
    """Element heights through the substrate, from the film downwards, summing exactly to H.

    Starts near ``first`` and grows by ``grading``; the count is the one whose geometric sum
    comes closest to H, then all heights are scaled to fit H exactly."""
    n = substrate_layer_count(H, first, grading)
    h = first * grading ** np.arange(n)
    return h * (H / h.sum())


def substrate_layer_count(H: float, first: float, grading: float) -> int:
    """The number of substrate element layers of :func:`substrate_layer_heights` (no array: any size)."""
    if grading == 1.0:
        return max(1, round(H / first))
    return max(1, round(math.log(1 + H * (grading - 1) / first) / math.log(grading)))


def film_interface_height(w: float, layers: int, grading: float) -> float:
    """The height of the film layer at the interface: ``film_layer_heights(w, layers, grading)[0]``."""
    return float(film_layer_heights(w, layers, grading)[0])


def film_layer_heights(w: float, layers: int, grading: float) -> np.ndarray:
    """Film element heights from the interface up to the surface; with grading > 1 each layer is
    ``grading`` times thinner than the one below, resolving the steep swelling front under the
    permeable surface."""
    h = grading ** -np.arange(layers, dtype=float)
    return h * (w / h.sum())


def add_model(length: float, substrate_thickness: float, film_thickness: float, element_size: float,
              film_layers: int, grading: float, film_grading: float = 1.0) -> tuple[dict, dict, dict]:
    """Mesh the bilayer in the current gmsh model: (cell groups, facet groups, info)."""
    base, sub, film, info = add_section(length, substrate_thickness, film_thickness, element_size, film_layers,
                                        grading, film_grading)
    L = length
    sides = [abs(t) for t in (sub[2][1], sub[3][1], film[2][1], film[3][1])]
    left = [c for c in sides if gmsh.model.getBoundingBox(1, c)[3] < 0.5 * L]
    right = [c for c in sides if c not in left]
    add_physical(2, [film[1][1]], CELLS["film"], "film")
    add_physical(2, [sub[1][1]], CELLS["substrate"], "substrate")
    add_physical(1, [base], FACETS["bottom"], "bottom")
    add_physical(1, [film[0][1]], FACETS["top"], "top")
    add_physical(1, left, FACETS["left"], "left")
    add_physical(1, right, FACETS["right"], "right")
    gmsh.option.setNumber("Mesh.RecombineAll", 1)
    gmsh.model.mesh.generate(2)
    return dict(CELLS), dict(FACETS), info


def add_section(length: float, substrate_thickness: float, film_thickness: float, element_size: float,
                film_layers: int, grading: float, film_grading: float = 1.0):
    """The bilayer's geometry in the x-y plane of the current gmsh model, transfinite and recombined but not
    meshed: (base line, substrate extrusion, film extrusion, info), the extrusions as gmsh returns them
    (top curve, surface, the two side curves). The 3D plate (:mod:`meshes.plate`) extrudes it along z."""
    L, H, w = length, substrate_thickness, film_thickness
    nx = max(1, round(L / element_size))
    film_hs = film_layer_heights(w, film_layers, film_grading)
    film_h = film_hs[0]  # the film layer at the interface
    sub_h = substrate_layer_heights(H, film_h * grading, grading)
    info = {"elements_along_length": nx, "film_layers": film_layers, "substrate_layers": len(sub_h),
            "film_element_aspect": (L / nx) / film_hs.min(), "surface_layer_height": film_hs[-1]}
    geo = gmsh.model.geo
    p0, p1 = geo.addPoint(0, 0, 0), geo.addPoint(L, 0, 0)
    base = geo.addLine(p0, p1)
    geo.mesh.setTransfiniteCurve(base, nx + 1)
    # Extrude upwards: heights listed bottom to top, so the finest sits under the film.
    bottom_up = sub_h[::-1]
    fractions = list(np.cumsum(bottom_up) / H)
    fractions[-1] = 1.0
    sub = geo.extrude([(1, base)], 0, H, 0, numElements=[1] * len(sub_h), heights=fractions,
                      recombine=True)
    film_fr = list(np.cumsum(film_hs) / w)
    film_fr[-1] = 1.0
    film = geo.extrude([sub[0]], 0, w, 0, numElements=[1] * film_layers, heights=film_fr, recombine=True)
    geo.synchronize()
    return base, sub, film, info
