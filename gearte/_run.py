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


def _allocation_key(seed: int):
    # A stream apart from the samples': sample keys are fold_in(root, i) with i < 2³² − 1.
    return jax.random.fold_in(jax.random.fold_in(as_key(seed), 2**32 - 1), 1)


def _with_rule(study: Study, offsets: dict[str, float]) -> Study:
    """The study with its optimised phases replaced by a concrete rule (offsets in rad)."""
    import dataclasses

    from ._distributions import FixedPhase, RelativePhase
    from ._errors import ErrorModel, ErrorSource

    spec = study.allocation
    sources = dict(study.errors.sources)
    for name, mode in spec.adjust.items():
        off = float(offsets[name])
        rule = RelativePhase(spec.datum, off) if mode == "relative" else FixedPhase(off)
        sources[name] = ErrorSource(sources[name].magnitude, rule)
    return dataclasses.replace(study, errors=ErrorModel(sources, study.errors.counts), allocation=None)


def _resolve_allocation(study: Study, progress) -> tuple[Study, dict, dict]:
    """Choose the assembly rule, evaluate it and the seed's rule exactly. Returns the study under
    the found rule, the summary's "allocation" entry, and Monte Carlo values for the plots."""
    from ._allocation import allocate_rule, evaluate_rule, rule_problem
    from ._distributions import UniformPhase
    from ._errors import ErrorModel, ErrorSource

    spec = study.allocation
    key = _allocation_key(study.seed)
    k_opt, k_seed = jax.random.split(key)
    p = rule_problem(study.drive, study.errors, adjust=spec.adjust, datum=spec.datum, tolerances=study.tolerances_um)
    res = allocate_rule(p, objective=spec.objective, key=k_opt, starts=spec.starts, n_samples=spec.surrogate_samples,
                        n_check=spec.check_samples)
    found = {n: float(v) for n, v in res.offsets.items()}
    sym = study.drive.phase_symbols
    to_unit = lambda x: float(angle_from_rad(float(x), study.unit))
    entry = {
        "objective": spec.objective,
        "datum": spec.datum,
        "convention": f"phases in rad with the datum phase {sym.get(spec.datum, spec.datum)} = 0 "
                      + "(relative rules: phase = datum + value; absolute rules: phase = value)",
        "phases_rad": {sym.get(n, n): v for n, v in found.items()},
        "rules": {n: spec.adjust[n] for n in spec.adjust},
        f"te_worst_case_{study.unit}": to_unit(res.worst_case),
        f"te_expected_{study.unit}": to_unit(res.expected),
        f"te_robust_{study.unit}": to_unit(res.robust),
        "check_samples": spec.check_samples,
        "starts": res.starts,
        "starts_converged": res.converged,
    }
    mc = {}
    resolved = _with_rule(study, found)
    if spec.seed_rule is not None:
        figs = evaluate_rule(p, spec.seed_rule, key=k_seed, n_check=spec.check_samples)
        entry["seed_rule_phases_rad"] = {sym.get(n, n): float(v) for n, v in spec.seed_rule.items()}
        for k, v in figs.items():
            entry[f"seed_rule_te_{k}_{study.unit}"] = to_unit(v)
        seed_study = _with_rule(study, spec.seed_rule)
        mc["seed rule"] = (seed_study, None)
    random_sources = {n: (ErrorSource(s.magnitude, UniformPhase()) if n in spec.adjust else s) for n, s in study.errors.sources.items()}
    mc["random assembly"] = (None, ErrorModel(random_sources, study.errors.counts))
    values = {}
    for label, (st, model) in mc.items():
        model = st.errors if st is not None else model
        r = monte_carlo(study.drive.te_study(model, metric=study.metric), key=study.seed, n_samples=study.samples,
                        chunk_size=study.chunk_size, progress=progress, desc=label)
        values[label] = angle_from_rad(r.values, study.unit)
    entry["monte_carlo_means"] = {label: float(np.mean(v)) for label, v in values.items()}
    return resolved, entry, {"values": values, "seed_study": mc.get("seed rule", (None, None))[0]}


