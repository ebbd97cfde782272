"""Plots of the cycloid-pin reducer's study outputs (matplotlib; drawn by the command line, never imported by the numerics).

The drive declares them as `gearte.drives.Figure("…", "gearte.drives.cycloid_pin_plots:NAME", data)`.
"""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib.figure import Figure


def clearance_per_pin(
    tangential_mm, normal_mm, on_driving, *, budget_mm: float, contact_pin: int, reverse_contact_pin: int, title: str, path
):
    """Tangential (arc on the pin circle) and normal clearance of every pin at one input position.

    Pins numbered 1 … z_b; driving-flank pins blue, reverse-flank pins orange; pins that can never
    touch (beyond the tooth tip) marked ×; the deformation budget dashed.
    """
    tang = np.asarray(tangential_mm, dtype=float)
    norm = np.asarray(normal_mm, dtype=float)
    drv = np.asarray(on_driving, dtype=bool)
    pins = np.arange(1, tang.size + 1)
    fig = Figure(figsize=(11, 7), dpi=110)
    axes = fig.subplots(2, 1, sharex=True)
    colors = np.where(drv, "#4477aa", "#ee7733")
    finite = np.isfinite(tang)
    top = float(np.max(tang[finite])) if np.any(finite) else 1.0
    ax = axes[0]
    ax.bar(pins[finite], tang[finite], color=colors[finite], width=0.7)
    ax.plot(pins[~finite], np.full(np.count_nonzero(~finite), top * 1.5), "x", color="#555555", markersize=8)
    ax.axhline(budget_mm, color="#cc3311", linestyle="--", linewidth=1.0, label=f"deformation budget {budget_mm:g} mm")
    ax.set_ylabel("tangential clearance (mm on the pin circle)")
    ax.set_yscale("symlog", linthresh=max(budget_mm / 10, 1e-4))
    ax.plot([], [], "s", color="#4477aa", label="driving flank")
    ax.plot([], [], "s", color="#ee7733", label="reverse flank")
    ax.plot([], [], "x", color="#555555", label="never touches (beyond the tooth tip)")
    ax.annotate(
        "contact",
        (contact_pin, 0),
        textcoords="offset points",
        xytext=(0, 12),
        ha="center",
        fontsize=8,
        arrowprops=dict(arrowstyle="->", color="#222222"),
    )
    ax.annotate(
        "reverse\ncontact",
        (reverse_contact_pin, 0),
        textcoords="offset points",
        xytext=(0, 12),
        ha="center",
        fontsize=8,
        arrowprops=dict(arrowstyle="->", color="#222222"),
    )
    ax.set_ylim(0, top * 3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_title(title, fontsize=9)
    ax = axes[1]
    ax.bar(pins, norm, color=colors, width=0.7)
    ax.axhline(0.0, color="#999999", linewidth=0.6)
    ax.set_ylabel("normal clearance (mm)")
    ax.set_xlabel("pin")
    ax.set_xticks(pins)
    fig.tight_layout()
    fig.savefig(path)


def clearance_vs_input(input_deg, tangential_mm, normal_mm, pins, *, budget_mm: float, title: str, path):
    """Clearance of each pin in `pins` (1-based) against the input angle over one pin pitch (the paper's figures 3–8).

    `tangential_mm`, `normal_mm`: arrays (positions, z_b).
    """
    x = np.asarray(input_deg, dtype=float)
    tang = np.asarray(tangential_mm, dtype=float)
    norm = np.asarray(normal_mm, dtype=float)
    fig = Figure(figsize=(13, 5), dpi=110)
    axes = fig.subplots(1, 2, sharex=True)
    cmap = matplotlib.colormaps["viridis"]
    for k, p in enumerate(pins):
        c = cmap(k / max(1, len(pins) - 1))
        t = tang[:, p - 1]
        if np.any(np.isfinite(t)):
            axes[0].plot(x, t, color=c, linewidth=1.1, label=f"pin {p}")
        axes[1].plot(x, norm[:, p - 1], color=c, linewidth=1.1, label=f"pin {p}")
    axes[0].axhline(budget_mm, color="#cc3311", linestyle="--", linewidth=1.0, label=f"budget {budget_mm:g} mm")
    axes[0].set_ylabel("tangential clearance (mm on the pin circle)")
    axes[0].set_yscale("symlog", linthresh=max(budget_mm / 10, 1e-4))
    axes[0].set_ylim(bottom=0.0)
    axes[1].set_ylabel("normal clearance (mm)")
    for ax in axes:
        ax.set_xlabel("input angle θ_T (°, one pin pitch)")
        ax.set_xlim(x[0], x[-1])
    # One legend for both panels: the pins (both) and the budget line, which only the tangential panel draws.
    handles, labels = axes[1].get_legend_handles_labels()
    budget = [(h, lb) for h, lb in zip(*axes[0].get_legend_handles_labels()) if lb.startswith("budget")]
    axes[1].legend(
        handles + [h for h, _ in budget], labels + [lb for _, lb in budget], fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0)
    )
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def rotation_error(input_rev, forward_arcsec, reverse_arcsec, *, title: str, path):
    """Rotation error of the stage under a forward and a reverse load against the input angle (top,
    each about its mean), and the lost motion between them (bottom; negative: interference)."""
    x = np.asarray(input_rev, dtype=float)
    f = np.asarray(forward_arcsec, dtype=float)
    r = np.asarray(reverse_arcsec, dtype=float)
    lm = (f - r) / 60.0
    fig = Figure(figsize=(10, 6.4), dpi=110)
    axes = fig.subplots(2, 1, sharex=True)
    ax = axes[0]
    ax.plot(x, f - f.mean(), color="#4477aa", linewidth=1.0, label=f"forward load: mean {f.mean():.1f}″, p-p {f.max() - f.min():.1f}″")
    ax.plot(x, r - r.mean(), color="#ee7733", linewidth=1.0, label=f"reverse load: mean {r.mean():.1f}″, p-p {r.max() - r.min():.1f}″")
    ax.axhline(0.0, color="#999999", linewidth=0.5)
    ax.set_ylabel("rotation error − its mean (″)")
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title, fontsize=9)
    ax = axes[1]
    ax.plot(x, lm, color="#228833", linewidth=1.0, label="lost motion")
    if np.any(lm < 0):
        ax.fill_between(x, lm, 0.0, where=lm < 0, color="#ee6677", alpha=0.6, label="interference (lost motion < 0)")
        ax.axhline(0.0, color="#999999", linewidth=0.5)
    ax.set_ylabel("lost motion (′)")
    ax.set_xlabel("input angle (revolutions of the input)")
    ax.set_xlim(x[0], x[-1])
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)


def distributions(series, *, title: str, path, bins: int = 60):
    """Monte Carlo histograms side by side; `series` = [(label, values, unit symbol)]."""
    n = len(series)
    fig = Figure(figsize=(4.2 * n, 3.8), dpi=105)
    axes = fig.subplots(1, n, squeeze=False)
    for ax, (label, v, sym) in zip(axes.flat, series):
        v = np.asarray(v, dtype=float)
        v = v[np.isfinite(v)]
        if v.size and np.all(v == np.round(v)) and v.max() - v.min() < 40:
            edges = np.arange(v.min() - 0.5, v.max() + 1.5)
        else:
            edges = bins
        ax.hist(v, bins=edges, color="#4477aa", alpha=0.85)
        if v.size:
            ax.text(
                0.98,
                0.95,
                f"mean {np.mean(v):.2f}{sym}\nP5 {np.percentile(v, 5):.2f}{sym}\nP95 {np.percentile(v, 95):.2f}{sym}",
                transform=ax.transAxes,
                ha="right",
                va="top",
                fontsize=8,
                family="monospace",
            )
        ax.set_xlabel(label)
        ax.set_ylabel("reducers")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
