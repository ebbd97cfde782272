"""``[allocation]``: choose the assembly phases marked ``rule = "optimise"`` (for drives whose TE has phases)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import jax
import numpy as np

from ..core.metrics import Peak
from ..core.schema import MAX_SAMPLES, ConfigError, Table
from ..core.units import UNIT_SYMBOLS, angle_from_rad
from ..drives.protocol import AbstractSinusoidalDrive, Figure
from ..optimise.rule_objectives import RULE_OBJECTIVES
from ..studies.errors import ErrorModel, ErrorSource
from ..studies.laws import FixedPhase, Optimised, RelativePhase, UniformPhase
from ..studies.montecarlo import TEStudy, as_key, monte_carlo
from .kind_base import AbstractStudyKind, Finish, KindOutcome

if TYPE_CHECKING:
    from .config import Study


@dataclasses.dataclass(frozen=True)
class AllocationSpec:
    """`[allocation]`: how the phases marked `rule = "optimise"` are chosen (see `gearte.allocate_rule`)."""

    objective: str
    datum: str
    adjust: dict[str, str]
    starts: int
    surrogate_samples: int
    check_samples: int
    seed_rule: dict[str, float] | None


def kind_key(seed: int):
    """The key stream of the study kinds, apart from the samples' (sample keys are fold_in(root, i), i < 2³² − 1)."""
    return jax.random.fold_in(jax.random.fold_in(as_key(seed), 2**32 - 1), 1)


def _optimised(study: Study) -> dict[str, Optimised]:
    return {n: s.phase for n, s in study.errors.sources.items() if isinstance(s.phase, Optimised)}


