"""Matplotlib figures (Agg backend, no display needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from app.model.shapes import SHAPES, along_profile, around_profile


def history_plot(rows: list[dict], path, critical: dict | None = None) -> None:
    """Growth and surface chemical potential against time (two stacked panels); ``critical`` (the
    summary's block) marks the onset: t_c on both panels, (t_c, g_c) on the growth curve."""
    t = [r["time"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5.6))
    ax1.plot(t, [1e3 * r["growth_mm"] for r in rows], "-", color="C0")
    ax1.set_ylabel("growth [um]")
    ax1.grid(alpha=0.3)
    if critical:
        tc, gc = critical["time"], critical["growth_um"]
        for ax in (ax1, ax2):
            ax.axvline(tc, color="C3", lw=0.8, ls=":")
        ax1.plot([tc], [gc], "o", color="C3", ms=6,
                 label=f"onset: g_c = {gc:.3g} um at t_c = {tc:.4g} s, N_c = {critical['wrinkle_count']:g}")
        ax1.legend(fontsize=8, loc="upper left")
    if any(r.get("applied_strain") for r in rows):
        ax1b = ax1.twinx()
        ax1b.plot(t, [r["applied_strain"] for r in rows], "--", color="C2")
        ax1b.set_ylabel("applied strain [-]", color="C2")
    ax2.plot(t, [r["mu_bar"] for r in rows], "-", color="C1")
    ax2.set_ylabel("surface chemical potential [MPa]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def mode_plot(polys, profile, geo, crossing, path) -> None:
    """The mode along the permeable surface, and the body deformed by the critical state with the
    mode superposed (amplified), as in the paper's mode figures: the near-surface band of a bilayer,
    the whole cross-section of a tube."""
    import numpy as np
    from matplotlib.collections import PolyCollection

    X, U, M, layer = polys
    x_prof, y_prof, xlabel, ylabel = profile

    around = SHAPES.get(geo.wrinkles).closed
    size = np.ptp(X[:, :, 0]) if not around else max(np.ptp(X[:, :, 0]), np.ptp(X[:, :, 1]))
    keep = np.ones(len(X), dtype=bool)
    if geo.plot_band is not None:
        top = X[:, :, 1].max()
        keep = X[:, :, 1].min(axis=1) >= top - geo.plot_band
        amp = 0.1 * geo.plot_band
    else:
        amp = 0.03 * size
    shapes = X + U + amp * M
    fig = plt.figure(figsize=(9, 8.5 if around else 5.5))
    if around:
        ax1 = fig.add_subplot(2, 1, 1)
        ax2 = fig.add_subplot(2, 1, 2)
    else:
        ax1, ax2 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1, 1.4]})
    ax1.plot(x_prof, y_prof, "-", color="C0", lw=1)
    if around:
        ax1.plot(x_prof, envelope(x_prof, y_prof), "-", color="C3", lw=1.2, label="local amplitude")
        ax1.legend(fontsize=8, loc="upper right")
    ax1.set_xlabel(xlabel, fontsize=9)
    ax1.set_ylabel(ylabel, fontsize=9)
    ax1.set_title(f"g_c = {1e3 * crossing.growth_mm:.3f} um, N_c = {crossing.wrinkle_count:g}, "
                  f"t_c = {crossing.time:.4f} s; first critical mode shown (N = "
                  f"{crossing.first_mode_wrinkle_count:g})", fontsize=10)
    ax1.grid(alpha=0.3)
    colors = np.where(layer[keep] == 1, "#c44e52", "#8fb1d9")
    coll = PolyCollection(shapes[keep], facecolors=colors, edgecolors="k", linewidths=0.05 if around else 0.1)
    ax2.add_collection(coll)
    ax2.autoscale_view()
    if around:
        ax2.set_aspect("equal")
    ax2.set_xlabel("x [mm]")
    ax2.set_ylabel("y [mm]")
    ax2.set_title("film (red) and substrate (blue), mode amplified", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def mode_map_plot(profile, crossing, path, axes=("x [mm]", "z [mm]"), wave_label="half-waves (m, n)") -> None:
    """A 3D run's mode seen from above: the permeable surface's normal mode displacement over its two in-plane
    coordinates (``profile``: (positions (N, 2), normalized values, labels); ``axes``: their labels; a tube's
    passage is shown unrolled) as a colour map."""
    position, value, _, _ = profile
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    tpc = ax.tricontourf(position[:, 0], position[:, 1], value, levels=21, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    fig.colorbar(tpc, ax=ax, label="normal mode displacement (max 1)")
    ax.set_aspect("equal")
    ax.set_xlabel(axes[0])
    ax.set_ylabel(axes[1])
    waves = ", ".join(str(tuple(m["wave_vector"])) for m in crossing.modes[:crossing.multiplicity]
                      if "wave_vector" in m)
    ax.set_title(f"g_c = {1e3 * crossing.growth_mm:.3f} um, t_c = {crossing.time:.4f} s, N_c = "
                 f"{crossing.wrinkle_count:.4g}\ncritical {wave_label}: {waves or '?'}"
                 f"\n{crossing.multiplicity} crossing together; the first shown", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def pattern_plot(profiles, patterns: list[dict], shape, path) -> None:
    """A followed 3D branch seen from above at the states of ``patterns``
    (:func:`app.model.patterns.branch_patterns`): the surface's detrended normal displacement as a colour map,
    each panel titled with its growth, pattern and strongest shapes (a passage is shown unrolled)."""
    import numpy as np

    index = {t: i for i, t in enumerate(profiles.time)}
    picks = [(index[p["time"]], p) for p in patterns if p["time"] in index] or [(len(profiles) - 1, None)]
    fig, axes = plt.subplots(1, len(picks), figsize=(4.2 * len(picks), 4.4), squeeze=False)
    for ax, (i, p) in zip(axes[0], picks):
        position, value = profiles.position[i], profiles.profile[i]
        if shape.name == "cylinder":  # angle -> arc length on the mean passage radius is not kept: degrees
            position = np.column_stack([np.degrees(position[:, 0]), position[:, 1]])
        scale = np.abs(value).max() or 1.0
        tpc = ax.tricontourf(position[:, 0], position[:, 1], 1e3 * value, levels=21, cmap="RdBu_r",
                             vmin=-1e3 * scale, vmax=1e3 * scale)
        fig.colorbar(tpc, ax=ax, label="normal displacement, detrended [um]", shrink=0.8)
        if shape.name != "cylinder":
            ax.set_aspect("equal")
        ax.set_xlabel("angle around the passage [deg]" if shape.name == "cylinder" else shape.map_axes[0])
        ax.set_ylabel(shape.map_axes[1])
        title = f"g = {1e3 * profiles.growth_mm[i]:.3f} um"
        if p is not None:
            ratio = f" ({p['growth_over_g_c']:.2f} g_c)" if p.get("growth_over_g_c") else ""
            shapes = ", ".join(f"({a}, {b}) {100 * f:.0f}%" for a, b, f in p["shapes"][:3])
            title += f"{ratio}\n{p['pattern']}: {shapes}"
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def convergence_plot(rows: list[dict], report: dict, path) -> None:
    """g_c against the refinement parameter per study, and the estimated error (log-log)."""
    import numpy as np

    studies = list(report["studies"])
    fig, axes = plt.subplots(1, len(studies), figsize=(5.2 * len(studies), 4), squeeze=False)
    for ax, study in zip(axes[0], studies):
        rs = [r for r in rows if r["study"] == study and r["g_c_um"] is not None]
        x = np.array([r["parameter"] for r in rs])
        g = np.array([r["g_c_um"] for r in rs])
        ax.semilogx(x, g, "o-", label="g_c")
        st = report["studies"][study]
        if st["converged"] is not None:
            ax.axhline(st["converged"], color="k", ls="--", lw=0.8, label=f"extrapolated {st['converged']:.4g} um")
        for xi, gi, r in zip(x, g, rs):
            ax.annotate(f"N={r['N_c']:g}", (xi, gi), textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_xlabel("time tolerance" if study == "time" else "element size [mm]")
        ax.set_ylabel("g_c [um]")
        order = st["order"]
        ax.set_title(f"{study}: observed order {order:.2f}" if order is not None else f"{study}: order n/a")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def envelope(angle_deg, values):
    """Local wrinkle amplitude along a closed surface: modulus of the analytic signal (Hilbert
    transform) of the profile resampled at even angles; shows where wrinkles fade."""
    import numpy as np
    from scipy.signal import hilbert

    order = np.argsort(angle_deg)
    a, v = np.asarray(angle_deg)[order], np.asarray(values)[order]
    grid = np.linspace(-180.0, 180.0, 2048, endpoint=False)
    even = np.interp(grid, a, v, period=360.0)
    env = np.abs(hilbert(even - even.mean()))
    return np.interp(angle_deg, grid, env, period=360.0)


def _series(rows):
    out = {}
    for r in rows:
        out.setdefault(r["series"], []).append(r)
    return out


def numeric(rows: list[dict]) -> bool:
    """Whether a study's swept values are numbers (else a string key, e.g. stability.branch_modes)."""
    try:
        [float(r["value"]) for r in rows]
    except (TypeError, ValueError):
        return False
    return True


def study_plot(rows: list[dict], title: str, param: str, path) -> None:
    """g_c and N_c against the swept parameter (two panels, one line per series), like the paper's
    study figures; error bars where a discretization error was estimated."""
    import numpy as np

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    labels = [] if numeric(rows) else list(dict.fromkeys(str(r["value"]) for r in rows))  # a string key: categories
    for i, (label, rs) in enumerate(_series(rows).items()):
        ok = [r for r in rs if r["g_c_um"] is not None]
        if not ok:
            continue
        x = np.array([float(r["value"]) if not labels else labels.index(str(r["value"])) for r in ok])
        g = np.array([r["g_c_um"] for r in ok])
        err = np.array([r["g_c_error_um"] or 0.0 for r in ok])
        ax1.errorbar(x, g, yerr=err if err.any() else None, fmt="o-", color=f"C{i}", label=label or None,
                     capsize=3, ms=4)
        ax2.plot(x, [r["N_c"] for r in ok], "s-", color=f"C{i}", label=label or None, ms=4)
        stable = [float(r["value"]) if not labels else labels.index(str(r["value"])) for r in rs
                  if r["status"] == "stable"]
        if stable:
            ax1.plot(stable, [g.min()] * len(stable), "x", color=f"C{i}", label="no onset (stable)")
    for ax, ylabel in ((ax1, "critical growth g_c [um]"), (ax2, "wrinkle count N_c")):
        ax.set_xlabel(param.split(".")[-1].replace("_", " "))
        if labels:
            ax.set_xticks(range(len(labels)), labels)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def modes_gallery(rows: list[dict], outdir, title: str, path) -> None:
    """The critical mode of every case: the normal mode displacement along an open surface, or the
    deformed passage outline of a tube."""
    import numpy as np

    cases = [r for r in rows if (outdir / r["directory"] / "mode_surface.csv").is_file()]
    if not cases:
        return
    ncol = min(4, len(cases))
    nrow = -(-len(cases) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 2.6 * nrow), squeeze=False)
    for ax in axes.flat:
        ax.set_axis_off()
    for ax, r in zip(axes.flat, cases):
        ax.set_axis_on()
        data = np.loadtxt(outdir / r["directory"] / "mode_surface.csv", delimiter=",", skiprows=1, ndmin=2)
        if data.shape[1] == 9:  # a 3D surface (x, y, z, mode, state): its normal mode displacement from above
            normal = int(np.argmin(np.ptp(data[:, :3], axis=0)))
            a, b = (k for k in range(3) if k != normal)
            ax.tricontourf(data[:, a], data[:, b], data[:, 3 + normal], levels=15, cmap="RdBu_r")
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(f"{r['value']}: g_c={r['g_c_um']:.3g} um", fontsize=8)
            continue
        xy, mode, state = data[:, :2], data[:, 2:4], data[:, 4:6]
        closed = np.allclose(xy.mean(axis=0), 0.0, atol=0.05 * np.ptp(xy))
        if closed:
            _, _, _, theta = around_profile(xy, mode)
            order = np.argsort(np.arctan2(xy[:, 1], xy[:, 0]))
            pts = xy[order] + state[order]
            m = mode[order] / (np.abs(mode).max() or 1.0)
            shape = pts + 0.04 * np.ptp(xy[:, 0]) * m
            shape = np.vstack([shape, shape[:1]])
            ax.plot(shape[:, 0], shape[:, 1], "-", color="#c44e52", lw=0.8)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
        else:
            t, un, _ = along_profile(xy, mode)
            ax.plot(t - t.min(), un / (np.abs(un).max() or 1.0), "-", color="C0", lw=0.7)
            ax.set_yticks([])
        ax.set_title(f"{r['value']}: g_c={r['g_c_um']:.3g} um, N={r['N_c']:g}", fontsize=8)
    fig.suptitle(f"critical modes: {title}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def isomode_plot(rows: list[dict], title: str, param: str, path) -> None:
    """Isomodes: for each wrinkle count N, the growth at the first crossing with that count across the
    sweep; their lower envelope is g_c (the paper's Fig. "bi_film")."""
    import numpy as np

    curves: dict[float, list] = {}
    envelope = []
    for r in rows:
        if not r["crossings"]:
            continue
        seen = set()
        pairs = [c.split("@") for c in r["crossings"].split(";")]
        for n, g in pairs:
            n, g = float(n), float(g)
            if n not in seen:
                curves.setdefault(n, []).append((float(r["value"]), g))
                seen.add(n)
        envelope.append((float(r["value"]), r["g_c_um"]))
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for n in sorted(curves):
        pts = np.array(sorted(curves[n]))
        if len(pts) >= 2:
            ax.plot(pts[:, 0], pts[:, 1], "-", lw=1, label=f"N = {n:g}")
    env = np.array(sorted(envelope))
    ax.plot(env[:, 0], env[:, 1], "k.-", lw=2, label="g_c (first crossing)")
    ax.set_xlabel(param.split(".")[-1].replace("_", " "))
    ax.set_ylabel("growth at crossing [um]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title(f"isomodes: {title}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def wrinkles_plot(profiles: list[tuple], critical: dict | None, closed: bool, path, count: int = 8,
                  creases: dict | None = None) -> None:
    """Surface profiles (the detrended normal displacement, app.model.surface.surface_profile) at up to
    ``count`` growths, evenly spaced from the first to the last, each offset by its rank, as wrinkle
    profiles are shown in experimental papers. ``profiles``: (growth_mm, time, position, profile) tuples;
    ``creases``: time -> number of contact zones (with self-contact), written beside each profile."""
    if not profiles:
        return
    pick = np.unique(np.round(np.linspace(0, len(profiles) - 1, min(count, len(profiles)))).astype(int))
    chosen = [profiles[i] for i in pick]
    span = max(float(np.ptp(p[3])) for p in chosen) or 1.0
    fig, ax = plt.subplots(figsize=(8, 1.2 + 0.6 * len(chosen)))
    for k, (g, t, pos, prof) in enumerate(chosen):
        x = np.degrees(pos) if closed else pos
        ax.plot(x, 1e3 * (prof + k * 1.2 * span), lw=1.0, color=plt.cm.viridis(k / max(1, len(chosen) - 1)))
        zones = (creases or {}).get(float(t), 0)
        label = f"  g = {1e3 * g:.2f} um" + (f", {zones} contact zone(s)" if zones else "")
        ax.text(x.max(), 1e3 * k * 1.2 * span, label, va="center", fontsize=8)
    ax.set_xlabel("angle around the passage [deg]" if closed else "position along the surface [mm]")
    ax.set_ylabel("normal displacement, detrended and offset [um]")
    gc = f" (g_c = {1e3 * critical['growth_mm']:.3f} um)" if critical else ""
    ax.set_title("surface profiles on the followed branch" + gc)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def amplitude_plot(rows: list[dict], critical: dict | None, path) -> None:
    """Wrinkle amplitude against growth with g_c marked, and the wrinkle count on a second axis."""
    g = np.array([1e3 * float(r["growth_mm"]) for r in rows])
    a = np.array([1e3 * float(r["amplitude_mm"]) for r in rows])
    n = np.array([float(r["wrinkle_count"]) for r in rows])
    order = np.argsort(g, kind="stable")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(g[order], a[order], "o-", ms=2.5, color="C0", label="amplitude")
    if critical:
        ax.axvline(1e3 * critical["growth_mm"], color="C3", ls="--", lw=1, label="g_c")
    touching = [r for r in rows if float(r.get("contact_length_mm") or 0.0) > 0.0]
    if touching:  # with self-contact: the first state in contact, the troughs folded into creases
        ax.axvline(1e3 * float(touching[0]["growth_mm"]), color="C2", ls=":", lw=1.2, label="first contact")
    ax.set_xlabel("growth [um]")
    ax.set_ylabel("amplitude [um]", color="C0")
    ax2 = ax.twinx()
    ax2.step(g[order], n[order], where="post", color="C1", lw=1, label="wrinkle count")
    ax2.set_ylabel("wrinkle count", color="C1")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def reduced_margin_plot(path, est, block: dict) -> None:
    """The 1D reduction's margin curve: each mode's critical growth against its wrinkle count (and
    wavelength), the onset marked, the surface's short-wave limit as a horizontal line."""
    curve = est.levels[0].curve
    ns = sorted(curve.modes)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if ns:
        ax.plot([curve.modes[n].wrinkles for n in ns], [1e3 * curve.modes[n].growth for n in ns], ".-", color="C0",
                ms=3, label=f"mode crossings ({block['criterion']})")
    if curve.short_wave is not None:
        ax.axhline(1e3 * curve.short_wave.growth, color="C3", ls="--", lw=1,
                   label=f"short-wave limit of the surface: {1e3 * curve.short_wave.growth:.4g} um")
    if block.get("kind") == "wrinkles":
        ax.plot([block["wrinkle_count"]], [block["growth_um"]], "o", color="C3",
                label=f"g_c = {block['growth_um']:.4g} um, N_c = {block['wrinkle_count']:g}")
    ax.set_xlabel("wrinkle count N")
    ax.set_ylabel("growth at the mode's crossing [um]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
