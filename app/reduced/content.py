"""The fluid content of a planar section's laterally uniform transient as a field of time and height
(:class:`ContentProfile`), from the 1D transient (:mod:`app.reduced.transient`): the crease trial on a run's
own transient state holds it in every cell (``stability.crease_fluid = "transient"``, docs/creases.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.reduced.section import Section
from app.reduced.transient import LayeredModel, Resolution, Transient


@dataclass
class ContentProfile:
    """The fluid content gained, c = s - s0 = -Div Q, of a planar section's uniform transient, at any time and
    height: in each 1D cell a polynomial of Y (one degree below the flux's) at every stored step, linear
    between steps in time (held at the last step after it). Plain arrays: it travels between ranks as is."""

    times: np.ndarray  # (m,) the stored steps' times
    nodes: np.ndarray  # (n + 1,) the 1D mesh's vertices
    coefficients: np.ndarray  # (m, n, degree) c's polynomial in each cell (numpy.polyval order) of
    # (Y - the cell's lower vertex) / the cell's width
    growth: np.ndarray  # (m,) the uniform state's growth at each step [mm]
    surface_stretch: np.ndarray  # (m,) the stretch across the layers at the permeable surface, 1 + dv/dY there

    def _weights(self, t: float) -> tuple[int, int, float]:
        times = self.times
        if t >= times[-1]:
            return len(times) - 1, len(times) - 1, 0.0
        j = int(np.searchsorted(times, t, side="right"))
        i = max(j - 1, 0)
        theta = (t - times[i]) / (times[j] - times[i]) if j > i else 0.0
        return i, j, theta

    def __call__(self, t: float, y: np.ndarray) -> np.ndarray:
        """c at time t and heights y (an array)."""
        y = np.asarray(y, dtype=float)
        cell = np.clip(np.searchsorted(self.nodes, y, side="right") - 1, 0, len(self.nodes) - 2)
        local = (y - self.nodes[cell]) / (self.nodes[cell + 1] - self.nodes[cell])
        i, j, theta = self._weights(t)
        coef = (1.0 - theta) * self.coefficients[i, cell] + theta * self.coefficients[j, cell]
        out = np.zeros_like(y)
        for k in range(coef.shape[-1]):  # Horner
            out = out * local + coef[..., k]
        return out

    def growth_at(self, t: float) -> float:
        i, j, theta = self._weights(t)
        return float((1.0 - theta) * self.growth[i] + theta * self.growth[j])

    def first_surface_stretch(self, value: float) -> float | None:
        """The first time the surface's stretch reaches ``value`` (linear between steps), None if never."""
        above = np.nonzero(self.surface_stretch >= value)[0]
        if len(above) == 0:
            return None
        j = int(above[0])
        if j == 0:
            return float(self.times[0])
        a, b = self.surface_stretch[j - 1], self.surface_stretch[j]
        return float(self.times[j - 1] + (value - a) / (b - a) * (self.times[j] - self.times[j - 1]))


def content_profile(section: Section, res: Resolution, t_end: float) -> ContentProfile:
    """Run the planar section's uniform transient to ``t_end`` (adaptive steps) and keep its content field at
    every step (:class:`ContentProfile`). Serial: call it on one rank and broadcast the result."""
    if section.shape != "planar":
        raise ValueError("a content profile in Y is defined for a planar section (geometry.kind = 'bilayer')")
    model = LayeredModel(section, res)
    steps = Transient(model).run(t_end)
    d, nodes = res.degree, model.nodes
    order = np.argsort(model.x_q)
    xq = model.x_q[order]
    n = len(nodes) - 1
    if len(xq) != n * d + 1 or not np.allclose(xq[::d], nodes, rtol=0.0, atol=1e-12):
        raise RuntimeError("the 1D flux dofs are not d + 1 per cell in coordinate order")
    coefficients, stretch = np.empty((len(steps), n, d)), np.empty(len(steps))
    v_order = np.argsort(model.x_v)
    if not np.allclose(model.x_v[v_order], xq, rtol=0.0, atol=1e-12):
        raise RuntimeError("the 1D displacement and flux dofs do not share their points")
    top, h_top = (n - 1) * d, nodes[-1] - nodes[-2]  # the last cell (the permeable surface at its end)
    for m, snap in enumerate(steps):
        v = snap.state[model.v_dofs][v_order][top:]
        stretch[m] = 1.0 + np.polyval(np.polyder(np.polyfit((xq[top:] - nodes[-2]) / h_top, v, d)), 1.0) / h_top
        Q = snap.state[model.q_dofs][order]
        for i in range(n):
            h = nodes[i + 1] - nodes[i]
            xi = (xq[i * d:i * d + d + 1] - nodes[i]) / h
            coefficients[m, i] = -np.polyder(np.polyfit(xi, Q[i * d:i * d + d + 1], d)) / h  # c = -dQ/dY
    return ContentProfile(np.array([s.t for s in steps]), np.asarray(nodes, float), coefficients,
                          np.array([s.growth for s in steps]), stretch)
