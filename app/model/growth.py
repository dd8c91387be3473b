"""What a run reports as the growth [mm]: measures of the converged state's permeable surface, each registered
once (:data:`GROWTH`); a geometry kind names its own (``GeometrySetup.growth``)."""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from app import fem_utils
from app.model.shapes import around_profile
from app.model.shapes3d import trapezoid_weights
from app.model.surface import boundary_displacement
from app.registry import Registry


class GrowthMeasure:
    """What the run reports as the growth [mm] (``GeometrySetup.growth`` names it): ``bind(problem)`` returns
    the function of the converged state that measures it (collective)."""

    name = ""

    def bind(self, problem):
        raise NotImplementedError


class MeanNormal(GrowthMeasure):
    """The paper's growth: the mean displacement of the permeable surface along the body's outward normal."""

    name = "mean_normal"

    def bind(self, problem):
        u_n, _ = ufl.split(problem.state)
        form = fem.form(ufl.dot(u_n, ufl.FacetNormal(problem.domain)) * problem.ds_permeable)
        return lambda: fem_utils.assemble_scalar(form, problem.comm) / problem.surface_length


class MeanRadial(GrowthMeasure):
    """A tube: the mean inward radial displacement of the passage's nodes about the axis (arc-length weighted)."""

    name = "mean_radial"

    def bind(self, problem):
        def growth() -> float:
            coords, disp = boundary_displacement(problem, problem.state.x.array,
                                                 problem.geo.facets_with_role("permeable"))
            if coords.shape[1] == 2:
                _, radial, weights, _ = around_profile(coords, disp, centre=(0.0, 0.0))
                return float(-np.sum(weights * radial) / np.sum(weights))
            # a 3D passage: each ring z = const as in 2D, the rings' means averaged along the axis (trapezoid)
            z = np.round(coords[:, 2], 12)
            rings = np.unique(z)
            means = []
            for zr in rings:
                at = z == zr
                _, radial, weights, _ = around_profile(coords[at, :2], disp[at, :2], centre=(0.0, 0.0))
                means.append(-np.sum(weights * radial) / np.sum(weights))
            wz = trapezoid_weights(rings)
            return float(np.dot(wz, means) / wz.sum())

        return growth


class AtVertex(GrowthMeasure):
    """The inward displacement of one surface point (``GeometrySetup.growth_point`` along ``growth_direction``):
    the elliptic passage's minor-axis vertex. In 3D the point is a line along the axis z (every node at that
    (x, y)), and its nodes' inward displacements are averaged along z (trapezoid), as the 3D tube's rings are."""

    name = "vertex"

    def bind(self, problem):
        geo, comm = problem.geo, problem.comm
        gdim = problem.domain.geometry.dim
        X = problem.V_u.tabulate_dof_coordinates()[:, :gdim]
        n_owned = problem.V_u.dofmap.index_map.size_local
        d = np.linalg.norm(X[:n_owned, :2] - np.asarray(geo.growth_point), axis=1)
        best = comm.allreduce(float(d.min()) if n_owned else np.inf, op=MPI.MIN)
        if best > 1e-8:
            raise RuntimeError(f"no mesh node at the growth point {geo.growth_point} (nearest {best:.3g} mm away)")
        rows = np.flatnonzero(d <= max(best, 1e-12) * (1 + 1e-9) + 1e-12) if n_owned else np.zeros(0, dtype=int)
        dofs = problem.u_dofs[gdim * rows[:, None] + np.array([0, 1])]  # (nodes, (u_x, u_y)) in W
        z = X[rows, 2] if gdim == 3 else np.zeros(len(rows))

        def growth() -> float:
            local = problem.state.x.array[dofs] @ np.asarray(geo.growth_direction) if len(rows) else np.zeros(0)
            zs, values = map(np.concatenate, zip(*comm.allgather((z, local))))
            if len(zs) == 1:
                return float(values[0])
            order = np.argsort(zs)
            zs, values = zs[order], values[order]
            return float(np.sum(0.5 * (values[1:] + values[:-1]) * np.diff(zs)) / (zs[-1] - zs[0]))

        return growth


GROWTH: Registry[GrowthMeasure] = Registry("growth measure")
for _measure in (MeanNormal(), MeanRadial(), AtVertex()):
    GROWTH.register(_measure)
