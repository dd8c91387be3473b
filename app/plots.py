"""Matplotlib figures (Agg backend, no display needed)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def history_plot(rows: list[dict], path) -> None:
    """Growth and surface chemical potential against time (two stacked panels)."""
    t = [r["time"] for r in rows]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(6.4, 5.6))
    ax1.plot(t, [1e3 * r["growth_mm"] for r in rows], "-", color="C0")
    ax1.set_ylabel("growth [um]")
    ax1.grid(alpha=0.3)
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
