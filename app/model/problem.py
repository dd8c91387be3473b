"""The discrete problem: mesh, spaces, per-cell materials, boundary conditions and loading, built from
typed objects (:func:`app.factory.problem` makes them from a resolved config).

One :class:`Problem` holds everything a time step needs: the unknown w = (u, dQ), the converged
previous state (u_n, Q_n), the compiled residual/Hessian forms, the Dirichlet conditions and the
loading as a function of time, plus the quantities of a converged state that history.csv records
(:mod:`app.model.history` names the columns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from app import compat, fem_utils
from app.geometry import GeometrySetup
from app.model.barrier import BarrierContact
from app.model.growth import GROWTH
from app.model.kinematics import deformation_gradient, fluid_content
from app.model.loading import BoundaryConditions, Loading
from app.model.material import Material
from app.model.penalty import PenaltyContact
from app.model.potential import CompiledForms, build, fields_class
from app.model.surface import surface_shape


@dataclass(frozen=True)
class Discretization:
    """Discretization settings of the forms (the [mesh] quadrature keys) and the step size the forms are
    first compiled with (``time.dt_initial``; every step sets its own)."""

    quadrature_degree: int = 2  # cell integrals
    coupling_quadrature_degree: int = 1  # the law's constraint part (one point: no volumetric locking)
    initial_step: float = 1.0e-3


class Problem:
    """The discrete incremental minimization problem of one configuration."""

    def __init__(self, comm, setup: GeometrySetup, materials: dict[str, Material], loading: Loading,
                 discretization: Discretization = Discretization()):
        self.comm = comm
        self.geo = setup
        self.tm = self.geo.tm
        domain = self.tm.mesh
        self.domain = domain
        tdim = domain.topology.dim
        domain.topology.create_connectivity(tdim - 1, tdim)

        self.W = compat.mixed_displacement_flux_space(domain)
        self.w = fem.Function(self.W)  # (u, dQ) of the current step
        self.state = fem.Function(self.W)  # (u_n, Q_n): converged previous state
        self.V_u, self.u_dofs = fem_utils.collapse(self.W.sub(0))
        self.V_q, self.q_dofs = fem_utils.collapse(self.W.sub(1))

        self.materials = materials
        self.mat = self._material_fields()

        self.tau = fem.Constant(domain, PETSc.ScalarType(discretization.initial_step))
        self.loading = loading
        self.mu_bar = fem.Constant(domain, PETSc.ScalarType(self.loading.mu_bar(0.0)))

        self.dx = ufl.Measure("dx", domain=domain, metadata={"quadrature_degree": discretization.quadrature_degree})
        self.dx_coupling = ufl.Measure("dx", domain=domain, metadata={
            "quadrature_degree": discretization.coupling_quadrature_degree})
        self.ds = ufl.Measure("ds", domain=domain, subdomain_data=self.tm.facet_tags)
        permeable = [self.tm.facet_names[g] for g in self.geo.facets_with_role("permeable")]
        self.ds_permeable = self.ds(tuple(permeable))
        # where the loading's surface term mu_bar dQ.n acts (None: nowhere)
        self.surface_measure = self.ds_permeable if loading.surface_term else None

        self.pot = build(self.w, self.state, self.mat, self.tau, self.mu_bar, self.dx, self.surface_measure,
                         self.dx_coupling)
        self.forms = CompiledForms(self.pot)
        self.bcs, self._driven = self._boundary_conditions(loading.conditions(self.geo.boundaries))
        self.contact = None  # the surface's self-contact term (app.model.penalty.PenaltyContact), if on
        self._observables()

    def enable_contact(self, kappa: float, energy: str = "penalty") -> None:
        """Add the traction-free surface's self-contact to Pi: the penalty (2D; interface stiffness kappa mu /
        h) or the barrier (2D and 3D; :mod:`app.model.barrier`)."""
        if energy == "barrier":
            self.contact = BarrierContact(self, kappa)
        else:
            self.contact = PenaltyContact(self, kappa)

    # --- setup helpers ---------------------------------------------------------------------

    def _material_fields(self):
        """The law's parameters and s0 as per-cell (DG0) fields, each cell carrying its layer's values."""
        laws = {mat.law for mat in self.materials.values()}
        if len(laws) != 1:
            raise ValueError("every layer's material must follow one material law")
        law = laws.pop()
        V0 = compat.scalar_space(self.domain, "DG", 0)
        fields = {}
        for name in (*law.params, "s0"):
            f = fem.Function(V0)
            f.name = name
            for group, mat_name in self.geo.layers.items():
                mat = self.materials[mat_name]
                f.x.array[self.tm.cells(group)] = getattr(mat, name)
            fields[name] = f
        return fields_class(law)(**fields)

    def _boundary_conditions(self, bc: BoundaryConditions):
        """dolfinx Dirichlet conditions of the loading's conditions: (bcs, the driven boundary's
        displacement function or None)."""
        fdim = self.domain.topology.dim - 1
        self._conditions = bc
        bcs = self.fixed_displacement_conditions(self.W.sub(0), driven=False)
        driven = None
        if bc.driven is not None:
            dbc, driven = fem_utils.dirichlet_zero_on_facets(self.W.sub(0).sub(bc.driven.component),
                                                              self.tm.facets(bc.driven.group), fdim)
            bcs.append(dbc)
        if bc.flux_open is not None:
            no_flux = np.setdiff1d(fem_utils.exterior_facets(self.domain), self.facets_of(bc.flux_open))
        else:  # diffusion switched off: every flux dof is zero, s stays s0
            imap = self.domain.topology.index_map(fdim)
            no_flux = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        bcs.append(fem_utils.dirichlet_zero_on_facets(self.W.sub(1), no_flux.astype(np.int32), fdim)[0])
        return bcs, driven

    @property
    def diffusion(self) -> bool:
        """Whether fluid can move at all (False: every flux dof fixed, s = s0, as under compression)."""
        return self._conditions.flux_open is not None

    def permeable_facets(self) -> int:
        """Number of facets (all ranks) where fluid may enter or leave."""
        bc = self._conditions
        if bc.flux_open is None:
            return 0
        f = self.facets_of(bc.flux_open)
        imap = self.domain.topology.index_map(self.domain.topology.dim - 1)
        return self.comm.allreduce(int(np.count_nonzero(f < imap.size_local)))

    def facets_of(self, groups) -> np.ndarray:
        """Local facets (owned and ghost) of the given facet groups."""
        tm = self.tm
        return np.unique(np.concatenate([tm.facets(g) for g in groups])) if groups else np.empty(0, np.int32)

    def fixed_displacement_conditions(self, Wu, driven: bool = True) -> list:
        """Zero Dirichlet conditions on the displacement sub-space ``Wu`` (of this or another mixed space on
        the same mesh) wherever the loading fixes a component: held, and with ``driven`` also the driven
        boundary. The stability tests of other spaces use them: which dofs are fixed, not their values."""
        bc, fdim = self._conditions, self.domain.topology.dim - 1
        bcs = [fem_utils.dirichlet_zero_on_facets(Wu.sub(comp), self.facets_of(groups), fdim)[0]
               for comp, groups in enumerate(bc.held[:self.domain.geometry.dim]) if groups]
        if driven and bc.driven is not None:
            bcs.append(fem_utils.dirichlet_zero_on_facets(Wu.sub(bc.driven.component), self.tm.facets(bc.driven.group),
                                                       fdim)[0])
        return bcs

    def _observables(self):
        u_n, Q_n = ufl.split(self.state)
        _, dQ = ufl.split(self.w)
        n = ufl.FacetNormal(self.domain)
        one = fem.Constant(self.domain, PETSc.ScalarType(1.0))
        self.surface_length = fem_utils.assemble_scalar(fem.form(one * self.ds_permeable), self.comm)
        self._fluid_form = fem.form(fluid_content(self.mat.s0, Q_n) * self.dx)
        self._influx_form = fem.form(-ufl.dot(dQ, n) * self.ds_permeable)
        # the stored energy of the converged state (the incremental potential without dissipation and load)
        F_n = deformation_gradient(u_n)
        bulk, constraint = self.mat.law.free_energy(F_n, fluid_content(self.mat.s0, Q_n), self.mat)
        self._stored_form = fem.form(bulk * self.dx + constraint * self.dx_coupling)
        self._growth = GROWTH.get(self.geo.growth).bind(self)  # the measure the geometry kind names

    # --- time-dependent data ---------------------------------------------------------------

    def set_time(self, t: float, tau: float) -> None:
        """Loading at time t for a step of size tau."""
        self.tau.value = tau
        self.mu_bar.value = self.loading.mu_bar(t)
        if self._driven is not None:
            self._driven.x.array[:] = self.loading.applied_displacement(t)

    def accept_step(self) -> None:
        """The converged step becomes the state: the unknown w holds (u, dQ) of the step, the state (u_n, Q_n)
        becomes (u, Q_n + dQ)."""
        w, state = self.w.x.array, self.state.x.array
        state[self.u_dofs] = w[self.u_dofs]
        state[self.q_dofs] += w[self.q_dofs]

    # --- observables of the converged state ------------------------------------------------

    def growth(self) -> float:
        """The growth [mm] of the converged state, as the geometry kind measures it
        (:class:`app.model.growth.GrowthMeasure`: the paper's mean normal displacement of the permeable
        surface; a tube's mean inward radial displacement; one vertex's inward displacement)."""
        return self._growth()

    def stored_energy(self) -> float:
        """Stored (free) energy of the converged state [N mm / mm depth]: psi integrated over the reference."""
        return fem_utils.assemble_scalar(self._stored_form, self.comm)

    def surface_shape(self, array=None) -> tuple[float, float]:
        """(amplitude [mm], wrinkle count) of the permeable surface's shape in ``array`` (default: the converged
        state); :func:`app.model.surface.surface_shape`."""
        return surface_shape(self, self.state.x.array if array is None else array)

    def fluid_volume(self) -> float:
        """Integral of the fluid content s over the reference domain [mm^2 per unit depth]."""
        return fem_utils.assemble_scalar(self._fluid_form, self.comm)

    def step_influx(self) -> float:
        """Fluid volume that entered through the permeable surface in the current step."""
        return fem_utils.assemble_scalar(self._influx_form, self.comm)

    def dofs(self) -> int:
        return fem_utils.global_size(self.W)

    def cells(self) -> int:
        return fem_utils.num_global_cells(self.domain)