def _scaled_study(study: Study, tolerances: dict[str, float]) -> Study:
    """The study with every magnitude law scaled from its nominal tolerance to `tolerances` (µm)."""
    import dataclasses

    import equinox as eqx

    from ._errors import ErrorModel, ErrorSource

    sources = {}
    for n, src in study.errors.sources.items():
        f = tolerances[n] / study.tolerances_um[n]
        law = jax.tree.map(lambda x: x * f if eqx.is_array(x) else x, src.magnitude)
        sources[n] = ErrorSource(law, src.phase)
    return dataclasses.replace(study, errors=ErrorModel(sources, study.errors.counts), tolerances_um=dict(tolerances), budget=None)


def _grade(spec: dict, tol_um: float):
    from ._iso1328 import nearest_grade

    try:
        return nearest_grade(spec["factor"] * tol_um, quantity=spec["quantity"], standard=spec["standard"], module=spec["module"],
                             diameter=spec["diameter"], face_width=spec["face_width"])
    except ValueError as e:
        return f"none ({e})"


def _resolve_budget(study: Study) -> tuple[Study, dict, dict]:
    """Optimise the tolerance budget; return the study at the optimised tolerances, the summary's
    "budget" entry and data for the plots."""
    from ._budget import budget_problem, contributions, optimise_budget, pareto_front, uniform_scaling
    from ._distributions import RelativePhase, FixedPhase, UniformPhase
    from ._errors import ErrorModel, ErrorSource

    b = study.budget
    u = study.unit
    to_rad = lambda x: float(x) / float(angle_from_rad(1.0, u))
    key = _allocation_key(study.seed)
    k_opt, k_sens, k_rand, k_front = jax.random.split(jax.random.fold_in(key, 2), 4)

    def problem(model, spec):
        return budget_problem(study.drive, model, costs=b.costs, nominal=study.tolerances_um, spec=to_rad(spec), constraint=b.constraint,
                              target=b.target, maximum=b.maximum_um, metric=study.metric)

    p = problem(study.errors, b.spec)
    best = optimise_budget(p, key=k_opt, n_samples=b.samples, n_check=b.check_samples)
    base = uniform_scaling(p, key=k_opt, n_check=b.check_samples)
    contrib = contributions(p, best.tolerances, key=k_sens, n_samples=min(b.samples, 8192))
    grades = {n: _grade(b.grades[n], best.tolerances[n]) for n in b.grades}
    entry = {
        "constraint": b.constraint,
        f"spec_{u}": b.spec,
        "target_yield" if b.constraint == "yield" else "k": b.target,
        "tolerances_um": best.tolerances,
        "nominal_tolerances_um": dict(study.tolerances_um),
        "maximum_tolerances_um": b.maximum_um,
        "grades": grades,
        "cost": best.cost,
        "baseline_cost": base.cost,
        "baseline_tolerances_um": base.tolerances,
        "baseline_scale": base.tolerances[next(iter(base.tolerances))] / study.tolerances_um[next(iter(base.tolerances))],
        "verified_yield": best.verified_yield,
        "verified_samples": best.verified_samples,
        "baseline_verified_yield": base.verified_yield,
        f"verified_statistic_{u}": float(angle_from_rad(best.verified_statistic, u)),
        "solver_converged": best.converged,
        "cost_models": {n: c.describe() for n, c in b.costs.items()},
        f"contributions_{u}": {n: float(angle_from_rad(v, u)) for n, v in contrib.items()},
        "optimisation_samples": b.samples,
        "assembly": {n: s.phase.describe() for n, s in study.errors.sources.items()},
    }
    plots = {"contributions": entry[f"contributions_{u}"], "verified": angle_from_rad(best.verified_values, u), "front": []}
    has_rule = any(isinstance(s.phase, (RelativePhase, FixedPhase)) for s in study.errors.sources.values())
    if b.compare_random_assembly and has_rule:
        rand_model = ErrorModel({n: ErrorSource(s.magnitude, UniformPhase()) for n, s in study.errors.sources.items()}, study.errors.counts)
        pr = problem(rand_model, b.spec)
        rb, rbase = optimise_budget(pr, key=k_rand, n_samples=b.samples, n_check=b.check_samples), uniform_scaling(pr, key=k_rand, n_check=b.check_samples)
        entry["random_assembly"] = {"tolerances_um": rb.tolerances, "cost": rb.cost, "baseline_cost": rbase.cost,
                                    "verified_yield": rb.verified_yield, "baseline_verified_yield": rbase.verified_yield}
    if b.pareto_specs:
        n_front = max(1000, b.check_samples // 2)
        front = pareto_front(p, [to_rad(x) for x in b.pareto_specs], key=k_front, n_samples=max(256, b.samples // 2), n_check=n_front)
        rows = []
        for spec, r in zip(b.pareto_specs, front):
            q = problem(study.errors, spec)
            rows.append({f"spec_{u}": spec, "cost": r.cost, "baseline_cost": uniform_scaling(q, key=k_front, n_check=n_front).cost,
                         "verified_yield": r.verified_yield, "tolerances_um": r.tolerances})
        entry["pareto"] = rows
        plots["front"] = rows
    return _scaled_study(study, best.tolerances), entry, plots


def run_study(study: Study, out: str | Path, *, progress: bool | None = None, command: str | None = None) -> dict:
    """Run `study` and write its results folder `out` atomically. Returns the summary dict."""
    from . import plotting

    t_start = time.perf_counter()
    allocation, alloc_plots = None, None
    budget, budget_plots = None, None
    original = study
    if study.allocation is not None:
        study, allocation, alloc_plots = _resolve_allocation(study, progress)
    if study.budget is not None:
        study, budget, budget_plots = _resolve_budget(study)
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
        "timing_s": {"monte_carlo": mc.seconds, "total": None},
        "versions": _versions(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }

    if allocation is not None:
        allocation[f"te_monte_carlo_mean_{study.unit}"] = stats.mean
        allocation["monte_carlo_means"]["found rule"] = stats.mean
        summary["allocation"] = allocation
        summary["study"]["source_rules"] = {n: s.phase.describe() for n, s in original.errors.sources.items()}

    if budget is not None:
        summary["budget"] = budget

    with atomic_output_dir(out) as tmp:
        if budget_plots is not None:
            u = study.unit
            plotting.contributions(budget_plots["contributions"], unit=u, path=tmp / "contributions.png",
                                   title="Share of the constrained TE statistic by source (∂stat/∂T_i · T_i)")
            if budget_plots["front"]:
                plotting.pareto(budget_plots["front"], unit=u, path=tmp / "pareto.png")
        if alloc_plots is not None:
            series = [(k, v) for k, v in alloc_plots["values"].items()] + [("found rule", values)]
            plotting.overlay_histograms(series, unit=study.unit, metric=study.metric, path=tmp / "allocation_histograms.png")
            seed_study = alloc_plots["seed_study"]
            if seed_study is not None:
                seed_sig = study.drive.signal(_sample_errors(seed_study, typical))
                te_seed = angle_from_rad(np.asarray(evaluate(seed_sig, theta)), study.unit)
                plotting.trace_pair(theta / (2 * math.pi), te_seed, te_trace, unit=study.unit, labels=("seed rule", "found rule"),
                                    title=f"Sample #{typical}: the same parts assembled by the seed's rule and by the found rule",
                                    path=tmp / "allocation_traces.png")
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
        text = _report(study, summary, errs, signal) + (_allocation_report(study, summary) if allocation is not None else "")
        text += _budget_report(study, summary) if budget is not None else ""
        (tmp / "report.md").write_text(text + "\n".join(extra_lines) + ("\n" if extra_lines else ""), encoding="utf-8")
        write_json(tmp / "summary.json", summary)
    return summary


def _allocation_report(study: Study, s: dict) -> str:
    a = s["allocation"]
    sym = UNIT_SYMBOLS[study.unit]
    u = study.unit
    lines = ["## Assembly-phase allocation", "",
             f"The phases marked `optimise` were chosen to minimise the **{a['objective'].replace('_', ' ')}** TE over the unknown "
             f"manufacturing phases ({a['starts']} BFGS starts on a smooth surrogate, {a['starts_converged']} converged; "
             "every figure below is the exact metric). Worst case: magnitudes at the tolerances, every unknown phase at its worst "
             "(exact: each unknown phase turns its own single-frequency group). Expected: magnitudes at the tolerances, unknown "
             f"phases uniform. Robust: magnitudes drawn by their laws too. Expected and robust by Monte Carlo, {a['check_samples']:,} samples.",
             "", f"{a['convention']}.", "",
             f"| rule | phases (rad) | worst case ({sym}) | expected ({sym}) | robust ({sym}) |", "|---|---|---|---|---|",
             "| found | " + ", ".join(f"{k} = {v:.4f}" for k, v in a["phases_rad"].items())
             + f" | {a[f'te_worst_case_{u}']:.2f} | {a[f'te_expected_{u}']:.2f} | {a[f'te_robust_{u}']:.2f} |"]
    if "seed_rule_phases_rad" in a:
        lines.append("| seed (Table 3) | " + ", ".join(f"{k} = {v:.4f}" for k, v in a["seed_rule_phases_rad"].items())
                     + f" | {a[f'seed_rule_te_worst_case_{u}']:.2f} | {a[f'seed_rule_te_expected_{u}']:.2f} | {a[f'seed_rule_te_robust_{u}']:.2f} |")
    lines += ["", "Mean TE of this study's Monte Carlo (same seed, same parts) under each assembly:", "",
              "| assembly | mean (" + sym + ") |", "|---|---|"]
    lines += [f"| {k} | {v:.2f} |" for k, v in a["monte_carlo_means"].items()]
    lines += ["", "![TE distributions under each assembly](allocation_histograms.png)", ""]
    if "seed_rule_phases_rad" in a:
        lines += ["![one set of parts under both rules](allocation_traces.png)", ""]
    lines += ["Same-frequency components add as phasors; the seed compensates them collinearly (λ = ±1), which leaves "
              "|Σ λ_i A_i|. When the amplitudes satisfy the polygon inequality their phasors can close, and the optimiser, "
              "which works on the true objective, finds that.", ""]
    return "\n".join(lines)


def _budget_report(study: Study, s: dict) -> str:
    b = s["budget"]
    u = study.unit
    sym = UNIT_SYMBOLS[u]
    cons = (f"yield P(TE ≤ {b[f'spec_{u}']:g}{sym}) ≥ {b['target_yield']}" if b["constraint"] == "yield"
            else f"mean + {b['k']}σ ≤ {b[f'spec_{u}']:g}{sym}")
    lines = ["## Tolerance budget", "",
             f"Cheapest tolerances with {cons}. Magnitudes are tolerance × a standard draw of each source's law "
             f"(common random numbers, {b['optimisation_samples']:,} samples, smoothed quantile); the budget is then scaled on a fresh "
             f"sample to clear the target by four binomial standard errors and verified on another fresh sample of "
             f"{b['verified_samples']:,}. Every source's tolerance is capped at 10 × nominal (`maximum_factor`). "
             f"Solver converged: {b['solver_converged']}.", "",
             f"| source | nominal (µm) | optimised (µm) | uniform scaling (µm) | ISO grade | cost model | share of the statistic ({sym}) |",
             "|---|---|---|---|---|---|---|"]
    for n, t in b["tolerances_um"].items():
        lines.append(f"| {n} | {b['nominal_tolerances_um'][n]:g} | {t:.2f} | {b['baseline_tolerances_um'][n]:.2f} | {b['grades'].get(n, '—')} | "
                     f"{b['cost_models'][n]} | {b[f'contributions_{u}'][n]:.2f} |")
    lines += ["", f"Cost {b['cost']:.4f} against {b['baseline_cost']:.4f} for the cheapest uniform scaling of the nominal tolerances "
              f"(× {b['baseline_scale']:.3f}); verified yield {b['verified_yield']:.5f} (baseline {b['baseline_verified_yield']:.5f}).", ""]
    if "random_assembly" in b:
        r = b["random_assembly"]
        lines += [f"Without the assembly rule (every phase random) the same spec costs {r['cost']:.4f} optimised, {r['baseline_cost']:.4f} "
                  f"by uniform scaling: the rule changes which tolerances matter.", "",
                  "| source | with the rule (µm) | random assembly (µm) |", "|---|---|---|"]
        lines += [f"| {n} | {b['tolerances_um'][n]:.2f} | {r['tolerances_um'][n]:.2f} |" for n in b["tolerances_um"]]
        lines.append("")
    lines += ["![contributions](contributions.png)", ""]
    if "pareto" in b:
        lines += [f"| spec ({sym}) | optimised cost | uniform-scaling cost | verified yield |", "|---|---|---|---|"]
        lines += [f"| {r[f'spec_{u}']:g} | {r['cost']:.4f} | {r['baseline_cost']:.4f} | {r['verified_yield']:.5f} |" for r in b["pareto"]]
        lines += ["", "![cost vs spec](pareto.png)", ""]
    lines += ["The \"te\" statistics above are a further Monte Carlo at the optimised tolerances (the study's own samples and seed).", ""]
    return "\n".join(lines)


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
