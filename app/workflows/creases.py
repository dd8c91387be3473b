"""``stability.creases``: the energetic crease onset of a run's config, with its error bar (docs/creases.md).

The trial crease (:class:`app.onset.creases.CreaseTrial`) is computed on meshes of its own, graded towards
the crease's tip: three of them, with ``stability.crease_resolution`` / 4, / 2 and x 1 elements along the
crease. On each, the load where the creased state's energy falls below the flat state's is bracketed and
then found by regula falsi; the three onsets give the answer by Richardson extrapolation and its error bar.
A growing crease (``stability.crease_growth``) that outgrows the fine zone on the coarsest level makes that
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

import math

from app import config, factory, geometry, logging_setup
from app.model import theory
from app.onset.creases import CreaseFailed, CreaseTrial, FlatFailed
from app.reduced.transient import TransientFailed, content_profile
from app.workflows.convergence import richardson
from app.workflows.reduced import settings as reduced_settings

SCAN_POINTS = 8  # the coarsest level's load grid over the run
BISECTIONS = 2  # the bracket is halved this often before regula falsi (its far end may be far past the onset)
FALSI_STEPS = 6  # at most this many Illinois regula falsi steps after that, until the bracket is within
TOLERANCE = 2e-4  # this fraction of its load
FAR_END_RATIO = 4.0  # a negative end this many times larger than the positive one is not interpolated towards
SNAP_DEPTH_RATIO = 2.0  # a bracket whose negative end's crease is this many times deeper (or failed) ends in a snap
MARCH_FRACTION = 0.03  # a finer level brackets its onset from the coarser one's in steps of this fraction of it
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
    block["first"] = _first(block["onset"], summary.get("critical"), block.get("wrinkling_equilibrium"))
    summary.setdefault("creases", {}).update(block)
    log.info("creases: " + describe(block, summary.get("critical")))


def crease_onset(cfg: dict, comm, log=lambda msg: None, critical: dict | None = None) -> dict:
    """The crease onset on every level and the extrapolated answer (a dict for summary.json). Under swelling,
    with the run's wrinkling onset ``critical``: also the equilibrium state's growth at its time
    (``wrinkling_equilibrium``), which says whether that onset was reached quasi-statically."""
    kind = geometry.kind_of(cfg)
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
        setup = (kind.crease_setup(cfg, comm, c / resolution, TIP_RADIUS * c, tip_depth=depth) if depth
                 else kind.crease_setup(cfg, comm, c / resolution, TIP_RADIUS * c))
        problem = factory.problem(cfg, comm, setup=setup)
        surface = problem.materials[setup.material_under("permeable", comm)]
        mu = getattr(surface, config.law(cfg).stiffness)  # the energies are reported per mu c^2
        # a growing crease: the mirror contact's stiffness per area, kappa mu / h at the tip's elements
        mirror = cfg["stability"]["contact_stiffness"] * mu * resolution / c if grows else None
        trial = CreaseTrial(problem, c, settings, line=kind.crease_line(cfg), fluid=fluid, mirror_stiffness=mirror,
                            content=content)
        swelling = trial.system.fluid != "frozen"
        # the load's end: the bath's equilibria change until the ramp ends; a transient's content to time.end
        end = cfg["time"]["end"] if transient else problem.loading.load_end()
        try:
            if swelling and not transient and critical is not None and wrinkling is None:
                at = min(critical["time"], end)
                wrinkling = {"growth_mm": critical["growth_mm"], "equilibrium_growth_mm": trial.flat_growth(at)}
            level = _level(trial, found, end, mu * c * c, log)
        finally:
            trial.destroy()
        level.update(resolution=resolution, tip_size_mm=c / resolution, tip_depth_mm=depth, cells=problem.cells())
        log(f"creases: {resolution} elements along the trial crease ({problem.cells()} cells"
            + (f", fine to a depth of {depth:.4g} mm" if depth else "") + "): "
            + (f"onset at t = {level['time']:.6g} s ({_load(level, swelling)})"
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
                 "position_mm": [kind.crease_line(cfg), _top(cfg)]}
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
    """The run's laterally uniform transient content (:func:`app.reduced.transient.content_profile`) to
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


def _load(level: dict, swelling: bool) -> str:
    if swelling:
        return f"growth {level['growth_mm'] * 1e3:.5g} um, bath potential {level['mu_bar']:.5g} MPa"
    return f"applied strain {level['applied_strain']:.5g}"


def _top(cfg: dict) -> float:
    geo = cfg["geometry"]
    return geo["substrate_thickness"] + geo["film_thickness"]


