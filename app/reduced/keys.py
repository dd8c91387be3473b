"""The [reduced] keys: how the exact 1D reduction beside a run and in ``hydrobuckle reduced`` is resolved
(app/workflows/reduction.py reads them into :class:`app.reduced.solve.Settings`)."""

from __future__ import annotations

from app.schema import Key, in_closed, in_open, key

KEYS: dict[str, Key] = {
    "beside_2d": key(bool, True, None, "a bilayer or circular-tube run also reports its exact 1D counterpart "
                     "(summary.json 'reduced', docs/reduction.md)"),
    "degree": key(int, 3, in_closed(1, 6), "Lagrange degree of the 1D fields"),
    "film_cells": key(int, 12, in_closed(1, 512), "1D cells through the film"),
    "grading": key(float, 1.25, in_closed(1.0, 3.0), "1D cell-size ratio away from the film"),
    "surface_grading": key(float, 1.35, in_closed(1.0, 3.0),
                           "1D cell-size ratio through the film away from the permeable surface (its "
                           "diffusion boundary layer)"),
    "step_change": key(float, 0.01, in_open(0.0, 0.5),
                       "largest relative change of the displacement per time step of the 1D transient"),
    "max_wavenumber": key(float, 20.0, in_closed(1.0, 1000.0),
                          "largest k w screened mode by mode (k along the surface, w the film thickness); "
                          "shorter waves: the surface's short-wave limit"),
    "grid": key(int, 48, in_closed(8, 2000), "mode numbers screened every step (logarithmically spaced)"),
    "horizon": key(float, 0.5, in_closed(0.0, 20.0),
                   "continue this fraction of the first crossing time past it (the margin curve's later "
                   "crossings)"),
}
