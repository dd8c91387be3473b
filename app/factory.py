"""Where a resolved config becomes hydrobuckle's objects: each layer's material under the config's law, the
discrete problem (geometry, materials, loading, discretization) and the 1D cross-section of the exact
reduction; the time stepper of a problem, with the onset layer's limits and diagnosis given to it. Above
config.py (it reads the config through it) and below io/ and the workflows; model/, solvers/ and reduced/ take
these objects and never see a config dict's structure, and solvers/ never see a problem."""

from __future__ import annotations

from functools import partial

from app import config, geometry
from app.model import history
from app.model.loading import Loading
from app.model.material import Material
from app.model.operators import cell_content_change
from app.model.problem import Discretization, Problem
from app.onset.contact import ModelLimits
from app.onset.criteria import LossOfStability
from app.reduced.section import Layer, NotReducible, Section, reducible
from app.solvers.newton import SolverSettings
from app.solvers.stepping import Evolution, TimeSettings, TimeStepper


def layer_materials(cfg: dict, names=("film", "substrate")) -> dict[str, Material]:
    """Parameters of each named material (film, substrate, [material.layers.*]) under the config's law."""
    law = config.law(cfg)
    return {name: law.material(config.layer_parameters(cfg, name)) for name in names}


def problem(cfg: dict, comm, setup: geometry.GeometrySetup | None = None) -> Problem:
    """The problem of a resolved config: the geometry (built unless given), each layer's material, the loading
    (its surface ramp starting at the mu0 of the material under the permeable surface) and the
    discretization settings."""
    setup = setup if setup is not None else geometry.build(cfg, comm)
    materials = layer_materials(cfg, sorted(set(setup.layers.values())))
    surface = setup.material_under("permeable", comm)
    loading = Loading.from_config(cfg, mu_start=materials[surface].mu0, drive=setup.drive)
    p = Problem(comm, setup, materials, loading, Discretization.from_config(cfg))
    stab = cfg.get("stability", {})
    if stab.get("contact"):
        energy = stab.get("contact_energy", "auto")
        if energy == "auto":  # the penalty in 2D (validated longest), the barrier in 3D (the only one there)
            energy = "barrier" if p.domain.geometry.dim == 3 else "penalty"
        p.enable_contact(stab["contact_stiffness"], energy)
    return p


def evolution(p: Problem) -> Evolution:
    """What the time stepper advances of a problem: its forms, conditions, index sets and hooks."""
    return Evolution(p.forms.energy, p.forms.residual, p.forms.hessian, p.bcs, p.w, p.state, p.u_dofs, p.q_dofs,
                     p.comm, cell_content_change(p), tuple(p.loading.kinks()), p.diffusion, p.set_time,
                     p.step_influx, partial(history.record, p), getattr(p, "contact", None),
                     uptake="fluid_volume")


def time_stepper(p: Problem, time: TimeSettings, solver: SolverSettings, log=None, limits: bool = True,
                 diagnose: bool = True) -> TimeStepper:
    """The problem's time stepper; ``limits``: a followed branch ends at self-contact or an inverted cell
    (:class:`app.onset.contact.ModelLimits`); ``diagnose``: two failed attempts in a row test the state's
    stability (:class:`app.onset.criteria.LossOfStability`)."""
    return TimeStepper(evolution(p), time, solver, log=log, limits=(lambda: ModelLimits(p)) if limits else None,
                       check=LossOfStability(p) if diagnose else None)


def section(cfg: dict) -> Section:
    """The cross-section of a reducible config (:func:`app.reduced.section.reducible`; else NotReducible
    naming the key)."""
    why = reducible(cfg)
    if why:
        raise NotReducible(why)
    geo = cfg["geometry"]
    cs = geometry.KINDS.get(geo["kind"]).cross_section(geo)  # the kind's own section
    materials = layer_materials(cfg)
    loading = Loading.from_config(cfg, mu_start=materials["film"].mu0, drive=cs.drive)
    return Section(cs.shape, tuple(Layer(*layer) for layer in cs.layers), cs.surface, cs.base, cs.length, materials,
                   loading, width=cs.width, axial=cs.axial, clamped=cs.clamped)
