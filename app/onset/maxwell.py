"""The Maxwell point of one mesh's trial crease: the load where the creased state's energy falls below the
flat state's (docs/creases.md), found from an energy difference dPi(t) that is positive before it.

The search needs nothing but the difference as a function of the load, with two ways for it to fail:
a creased state that cannot be held (:class:`~app.onset.creases.CreaseFailed`, counted as past the onset)
and a flat state that cannot be solved (:class:`~app.onset.creases.FlatFailed`, which ends the search). It
brackets the sign change, either scanning the whole run (the coarsest mesh) or marching from a coarser
mesh's answer, halves the bracket, then closes it by Illinois regula falsi. A growing crease's bracket is
moved onto the branch of the crease of least energy before it is closed; a bracket whose negative end is a
far deeper fold is a snap, an upper bound of the onset. :func:`level_onset` is the whole search on one
:class:`~app.onset.creases.CreaseTrial`; the workflow (:mod:`app.workflows.crease_onset`) runs it on three meshes
and extrapolates.
"""

from __future__ import annotations

import math

from app.onset.creases import CreaseFailed, CreaseTrial, FlatFailed

SCAN_POINTS = 8  # the coarsest level's load grid over the run
BISECTIONS = 2  # the bracket is halved this often before regula falsi (its far end may be far past the onset)
FALSI_STEPS = 6  # at most this many Illinois regula falsi steps after that, until the bracket is within
TOLERANCE = 2e-4  # this fraction of its load
FAR_END_RATIO = 4.0  # a negative end this many times larger than the positive one is not interpolated towards
SNAP_DEPTH_RATIO = 2.0  # a bracket whose negative end's crease is this many times deeper (or failed) ends in a snap
MARCH_FRACTION = 0.03  # a finer level brackets its onset from the coarser one's in steps of this fraction of it


def load_text(level: dict, swelling: bool) -> str:
    """A level's (or one trial's) load in words: the flat state's growth and bath potential under swelling, else
    the applied strain."""
    if swelling:
        return f"growth {level['growth_mm'] * 1e3:.5g} um, bath potential {level['mu_bar']:.5g} MPa"
    return f"applied strain {level['applied_strain']:.5g}"


def level_onset(trial: CreaseTrial, guess: float | None, end: float, scale: float, log) -> dict:
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
        log(f"  t = {t:.6g} s, {load_text(entry, swelling)}: creased - flat energy = "
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
