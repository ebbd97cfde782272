"""Plots (matplotlib), kept apart from the numerics: nothing under gearte.core, drives, studies or optimise imports this.

Every plot is drawn on its own `matplotlib.figure.Figure` and saved to a file, without pyplot:
no backend is chosen and no global state is touched, so it works headless and beside a
user's own plotting. Studies declare plots as `gearte.drives.Figure` (a function name here
and its keyword arguments); the command line calls the function with ``path=``.
"""

from __future__ import annotations

import math
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure

from ..core.units import UNIT_SYMBOLS

_METRIC_LABEL = {"peak": "peak |Δθ|", "peak_to_peak": "peak-to-peak Δθ", "rms": "RMS Δθ"}


def histogram(values, stats, *, unit: str, metric: str, title: str, path, bins: int = 80, estimate: float | None = None):
    """TE histogram with its statistics written on it."""
    sym = UNIT_SYMBOLS[unit]
    fig = Figure(figsize=(8, 4.8), dpi=110)
    ax = fig.subplots()
    ax.hist(values, bins=bins, color="#4477aa", alpha=0.85, edgecolor="white", linewidth=0.3)
    for p, style in (("5", ":"), ("50", "--"), ("95", ":"), ("99.73", "-.")):
        ax.axvline(stats.percentiles[p], color="#222222", linestyle=style, linewidth=1.0, label=f"P{p} = {stats.percentiles[p]:.1f}{sym}")
    if estimate is not None:
        ax.axvline(estimate, color="#cc3311", linewidth=1.5, label=f"estimate {estimate:.1f}{sym}")
    text = (f"n = {stats.n:,}\nmin = {stats.min:.1f}{sym}\nmax = {stats.max:.1f}{sym}\n"
            f"mean = {stats.mean:.1f}{sym}\nstd = {stats.std:.1f}{sym}")
    ax.text(0.02, 0.97, text, transform=ax.transAxes, va="top", ha="left", family="monospace", fontsize=8,
            bbox=dict(boxstyle="round", facecolor="white", alpha=0.85, edgecolor="#bbbbbb"))
    ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    ax.set_ylabel("samples")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)


def trace(theta_rev, te, *, unit: str, title: str, path, marks=()):
    """TE over the hyper-period against input revolutions; `marks` = [(rev, value, label)]."""
    sym = UNIT_SYMBOLS[unit]
    fig = Figure(figsize=(9, 4), dpi=110)
    ax = fig.subplots()
    ax.plot(theta_rev, te, color="#4477aa", linewidth=0.8)
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


def overlay_histograms(series, *, unit: str, metric: str, path, bins: int = 80):
    """Several studies' TE distributions on one axis; `series` = [(label, values)]."""
    sym = UNIT_SYMBOLS[unit]
    fig = Figure(figsize=(9, 5), dpi=110)
    ax = fig.subplots()
    lo = min(float(np.min(v)) for _, v in series)
    hi = max(float(np.max(v)) for _, v in series)
    edges: Any = np.linspace(lo, hi, bins + 1) if hi > lo else bins
    colors = ["#4477aa", "#cc3311", "#228833", "#ccbb44", "#66ccee", "#aa3377", "#bbbbbb"]
    for (label, v), c in zip(series, colors * 4):
        ax.hist(v, bins=edges, histtype="stepfilled", alpha=0.35, color=c, label=f"{label} (mean {np.mean(v):.1f}{sym})")
        ax.hist(v, bins=edges, histtype="step", color=c, linewidth=1.0)
    ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    ax.set_ylabel("samples")
    ax.legend(fontsize=8)
    ax.set_title("TE distributions compared", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def grid_of_histograms(series, *, unit: str, metric: str, path, bins: int = 60):
    """Histograms side by side, one panel per study; `series` = [(label, values)]."""
    sym = UNIT_SYMBOLS[unit]
    n = len(series)
    cols = min(n, 2)
    rows = math.ceil(n / cols)
    lo = min(float(np.min(v)) for _, v in series)
    hi = max(float(np.max(v)) for _, v in series)
    fig = Figure(figsize=(6 * cols, 3.6 * rows), dpi=100)
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    for ax, (label, v) in zip(axes.flat, series):
        ax.hist(v, bins=np.linspace(lo, hi, bins + 1) if hi > lo else bins, color="#4477aa", alpha=0.85)
        ax.set_title(label, fontsize=9)
        ax.text(0.98, 0.95, f"mean {np.mean(v):.1f}{sym}\nstd {np.std(v, ddof=1) if len(v) > 1 else 0:.1f}{sym}\n"
                f"min {np.min(v):.1f}{sym}\nmax {np.max(v):.1f}{sym}", transform=ax.transAxes, ha="right", va="top",
                fontsize=8, family="monospace")
        ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    for ax in list(axes.flat)[n:]:
        ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path)


