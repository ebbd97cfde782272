"""Plots of the RV (K-H-V) reducer's study outputs (matplotlib; drawn by the command line, never imported by the numerics).

The drive declares them as `gearte.drives.Figure("…", "gearte.drives.rv_khv_plots:NAME", data)`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure


def te_both_directions(output_deg, forward_arcsec, reverse_arcsec, *, title: str, path, resolution_arcsec: float = 0.0):
    """TE under the forward and the reverse load against the output angle (″), the lost-motion band between them
    shaded (red where the lost motion is below −`resolution_arcsec`: not an equilibrium)."""
    x = np.asarray(output_deg, dtype=float)
    f = np.asarray(forward_arcsec, dtype=float)
    r = np.asarray(reverse_arcsec, dtype=float)
    fig = Figure(figsize=(10, 4.8), dpi=110)
    ax = fig.subplots()
    ax.fill_between(x, r, f, where=f >= r, color="#bbbbbb", alpha=0.6, linewidth=0, label="lost motion TE(+) − TE(−)", interpolate=True)
    bad = f < r - resolution_arcsec
    if np.any(bad):
        ax.fill_between(
            x, r, f, where=bad, color="#ee6677", alpha=0.7, linewidth=0, label="lost motion < 0: not an equilibrium", interpolate=True
        )
    ax.plot(x, f, color="#4477aa", linewidth=1.0, label=f"forward load (carrier CCW): p-p {f.max() - f.min():.2f}″")
    ax.plot(x, r, color="#ee7733", linewidth=1.0, label=f"reverse load (carrier CW): p-p {r.max() - r.min():.2f}″")
    ax.axhline(0.0, color="#999999", linewidth=0.5)
    ax.set_xlabel("output angle θ_o (°)")
    ax.set_ylabel("TE θ_o − θ_in / i (″)")
    ax.set_xlim(0.0, 360.0)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.legend(fontsize=8, loc="best")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def spectrum(orders, amplitude_arcsec, *, marks=(), title: str, path):
    """Amplitude per order of the output speed (stems, the mean left out); `marks` = [(order on the grid, drive
    order)]: the drive's own orders, labelled where the grid shows them."""
    k = np.asarray(orders, dtype=float)[1:]
    a = np.asarray(amplitude_arcsec, dtype=float)[1:]
    fig = Figure(figsize=(10, 4.2), dpi=110)
    ax = fig.subplots()
    ax.vlines(k, 0.0, a, color="#4477aa", linewidth=1.2)
    top = float(a.max()) if a.size and a.max() > 0 else 1.0
    last = float(k[-1]) if k.size else 0.0
    for i, (at, order) in enumerate(marks):
        if 0 < at <= last:
            ax.axvline(at, color="#cc3311", linewidth=0.6, linestyle=":")
            label = str(order) if order == at else f"{order}→{at}"
            ax.annotate(label, (at, top * (1.12 - 0.1 * (i % 2))), fontsize=7, color="#cc3311", rotation=90, va="top", ha="right")
    ax.set_xlabel("order (cycles per output revolution)")
    ax.set_ylabel("amplitude (″)")
    ax.set_xlim(0, k[-1] + 1 if k.size else 1)
    ax.set_ylim(0, top * 1.15)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def contact_map(output_deg, loaded, *, groups, counts, title: str, path):
    """Which contacts carry load (top: output angle × contact, one colour per group, `groups` = [(label, first,
    stop)]) and the count of loaded pins of each disc against the output angle (bottom, `counts` = [(label, n)])."""
    x = np.asarray(output_deg, dtype=float)
    m = np.asarray(loaded, dtype=bool)
    colors = ["#4477aa", "#228833", "#ee7733", "#aa3377"]
    img = np.zeros(m.shape, dtype=float)
    for g, (_, a, b) in enumerate(groups):
        img[:, a:b] = np.where(m[:, a:b], g + 1, 0)
    cmap = ListedColormap(["#ffffff", *colors[: len(groups)]])
    fig = Figure(figsize=(10, 7.5), dpi=110)
    axes = fig.subplots(2, 1, sharex=True, height_ratios=[3, 1])
    ax = axes[0]
    step = x[1] - x[0] if x.size > 1 else 1.0
    ax.imshow(
        img.T,
        aspect="auto",
        origin="lower",
        interpolation="nearest",
        cmap=cmap,
        vmin=-0.5,
        vmax=len(groups) + 0.5,
        extent=(x[0] - step / 2, x[-1] + step / 2, 0.5, m.shape[1] + 0.5),
    )
    for label, a, b in groups:
        ax.axhline(a + 0.5, color="#555555", linewidth=0.5)
        ax.text(1.005, (a + b + 1) / 2 / m.shape[1], label, transform=ax.transAxes, fontsize=7, va="center", rotation=90)
    ax.set_ylabel("contact (pins of each disc, then the mesh flanks)")
    ax.set_title(title, fontsize=9)
    ax = axes[1]
    for (label, n), c in zip(counts, colors):
        ax.step(x, np.asarray(n), where="mid", color=c, linewidth=1.0, label=f"{label}: mean {np.mean(n):.1f}, {np.min(n)}–{np.max(n)}")
    ax.set_ylabel("loaded pins")
    ax.set_xlabel("output angle θ_o (°)")
    ax.set_xlim(0.0, 360.0)
    ax.set_xticks(np.arange(0, 361, 45))
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
