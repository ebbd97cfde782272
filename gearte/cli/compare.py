"""``gearte compare``: finished runs side by side (statistics table, overlaid histograms)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..core.units import UNIT_SYMBOLS
from . import plots
from .io import atomic_output_dir, write_json


def _fmt(x: float) -> str:
    return f"{x:.2f}"


def compare_runs(run_dirs: list[str | Path], out: str | Path) -> dict:
    """Compare finished runs: a table of their statistics and overlaid histograms, written atomically to `out`."""
    runs = []
    for d in run_dirs:
        d = Path(d)
        try:
            summ = json.loads((d / "summary.json").read_text(encoding="utf-8"))
            with np.load(d / "samples.npz") as z:
                vals = np.asarray(z["te"])
        except FileNotFoundError as e:
            raise ValueError(f"{d}: not a finished gearte run (missing {Path(e.filename).name}); run `gearte run` first") from None
        runs.append((d, summ, vals))
    units = {r[1]["te"]["unit"] for r in runs}
    metrics = {r[1]["te"]["metric"] for r in runs}
    if len(units) > 1 or len(metrics) > 1:
        raise ValueError(f"runs differ in unit {sorted(units)} or metric {sorted(metrics)}; compare like with like")
    unit, metric = units.pop(), metrics.pop()
    sym = UNIT_SYMBOLS[unit]
    base = runs[0][1]["te"]["mean"]
    rows = []
    for d, summ, _ in runs:
        te = summ["te"]
        rows.append(
            {
                "run": str(d),
                "name": summ["study"]["name"],
                "title": summ["study"]["title"],
                "n": te["n"],
                "min": te["min"],
                "max": te["max"],
                "mean": te["mean"],
                "std": te["std"],
                "p99.73": te["percentiles"]["99.73"],
                "mean_vs_first": te["mean"] / base if base else float("nan"),
            }
        )
    result = {"unit": unit, "metric": metric, "runs": rows}
    with atomic_output_dir(out) as tmp:
        series = [(r["title"], v) for r, (_, _, v) in zip(rows, runs)]
        plots.overlay_histograms(series, unit=unit, metric=metric, path=tmp / "overlay.png")
        plots.grid_of_histograms(series, unit=unit, metric=metric, path=tmp / "histograms.png")
        lines = [
            "# Comparison of TE studies",
            "",
            f"Metric: {metric}; unit {unit} ({sym}).",
            "",
            "| study | n | min | max | mean | std | P99.73 | mean / first |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r['title']} (`{r['run']}`) | {r['n']:,} | {_fmt(r['min'])} | {_fmt(r['max'])} | {_fmt(r['mean'])} | "
                f"{_fmt(r['std'])} | {_fmt(r['p99.73'])} | {r['mean_vs_first']:.3f} |"
            )
        lines += [
            "",
            "![overlaid histograms](overlay.png)",
            "",
            "![histograms side by side](histograms.png)",
            "",
            "Each study's own report (assumptions, drive, error laws) is `report.md` in its folder.",
            "",
        ]
        (tmp / "report.md").write_text("\n".join(lines), encoding="utf-8")
        write_json(tmp / "comparison.json", result)
    return result