def _level(trial: CreaseTrial, guess: float | None, end: float, scale: float, log) -> dict:
    """One mesh's onset: a bracket where the energy difference changes sign (the whole run scanned, or
    marching from ``guess``), halved twice, then Illinois regula falsi (halving while the negative end is
    far below zero against the positive one). A load where the crease cannot be
    held at its size (the solve fails: far past the onset, the crease runs away) counts as past the onset."""
    trials = []
    swelling = trial.system.fluid != "frozen"

    def difference(t: float) -> float:
        try:
            tr = trial.trial(t)
        except FlatFailed:  # no flat state, no comparison: the level cannot be completed
            raise
        except CreaseFailed as err:
            log(f"  t = {t:.6g} s: {err}; counted as past the onset")
            trials.append({"time": t, "failed": str(err)})
            return -math.inf
        entry = {"time": t, "applied_strain": tr.applied_strain, "difference": tr.difference,
                 "difference_per_mu_c2": tr.difference / scale, "penetration_mm": tr.penetration,
                 "depth_mm": tr.depth, "substeps": tr.substeps, "followed": tr.followed}
        if swelling:
            entry.update(mu_bar=tr.mu_bar, growth_mm=tr.growth)
        trials.append(entry)
        log(f"  t = {t:.6g} s, {_load(entry, swelling)}: creased - flat energy = "
            f"{tr.difference / scale:+.5f} mu c^2, crease depth {tr.depth:.4g} mm")
        return tr.difference

    try:
        bracket = _bracket(difference, guess, end)
    except CreaseFailed:
        failed = [tr["failed"] for tr in trials if "failed" in tr]
        if failed and len(failed) == len(trials):  # not one trial completed: that is the reason
            raise CreaseFailed(failed[0]) from None
        raise
    time, snap = None, False
    if bracket is not None:
        (a, fa), (b, fb) = bracket
        for _ in range(BISECTIONS):
            t = 0.5 * (a + b)
            ft = difference(t)
            (a, fa), (b, fb) = ((t, ft), (b, fb)) if ft > 0 else ((a, fa), (t, ft))
        rechecked = set()

        def on_branch(a, fa, b, fb):
            """The bracket with its positive end on the grown crease's branch (:func:`_on_the_grown_branch`):
            once, for an end closed from the flat state while a growing crease with less energy is known."""
            if not (trial.grows and math.isfinite(fb)) or a in rechecked or _entry(trials, a).get("followed"):
                return (a, fa), (b, fb)
            (a, fa), (b, fb) = _on_the_grown_branch(difference, ((a, fa), (b, fb)), end)
            rechecked.add(a)
            return (a, fa), (b, fb)

        side, ga, gb = None, fa, fb  # g: Illinois' weights (halved on a retained end); f: the true values
        for _ in range(FALSI_STEPS):
            (a2, fa2), (b2, fb2) = on_branch(a, fa, b, fb)
            if (a2, b2) != (a, b):  # the bracket moved onto the branch: Illinois starts again
                (a, fa), (b, fb), side, ga, gb = (a2, fa2), (b2, fb2), None, fa2, fb2
            if b - a <= TOLERANCE * b:
                break
            if not math.isfinite(gb) or -gb > FAR_END_RATIO * ga:  # the far end is far past the onset: halve instead
                t = 0.5 * (a + b)
            else:
                t = b - gb * (b - a) / (gb - ga)
            ft = difference(t)
            if ft > 0:
                a, fa, ga = t, ft, ft
                if side == "a":
                    gb *= 0.5
                side = "a"
            else:
                b, fb, gb = t, ft, ft
                if side == "b":
                    ga *= 0.5
                side = "b"
        time = a - fa * (b - a) / (fb - fa) if math.isfinite(fb) else 0.5 * (a + b)
        snap = _snapped(trials, a, b, trial.grows)
    loading = trial.problem.loading
    level = {"time": time, "applied_strain": loading.applied_strain(time) if time is not None else None,
             "trials": trials}
    if bracket is not None and math.isfinite(fb):  # the crease of least energy at the onset: its depth
        level["depth_mm"] = _entry(trials, b)["depth_mm"]
    if snap:
        level["snap"] = True
        log(f"  the trial crease snaps at t = {time:.6g} s to a fold far deeper than itself (or cannot be held) "
            f"while its energy difference is still {fa / scale:+.3g} mu c^2: a larger crease has less energy "
            "there, so this load bounds the onset from above")
    if swelling:  # the flat state's growth at the onset
        level.update(mu_bar=loading.mu_bar(time) if time is not None else None,
                     growth_mm=trial.flat_growth(time) if time is not None else None)
    return level


def _entry(trials: list, t: float) -> dict:
    """The last trial at load t (a load may have been evaluated again on a grown crease's branch)."""
    return next(tr for tr in reversed(trials) if tr["time"] == t)