class Allocation(AbstractStudyKind):
    """Assembly-rule allocation for unmeasured parts (Wang et al. 2013, sec. 3; `gearte.allocate_rule`)."""

    table = "allocation"

    def check_absent(self, study: Study) -> None:
        optimised = _optimised(study)
        if optimised:
            raise ConfigError(
                f"[allocation]: phases of {sorted(optimised)} are to be optimised; add an [allocation] table "
                '(objective = "worst_case" | "expected" | "robust")'
            )

    def read(self, t: Table, study: Study) -> AllocationSpec:
        optimised = _optimised(study)
        if not isinstance(study.drive, AbstractSinusoidalDrive):
            raise ConfigError(
                f"[allocation]: assembly-phase allocation needs a drive with phases (sinusoidal TE); {study.drive.type_name} has none"
            )
        if not optimised:
            raise ConfigError('[allocation]: no phase is marked `rule = "optimise"` in [errors]; mark the assembly phases to choose')
        if not isinstance(study.metric, Peak):
            raise ConfigError('[allocation]: assembly rules are optimised for the peak metric; set [study] metric = "peak"')
        datums = {r.to for r in optimised.values() if r.to is not None}
        if len(datums) > 1:
            raise ConfigError(f"[errors]: optimised phases must share one datum, got relative_to {sorted(datums)}")
        by_symbol = {s.symbol: n for n, s in study.drive.error_sources.items()}
        datum = datums.pop() if datums else None
        if t.has("datum"):
            d = t.string("datum")
            d = by_symbol.get(d, d)
            if datum is not None and d != datum:
                raise ConfigError(f"[allocation] datum: {d!r} differs from the optimised phases' relative_to {datum!r}")
            datum = d
        if datum is None:
            raise ConfigError('[allocation] datum: name the error source whose phase is the assembly datum (e.g. "ring_manufacturing")')
        sources = study.errors.sources
        if datum not in sources or not isinstance(sources[datum].phase, UniformPhase):
            raise ConfigError(f"[allocation] datum: {datum!r} must be an error source with a uniform (unknown) phase")
        missing = sorted(n for n, tol in study.tolerances.items() if tol is None)
        if missing:
            raise ConfigError(f"[allocation]: every error source needs `tolerance_um` for the allocation objectives; missing in {missing}")
        seed_rule = None
        if t.has("seed_rule"):
            sr = t.table("seed_rule")
            seed_rule = {n: sr.angle(n) for n in optimised}
            sr.finish()
        return AllocationSpec(
            objective=t.string("objective", "worst_case", choices=tuple(RULE_OBJECTIVES)),
            datum=datum,
            adjust={n: ("relative" if r.to is not None else "absolute") for n, r in optimised.items()},
            starts=t.integer("starts", 16, minimum=1, maximum=MAX_SAMPLES),
            surrogate_samples=t.integer("surrogate_samples", 512, minimum=16, maximum=MAX_SAMPLES),
            check_samples=t.integer("check_samples", 50_000, minimum=100, maximum=MAX_SAMPLES),
            seed_rule=seed_rule,
        )

    def check_together(self, study: Study) -> None:
        if "allocation" in study.kinds and "budget" in study.kinds:
            raise ConfigError(
                '[budget]: give the assembly rule as concrete phases (rule = "relative" or "fixed") in a budget '
                "study; optimise the rule in its own study first"
            )

    def evaluations(self, study: Study, spec: AllocationSpec) -> int:
        # every start's surrogate once (the worst case has none: it is exact), the check of the found (and the given)
        # rule (its expected and robust TE), and the Monte Carlo of each other assembly shown beside the study's own
        # (random, and the given rule)
        rules = 1 + (spec.seed_rule is not None)
        surrogate = 0 if spec.objective == "worst_case" else spec.starts * spec.surrogate_samples
        return surrogate + rules * (2 * spec.check_samples + study.samples)

    def run(self, study: Study, spec: AllocationSpec, *, progress: bool | None) -> KindOutcome:
        # The optimiser (optimistix) is imported here: reading and checking the table need none of it.
        from ..core.solution import is_successful, message
        from ..optimise.allocation import allocate_rule, evaluate_rule, rule_problem

        key = kind_key(study.seed)
        k_opt, k_seed = jax.random.split(key)
        drive = study.drive
        assert isinstance(drive, AbstractSinusoidalDrive)  # checked when the table was read
        tolerances = {n: float(t) for n, t in study.tolerances.items() if t is not None}  # all given (checked)
        p = rule_problem(drive, study.errors, adjust=spec.adjust, datum=spec.datum, tolerances=tolerances)
        res = allocate_rule(
            p,
            objective=RULE_OBJECTIVES[spec.objective](),
            key=k_opt,
            starts=spec.starts,
            n_samples=spec.surrogate_samples,
            n_check=spec.check_samples,
            throw=False,
        )
        found = {n: float(v) for n, v in res.offsets.items()}
        sym = {n: s.symbol for n, s in study.drive.error_sources.items()}
        to_unit = lambda x: float(angle_from_rad(float(x), study.unit))
        u = study.unit
        entry: dict[str, Any] = {
            "objective": spec.objective,
            "datum": spec.datum,
            "convention": f"phases in rad with the datum phase {sym.get(spec.datum, spec.datum)} = 0 "
            + "(relative rules: phase = datum + value; absolute rules: phase = value)",
            "phases_rad": {sym.get(n, n): v for n, v in found.items()},
            "rules": dict(spec.adjust),
            f"te_worst_case_{u}": to_unit(res.worst_case),
            f"te_expected_{u}": to_unit(res.expected),
            f"te_robust_{u}": to_unit(res.robust),
            "check_samples": spec.check_samples,
            "starts": res.starts,
            "starts_converged": res.converged,
            "result": "successful" if is_successful(res.result) else message(res.result),
        }
        resolved = _with_rule(study, spec, found)
        series: dict[str, tuple[Study, ErrorModel]] = {}
        seed_study = None
        if spec.seed_rule is not None:
            figs = evaluate_rule(p, spec.seed_rule, key=k_seed, n_check=spec.check_samples)
            entry["seed_rule_phases_rad"] = {sym.get(n, n): float(v) for n, v in spec.seed_rule.items()}
            for k, v in figs.items():
                entry[f"seed_rule_te_{k}_{u}"] = to_unit(v)
            seed_study = _with_rule(study, spec, spec.seed_rule)
            series["given rule (seed_rule)"] = (seed_study, seed_study.errors)
        random_sources = {n: (ErrorSource(s.magnitude, UniformPhase()) if n in spec.adjust else s) for n, s in study.errors.sources.items()}
        series["random assembly"] = (study, ErrorModel(random_sources, study.errors.specs))
        values = {}
        for label, (_, model) in series.items():
            r = monte_carlo(
                _te_study(study, model), key=study.seed, n_samples=study.samples, chunk_size=study.chunk_size, progress=progress, desc=label
            )
            values[label] = angle_from_rad(r.values, u)
        entry["monte_carlo_means"] = {label: float(np.mean(v)) for label, v in values.items()}

        def finish(f: Finish, summary: dict) -> list[Figure]:
            mean = float(np.mean(f.values))
            entry[f"te_monte_carlo_mean_{u}"] = mean
            entry["monte_carlo_means"]["found rule"] = mean
            summary["study"]["source_rules"] = {n: s.phase.describe() for n, s in study.errors.sources.items() if s.phase is not None}
            figures = [
                Figure(
                    "allocation_histograms.png",
                    "overlay_histograms",
                    {"series": [*values.items(), ("found rule", f.values)], "unit": u, "metric": study.metric.label},
                )
            ]
            if seed_study is not None:
                theta, te_found = f.trace(resolved, f.typical)
                _, te_seed = f.trace(seed_study, f.typical)
                figures.append(
                    Figure(
                        "allocation_traces.png",
                        "trace_pair",
                        {
                            "theta_rev": theta,
                            "te_a": te_seed,
                            "te_b": te_found,
                            "unit": u,
                            "labels": ("given rule (seed_rule)", "found rule"),
                            "title": f"Sample #{f.typical}: the same parts assembled by Wang et al.'s rule and by the found rule",
                        },
                    )
                )
            return figures

        return KindOutcome(study=resolved, key="allocation", summary=entry, report=lambda s: _report(study, s), finish=finish)


