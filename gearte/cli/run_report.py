"""The Markdown report (report.md) of a `gearte run`: result, drive, error laws, assumptions, the typical sample."""

from __future__ import annotations

import math

import numpy as np

from ..core.units import ARCSEC_PER_RAD, UNIT_SYMBOLS, angle_from_rad, number_text
from ..studies.montecarlo import PERCENTILES
from .config import Study


def _values_text(x: np.ndarray, unit: str, name: str) -> str:
    """A typical sample's values (one per instance) with their unit once: µm; an angle in ″, or, for a source that is a
    phase (its name ends in `_phase`), in rad (0 … 2π) with degrees."""
    if unit != "rad":
        return ", ".join(f"{v:.4g}" for v in x) + f" {unit}"
    if name.endswith("_phase"):
        x = x % (2 * math.pi)
        return ", ".join(f"{v:.4f}" for v in x) + " rad (" + ", ".join(f"{math.degrees(v):.1f}" for v in x) + "°)"
    return ", ".join(f"{v * ARCSEC_PER_RAD:.4g}" for v in x) + "″"


def _thin_tails(n: int) -> str:
    """A warning for the percentiles that fewer than 3 samples lie beyond (either side), with `n` samples: there a
    percentile is an interpolation between the few extreme samples, not an estimate of the batch's."""
    thin = [p for p in PERCENTILES if n * min(p, 100.0 - p) / 100.0 < 3.0]
    if not thin:
        return ""
    return (
        f" {', '.join(f'P{p:g}' for p in thin)} from {n:,} samples: fewer than 3 samples lie beyond "
        f"{'it' if len(thin) == 1 else 'each'}, so {'it is' if len(thin) == 1 else 'they are'} an interpolation between the "
        "extreme samples, not an estimate of the batch's tail (run more samples)."
    )


def _fmt(x: float) -> str:
    return number_text(x, ".2f")


def report(study: Study, s: dict, errs: dict, tr) -> str:
    """The Markdown report of a study: result, drive, error laws, assumptions, the typical sample."""
    sym = UNIT_SYMBOLS[study.unit]
    te = s["te"]
    angle = study.metric.quantity == "angle"
    shown = f"in {study.unit} ({sym})" if angle else "in loaded pairs"
    lines = [f"# {study.title}", ""]
    if study.description:
        lines += [study.description, ""]
    lines += [
        f"Study `{study.name}` from `{study.source_path}`, run with gearte {s['versions']['gearte']} "
        f"(JAX {s['versions']['jax']}) on {s['created']}.",
        "",
    ]
    if s["study"]["command"]:
        lines += ["Reproduce with:", "", f"    {s['study']['command']}", ""]
    lines += ["## Result", ""]
    lines += [f"**Warning:** {w}." for w in s.get("warnings", ())] + ([""] if s.get("warnings") else [])
    lines += [
        f"{study.metric.describe()}, {shown}, over {te['n']:,} samples:",
        "",
        "| n | min | max | mean | std | " + " | ".join(f"P{p:g}" for p in PERCENTILES) + " |",
        "|---" * (5 + len(PERCENTILES)) + "|",
        f"| {te['n']:,} | {_fmt(te['min'])} | {_fmt(te['max'])} | {_fmt(te['mean'])} | {_fmt(te['std'])} | "
        + " | ".join(_fmt(te["percentiles"][f"{p:g}"]) for p in PERCENTILES)
        + " |",
        "",
        "std is the sample standard deviation (n − 1); percentiles by linear interpolation." + _thin_tails(te["n"]),
        "",
        "![histogram](histogram.png)",
        "",
        "![TE trace of a typical sample](trace.png)",
        "",
        "## Drive",
        "",
        "| parameter | value |",
        "|---|---|",
    ]
    lines += [f"| {k} | {v} |" for k, v in study.drive.describe()]
    lines += [
        "",
        "## Error sources and how they are drawn",
        "",
        "Eccentricities: magnitude in µm at a phase in rad (degrees in brackets); deviations: signed values in µm or rad.",
        "",
        "| source | kind | phase symbol | instances | tolerance | value / magnitude | phase |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, e in s["errors"].items():
        tol = "—" if e["tolerance"] is None else f"{e['tolerance']:g} {e['unit']}"
        lines.append(f"| {name} | {e['kind']} | {e['phase_symbol']} | {e['count']} | {tol} | {e['magnitude']} | {e['phase']} |")
    lines += [
        "",
        "## Assumptions",
        "",
        f"- Metric: {study.metric.describe()}.",
        "- TE Δθ = θ_out − θ_in / i (rad inside gearte; reported in " + study.unit + f", 1 rad = {ARCSEC_PER_RAD:.3f}″).",
        f"- Samples: {s['samples']:,}; seed {s['seed']}; {s['assumptions']['random_keys']}. Samples are computed in blocks of "
        f"{s['block_size']} (one compiled program), progress shown every {s['chunk_size']}; results do not depend on the chunk size.",
        "- Random phases are uniform on [0, 2π); magnitudes and values follow the laws in the table above.",
        f"- Precision: {s['assumptions']['precision']}.",
        f"- Accuracy: {s['assumptions']['accuracy']}.",
    ]
    lines += [f"- {n}" for n in study.notes]
    typ = s["typical_sample"]
    lines += [
        "",
        "## The typical sample",
        "",
        f"Sample #{typ['index']} (closest to the median): {study.metric.name} {typ['te']:.3f}{sym if angle else ''}; over "
        f"{typ['trace_input_revs']} input revolutions the TE runs from {typ['min']:.3f}{sym} "
        f"(at θ_in = {typ['theta_min_rad']:.6f} rad) to {typ['max']:.3f}{sym} (at θ_in = {typ['theta_max_rad']:.6f} rad).",
        "",
        "| source | value or magnitude | phase (rad) |",
        "|---|---|---|",
    ]
    specs = study.errors.specs
    for name, e in errs.items():
        mag = e.magnitude if hasattr(e, "magnitude") else e
        mags = _values_text(np.atleast_1d(np.asarray(mag, dtype=float)), specs[name].unit if name in specs else "µm", name)
        phs = ", ".join(f"{float(x) % (2 * math.pi):.4f}" for x in np.atleast_1d(np.asarray(e.phase))) if hasattr(e, "phase") else "—"
        lines.append(f"| {name} | {mags} | {phs} |")
    if tr.lines:
        lines += [
            "",
            "Its TE spectrum (amplitude per frequency, frequency as a multiple of the input speed):",
            "",
            f"| frequency | amplitude ({sym}) |",
            "|---|---|",
        ]
        lines += [f"| {f} | {angle_from_rad(a, study.unit):.3f} |" for f, a in tr.lines]
    lines += [
        "",
        "## Files",
        "",
        "- `summary.json`: the statistics above and every setting, machine-readable.",
        f"- `samples.npz`: the {s['samples']:,} per-sample values (`te` in {study.unit if angle else 'pairs'}, `te_rad`), "
        "with `seed` and `index`.",
        "- `histogram.png`, `trace.png`: the plots above.",
        "",
        f"Monte Carlo time {s['timing_s']['monte_carlo']:.2f} s (compilation included); total {s['timing_s']['total']:.2f} s.",
        "",
    ]
    return "\n".join(lines)


__all__ = ("report",)
