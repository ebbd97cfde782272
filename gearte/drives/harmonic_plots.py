"""Plots of the harmonic drive's study outputs (matplotlib; drawn by the command line, never imported by the numerics).

The drive declares them as `gearte.drives.Figure("…", "gearte.drives.harmonic_plots:NAME", data)`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..core.units import UNIT_SYMBOLS


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
    ax.set_xlabel(f"{metric} ({sym})")
    ax.set_ylabel("units")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