# ---------------------------------------------------------------- harmonic drive: records, spectra, estimate


def record_with_envelope(time_s, te, *, envelopes=(), unit: str, title: str, path, revolutions_s=None, offset=None):
    """A TE record against time with envelopes drawn as ±curves around `offset` (default 0).

    `envelopes` = [(time_s, envelope, label)]; `revolutions_s` = times of output-revolution
    boundaries, drawn as vertical lines.
    """
    sym = UNIT_SYMBOLS[unit]
    fig = Figure(figsize=(10, 4.4), dpi=110)
    ax = fig.subplots()
    ax.plot(time_s, te, color="#4477aa", linewidth=0.5, label="TE record")
    colors = ["#cc3311", "#228833", "#aa3377"]
    for (t, env, label), c in zip(envelopes, colors * 3):
        base = 0.0 if offset is None else offset
        ax.plot(t, base + env, color=c, linewidth=1.2, label=label)
        ax.plot(t, base - env, color=c, linewidth=1.2)
    for x in revolutions_s or ():
        ax.axvline(x, color="#777777", linewidth=0.8, linestyle=":")
    ax.axhline(0.0, color="#999999", linewidth=0.5)
    ax.set_xlabel("time (s)" + ("; dotted: output revolutions" if revolutions_s else ""))
    ax.set_ylabel(f"TE at the output ({sym})")
    ax.set_xlim(time_s[0], time_s[-1])
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)


def labelled_spectrum(freq_cpm, amplitude, lines, *, unit: str, title: str, path, zooms=(), zoom_spectrum=None):
    """Amplitude spectrum in cycles per minute with labelled lines; `lines` = [(cpm, amplitude, label, is_line)].

    The first panel shows the whole range on a log scale (labels for lines only); one more
    linear panel per range in `zooms` = [(low, high)], with the bins as dots and, if given,
    `zoom_spectrum` = (cpm, amplitude) (e.g. zero-padded) as a curve; there side lobes
    (``is_line`` False) are marked too.
    """
    sym = UNIT_SYMBOLS[unit]
    panels = 1 + len(zooms)
    fig = Figure(figsize=(10, 3.3 * panels), dpi=110)
    axes = fig.subplots(panels, 1, squeeze=False)
    freq_cpm, amplitude = np.asarray(freq_cpm), np.asarray(amplitude)
    top = float(np.max(amplitude))
    floor = max(top * 1e-6, 1e-30)
    ax = axes[0, 0]
    ax.semilogy(freq_cpm[1:], np.maximum(amplitude[1:], floor), color="#4477aa", linewidth=0.6)
    for f, a, label, is_line in lines:
        if is_line:
            ax.plot([f], [a], "v", color="#cc3311", markersize=5)
            ax.annotate(label, (f, a), textcoords="offset points", xytext=(5, 2), fontsize=7)
    ax.set_xlim(0, freq_cpm[-1])
    ax.set_ylim(floor, top * 5)
    ax.set_xlabel("frequency (cycles per minute)")
    ax.set_ylabel(f"amplitude ({sym})")
    ax.set_title(title, fontsize=10)
    for ax, (lo, hi) in zip(axes[1:, 0], zooms):
        sel = (freq_cpm >= lo) & (freq_cpm <= hi)
        if zoom_spectrum is not None:
            zf, za = (np.asarray(v) for v in zoom_spectrum)
            zs = (zf >= lo) & (zf <= hi)
            ax.plot(zf[zs], za[zs], color="#4477aa", linewidth=0.8, label="zero-padded (interpolated)")
        ax.plot(freq_cpm[sel], amplitude[sel], ".", color="#222222", markersize=3, label="DFT bins")
        for f, a, label, is_line in lines:
            if lo <= f <= hi:
                ax.plot([f], [a], "v" if is_line else "x", color="#cc3311" if is_line else "#777777", markersize=6 if is_line else 4)
                if is_line:
                    ax.annotate(label, (f, a), textcoords="offset points", xytext=(5, -3), fontsize=8)
        ax.set_xlim(lo, hi)
        ax.set_xlabel("frequency (cycles per minute)")
        ax.set_ylabel(f"amplitude ({sym})")
        ax.set_title(f"{lo:g}–{hi:g} cpm (Hann window; x: window side lobes, not lines)", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)


