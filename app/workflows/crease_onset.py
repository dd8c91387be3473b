"""``stability.creases``: the energetic crease onset of a run's config, with its error bar (docs/creases.md).

The trial crease (:class:`app.onset.creases.CreaseTrial`) is computed on meshes of its own, graded towards
the crease's tip: three of them, with ``stability.crease_resolution`` / 4, / 2 and x 1 elements along the
crease. On each, the load where the creased state's energy falls below the flat state's is bracketed and
then found by regula falsi (:func:`app.onset.maxwell.level_onset`); the three onsets give the answer by
Richardson extrapolation and its error bar. A growing crease (``stability.crease_growth``) that outgrows the fine
zone on the coarsest level makes that
level a pilot: the three levels are then meshed with a band of fine elements along the symmetry line, and
the first of them marches from the pilot's onset. The coarsest level (the pilot, if there is one) scans the
whole run (time 0 to time.end, or to the end of a swelling ramp, after which the bath and so its
equilibrium states no longer change); each finer one starts from the coarser answer.

Under compression the load is the applied strain (linear in time). Under swelling the states are the body's
equilibria with the bath at mu_bar(t) (quasi-static swelling) and the load is reported as the flat state's
growth and the bath potential; which comes first, crease or wrinkle, is then decided on the growth (a
transient run's wrinkling onset is not at equilibrium at its time, its growth is the paper's measure).
With ``stability.crease_fluid = "transient"`` the states hold the run's own transient content at time t
instead (the laterally uniform transient of the exact 1D reduction, computed once on rank 0): the load is
the run's time, to time.end, and which comes first is decided on the time.
"""

from __future__ import annotations

from app import config, factory, geometry, logging_setup
from app.model import theory
from app.onset.creases import CreaseFailed, CreaseTrial
from app.onset.maxwell import level_onset, load_text
from app.reduced.content import content_profile
from app.reduced.transient import TransientFailed
from app.workflows.convergence import richardson
from app.workflows.reduction import settings as reduced_settings
from app.workflows.variants import variant

LEVEL_RATIO = 2  # crease_resolution halves from one level to the next coarser one
TIP_RADIUS = 1.5  # the finest elements reach this many crease lengths around the tip
GROWN_ZONES = 1.0  # a growing crease deeper than this many fine zones at its onset on the coarsest level ...
GROWN_MARGIN = 1.25  # ... has every level meshed again, fine along the symmetry line to this many times its depth
EQUILIBRIUM = 0.02  # under swelling, a wrinkling onset whose growth is this close to the equilibrium one at its
# time (relative) was reached quasi-statically: only then do the trial's equilibrium states decide which is first


def crease_length(cfg: dict) -> float:
    geo = cfg["geometry"]
    return cfg["stability"]["crease_size"] * (geo["substrate_thickness"] + geo["film_thickness"])


def add_creases(summary: dict, cfg: dict, comm) -> None:
    """The pipeline step: summary["creases"] (and its log line); a trial that cannot be completed is
    reported there, the run's other results kept."""
    log = logging_setup.get()
    try:
        block = crease_onset(cfg, comm, log.info, summary.get("critical"))
    except CreaseFailed as err:
        log.warning(f"creases: {err}")
        summary.setdefault("creases", {})["error"] = str(err)
        return
    critical, wrinkling = summary.get("critical"), block.get("wrinkling_equilibrium")
    try:
        block["film_onset"] = film_onset(cfg, comm, block, log.info)
    except CreaseFailed as err:
        log.warning(f"creases: the film's own crease onset: {err}")
        block["film_onset"] = {"error": str(err)}
    film = block["film_onset"]
    block["first"] = {"least_energy": _first(block["onset"], critical, wrinkling),
                      "nucleation": (None if "error" in film else
                                     _first(film.get("onset") and _by_time(film["onset"]), critical, wrinkling))}
    summary.setdefault("creases", {}).update(block)
    log.info("creases: " + describe(block, critical))


