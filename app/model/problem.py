"""Problem setup from a resolved config: mesh, spaces, materials, boundary conditions, loading.

One :class:`Problem` holds everything a time step needs: the unknown w = (u, dQ), the converged
previous state (u_n, Q_n), the compiled residual/Hessian forms, the Dirichlet conditions and the
loading as a function of time, plus the observables written to history.csv.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl

from app import compat, config, geometry
from app.geometry import GeometrySetup
from app.model.material import Material
from app.model.potential import CompiledForms, MaterialFields, build, fields_class


@dataclass
class Loading:
    """Surface chemical potential ramp (swelling) or end-displacement ramp (compression)."""

    kind: str
    mu_start: float  # the film's mu0: the permeable surface starts in equilibrium with it
    mu_end: float
    ramp_time: float
    end_time: float
    compression_strain: float
    length: float

    def mu_bar(self, t: float) -> float:
        frac = min(max(t / self.ramp_time, 0.0), 1.0)
        return self.mu_start + (self.mu_end - self.mu_start) * frac

    def applied_strain(self, t: float) -> float:
        if self.kind != "compression":
            return 0.0
        return self.compression_strain * min(t / self.end_time, 1.0)

    def kinks(self) -> list[float]:
        """Times where the load rate jumps: steps must not cross them."""
        return [self.ramp_time] if self.kind == "swelling" else []


def layer_materials(cfg: dict, names=("film", "substrate")) -> dict[str, Material]:
    """Parameters of each named material (film, substrate, [material.layers.*]) under the config's law."""
    law = config.law(cfg)
    return {name: law.material(config.layer_parameters(cfg, name)) for name in names}


