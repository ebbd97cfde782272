"""Plots (matplotlib), kept apart from the numerics: nothing under gearte.core, drives, studies or optimise imports this.

Every plot is drawn on its own `matplotlib.figure.Figure` and saved to a file, without pyplot:
no backend is chosen and no global state is touched, so it works headless and beside a
user's own plotting. Studies declare plots as `gearte.drives.Figure` (a function name here
and its keyword arguments); the command line calls the function with ``path=``.
"""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..core.units import UNIT_SYMBOLS

_METRIC_LABEL = {"peak": "peak |Δθ|", "peak_to_peak": "peak-to-peak Δθ", "rms": "RMS Δθ"}


def _symbol(unit: str) -> str:
    """The symbol of an angle unit; other units (loaded pairs) by name."""
    return UNIT_SYMBOLS.get(unit, f" {unit}")


def histogram(values, stats, *, unit: str, metric: str, title: str, path, bins: int = 80, estimate: float | None = None, counts=None):
    """TE histogram with its statistics written on it: of the `values`, or, for a study streamed without its
    samples, ``counts=(edges, counts)`` (`gearte.studies.streaming.StreamingStatistics.histogram`)."""
    sym = _symbol(unit)
    fig = Figure(figsize=(8, 4.8), dpi=110)
    ax = fig.subplots()
    if counts is not None:
        edges, c = counts
        ax.stairs(c, edges, fill=True, color="#4477aa", alpha=0.85)
    else:
        ax.hist(values, bins=bins, color="#4477aa", alpha=0.85, edgecolor="white", linewidth=0.3)
    for p, style in (("5", ":"), ("50", "--"), ("95", ":"), ("99.73", "-.")):
        ax.axvline(stats.percentiles[p], color="#222222", linestyle=style, linewidth=1.0, label=f"P{p} = {stats.percentiles[p]:.1f}{sym}")
    if estimate is not None:
        ax.axvline(estimate, color="#cc3311", linewidth=1.5, label=f"estimate {estimate:.1f}{sym}")
    text = (
        f"n = {stats.n:,}\nmin = {stats.min:.1f}{sym}\nmax = {stats.max:.1f}{sym}\nmean = {stats.mean:.1f}{sym}\nstd = {stats.std:.1f}{sym}"
    )
    ax.text(
        0.02,
        0.97,
        text,
        transform=ax.transAxes,
        va="top",
        ha="left",
        family="monospace",
        fontsize=8,
        bbox=dict(boxstyle="round", facecolor="white", alpha=0.85, edgecolor="#bbbbbb"),
    )
    ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    ax.set_ylabel("samples")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)


def trace(theta_rev, te, *, unit: str, title: str, path, marks=()):
    """TE over the hyper-period against input revolutions; `marks` = [(rev, value, label)]."""
    sym = _symbol(unit)
    fig = Figure(figsize=(9, 4), dpi=110)
    ax = fig.subplots()
    ax.plot(theta_rev, te, color="#4477aa", linewidth=0.8)
    lo, hi = float(np.min(te)), float(np.max(te))
    if lo - 0.5 * (hi - lo) <= 0.0 <= hi + 0.5 * (hi - lo):  # the zero line where it does not squash the curve flat
        ax.axhline(0.0, color="#999999", linewidth=0.6)
    for x, y, label in marks:
        ax.plot([x], [y], "o", color="#cc3311", markersize=5)
        ax.annotate(label, (x, y), textcoords="offset points", xytext=(6, 6), fontsize=8)
    ax.set_xlabel("input angle (revolutions of the input)")
    ax.set_ylabel(f"TE Δθ ({sym})")
    ax.set_xlim(theta_rev[0], theta_rev[-1])
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def _wrapped(text: str, width: int) -> str:
    """`text` on lines of at most `width` characters (a run's title in a panel or legend)."""
    return "\n".join(textwrap.wrap(text, width)) or text