def histogram_with_estimates(values, *, percentiles, estimates, unit: str, metric: str, title: str, path, bins: int = 80):
    """Monte Carlo histogram with its median and P99.73 and vertical lines for design estimates.

    Plain data, as a `gearte.drives.Figure` declares it: `percentiles` = {"50": …, "99.73": …}
    (in `unit`), `estimates` = [(value, label)].
    """
    sym = UNIT_SYMBOLS[unit]
    fig = Figure(figsize=(9, 4.8), dpi=110)
    ax = fig.subplots()
    ax.hist(values, bins=bins, color="#4477aa", alpha=0.85, edgecolor="white", linewidth=0.3)
    for p, style in (("50", "--"), ("99.73", "-.")):
        ax.axvline(percentiles[p], color="#222222", linestyle=style, linewidth=1.0, label=f"Monte Carlo P{p} = {percentiles[p]:.2f}{sym}")
    for (v, label), c in zip(estimates, ["#cc3311", "#ee7733", "#aa3377"]):
        ax.axvline(v, color=c, linewidth=1.6, label=label)
    ax.set_xlabel(f"{_METRIC_LABEL.get(metric, metric)} ({sym})")
    ax.set_ylabel("units")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)


def trace_pair(theta_rev, te_a, te_b, *, unit: str, labels, title: str, path):
    """Two TE traces of the same parts over the hyper-period (e.g. before and after allocation)."""
    sym = UNIT_SYMBOLS[unit]
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


def cycloid_clearance_per_pin(tangential_mm, normal_mm, on_driving, *, budget_mm: float, contact_pin: int,
                              reverse_contact_pin: int, title: str, path):
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
    ax.annotate("contact", (contact_pin, 0), textcoords="offset points", xytext=(0, 12), ha="center", fontsize=8,
                arrowprops=dict(arrowstyle="->", color="#222222"))
    ax.annotate("reverse\ncontact", (reverse_contact_pin, 0), textcoords="offset points", xytext=(0, 12), ha="center",
                fontsize=8, arrowprops=dict(arrowstyle="->", color="#222222"))
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


def cycloid_clearance_vs_input(input_deg, tangential_mm, normal_mm, pins, *, budget_mm: float, title: str, path):
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
    axes[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def cycloid_rotation_error(input_rev, forward_arcsec, reverse_arcsec, *, title: str, path):
    """Rotation error of the stage under a forward and a reverse load against the input angle (top,
    each about its mean), and the lost motion between them (bottom; negative: interference)."""
    x = np.asarray(input_rev, dtype=float)
    f = np.asarray(forward_arcsec, dtype=float)
    r = np.asarray(reverse_arcsec, dtype=float)
    lm = (f - r) / 60.0
    fig = Figure(figsize=(10, 6.4), dpi=110)
    axes = fig.subplots(2, 1, sharex=True)
    ax = axes[0]
    ax.plot(x, f - f.mean(), color="#4477aa", linewidth=1.0,
            label=f"forward load: mean {f.mean():.1f}″, p-p {f.max() - f.min():.1f}″")
    ax.plot(x, r - r.mean(), color="#ee7733", linewidth=1.0,
            label=f"reverse load: mean {r.mean():.1f}″, p-p {r.max() - r.min():.1f}″")
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


def cycloid_distributions(series, *, title: str, path, bins: int = 60):
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
            ax.text(0.98, 0.95, f"mean {np.mean(v):.2f}{sym}\nP5 {np.percentile(v, 5):.2f}{sym}\nP95 {np.percentile(v, 95):.2f}{sym}",
                    transform=ax.transAxes, ha="right", va="top", fontsize=8, family="monospace")
        ax.set_xlabel(label)
        ax.set_ylabel("reducers")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def contributions(values: dict, *, unit: str, path, title: str):
    """Horizontal bars: each source's share of a TE statistic."""
    sym = UNIT_SYMBOLS[unit]
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
    sym = UNIT_SYMBOLS[unit]
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