def homogeneous(cfg: dict) -> dict:
    """The config of a homogeneous block of the film's law: every layer made of the film's material (its
    parameters as the substrate's, the film's own table unset), the run's geometry, mesh, loading and
    trial keys otherwise. Raises :class:`CreaseFailed` for a mesh with further named layers."""
    if cfg["material"].get("layers"):
        raise CreaseFailed("a mesh with named layers beyond film and substrate has no single surface layer "
                           "whose own onset this computes")
    changes = {f"material.{k}": v for k, v in config.film_overrides(cfg).items()}
    changes.update({f"material.film.{k}": None for k in cfg["material"]["film"]})
    return variant(cfg, changes)


def film_onset(cfg: dict, comm, block: dict, log=lambda msg: None) -> dict:
    """The film's own crease onset (a dict for summary.json ``creases.film_onset``): the onset of a crease
    small against the film, which sees a homogeneous body of the film's law. A flawless film nucleates creases
    there, not at the least-energy onset of a crease grown over a barrier (docs/creases.md, "Nucleation or
    least energy"). Computed as the trial crease's onset on a homogeneous block of the film's law
    (:func:`homogeneous`) under the run's loading, three levels and an error bar like the run's own; a run
    whose layers already share one law reuses its own onset. On the run's own transient (crease_fluid =
    "transient") the block's transient is not the run's, so there the small-crease limit on the run's surface
    (the surface's stretch ratio reaching Hong, Zhao & Suo's) stands for it."""
    if "small_crease_limit" in block:
        limit = block["small_crease_limit"]
        return {"onset": limit and {"time": limit["time"], "growth_mm": limit["growth_mm"], "fluid": "transient"},
                "method": "the small-crease limit on the run's own transient surface (stretch ratio "
                          f"{theory.CREASE_STRETCH_RATIO:.4g}, Hong, Zhao & Suo)"}
    if config.film_overrides(cfg) == config.substrate_parameters(cfg) and not cfg["material"].get("layers"):
        return {"onset": block["onset"], "method": "the run's own onset: its layers share one law"}
    block_cfg = homogeneous(cfg)
    log("creases: the film's own crease onset, on a homogeneous block of its law")
    own = crease_onset(block_cfg, comm, lambda msg: log(msg.replace("creases:", "creases (film's own):", 1)))
    return {"onset": own["onset"], "levels": own["levels"], "method": "the trial crease on a homogeneous block of the "
            "film's law under the run's loading (every layer the film's material)"}


def _by_time(onset: dict) -> dict:
    """A film's own onset compared on the load's time: its block's flat growth is not the run's, while the
    film's state at a time is (the same strain, or the same bath)."""
    return {k: v for k, v in onset.items() if k in ("time", "time_error", "snap")}