def overlay_histograms(series, *, unit: str, metric: str, path, bins: int = 80):
    """Several studies' TE distributions on one axis; `series` = [(label, values)]."""
    sym = _symbol(unit)
    fig = Figure(figsize=(9, 5), dpi=110)
    ax = fig.subplots()
    lo = min(float(np.min(v)) for _, v in series)
    hi = max(float(np.max(v)) for _, v in series)
    edges: Any = np.linspace(lo, hi, bins + 1) if hi > lo else bins
    colors = ["#4477aa", "#cc3311", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb"]
    # Densities, not counts: runs of different sample counts are drawn on one scale.
    for (label, v), c in zip(series, colors * 4):
        text = f"{_wrapped(label, 60)} (n = {len(v):,}, mean {np.mean(v):.1f}{sym})"
        ax.hist(v, bins=edges, density=True, histtype="stepfilled", alpha=0.35, color=c, label=text)
        ax.hist(v, bins=edges, density=True, histtype="step", color=c, linewidth=1.0)
    ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    ax.set_ylabel(f"probability density (1/{sym.strip()})")
    ax.legend(fontsize=8)
    ax.set_title("TE distributions compared", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def grid_of_histograms(series, *, unit: str, metric: str, path, bins: int = 60):
    """Histograms side by side, one panel per study; `series` = [(label, values)]."""
    sym = _symbol(unit)
    n = len(series)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    lo = min(float(np.min(v)) for _, v in series)
    hi = max(float(np.max(v)) for _, v in series)
    fig = Figure(figsize=(6 * cols, 3.6 * rows), dpi=100)
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    for ax, (label, v) in zip(axes.flat, series):
        ax.hist(v, bins=np.linspace(lo, hi, bins + 1) if hi > lo else bins, color="#4477aa", alpha=0.85)
        ax.set_title(_wrapped(label, 48), fontsize=9)
        ax.text(
            0.98,
            0.95,
            f"mean {np.mean(v):.1f}{sym}\nstd {np.std(v, ddof=1) if len(v) > 1 else 0:.1f}{sym}\n"
            f"min {np.min(v):.1f}{sym}\nmax {np.max(v):.1f}{sym}",
            transform=ax.transAxes,
            ha="right",
            va="top",
            fontsize=8,
            family="monospace",
        )
        ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path)


# ---------------------------------------------------------------- harmonic drive: records, spectra, estimate


def trace_pair(theta_rev, te_a, te_b, *, unit: str, labels, title: str, path):
    """Two TE traces of the same parts over the hyper-period (e.g. before and after allocation)."""
    sym = _symbol(unit)
    fig = Figure(figsize=(9, 4), dpi=110)
    ax = fig.subplots()
    for te, label, c in ((te_a, labels[0], "#cc3311"), (te_b, labels[1], "#4477aa")):
        ax.plot(theta_rev, te, color=c, linewidth=0.9, label=f"{label}: peak {np.max(np.abs(te)):.1f}{sym}")
    ax.axhline(0.0, color="#999999", linewidth=0.6)
    ax.set_xlabel("input angle (revolutions of the input)")
    ax.set_ylabel(f"TE Δθ ({sym})")
    ax.set_xlim(theta_rev[0], theta_rev[-1])
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


# ---------------------------------------------------------------- cycloid-pin reducer: clearances and rotation error


def contributions(values: dict, *, unit: str, path, title: str):
    """Horizontal bars: each source's share of a TE statistic."""
    sym = _symbol(unit)
    names = list(values)
    v = np.array([values[n] for n in names])
    fig = Figure(figsize=(8, 0.5 * len(names) + 1.5), dpi=110)
    ax = fig.subplots()
    ax.barh(names, v, color=["#4477aa" if x >= 0 else "#cc3311" for x in v])
    ax.axvline(0, color="#999999", linewidth=0.6)
    for i, x in enumerate(v):
        ax.text(x, i, f" {x:.1f}{sym}", va="center", fontsize=8)
    ax.set_xlabel(f"contribution ({sym})")
    ax.set_title(title, fontsize=10)
    ax.invert_yaxis()
    fig.tight_layout()
    fig.savefig(path)


def pareto(rows, *, unit: str, path):
    """Cost against TE spec: optimised budget and uniform scaling of the nominal tolerances."""
    sym = _symbol(unit)
    specs = [r[f"spec_{unit}"] for r in rows]
    fig = Figure(figsize=(7, 4.5), dpi=110)
    ax = fig.subplots()
    ax.plot(specs, [r["cost"] for r in rows], "o-", color="#4477aa", label="optimised budget")
    ax.plot(specs, [r["baseline_cost"] for r in rows], "s--", color="#cc3311", label="uniform scaling of the nominal tolerances")
    ax.set_xlabel(f"TE specification ({sym})")
    ax.set_ylabel("cost (model units)")
    ax.set_title("Cost of meeting the specification", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
