"""Problem setup from a resolved config: mesh, spaces, materials, boundary conditions, loading.

One :class:`Problem` holds everything a time step needs: the unknown w = (u, dQ), the converged
previous state (u_n, Q_n), the compiled residual/Hessian forms, the Dirichlet conditions and the
loading as a function of time, plus the observables written to history.csv.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl

from app import compat, config
from app.material import Hydrogel
from app.potential import CompiledForms, MaterialFields, build


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


def build_mesh(cfg: dict, comm):
    """The tagged mesh for ``geometry.kind``."""
    geo, mesh = cfg["geometry"], cfg["mesh"]
    if geo["kind"] == "bilayer":
        from meshes import bilayer

        return bilayer.build(comm, geo["length"], geo["substrate_thickness"], geo["film_thickness"],
                             mesh["element_size"], mesh["film_layers"], mesh["substrate_grading"],
                             film_grading=mesh["film_grading"])
    raise config.ConfigError("geometry.kind", f"unsupported kind {geo['kind']!r}")


def layer_materials(cfg: dict) -> dict[str, Hydrogel]:
    return {"film": Hydrogel.from_dict(config.film_overrides(cfg)),
            "substrate": Hydrogel.from_dict(config.substrate_parameters(cfg))}


class Problem:
    """The discrete incremental minimization problem of one configuration."""

    def __init__(self, cfg: dict, comm, tagged_mesh=None):
        self.cfg, self.comm = cfg, comm
        self.tm = tagged_mesh if tagged_mesh is not None else build_mesh(cfg, comm)
        domain = self.tm.mesh
        self.domain = domain
        tdim = domain.topology.dim
        domain.topology.create_connectivity(tdim - 1, tdim)

        self.W = compat.mixed_displacement_flux_space(domain)
        self.w = compat.Function(self.W)  # (u, dQ) of the current step
        self.state = compat.Function(self.W)  # (u_n, Q_n): converged previous state
        self.V_u, self.u_dofs = compat.collapse(self.W.sub(0))
        self.V_q, self.q_dofs = compat.collapse(self.W.sub(1))

        self.materials = layer_materials(cfg)
        self.mat = self._material_fields()

        self.tau = compat.Constant(domain, compat.ScalarType(cfg["time"]["dt_initial"]))
        lo = cfg["loading"]
        self.loading = Loading(lo["kind"], self.materials["film"].mu0, lo["chemical_potential"], lo["ramp_time"],
                               cfg["time"]["end"], lo["compression_strain"], cfg["geometry"]["length"])
        self.mu_bar = compat.Constant(domain, compat.ScalarType(self.loading.mu_bar(0.0)))

        q = cfg["mesh"]["quadrature_degree"]
        self.dx = ufl.Measure("dx", domain=domain, metadata={"quadrature_degree": q})
        self.dx_coupling = ufl.Measure("dx", domain=domain,
                                       metadata={"quadrature_degree": cfg["mesh"]["coupling_quadrature_degree"]})
        self.ds = ufl.Measure("ds", domain=domain, subdomain_data=self.tm.facet_tags)
        top = self.tm.facet_names["top"]
        self.ds_top = self.ds(top)
        permeable = self.ds_top if self.loading.kind == "swelling" else None

        self.pot = build(self.w, self.state, self.mat, self.tau, self.mu_bar, self.dx, permeable,
                         self.dx_coupling)
        self.forms = CompiledForms(self.pot)
        self.bcs, self._right_ux = self._boundary_conditions()
        self._observables()

    # --- setup helpers ---------------------------------------------------------------------

    def _material_fields(self) -> MaterialFields:
        V0 = compat.scalar_space(self.domain, "DG", 0)
        names = ["shear_modulus", "mixing_modulus", "penalty", "mobility", "preswelling", "interaction", "s0"]
        fields = {}
        for name in names:
            f = compat.Function(V0)
            f.name = name
            for layer, mat in self.materials.items():
                value = mat.s0 if name == "s0" else getattr(mat, name)
                f.x.array[self.tm.cells(layer)] = value
            fields[name] = f
        return MaterialFields(**fields)

    def _boundary_conditions(self):
        fdim = self.domain.topology.dim - 1
        tm = self.tm
        side = np.concatenate([tm.facets("left"), tm.facets("right")])
        bcs = []
        bc, _ = compat.dirichlet_zero_on_facets(self.W.sub(0).sub(0), tm.facets("left"), fdim)
        bcs.append(bc)
        bc, g_right = compat.dirichlet_function_on_facets(self.W.sub(0).sub(0), tm.facets("right"), fdim)
        bcs.append(bc)
        bc, _ = compat.dirichlet_zero_on_facets(self.W.sub(0).sub(1), tm.facets("bottom"), fdim)
        bcs.append(bc)
        if self.loading.kind == "swelling":
            no_flux = np.concatenate([side, tm.facets("bottom")])
        else:  # diffusion switched off: every flux dof is zero, s stays s0
            num_facets = self.domain.topology.index_map(fdim).size_local + \
                self.domain.topology.index_map(fdim).num_ghosts
            no_flux = np.arange(num_facets, dtype=np.int32)
        bc, _ = compat.dirichlet_zero_on_facets(self.W.sub(1), np.unique(no_flux), fdim)
        bcs.append(bc)
        return bcs, g_right

    def _observables(self):
        u_n, Q_n = ufl.split(self.state)
        _, dQ = ufl.split(self.w)
        n = ufl.FacetNormal(self.domain)
        one = compat.Constant(self.domain, compat.ScalarType(1.0))
        self.top_length = compat.assemble_scalar(compat.form(one * self.ds_top), self.comm)
        self._growth_form = compat.form(u_n[1] * self.ds_top)
        self._fluid_form = compat.form((self.mat.s0 - ufl.div(Q_n)) * self.dx)
        self._influx_form = compat.form(-ufl.dot(dQ, n) * self.ds_top)

    # --- time-dependent data ---------------------------------------------------------------

    def set_time(self, t: float, tau: float) -> None:
        """Loading at time t for a step of size tau."""
        self.tau.value = tau
        self.mu_bar.value = self.loading.mu_bar(t)
        self._right_ux.x.array[:] = -self.loading.applied_strain(t) * self.loading.length

    # --- observables of the converged state ------------------------------------------------

    def growth(self) -> float:
        """Mean vertical displacement of the top surface (the paper's growth) [mm]."""
        return compat.assemble_scalar(self._growth_form, self.comm) / self.top_length

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