def crease_onset(cfg: dict, comm, log=lambda msg: None, critical: dict | None = None) -> dict:
    """The crease onset on every level and the extrapolated answer (a dict for summary.json). Under swelling,
    with the run's wrinkling onset ``critical``: also the equilibrium state's growth at its time
    (``wrinkling_equilibrium``), which says whether that onset was reached quasi-statically."""
    g = config.geometry_input(cfg)
    kind = geometry.kind_of(g)
    c = crease_length(cfg)
    finest = cfg["stability"]["crease_resolution"]
    resolutions = [finest // LEVEL_RATIO ** k for k in (2, 1, 0)]
    settings = factory.solver_settings(cfg)
    fluid = cfg["stability"]["crease_fluid"]
    grows = cfg["stability"]["crease_growth"]
    transient = fluid == "transient" and not config.loading_kind(cfg).fluid_frozen
    content = _content_profile(cfg, comm, log) if transient else None
    levels, found, swelling, wrinkling, depth, pilot = [], None, False, None, 0.0, None
    queue = list(resolutions)
    while queue:
        resolution = queue.pop(0)
        setup = (kind.crease_setup(g, comm, c / resolution, TIP_RADIUS * c, tip_depth=depth) if depth
                 else kind.crease_setup(g, comm, c / resolution, TIP_RADIUS * c))
        problem = factory.problem(cfg, comm, setup=setup)
        surface = problem.materials[setup.material_under("permeable", comm)]
        mu = getattr(surface, config.law(cfg).stiffness)  # the energies are reported per mu c^2
        # a growing crease: the mirror contact's stiffness per area, kappa mu / h at the tip's elements
        mirror = cfg["stability"]["contact_stiffness"] * mu * resolution / c if grows else None
        trial = CreaseTrial(problem, c, settings, line=kind.crease_line(g), fluid=fluid, mirror_stiffness=mirror,
                            content=content)
        swelling = trial.system.fluid != "frozen"
        # the load's end: the bath's equilibria change until the ramp ends; a transient's content to time.end
        end = cfg["time"]["end"] if transient else problem.loading.load_end()
        try:
            if swelling and not transient and critical is not None and wrinkling is None:
                at = min(critical["time"], end)
                wrinkling = {"growth_mm": critical["growth_mm"], "equilibrium_growth_mm": trial.flat_growth(at)}
            level = level_onset(trial, found, end, mu * c * c, log)
        finally:
            trial.destroy()
        level.update(resolution=resolution, tip_size_mm=c / resolution, tip_depth_mm=depth, cells=problem.cells())
        log(f"creases: {resolution} elements along the trial crease ({problem.cells()} cells"
            + (f", fine to a depth of {depth:.4g} mm" if depth else "") + "): "
            + (f"onset at t = {level['time']:.6g} s ({load_text(level, swelling)})"
               if level["time"] is not None else "no onset up to time.end"))
        found = level["time"]
        if found is None:
            levels.append(level)
            break
        grown = level.get("depth_mm", 0.0)
        if grows and not levels and not depth and grown > GROWN_ZONES * TIP_RADIUS * c:
            # the crease has grown out of its fine zone: every level again, fine along the line to past it
            depth = GROWN_MARGIN * grown
            log(f"creases: the crease grew to a depth of {grown:.4g} mm at its onset, beyond the fine zone "
                f"({TIP_RADIUS * c:.4g} mm): every level again, fine along the symmetry line to {depth:.4g} mm")
            pilot = {**level, "pilot": True}
            queue = list(resolutions)
            continue
        levels.append(level)
    if depth:
        levels.insert(0, pilot)
    onset = None
    if found is not None:
        levels_used = [lv for lv in levels if not lv.get("pilot")]
        times = [lv["time"] for lv in levels_used]
        snap = any(lv.get("snap") for lv in levels_used)
        rich = _extrapolated(times, snap)
        t, err = rich["converged"], rich["errors"][-1]
        onset = {"time": t, "time_error": err, "order": rich["order"],
                 "position_mm": [kind.crease_line(g), _top(cfg)]}
        if snap:
            onset["snap"] = True
        if swelling:  # each level's flat growth at its onset, extrapolated like the times
            growth = _extrapolated([lv["growth_mm"] for lv in levels_used], snap)
            mu_bar = problem.loading.mu_bar
            onset.update(growth_mm=growth["converged"], growth_error=growth["errors"][-1], mu_bar=mu_bar(t),
                         mu_bar_error=abs(mu_bar(t + err) - mu_bar(t)), fluid=fluid)
        else:
            last = levels_used[-1]
            strain_rate = last["applied_strain"] / last["time"]  # the compression ramp is linear in t
            onset.update(applied_strain=strain_rate * t, applied_strain_error=abs(strain_rate) * err)
    extra = {"wrinkling_equilibrium": wrinkling} if wrinkling is not None else {}
    if transient:
        extra["small_crease_limit"] = _small_crease_limit(content, log)
    return {"onset": onset, "crease_size_mm": c, "levels": levels, "growth": grows, "tip_depth_mm": depth, **extra,
            "method": ("trial crease on the symmetry line, growing in contact with its mirror image to its size of "
                       "least energy, followed down in load" if grows else
                       "trial crease of fixed size on the symmetry line") + " (Hong, Zhao & Suo 2009)"
                      + ("; the run's own transient states (content from the exact 1D transient, held in every "
                         "cell: undrained), stored energies compared" if transient else
                         f"; states in equilibrium with the bath, grand potentials compared ({fluid})"
                         if swelling else ""),
            "penetration_mm": max((e["penetration_mm"] for lv in levels for e in lv["trials"]
                                   if "penetration_mm" in e and e["difference"] > 0), default=0.0)}


def _content_profile(cfg: dict, comm, log):
    """The run's laterally uniform transient content (:func:`app.reduced.content.content_profile`) to
    time.end, at the 1D reduction's resolution (its [reduced] keys): computed on rank 0, broadcast."""
    profile, error = None, None
    if comm.rank == 0:
        try:
            profile = content_profile(factory.section(cfg), reduced_settings(cfg).resolution, cfg["time"]["end"])
        except TransientFailed as err:
            error = str(err)
    profile, error = comm.bcast((profile, error), root=0)
    if error is not None:
        raise CreaseFailed(f"the run's uniform transient (1D) failed: {error}")
    log(f"creases: the run's content from its uniform 1D transient, {len(profile.times)} steps to "
        f"t = {profile.times[-1]:.4g} s")
    return profile


def _small_crease_limit(profile, log) -> dict | None:
    """Where the trial crease tends as it shrinks on a transient state: a crease much smaller than the depth over
    which the content varies sees a uniformly prestretched surface, and forms when the surface's stretch ratio
    (across the layers / along them = 1) reaches Hong, Zhao & Suo's 2.396 (their strain 0.354). From the 1D
    transient's surface stretch; None if it is never reached."""
    t = profile.first_surface_stretch(theory.CREASE_STRETCH_RATIO)
    if t is None:
        return None
    out = {"time": t, "growth_mm": profile.growth_at(t), "surface_stretch": theory.CREASE_STRETCH_RATIO}
    log(f"creases: the small-crease limit: the surface's stretch reaches {theory.CREASE_STRETCH_RATIO:.4g} at "
        f"t = {t:.6g} s, growth {out['growth_mm'] * 1e3:.5g} um")
    return out


def _extrapolated(values: list, snap: bool) -> dict:
    """Richardson over the levels; a snap's loads are upper bounds, not a converging sequence: the finest one,
    with its distance from the next coarser as the error."""
    if snap:
        return {"converged": values[-1], "errors": [abs(values[-1] - values[-2])], "order": None}
    return richardson(values, LEVEL_RATIO)


def _top(cfg: dict) -> float:
    geo = cfg["geometry"]
    return geo["substrate_thickness"] + geo["film_thickness"]


def _first(onset: dict | None, critical: dict | None, wrinkling: dict | None = None) -> str | None:
    """Which comes first: "crease" or "wrinkle" (None: neither within the run, or, under swelling, a wrinkling
    onset away from equilibrium with the bath, which the trial's equilibrium states cannot be compared with);
    under swelling by the growth."""
    if wrinkling is not None and not quasi_static(wrinkling):
        return None
    if onset is None:
        return "wrinkle" if critical else None
    measure = _measure(onset)
    if critical is None or onset[measure] < critical[measure]:
        return "crease"
    return None if onset.get("snap") else "wrinkle"  # an upper bound above the wrinkling onset decides nothing


def _measure(onset: dict) -> str:
    """What a crease onset is compared with the wrinkling onset on: the growth of an equilibrium state, else the
    time (a compression's, or the run's own transient)."""
    return "growth_mm" if "growth_mm" in onset and onset.get("fluid") != "transient" else "time"


def quasi_static(wrinkling: dict) -> bool:
    """Whether a swelling run's wrinkling onset was in equilibrium with the bath (its growth within
    EQUILIBRIUM of the equilibrium state's at its time)."""
    eq = wrinkling["equilibrium_growth_mm"]
    return abs(wrinkling["growth_mm"] - eq) <= EQUILIBRIUM * abs(eq)


def _onset_line(onset: dict | None) -> str:
    if onset is None:
        return "no trial crease has less energy than the flat state up to time.end"
    if onset.get("snap"):
        return _onset_line({**onset, "snap": False}).replace(" from ", " from at most ", 1) + (
            " (the trial crease snaps there to a far deeper fold: a larger crease has less energy, the onset is "
            "at or below this load)")
    if onset.get("fluid") == "transient":
        return (f"on the run's own transient state (its content held: undrained), a crease has less energy than "
                f"the flat surface from t = {onset['time']:.5g} +- {onset['time_error']:.2g} s (growth "
                f"{onset['growth_mm'] * 1e3:.5g} +- {onset['growth_error'] * 1e3:.2g} um)")
    if "growth_mm" in onset:
        return (f"in equilibrium with the bath, a crease has less grand potential than the flat surface from a "
                f"growth of {onset['growth_mm'] * 1e3:.5g} +- {onset['growth_error'] * 1e3:.2g} um (bath potential "
                f"{onset['mu_bar']:.4g} MPa, t = {onset['time']:.5g} s, {onset['fluid']})")
    return (f"a crease has less energy than the flat surface from t = {onset['time']:.5g} +- "
            f"{onset['time_error']:.2g} s (applied strain {onset['applied_strain']:.4g} +- "
            f"{onset['applied_strain_error']:.2g})")


def describe(block: dict, critical: dict | None) -> str:
    onset = block["onset"]
    line = _onset_line(onset)
    limit = block.get("small_crease_limit")
    if limit is not None:
        line += (f" [as the trial crease shrinks: t = {limit['time']:.5g} s, growth {limit['growth_mm'] * 1e3:.5g} um, "
                 "where the surface's stretch reaches Hong, Zhao & Suo's ratio]")
    wrinkling = block.get("wrinkling_equilibrium")
    if wrinkling is not None and not quasi_static(wrinkling):
        return line + (f"; the run's wrinkling onset (growth {wrinkling['growth_mm'] * 1e3:.5g} um) is far from "
                       f"equilibrium with the bath (there: {wrinkling['equilibrium_growth_mm'] * 1e3:.5g} um), so "
                       "these equilibrium states do not say which comes first (a quasi-static ramp would)")
    return line + _energy_verdict(block, critical) + _nucleation_verdict(block, critical)


def _energy_verdict(block: dict, critical: dict | None) -> str:
    onset = block["onset"]
    if onset is None:
        return ""
    measure = _measure(onset)
    unit, scale, at = ("um", 1e3, "a growth of") if measure == "growth_mm" else ("s", 1.0, "t =")
    if critical is None:
        return "; no wrinkling onset within the run: the crease comes first"
    where = f"the wrinkling onset at {at} {critical[measure] * scale:.5g} {unit}"
    if _verdict(block, "least_energy") == "crease":
        return f", before {where}: by least energy the crease comes first"
    return (f", after {where} ({onset[measure] / critical[measure]:.3g} x its "
            f"{'growth' if measure == 'growth_mm' else 'time'}): by least energy wrinkles come first")


def _verdict(block: dict, criterion: str) -> str | None:
    return (block.get("first") or {}).get(criterion)


def _nucleation_verdict(block: dict, critical: dict | None) -> str:
    """The log's sentence on the film's own onset against the wrinkling onset (empty without one)."""
    film = block.get("film_onset") or {}
    own = film.get("onset")
    if "error" in film or not film:
        return ""
    if own is None:
        return ("; the film's own crease onset lies beyond the run"
                + (": by nucleation wrinkles come first" if _verdict(block, "nucleation") == "wrinkle" else ""))
    err = f" +- {own['time_error']:.2g}" if "time_error" in own else ""
    text = f"; the film's own crease onset (a crease small against the film) at t = {own['time']:.5g}{err} s"
    verdict = _verdict(block, "nucleation")
    if verdict is None:
        return text + ": by nucleation undecided"
    return text + (", before the wrinkling onset: by nucleation creases come first" if verdict == "crease" else
                   (", after the wrinkling onset: by nucleation wrinkles come first" if critical else
                    ": by nucleation wrinkles come first"))
