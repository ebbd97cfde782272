"""Run a validated study and write its results folder (summary.json, samples.npz, plots, report.md)."""

from __future__ import annotations

import datetime as _dt
import json
import math
import platform
import time
from pathlib import Path

import jax
import numpy as np

from ._config import Study
from ._io import atomic_output_dir, write_json
from ._metrics import extrema
from ._montecarlo import PERCENTILES, as_key, monte_carlo, statistics
from ._signal import evaluate
from .units import ARCSEC_PER_RAD, UNIT_SYMBOLS, angle_from_rad

METRIC_TEXT = {
    "peak": "peak = max over the whole hyper-period of |Δθ(θ_in)| (includes constant offsets; the seed's \"amplitude\")",
    "peak_to_peak": "peak-to-peak = max Δθ − min Δθ over the whole hyper-period (ISO / catalogue sense)",
    "rms": "RMS of Δθ over the hyper-period (exact, by Parseval)",
}


def _versions() -> dict:
    import equinox
    import optimistix

    from . import __version__

    return {"gearte": __version__, "jax": jax.__version__, "equinox": equinox.__version__,
            "optimistix": optimistix.__version__, "numpy": np.__version__, "python": platform.python_version()}


def _sample_errors(study: Study, index: int):
    key = jax.random.fold_in(as_key(study.seed), index)
    return study.errors.sample(key)