class Problem:
    """The discrete incremental minimization problem of one configuration."""

    @classmethod
    def from_config(cls, cfg: dict, comm, setup: GeometrySetup | None = None) -> Problem:
        """The problem of a resolved config (the boundary where config dicts become objects)."""
        return cls(cfg, comm, setup)

    def __init__(self, cfg: dict, comm, setup: GeometrySetup | None = None):
        self.cfg, self.comm = cfg, comm
        self.geo = setup if setup is not None else geometry.build(cfg, comm)
        self.tm = self.geo.tm
        domain = self.tm.mesh
        self.domain = domain
        tdim = domain.topology.dim
        domain.topology.create_connectivity(tdim - 1, tdim)

        self.W = compat.mixed_displacement_flux_space(domain)
        self.w = compat.Function(self.W)  # (u, dQ) of the current step
        self.state = compat.Function(self.W)  # (u_n, Q_n): converged previous state
        self.V_u, self.u_dofs = compat.collapse(self.W.sub(0))
        self.V_q, self.q_dofs = compat.collapse(self.W.sub(1))

        self.materials = layer_materials(cfg, sorted(set(self.geo.layers.values())))
        self.mat = self._material_fields()

        self.tau = compat.Constant(domain, compat.ScalarType(cfg["time"]["dt_initial"]))
        lo = cfg["loading"]
        self.surface_material = self._surface_material()
        self.loading = Loading(lo["kind"], self.materials[self.surface_material].mu0, lo["chemical_potential"],
                               lo["ramp_time"], cfg["time"]["end"], lo["compression_strain"],
                               cfg["geometry"].get("length") or 0.0)
        self.mu_bar = compat.Constant(domain, compat.ScalarType(self.loading.mu_bar(0.0)))

        q = cfg["mesh"]["quadrature_degree"]
        self.dx = ufl.Measure("dx", domain=domain, metadata={"quadrature_degree": q})
        self.dx_coupling = ufl.Measure("dx", domain=domain,
                                       metadata={"quadrature_degree": cfg["mesh"]["coupling_quadrature_degree"]})
        self.ds = ufl.Measure("ds", domain=domain, subdomain_data=self.tm.facet_tags)
        permeable = [self.tm.facet_names[g] for g in self.geo.facets_with_role("permeable")]
        self.ds_permeable = self.ds(tuple(permeable))
        swelling = self.loading.kind == "swelling"

        self.pot = build(self.w, self.state, self.mat, self.tau, self.mu_bar, self.dx,
                         self.ds_permeable if swelling else None, self.dx_coupling)
        self.forms = CompiledForms(self.pot)
        self.bcs, self._right_ux = self._boundary_conditions()
        self._observables()

    # --- setup helpers ---------------------------------------------------------------------

    def _material_fields(self) -> MaterialFields:
        """The law's parameters and s0 as per-cell (DG0) fields, each cell carrying its layer's values."""
        V0 = compat.scalar_space(self.domain, "DG", 0)
        law = next(iter(self.materials.values())).law
        fields = {}
        for name in (*law.params, "s0"):
            f = compat.Function(V0)
            f.name = name
            for group, mat_name in self.geo.layers.items():
                mat = self.materials[mat_name]
                f.x.array[self.tm.cells(group)] = getattr(mat, name)
            fields[name] = f
        return fields_class(law)(**fields)

    def _surface_material(self) -> str:
        """The material under the permeable surface (the film): the ramp starts at its mu0."""
        tdim = self.domain.topology.dim
        f2c = self.domain.topology.connectivity(tdim - 1, tdim)
        n_owned = compat.num_owned_cells(self.domain)
        group_of_cell = {}
        for group in self.geo.layers:
            for c in self.tm.cells(group):
                group_of_cell[int(c)] = group
        counts: dict[str, int] = {}
        for g in self.geo.facets_with_role("permeable"):
            for f in self.tm.facets(g):
                for c in f2c.links(f):
                    if c < n_owned and int(c) in group_of_cell:
                        name = self.geo.layers[group_of_cell[int(c)]]
                        counts[name] = counts.get(name, 0) + 1
        totals: dict[str, int] = {}
        for part in self.comm.allgather(counts):
            for k, v in part.items():
                totals[k] = totals.get(k, 0) + v
        return max(sorted(totals), key=lambda k: totals[k]) if totals else "film"

    def _boundary_conditions(self):
        fdim = self.domain.topology.dim - 1
        tm, geo = self.tm, self.geo
        Wu = self.W.sub(0)

        def facets(*roles):
            groups = geo.facets_with_role(*roles)
            return np.unique(np.concatenate([tm.facets(g) for g in groups])) if groups else np.empty(0, np.int32)

        bcs = []
        g_right = None
        compressed = "right" if self.loading.kind == "compression" else None
        for comp, roles in ((0, ("roller_x", "fixed")), (1, ("roller_y", "fixed"))):
            groups = [g for g in geo.facets_with_role(*roles) if not (comp == 0 and g == compressed)]
            if groups:
                fs = np.unique(np.concatenate([tm.facets(g) for g in groups]))
                bcs.append(compat.dirichlet_zero_on_facets(Wu.sub(comp), fs, fdim)[0])
        if compressed:
            bc, g_right = compat.dirichlet_function_on_facets(Wu.sub(0), tm.facets(compressed), fdim)
            bcs.append(bc)
        if self.loading.kind == "swelling":
            no_flux = np.setdiff1d(compat.exterior_facets(self.domain), facets("permeable"))
        else:  # diffusion switched off: every flux dof is zero, s stays s0
            imap = self.domain.topology.index_map(fdim)
            no_flux = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        bcs.append(compat.dirichlet_zero_on_facets(self.W.sub(1), no_flux.astype(np.int32), fdim)[0])
        return bcs, g_right

    def _observables(self):
        u_n, Q_n = ufl.split(self.state)
        _, dQ = ufl.split(self.w)
        n = ufl.FacetNormal(self.domain)
        one = compat.Constant(self.domain, compat.ScalarType(1.0))
        self.surface_length = compat.assemble_scalar(compat.form(one * self.ds_permeable), self.comm)
        self._growth_form = compat.form(ufl.dot(u_n, n) * self.ds_permeable)
        self._fluid_form = compat.form((self.mat.s0 - ufl.div(Q_n)) * self.dx)
        self._influx_form = compat.form(-ufl.dot(dQ, n) * self.ds_permeable)
        self._growth_dof = None
        if self.geo.growth == "vertex":
            self._growth_dof = self._locate_point_dofs(self.geo.growth_point)

    def _locate_point_dofs(self, point) -> np.ndarray | None:
        """Indices in W of (u_x, u_y) at the owned mesh node at ``point`` (None on other ranks)."""
        X = self.V_u.tabulate_dof_coordinates()[:, :2]
        n_owned = self.V_u.dofmap.index_map.size_local
        d = np.linalg.norm(X[:n_owned] - np.asarray(point), axis=1)
        i = int(np.argmin(d)) if n_owned else -1
        best = self.comm.allreduce(float(d[i]) if n_owned else np.inf, op=_mpi_min())
        if best > 1e-8:
            raise RuntimeError(f"no mesh node at the growth point {point} (nearest {best:.3g} mm away)")
        if n_owned and d[i] == best:
            return self.u_dofs[[2 * i, 2 * i + 1]]
        return None

    # --- time-dependent data ---------------------------------------------------------------

    def set_time(self, t: float, tau: float) -> None:
        """Loading at time t for a step of size tau."""
        self.tau.value = tau
        self.mu_bar.value = self.loading.mu_bar(t)
        if self._right_ux is not None:
            self._right_ux.x.array[:] = -self.loading.applied_strain(t) * self.loading.length

    # --- observables of the converged state ------------------------------------------------

    def growth(self) -> float:
        """The paper's growth [mm]: mean displacement of the permeable surface along the body's outward
        normal; for tubes the mean inward radial displacement of the passage's nodes (arc-length
        weighted); or the inward displacement of one point (elliptic passage: minor-axis vertex)."""
        if self.geo.growth == "mean_radial":
            from app.onset.wrinkles import around_profile, boundary_displacement

            coords, disp = boundary_displacement(self, self.state.x.array, self.geo.facets_with_role("permeable"))
            _, radial, weights, _ = around_profile(coords, disp, centre=(0.0, 0.0))
            return float(-np.sum(weights * radial) / np.sum(weights))
        if self.geo.growth == "vertex":
            local = 0.0
            if self._growth_dof is not None:
                u = self.state.x.array[self._growth_dof]
                local = float(np.dot(u, self.geo.growth_direction))
            return self.comm.allreduce(local)
        return compat.assemble_scalar(self._growth_form, self.comm) / self.surface_length

    def fluid_volume(self) -> float:
        """Integral of the fluid content s over the reference domain [mm^2 per unit depth]."""
        return compat.assemble_scalar(self._fluid_form, self.comm)

    def step_influx(self) -> float:
        """Fluid volume that entered through the permeable surface in the current step."""
        return compat.assemble_scalar(self._influx_form, self.comm)

    # --- state updates ---------------------------------------------------------------------

    def accept(self) -> None:
        """Make the converged (u, dQ) the new state: u_n = u, Q_n += dQ."""
        a, s = self.w.x.array, self.state.x.array
        s[self.u_dofs] = a[self.u_dofs]
        s[self.q_dofs] += a[self.q_dofs]

    def dofs(self) -> int:
        return compat.global_size(self.W)

    def cells(self) -> int:
        return compat.num_global_cells(self.domain)


def _mpi_min():
    from mpi4py import MPI

    return MPI.MIN
