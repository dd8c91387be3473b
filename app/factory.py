"""Where a resolved config becomes hydrobuckle's objects: each layer's material under the config's law, the
discrete problem (geometry, materials, loading, discretization) and the 1D cross-section of the exact
reduction; the time stepper of a problem, with the onset layer's limits and diagnosis given to it. Above
config.py (it reads the config through it) and below io/ and the workflows; model/, solvers/ and reduced/ take
these objects and never see a config dict's structure, and solvers/ never see a problem."""

from __future__ import annotations

from functools import partial

from app import config, geometry
from app.model import history
from app.model.loading import LOADINGS, Loading
from app.model.material import Material
from app.model.operators import cell_content_change
from app.model.problem import Discretization, Problem
from app.onset.contact import ModelLimits
from app.onset.criteria import CRITERIA, LossOfStability
from app.onset.policy import CrossingPolicy
from app.onset.tracker import StabilitySettings
from app.reduced.section import Layer, NotReducible, Section
from app.solvers.newton import SolverSettings
from app.solvers.step_control import TimeSettings
from app.solvers.stepped_problem import SteppedProblem
from app.solvers.stepping import TimeStepper


def layer_materials(cfg: dict, names=("film", "substrate")) -> dict[str, Material]:
    """Parameters of each named material (film, substrate, [material.layers.*]) under the config's law."""
    law = config.law(cfg)
    return {name: law.material(config.layer_parameters(cfg, name)) for name in names}


# --- settings objects from a resolved config (the layers below never read the config) ----------------------


def time_settings(cfg: dict) -> TimeSettings:
    """The [time] table."""
    t = cfg["time"]
    return TimeSettings(t["end"], t["dt_initial"], t["dt_min"], t["dt_max"], t["tolerance"], t["adaptive"],
                        t["max_steps"], t.get("stop_at_equilibrium", 0.0), t.get("controller", "predictive"))


def solver_settings(cfg: dict) -> SolverSettings:
    """The [solver] table."""
    s = cfg["solver"]
    return SolverSettings(s["rtol"], s["atol"], s["max_it"], s["factorization"], s["linear"], s["ksp_rtol"],
                          s["ksp_max_it"], reuse=s["reuse"], reuse_rate=s["reuse_rate"])


def stability_settings(cfg: dict) -> StabilitySettings:
    """The [stability] table: the criterion with its own keys, the crossing policy."""
    s = cfg["stability"]
    rule = CRITERIA.get(s["criterion"])
    return StabilitySettings(s["enabled"], s["tolerance"],
                             CrossingPolicy.from_flags(s["stop_at_onset"], s["max_crossings"], s.get("after_onset")),
                             s["modes"], s["eigen_every"], s["screening"], s["error_estimate"], s["criterion"],
                             {k: s[k] for k in rule.keys}, s.get("imperfection", 0.01), s.get("surface_check", True),
                             s.get("branch_modes") or "1")


def discretization(cfg: dict) -> Discretization:
    """The quadrature degrees and the step the forms are first compiled with."""
    mesh = cfg["mesh"]
    return Discretization(mesh["quadrature_degree"], mesh["coupling_quadrature_degree"], cfg["time"]["dt_initial"])


def loading(cfg: dict, mu_start: float, drive=None) -> Loading:
    """The [loading] table's kind with its keys; ``mu_start``: mu0 of the material under the permeable surface;
    ``drive``: the geometry's movable boundary."""
    lo = cfg["loading"]
    return LOADINGS.get(lo["kind"])(lo, mu_start=mu_start, end_time=cfg["time"]["end"], drive=drive)


def reference_length(cfg: dict) -> float | None:
    """The length stability.imperfection is a fraction of: the film thickness, or (kinds without one) the
    element size; None if the config has neither (a user's .msh: then the mesh's typical cell size,
    :func:`app.onset.branching.typical_cell_size`)."""
    value = cfg["geometry"].get("film_thickness") or cfg["mesh"].get("element_size")
    return float(value) if value else None


def problem(cfg: dict, comm, setup: geometry.GeometrySetup | None = None) -> Problem:
    """The problem of a resolved config: the geometry (built unless given), each layer's material, the loading
    (its surface ramp starting at the mu0 of the material under the permeable surface) and the
    discretization settings."""
    setup = setup if setup is not None else geometry.build(config.geometry_input(cfg), comm)
    materials = layer_materials(cfg, sorted(set(setup.layers.values())))
    surface = setup.material_under("permeable", comm)
    p = Problem(comm, setup, materials, loading(cfg, materials[surface].mu0, setup.drive), discretization(cfg))
    stab = cfg.get("stability", {})
    if stab.get("contact"):
        energy = stab.get("contact_energy", "auto")
        if energy == "auto":  # the penalty in 2D (validated longest), the barrier in 3D (the only one there)
            energy = "barrier" if p.domain.geometry.dim == 3 else "penalty"
        p.enable_contact(stab["contact_stiffness"], energy)
    return p


def stepped_problem(p: Problem) -> SteppedProblem:
    """What the time stepper advances of a problem: its forms, conditions, index sets and hooks."""
    return SteppedProblem(p.forms.energy, p.forms.residual, p.forms.hessian, p.bcs, p.w, p.state, p.u_dofs,
                          p.q_dofs, p.comm, cell_content_change(p), tuple(p.loading.kinks()), p.diffusion,
                          p.set_time, p.step_influx, partial(history.record, p), p.accept_step,
                          getattr(p, "contact", None), uptake="fluid_volume")


def time_stepper(p: Problem, time: TimeSettings, solver: SolverSettings, log=None, limits: bool = True,
                 diagnose: bool = True) -> TimeStepper:
    """The problem's time stepper; ``limits``: a followed branch ends at self-contact or an inverted cell
    (:class:`app.onset.contact.ModelLimits`); ``diagnose``: two failed attempts in a row test the state's
    stability (:class:`app.onset.criteria.LossOfStability`)."""
    return TimeStepper(stepped_problem(p), time, solver, log=log, limits=(lambda: ModelLimits(p)) if limits else None,
                       check=LossOfStability(p) if diagnose else None)


def section(cfg: dict) -> Section:
    """The cross-section of a reducible config (:func:`app.reduced.section.reducible`; else NotReducible
    naming the key)."""
    why = config.reducible(cfg)
    if why:
        raise NotReducible(why)
    geo = cfg["geometry"]
    cs = geometry.KINDS.get(geo["kind"]).cross_section(geo)  # the kind's own section
    materials = layer_materials(cfg)
    return Section(cs.shape, tuple(Layer(*layer) for layer in cs.layers), cs.surface, cs.base, cs.length, materials,
                   loading(cfg, materials["film"].mu0, cs.drive), width=cs.width, axial=cs.axial, clamped=cs.clamped)