def run_study(study: Study, out: str | Path, *, progress: bool | None = None, command: str | None = None) -> dict:
    """Run `study` and write its results folder `out` atomically. Returns the summary dict."""
    from . import plotting

    t_start = time.perf_counter()
    te_study = study.drive.te_study(study.errors, metric=study.metric)
    mc = monte_carlo(te_study, key=study.seed, n_samples=study.samples, chunk_size=study.chunk_size,
                     progress=progress, desc=study.name)
    values_rad = mc.values
    values = angle_from_rad(values_rad, study.unit)
    stats = statistics(values, unit=study.unit)
    sym = UNIT_SYMBOLS[study.unit]

    # A typical sample (closest to the median) for the TE trace; its draws are regenerated from its key.
    typical = int(np.argmin(np.abs(values - stats.percentiles["50"])))
    errs = _sample_errors(study, typical)
    signal = study.drive.signal(errs)
    ext = extrema(signal)
    revs = float(signal.hyper_period_revs)
    top_order = max(signal.orders) if signal.orders else 1
    npts = int(min(200_000, max(4000, 40 * top_order)))
    theta = np.linspace(0.0, 2 * math.pi * revs, npts)
    te_trace = angle_from_rad(np.asarray(evaluate(signal, theta)), study.unit)
    t_mx, t_mn = float(ext.theta_max), float(ext.theta_min)
    mx, mn = angle_from_rad(float(ext.max), study.unit), angle_from_rad(float(ext.min), study.unit)

    summary = {
        "gearte_version": _versions()["gearte"],
        "study": {"name": study.name, "title": study.title, "description": study.description, "config": study.source_path,
                  "command": command},
        "te": stats.to_dict() | {"metric": study.metric},
        "samples": study.samples,
        "seed": study.seed,
        "chunk_size": mc.chunk_size,
        "block_size": mc.block_size,
        "drive": dict(study.drive.describe()),
        "errors": {name: {"tolerance_um": study.tolerances_um[name], "count": study.errors.counts[name],
                          "phase_symbol": study.drive.phase_symbols.get(name, name),
                          "magnitude": src.magnitude.describe(), "phase": src.phase.describe()}
                   for name, src in study.errors.sources.items()},
        "typical_sample": {"index": typical, "te": float(values[typical]),
                           "hyper_period_input_revs": str(signal.hyper_period_revs),
                           "max": mx, "min": mn, "theta_max_rad": t_mx, "theta_min_rad": t_mn},
        "assumptions": {
            "metric": METRIC_TEXT[study.metric],
            "random_keys": "sample i uses jax.random.fold_in(jax.random.key(seed), i); error source j of a sample uses fold_in(that key, j)",
            "precision": "float64 throughout (jax_enable_x64)",
            "exact_extrema": "grid of 16 points per period of the fastest term, best maxima refined by Newton's method on the exact trigonometric polynomial (≤ 1e-6 relative; tested ~1e-10)",
            "phases": "uniform on [0, 2π) unless a rule or fixed value is given",
            "notes": list(study.notes),
        },
        "timing_s": {"monte_carlo": mc.seconds},
        "versions": _versions(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }

    with atomic_output_dir(out) as tmp:
        np.savez_compressed(tmp / "samples.npz", te=values, te_rad=values_rad, unit=study.unit, metric=study.metric,
                            seed=study.seed, index=np.arange(study.samples))
        plotting.histogram(values, stats, unit=study.unit, metric=study.metric, title=study.title, path=tmp / "histogram.png")
        plotting.trace(theta / (2 * math.pi), te_trace, unit=study.unit, path=tmp / "trace.png",
                       title=f"TE of a typical sample (#{typical}, {study.metric} {values[typical]:.1f}{sym}) over the hyper-period",
                       marks=[(t_mx / (2 * math.pi), mx, f"max {mx:.1f}{sym}"), (t_mn / (2 * math.pi), mn, f"min {mn:.1f}{sym}")])
        extra_summary, extra_lines = study.drive.study_outputs(study, values_rad, tmp)
        clash = set(extra_summary) & set(summary)
        if clash:
            raise ValueError(f"{type(study.drive).__name__}.study_outputs: keys {sorted(clash)} are already in summary.json")
        summary.update(extra_summary)
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        (tmp / "report.md").write_text(_report(study, summary, errs, signal) + "\n".join(extra_lines) + ("\n" if extra_lines else ""), encoding="utf-8")
        write_json(tmp / "summary.json", summary)
    return summary


def _fmt(x: float) -> str:
    return f"{x:.2f}"


def _report(study: Study, s: dict, errs, signal) -> str:
    sym = UNIT_SYMBOLS[study.unit]
    te = s["te"]
    lines = [f"# {study.title}", ""]
    if study.description:
        lines += [study.description, ""]
    lines += [f"Study `{study.name}` from `{study.source_path}`, run with gearte {s['versions']['gearte']} "
              f"(JAX {s['versions']['jax']}) on {s['created']}.", ""]
    if s["study"]["command"]:
        lines += ["Reproduce with:", "", f"    {s['study']['command']}", ""]
    lines += ["## Result", "", f"{METRIC_TEXT[study.metric]}, in {study.unit} ({sym}), over {te['n']:,} samples:", "",
              "| n | min | max | mean | std | " + " | ".join(f"P{p:g}" for p in PERCENTILES) + " |",
              "|---" * (5 + len(PERCENTILES)) + "|",
              f"| {te['n']:,} | {_fmt(te['min'])} | {_fmt(te['max'])} | {_fmt(te['mean'])} | {_fmt(te['std'])} | "
              + " | ".join(_fmt(te["percentiles"][f"{p:g}"]) for p in PERCENTILES) + " |", "",
              "std is the sample standard deviation (n − 1); percentiles by linear interpolation.", "",
              "![TE histogram](histogram.png)", "",
              f"![TE trace of a typical sample](trace.png)", "",
              "## Drive", "", "| parameter | value |", "|---|---|"]
    lines += [f"| {k} | {v} |" for k, v in study.drive.describe()]
    lines += ["", "## Error sources and how they are drawn", "",
              "Magnitudes are eccentricities in µm; phases in rad (degrees in brackets).", "",
              "| source | phase symbol | instances | tolerance (µm) | magnitude | phase |", "|---|---|---|---|---|---|"]
    for name, e in s["errors"].items():
        tol = "—" if e["tolerance_um"] is None else f"{e['tolerance_um']:g}"
        lines.append(f"| {name} | {e['phase_symbol']} | {e['count']} | {tol} | {e['magnitude']} | {e['phase']} |")
    lines += ["", "## Assumptions", "",
              f"- Metric: {METRIC_TEXT[study.metric]}.",
              "- TE Δθ = θ_out − θ_in / i (rad inside gearte; reported in " + study.unit + f", 1 rad = {ARCSEC_PER_RAD:.3f}″).",
              f"- Samples: {s['samples']:,}; seed {s['seed']}; {s['assumptions']['random_keys']}. Samples are computed in blocks of {s['block_size']}, {s['chunk_size']} per compiled call; results do not depend on the chunk size.",
              "- Random phases are uniform on [0, 2π); magnitudes follow the laws in the table above.",
              f"- Precision: {s['assumptions']['precision']}.",
              f"- Exact extrema: {s['assumptions']['exact_extrema']}."]
    lines += [f"- {n}" for n in study.notes]
    typ = s["typical_sample"]
    lines += ["", "## The typical sample", "",
              f"Sample #{typ['index']} (closest to the median): {study.metric} {typ['te']:.3f}{sym}; over its hyper-period of "
              f"{typ['hyper_period_input_revs']} input revolutions the TE runs from {typ['min']:.3f}{sym} "
              f"(at θ_in = {typ['theta_min_rad']:.6f} rad) to {typ['max']:.3f}{sym} (at θ_in = {typ['theta_max_rad']:.6f} rad).", "",
              "| source | magnitude (µm) | phase (rad) |", "|---|---|---|"]
    for name, e in errs.items():
        mags = ", ".join(f"{float(x):.3f}" for x in np.atleast_1d(np.asarray(e.magnitude)))
        phs = ", ".join(f"{float(x) % (2 * math.pi):.4f}" for x in np.atleast_1d(np.asarray(e.phase)))
        lines.append(f"| {name} | {mags} | {phs} |")
    lines += ["", "Its TE spectrum (amplitude per frequency, frequency as a multiple of the input speed):", "",
              f"| frequency | amplitude ({sym}) |", "|---|---|"]
    amp = np.hypot(np.asarray(signal.cos_coef), np.asarray(signal.sin_coef))
    lines.append(f"| 0 (constant) | {angle_from_rad(float(signal.offset), study.unit):.3f} |")
    for f, a in zip(signal.frequencies, amp):
        lines.append(f"| {f} | {angle_from_rad(float(a), study.unit):.3f} |")
    lines += ["", "## Files", "", "- `summary.json`: the statistics above and every setting, machine-readable.",
              f"- `samples.npz`: the {s['samples']:,} per-sample values (`te` in {study.unit}, `te_rad`), with `seed` and `index`.",
              "- `histogram.png`, `trace.png`: the plots above.", "",
              f"Monte Carlo time {s['timing_s']['monte_carlo']:.2f} s (compilation included); total {s['timing_s']['total']:.2f} s.", ""]
    return "\n".join(lines)


def compare_runs(run_dirs: list[str | Path], out: str | Path) -> dict:
    """Compare finished runs: a table of their statistics and overlaid histograms, written atomically to `out`."""
    from . import plotting

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
    for d, summ, vals in runs:
        te = summ["te"]
        rows.append({"run": str(d), "name": summ["study"]["name"], "title": summ["study"]["title"], "n": te["n"], "min": te["min"],
                     "max": te["max"], "mean": te["mean"], "std": te["std"], "p99.73": te["percentiles"]["99.73"],
                     "mean_vs_first": te["mean"] / base if base else float("nan")})
    result = {"unit": unit, "metric": metric, "runs": rows}
    with atomic_output_dir(out) as tmp:
        series = [(r["title"], v) for r, (_, _, v) in zip(rows, runs)]
        plotting.overlay_histograms(series, unit=unit, metric=metric, path=tmp / "overlay.png")
        plotting.grid_of_histograms(series, unit=unit, metric=metric, path=tmp / "histograms.png")
        lines = ["# Comparison of TE studies", "", f"Metric: {METRIC_TEXT[metric]}; unit {unit} ({sym}).", "",
                 "| study | n | min | max | mean | std | P99.73 | mean / first |", "|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['title']} (`{r['run']}`) | {r['n']:,} | {_fmt(r['min'])} | {_fmt(r['max'])} | {_fmt(r['mean'])} | "
                         f"{_fmt(r['std'])} | {_fmt(r['p99.73'])} | {r['mean_vs_first']:.3f} |")
        lines += ["", "![overlaid histograms](overlay.png)", "", "![histograms side by side](histograms.png)", "",
                  "Each study's own report (assumptions, drive, error laws) is `report.md` in its folder.", ""]
        (tmp / "report.md").write_text("\n".join(lines), encoding="utf-8")
        write_json(tmp / "comparison.json", result)
    return result
