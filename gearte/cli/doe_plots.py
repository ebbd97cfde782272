"""Plots of a designed experiment (matplotlib, imported when a plot is drawn): residuals and the response surface.

Each function draws on its own `matplotlib.figure.Figure` and saves it to `path`, like `gearte.cli.plots`;
`gearte run` calls them for a ``[doe]`` study, and they take plain arrays, so they serve a Python session too:
``residuals(s.y, s.fitted, s.residuals, unit="arcsec", path=PATH)`` for a `gearte.ResponseSurface` s.
"""

from __future__ import annotations

import numpy as np

from ..core.units import UNIT_SYMBOLS


def _symbol(unit: str) -> str:
    return UNIT_SYMBOLS.get(unit, f" {unit}")


def residuals(actual, fitted, residuals, *, unit: str, path, title: str = "Response surface: residuals"):
    """Two panels: residuals against fitted values, and fitted against actual responses (with the 1:1 line)."""
    from matplotlib.figure import Figure

    sym = _symbol(unit)
    actual, fitted, residuals = (np.asarray(a, dtype=float) for a in (actual, fitted, residuals))
    fig = Figure(figsize=(10, 4.2), dpi=110)
    a1, a2 = fig.subplots(1, 2)
    a1.axhline(0.0, color="#888888", linewidth=0.8)
    a1.plot(fitted, residuals, "o", color="#4477aa")
    for i, (f, r) in enumerate(zip(fitted, residuals)):
        a1.annotate(str(i + 1), (f, r), textcoords="offset points", xytext=(3, 3), fontsize=7, color="#555555")
    a1.set_xlabel(f"fitted ({sym.strip()})")
    a1.set_ylabel(f"residual ({sym.strip()})")
    a1.set_title("residuals vs fitted", fontsize=10)
    lo, hi = float(min(actual.min(), fitted.min())), float(max(actual.max(), fitted.max()))
    pad = 0.05 * (hi - lo or 1.0)
    a2.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="#888888", linewidth=0.8)
    a2.plot(actual, fitted, "o", color="#cc6677")
    a2.set_xlabel(f"actual ({sym.strip()})")
    a2.set_ylabel(f"predicted ({sym.strip()})")
    a2.set_title("predicted vs actual", fontsize=10)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


def surface(x, y, z, *, points, optimum, labels, unit: str, path, others: str = "", title: str = "Response surface"):
    """Contours of the surface z (len(y), len(x)) over two variables, with the design's runs and the optimum."""
    from matplotlib.figure import Figure

    sym = _symbol(unit)
    fig = Figure(figsize=(6.8, 5.4), dpi=110)
    ax = fig.subplots()
    cs = ax.contourf(np.asarray(x), np.asarray(y), np.asarray(z), levels=20, cmap="viridis")
    ax.contour(np.asarray(x), np.asarray(y), np.asarray(z), levels=10, colors="white", linewidths=0.5, alpha=0.6)
    fig.colorbar(cs, ax=ax, label=f"predicted response ({sym.strip()})")
    pts = np.asarray(points)
    ax.plot(pts[:, 0], pts[:, 1], "o", markerfacecolor="none", markeredgecolor="#222222", label="runs")
    ax.plot([optimum[0]], [optimum[1]], "*", color="#ee3377", markersize=14, label="optimum")
    ax.set_xlabel(labels[0])
    ax.set_ylabel(labels[1])
    ax.set_title(title + (f" ({others})" if others else ""), fontsize=10)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    fig.savefig(path)