def _on_the_grown_branch(difference, bracket, end: float):
    """A growing crease's bracket with both ends on the branch of the crease found at its negative end: the
    positive end was closed from the flat state before that crease was known, and may be a smaller crease
    with more energy (the two coexist near the onset). Evaluated again it is followed down from the
    negative end (:meth:`CreaseTrial.trial`); while that is still negative, the bracket moves down by its
    width, doubled at every move (:func:`_down_to_positive`)."""
    (a, _), negative = bracket
    return _down_to_positive(difference, negative, end, negative[0] - a, 2.0, "the grown crease")


def _snapped(trials: list, a: float, b: float, grows: bool) -> bool:
    """Whether the final bracket [a, b] ends in a snap rather than a sign change of one crease's energy: at b
    the trial failed, or, for a crease held at its size, its crease is SNAP_DEPTH_RATIO times deeper than at a (the free
    surface beyond the trial crease has folded onto the line, through it: a larger crease). A growing crease
    (``stability.crease_growth``) is that larger crease, followed down to its own sign change."""
    at = {tr["time"]: tr for tr in trials}
    ta, tb = at[a], at[b]
    return "failed" in tb or (not grows and tb["depth_mm"] > SNAP_DEPTH_RATIO * ta["depth_mm"])


def _bracket(difference, guess: float | None, end: float):
    """((t, dPi > 0), (t, dPi <= 0)) or None if the difference stays positive to ``end``: a scan of the run
    (no ``guess``), or a march from ``guess`` in steps of MARCH_FRACTION of it, up or down as its sign says."""
    if guess is None:
        found = _walk(difference, None, 0.0, end / SCAN_POINTS, end)
        if found is not None and found[0] is None:  # negative at the first load: halve it down to a positive one
            return _down_to_positive(difference, found[1], end, found[1][0] / 2, 0.5)
        return found
    step = MARCH_FRACTION * guess
    f = difference(guess)
    if f <= 0:
        return _down_to_positive(difference, (guess, f), end, step)
    return _walk(difference, (guess, f), guess, step, end)


def _walk(difference, prev, origin: float, step: float, end: float):
    """Up from ``origin`` (``prev``: its (t, dPi > 0), or None) in steps of ``step`` to ``end``: (the last
    positive (t, dPi) or None, the first non-positive) at the first sign change, else None. Where the flat
    state ends before a load (FlatFailed: a transient's surface past its own stability) the walk starts
    again, once, from its last positive load (or ``origin``) in SCAN_POINTS steps up to the last load the
    flat state was solved at; a crease onset lies below it or is not known (FlatFailed again)."""
    narrowed, k = None, 0
    if origin >= end:
        return None
    while True:
        k += 1
        t = min(end, origin + k * step)
        try:
            f = difference(t)
        except FlatFailed as err:
            start = prev[0] if prev else origin
            if narrowed is not None or err.reached <= start:
                raise
            narrowed, end = err, err.reached
            origin, step, k = start, (end - start) / SCAN_POINTS, 0
            continue
        if f <= 0:
            return prev, (t, f)
        prev = (t, f)
        if t >= end:
            break
    if narrowed is not None:  # no onset below the flat state's end: nothing is known beyond it
        raise narrowed
    return None


def _down_to_positive(difference, negative, end: float, width: float, growth: float = 1.0,
                      what: str = "the trial crease"):
    """From a load whose difference is not positive, ``negative`` = (t, dPi), down in steps of ``width``
    (times ``growth`` at every move) to a positive one, at most to end / 1000: ((t, dPi > 0), the lowest
    non-positive (t, dPi) seen)."""
    (b, fb), floor = negative, end * 1e-3
    while True:
        if b <= floor:
            raise CreaseFailed(f"{what} has less energy than the flat state at every load tried, down to "
                               f"t = {floor:.3g} s: no onset to bracket")
        a = max(floor, b - width)
        fa = difference(a)
        if fa > 0:
            return (a, fa), (b, fb)
        b, fb, width = a, fa, width * growth


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
    if onset is None:
        return line
    measure = _measure(onset)
    unit, scale, at = ("um", 1e3, "a growth of") if measure == "growth_mm" else ("s", 1.0, "t =")
    if critical is None:
        return line + "; no wrinkling onset within the run: the crease comes first"
    where = f"the wrinkling onset at {at} {critical[measure] * scale:.5g} {unit}"
    if block["first"] == "crease":
        return line + f", before {where}: the crease comes first"
    return line + (f", after {where} ({onset[measure] / critical[measure]:.3g} x its "
                   f"{'growth' if measure == 'growth_mm' else 'time'}): wrinkles come first")