def _te_study(study: Study, model: ErrorModel) -> TEStudy:
    return TEStudy(study.drive, model, metric=study.metric)


def _with_rule(study: Study, spec: AllocationSpec, offsets: dict[str, float]) -> Study:
    """The study with its optimised phases replaced by a concrete rule (offsets in rad)."""
    sources = dict(study.errors.sources)
    for name, mode in spec.adjust.items():
        off = float(offsets[name])
        rule = RelativePhase(spec.datum, off) if mode == "relative" else FixedPhase(off)
        sources[name] = ErrorSource(sources[name].magnitude, rule)
    kinds = {k: v for k, v in study.kinds.items() if k != "allocation"}
    return dataclasses.replace(study, errors=ErrorModel(sources, study.errors.specs), kinds=kinds)


def _report(study: Study, s: dict) -> list[str]:
    a = s["allocation"]
    sym = UNIT_SYMBOLS[study.unit]
    u = study.unit
    lines = [
        "## Assembly-phase allocation",
        "",
        f"The phases marked `optimise` were chosen to minimise the **{a['objective'].replace('_', ' ')}** TE over the unknown "
        f"manufacturing phases ({a['starts']} BFGS starts on a smooth surrogate, {a['starts_converged']} converged; "
        f"solver result: {a['result']}; every figure below is the exact metric). Worst case: magnitudes at the tolerances, "
        "every unknown phase at its worst (exact: each unknown phase turns its own single-frequency group). Expected: "
        "magnitudes at the tolerances, unknown phases uniform. Robust: magnitudes drawn by their laws too. Expected and "
        f"robust by Monte Carlo, {a['check_samples']:,} samples.",
        "",
        f"{a['convention']}.",
        "",
        f"| rule | phases (rad) | worst case ({sym}) | expected ({sym}) | robust ({sym}) |",
        "|---|---|---|---|---|",
        "| found | "
        + ", ".join(f"{k} = {v:.4f}" for k, v in a["phases_rad"].items())
        + f" | {a[f'te_worst_case_{u}']:.2f} | {a[f'te_expected_{u}']:.2f} | {a[f'te_robust_{u}']:.2f} |",
    ]
    if "seed_rule_phases_rad" in a:
        lines.append(
            "| given (`seed_rule`) | "
            + ", ".join(f"{k} = {v:.4f}" for k, v in a["seed_rule_phases_rad"].items())
            + f" | {a[f'seed_rule_te_worst_case_{u}']:.2f} | {a[f'seed_rule_te_expected_{u}']:.2f} | {a[f'seed_rule_te_robust_{u}']:.2f} |"
        )
    lines += [
        "",
        "Mean TE of this study's Monte Carlo (same seed, same parts) under each assembly:",
        "",
        "| assembly | mean (" + sym + ") |",
        "|---|---|",
    ]
    lines += [f"| {k} | {v:.2f} |" for k, v in a["monte_carlo_means"].items()]
    lines += ["", "![TE distributions under each assembly](allocation_histograms.png)", ""]
    if "seed_rule_phases_rad" in a:
        lines += ["![one set of parts under both rules](allocation_traces.png)", ""]
    lines += [
        "Same-frequency components add as phasors; Wang et al. (2013) compensate them collinearly (λ = ±1), which "
        "leaves |Σ λ_i A_i|. When the amplitudes satisfy the polygon inequality their phasors can close, and the "
        "optimiser, which works on the true objective, finds that.",
        "",
    ]
    return lines
