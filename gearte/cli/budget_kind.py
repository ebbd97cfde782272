"""``[budget]``: the cheapest tolerances that meet the study's specifications (any drive, `gearte.optimise_budget`)."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import jax

from ..core.metrics import AbstractMetric
from ..core.schema import MAX_SAMPLES, ConfigError, Table
from ..core.units import ARCSEC_PER_RAD, UNIT_SYMBOLS, angle_from_rad
from ..drives.protocol import Figure
from ..optimise.budget_model import Constraint, budget_problem
from ..optimise.costs import Exponential, GradeTable, Power, Reciprocal, ReciprocalSquare
from ..optimise.statistics import MeanKSigma, Yield, binomial_se
from ..standards.iso1328 import check_length, nearest_grade
from ..studies.errors import ErrorModel, ErrorSource
from ..studies.laws import FixedPhase, RelativePhase, UniformPhase
from .allocation_kind import kind_key
from .kind_base import AbstractStudyKind, KindOutcome

if TYPE_CHECKING:
    from .config import Study

COST_MODELS = ("reciprocal", "reciprocal_square", "exponential", "power", "grade_table")


@dataclasses.dataclass(frozen=True)
class ConstraintSpec:
    """One constraint as the study file gives it: the metric, its spec in the study's unit (pairs for counts)."""

    metric: AbstractMetric
    spec: float
    constraint: str
    target: float

    def to_internal(self, unit: str, spec: float | None = None) -> Constraint:
        s = self.spec if spec is None else spec
        value = s / float(angle_from_rad(1.0, unit)) if self.metric.quantity == "angle" else s
        stat = Yield(self.target) if self.constraint == "yield" else MeanKSigma(self.target)
        return Constraint(self.metric, value, stat)


@dataclasses.dataclass(frozen=True)
class BudgetSpec:
    """`[budget]`: a tolerance-budget optimisation (see `gearte.optimise_budget`)."""

    constraints: tuple[ConstraintSpec, ...]
    samples: int
    check_samples: int
    costs: dict
    nominal: dict[str, float]
    maximum: dict[str, float]
    grades: dict[str, dict]
    pareto_specs: tuple[float, ...]
    compare_random_assembly: bool

    @property
    def spec(self) -> float:
        return self.constraints[0].spec


#: Largest `maximum_factor` of a budget: its tolerances stay within this many times the nominal ones.
MAX_TOLERANCE_FACTOR = 1000.0


def _cost_model(t: Table, nominal: float):
    """A cost model from its table; without coefficients, normalised to cost 1 at the nominal tolerance."""
    kind = t.string("model", choices=COST_MODELS)
    try:
        if kind == "grade_table":
            raw = t.table("costs_by_grade")
            costs = {int(k): raw.number(k, minimum=0) for k in list(raw.data)}
            return GradeTable(
                costs,
                quantity=t.string("quantity"),
                standard=t.string("standard"),
                module=t.number("module_mm", positive=True),
                diameter=t.number("diameter_mm", positive=True),
                face_width=t.number("face_width_mm", None, positive=True) if t.has("face_width_mm") else None,
            )
        cls = {"reciprocal": Reciprocal, "reciprocal_square": ReciprocalSquare, "exponential": Exponential, "power": Power}[kind]
        params = {"reciprocal": ("a", "b"), "reciprocal_square": ("a", "b"), "exponential": ("a", "b", "k"), "power": ("a", "k")}[kind]
        if not any(t.has(k) for k in params):
            if cls is Power:
                return Power.normalised(nominal, k=t.number("exponent", 1.0, positive=True))
            return cls.normalised(nominal)  # pyright: ignore[reportAttributeAccessIssue]
        model = cls(*[t.number(k) for k in params])  # pyright: ignore[reportCallIssue]
        at_nominal = float(model(nominal))
        if not (math.isfinite(at_nominal) and at_nominal > 0):
            raise ConfigError(
                f"{t.where}: the cost at the nominal tolerance ({nominal:g}) is {at_nominal:g}; give coefficients for which "
                "it is a positive finite number"
            )
        return model
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"{t.where}: {e}") from None


def _constraint(t: Table, study: Study, *, default_metric: AbstractMetric) -> ConstraintSpec:
    offered = study.drive.metrics
    metric = offered[t.string("metric", default_metric.name, choices=tuple(offered))] if t.has("metric") else default_metric
    spec = t.number("spec", positive=True)
    constraint = t.string("constraint", "yield", choices=("yield", "mean_k_sigma"))
    target = t.number("target", 0.9973 if constraint == "yield" else 3.0, minimum=0)
    if constraint == "yield" and not 0.5 <= target < 1:
        raise ConfigError(f"{t.where} target: a yield in [0.5, 1), got {target:g}")
    return ConstraintSpec(metric, spec, constraint, target)


class Budget(AbstractStudyKind):
    """Tolerance budget (`gearte.budget_problem`, `gearte.optimise_budget`)."""

    table = "budget"

    def read(self, t: Table, study: Study) -> BudgetSpec:
        specs = study.drive.error_sources
        if t.has("sources"):
            raw = t.get("sources")
            if not isinstance(raw, list) or not all(isinstance(x, str) for x in raw) or not raw:
                raise ConfigError("[budget] sources: a list of error-source names whose tolerances are chosen")
            unknown = [x for x in raw if x not in specs]
            if unknown:
                raise ConfigError(f"[budget] sources: {unknown} are not error sources; use some of {list(specs)}")
            repeated = sorted({x for x in raw if raw.count(x) > 1})
            if repeated:
                raise ConfigError(f"[budget] sources: {repeated} named more than once; name each source once")
            names = list(raw)
        else:
            names = list(specs)
        missing = sorted(n for n in names if not study.tolerances.get(n))
        if missing:
            raise ConfigError(
                f"[budget]: every budgeted error source needs a nominal tolerance > 0 (`tolerance_um` in "
                f"[errors.NAME]); missing or zero in {missing}"
            )
        if t.has("constraints"):
            if t.has("spec"):
                raise ConfigError("[budget]: give `spec` (one constraint on the study's metric) or [[budget.constraints]], not both")
            raw = t.get("constraints")
            if not isinstance(raw, list) or not raw:
                raise ConfigError("[budget] constraints: a list of [[budget.constraints]] tables (metric, spec, constraint, target)")
            constraints = []
            for i, item in enumerate(raw):
                ct = Table(item, f"[[budget.constraints]] #{i + 1}")
                constraints.append(_constraint(ct, study, default_metric=study.metric))
                ct.finish()
        else:
            constraints = [_constraint(t, study, default_metric=study.metric)]
        nominal = {n: float(study.tolerances[n]) for n in names}  # pyright: ignore[reportArgumentType]
        default = t.string("cost_model", "reciprocal", choices=COST_MODELS[:-1])
        overrides = t.table("costs", {}) if t.has("costs") else None
        costs = {}
        for n in names:
            if overrides is not None and overrides.has(n):
                ct = overrides.table(n)
                costs[n] = _cost_model(ct, nominal[n])
                ct.finish()
            else:
                costs[n] = _cost_model(Table({"model": default}, "[budget] cost_model"), nominal[n])
        if overrides is not None:
            extra = [k for k in overrides.data if k not in names]
            if extra:
                raise ConfigError(f"[budget.costs]: {extra} are not budgeted sources; use some of {names}")
            overrides.finish()
        factor = t.number("maximum_factor", 10.0, positive=True)
        if factor <= 1:
            raise ConfigError(f"[budget] maximum_factor: must be > 1 (largest tolerance = factor × nominal), got {factor:g}")
        if factor > MAX_TOLERANCE_FACTOR:
            raise ConfigError(
                f"[budget] maximum_factor: {factor:g} is more than {MAX_TOLERANCE_FACTOR:g} (largest tolerance = factor × "
                "nominal: a budget searches within a few times the nominal tolerances)"
            )
        grades = {}
        if t.has("grades"):
            gt = t.table("grades")
            for n in list(gt.data):
                if n not in names:
                    raise ConfigError(f"[budget.grades]: {n!r} is not a budgeted error source; use one of {names}")
                g = gt.table(n)
                grades[n] = {
                    "quantity": g.string("quantity", "F_r", choices=("f_pt", "F_p", "F_alpha", "F_beta", "F_r")),
                    "factor": g.number("factor", 2.0, positive=True),
                    "standard": g.string("standard", "1328-1:2013", choices=("1328-1:2013", "1328-1:1995")),
                    "module": g.number("module_mm", positive=True),
                    "diameter": g.number("diameter_mm", positive=True),
                    "face_width": g.number("face_width_mm", positive=True) if g.has("face_width_mm") else None,
                }
                if grades[n]["quantity"] == "F_beta" and grades[n]["face_width"] is None:
                    raise ConfigError(f"{g.where}: quantity F_beta (total helix) needs face_width_mm")
                for key in ("module", "diameter", "face_width"):  # the standard's range, checked before the run
                    if grades[n][key] is not None:
                        try:
                            check_length(key, grades[n][key], grades[n]["standard"])
                        except ValueError as e:
                            raise ConfigError(f"{g.where} {key}_mm: {e}") from None
                g.finish()
            gt.finish()
        pareto = t.get("pareto_specs", [])
        if not isinstance(pareto, list) or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and 0 < x < math.inf for x in pareto
        ):
            raise ConfigError("[budget] pareto_specs: expected a list of positive numbers (specs of the first constraint)")
        return BudgetSpec(
            constraints=tuple(constraints),
            samples=t.integer("samples", 4096, minimum=64, maximum=MAX_SAMPLES),
            check_samples=t.integer("check_samples", 50_000, minimum=1000, maximum=MAX_SAMPLES),
            costs=costs,
            nominal=nominal,
            maximum={n: factor * nominal[n] for n in names},
            grades=grades,
            pareto_specs=tuple(float(x) for x in pareto),
            compare_random_assembly=t.boolean("compare_random_assembly", True),
        )

    def evaluations(self, study: Study, spec: BudgetSpec) -> int:
        # one pass of the optimiser, the optimum's and the uniform scaling's checks, the contributions; the same again
        # for random assembly where it is compared; each Pareto point on half the samples
        one = spec.samples + 2 * spec.check_samples + min(spec.samples, 8192)
        front = max(1000, spec.check_samples // 2)
        return one * (1 + _compares_random_assembly(study, spec)) + len(spec.pareto_specs) * (max(256, spec.samples // 2) + 2 * front)

    def run(self, study: Study, spec: BudgetSpec, *, progress: bool | None) -> KindOutcome:
        # The optimiser (optimistix) is imported here: reading and checking the table need none of it.
        from ..core.solution import RESULTS, is_successful, message
        from ..optimise.budget import contributions, optimise_budget, pareto_front, uniform_scaling

        b = spec
        u = study.unit
        key = kind_key(study.seed)
        k_opt, k_sens, k_rand, k_front = jax.random.split(jax.random.fold_in(key, 2), 4)

        def problem(model: ErrorModel, first: float | None = None):
            cons = [c.to_internal(u, first if j == 0 else None) for j, c in enumerate(b.constraints)]
            return budget_problem(study.drive, model, costs=b.costs, nominal=b.nominal, constraints=cons, maximum=b.maximum)

        p = problem(study.errors)
        best = optimise_budget(p, key=k_opt, n_samples=b.samples, n_check=b.check_samples, throw=False, progress=progress)
        if not is_successful(best.result) and best.label == "infeasible":
            raise ValueError(f"[budget]: {message(best.result)}")
        base = uniform_scaling(p, key=k_opt, n_check=b.check_samples, progress=progress)
        # The optimiser works on smooth surrogates of the statistics over a few common samples; the calibration
        # on exact metrics can leave its direction costlier than plain uniform scaling. Then report so, and keep
        # the cheaper budget that meets the same checks.
        # An optimised direction that the calibration cannot scale to meet the spec on fresh samples is no answer:
        # uniform scaling, if it meets the spec, is; if neither does, the spec cannot be met.
        uncalibrated = bool(best.result == RESULTS.infeasible)
        if uncalibrated and not is_successful(base.result):
            raise ValueError(
                f"[budget]: {message(best.result)} Neither the optimised tolerances nor the nominal ones, each scaled down to "
                f"1e-3 of themselves, meet the spec on {b.check_samples:,} fresh samples"
            )
        beaten = is_successful(base.result) and (base.cost < best.cost or uncalibrated)
        optimiser = best  # what the optimiser itself reports, whichever budget is kept
        if beaten:
            best = base
        contrib = contributions(p, best.tolerances, key=k_sens, n_samples=min(b.samples, 8192))
        grades = {n: _grade(b.grades[n], best.tolerances[n]) for n in b.grades}
        c0 = b.constraints[0]
        first = next(iter(base.tolerances))
        show = (lambda x: float(angle_from_rad(x, u))) if c0.metric.quantity == "angle" else float
        entry: dict[str, Any] = {
            "constraint": c0.constraint,
            f"spec_{u}": c0.spec,
            "target_yield" if c0.constraint == "yield" else "k": c0.target,
        }
        if len(b.constraints) > 1 or c0.metric.name != study.metric.name:
            entry["constraints"] = [
                {
                    "metric": c.metric.name,
                    "spec": c.spec,
                    "spec_unit": u if c.metric.quantity == "angle" else "pairs",
                    "constraint": c.constraint,
                    "target": c.target,
                }
                for c in b.constraints
            ]
            entry["verified_yields"] = list(best.verified_yields)
            # Each constraint's own statistic on the fresh sample, in its spec's unit (a mean ± kσ has no yield).
            entry["verified_statistics"] = [
                float(angle_from_rad(v, u)) if c.metric.quantity == "angle" else float(v)
                for c, v in zip(b.constraints, best.verified_statistics, strict=True)
            ]
        entry["optimised_direction_beaten_by_uniform_scaling"] = beaten
        entry["optimised_direction_misses_the_spec"] = uncalibrated
        entry |= {
            "tolerances_um": best.tolerances,
            "nominal_tolerances_um": dict(b.nominal),
            "maximum_tolerances_um": b.maximum,
            "grades": grades,
            "cost": best.cost,
            "baseline_cost": base.cost,
            "baseline_tolerances_um": base.tolerances,
            "baseline_scale": base.tolerances[first] / b.nominal[first],
            "verified_yield": best.verified_yield,
            "verified_samples": best.verified_samples,
            "verified_samples_with_failed_solves": best.failed_solves,
            "baseline_verified_yield": base.verified_yield,
            f"verified_statistic_{u}": show(best.verified_statistic),
            "baseline_meets_spec": is_successful(base.result),
            "solver_converged": optimiser.converged,
            "solver_result": "successful" if is_successful(optimiser.result) else message(optimiser.result),
            "cost_models": {n: c.describe() for n, c in b.costs.items()},
            f"contributions_{u}": {n: show(v) for n, v in contrib.items()},
            "optimisation_samples": b.samples,
            "assembly": {n: s.phase.describe() for n, s in study.errors.sources.items() if s.phase is not None},
        }
        figures = [
            Figure(
                "contributions.png",
                "contributions",
                {
                    "values": entry[f"contributions_{u}"],
                    "unit": u,
                    "title": "Share of the constrained statistic by source (∂stat/∂T_i · T_i)",
                },
            )
        ]
        if _compares_random_assembly(study, b):
            rand_model = ErrorModel(
                {n: ErrorSource(s.magnitude, UniformPhase() if s.phase is not None else None) for n, s in study.errors.sources.items()},
                study.errors.specs,
            )
            pr = problem(rand_model)
            rb = optimise_budget(pr, key=k_rand, n_samples=b.samples, n_check=b.check_samples, throw=False, progress=progress)
            rbase = uniform_scaling(pr, key=k_rand, n_check=b.check_samples, progress=progress)
            entry["random_assembly"] = {
                "tolerances_um": rb.tolerances,
                "cost": rb.cost,
                "baseline_cost": rbase.cost,
                "verified_yield": rb.verified_yield,
                "baseline_verified_yield": rbase.verified_yield,
                "meets_spec": is_successful(rb.result),
                "baseline_meets_spec": is_successful(rbase.result),
            }
        if b.pareto_specs:
            n_front = max(1000, b.check_samples // 2)
            to_int = [c0.to_internal(u, x).spec for x in b.pareto_specs]
            front = pareto_front(
                p, [float(x) for x in to_int], key=k_front, n_samples=max(256, b.samples // 2), n_check=n_front, progress=progress
            )
            rows = []
            for s, r in zip(b.pareto_specs, front):
                q = problem(study.errors, s)
                rq = uniform_scaling(q, key=k_front, n_check=n_front, progress=progress)
                rows.append(
                    {
                        f"spec_{u}": s,
                        "cost": r.cost,
                        "baseline_cost": rq.cost,
                        "verified_yield": r.verified_yield,
                        "meets_spec": is_successful(r.result),
                        "baseline_meets_spec": is_successful(rq.result),
                        "tolerances_um": r.tolerances,
                    }
                )
            entry["pareto"] = rows
            figures.append(Figure("pareto.png", "pareto", {"rows": rows, "unit": u}))
        return KindOutcome(
            study=_scaled_study(study, b, best.tolerances), key="budget", summary=entry, figures=figures, report=lambda s: _report(study, s)
        )


def _scaled_study(study: Study, b: BudgetSpec, tolerances: dict[str, float]) -> Study:
    """The study with every budgeted law scaled from its nominal tolerance to `tolerances`, about its centre."""
    sources = dict(study.errors.sources)
    for n, t in tolerances.items():
        src = sources[n]
        about_centre = study.errors.specs[n].kind == "deviation"
        sources[n] = ErrorSource(src.magnitude.scaled(t / b.nominal[n], about_centre=about_centre), src.phase)
    tol = dict(study.tolerances) | dict(tolerances)
    kinds = {k: v for k, v in study.kinds.items() if k != "budget"}
    return dataclasses.replace(study, errors=ErrorModel(sources, study.errors.specs), tolerances=tol, kinds=kinds)


def _grade(spec: dict, tol_um: float):
    try:
        return nearest_grade(
            spec["factor"] * tol_um,
            quantity=spec["quantity"],
            standard=spec["standard"],
            module=spec["module"],
            diameter=spec["diameter"],
            face_width=spec["face_width"],
        )
    except ValueError as e:
        return f"none ({e})"


def _constraints(b: dict) -> list[dict]:
    """The budget's constraints as summary.json lists them (one built from the first's keys where there is one)."""
    return b.get("constraints") or [{"metric": "the metric", "constraint": b["constraint"], "target": b.get("target_yield")}]


def _yield_target(b: dict) -> float:
    """The yield whose binomial standard error the report states: the highest yield target among the constraints (the
    verified yield where there is none), so that a verified yield of 1 does not read as exact."""
    targets = [float(c["target"]) for c in _constraints(b) if c["constraint"] == "yield"]
    return max(targets) if targets else float(b["verified_yield"])


def _below_target(b: dict) -> list[str]:
    """A warning for every yield constraint whose verified yield on the fresh sample is below its target."""
    yields = b.get("verified_yields") or [b["verified_yield"]]
    n = b["verified_samples"]
    out = []
    for c, y in zip(_constraints(b), yields, strict=False):
        if c["constraint"] != "yield" or y >= c["target"]:
            continue
        se = binomial_se(c["target"], n)
        out.append(
            f"**Below its target on the fresh sample:** the yield of {c['metric']} is {y:.4f} against {c['target']:g}, "
            f"{(c['target'] - y) / se:.1f} binomial standard errors ({se:.4f} at the target for {n:,} samples) below it. "
            "A sample this size cannot verify the target more closely: raise `check_samples` for a firmer check."
        )
        out.append("")  # each warning a paragraph of its own
    return out


def _constraint_rows(study: Study, b: dict) -> list[str]:
    """Each constraint as verified on the fresh sample, where there are several: a yield by its yield, a mean ± kσ by
    its value against the spec (a mean ± kσ has no yield)."""
    if "verified_statistics" not in b:
        return []
    rows = [
        f"| constraint | spec | verified on {b['verified_samples']:,} fresh samples | met |",
        "|---|---|---|---|",
    ]
    for c, y, v in zip(b["constraints"], b["verified_yields"], b["verified_statistics"], strict=True):
        higher = study.drive.metrics[c["metric"]].higher_is_better
        unit = UNIT_SYMBOLS.get(c["spec_unit"], f" {c['spec_unit']}")
        if c["constraint"] == "yield":
            what, got, met = f"yield of {c['metric']} ≥ {c['target']:g}", f"yield {y:.5f}", y >= c["target"]
        else:
            sign = "−" if higher else "+"
            what = f"mean {sign} {c['target']:g}σ of {c['metric']}"
            got, met = f"{v:.4g}{unit}", (v >= c["spec"]) if higher else (v <= c["spec"])
        rows.append(f"| {what} | {'≥' if higher else '≤'} {c['spec']:g}{unit} | {got} | {'yes' if met else '**no**'} |")
    return [*rows, ""]


def _compares_random_assembly(study: Study, b: BudgetSpec) -> bool:
    """Whether the budget is also computed with every phase random: asked for, and some phase follows a rule."""
    return b.compare_random_assembly and any(isinstance(s.phase, (RelativePhase, FixedPhase)) for s in study.errors.sources.values())


def _meets(optimised: bool, uniform: bool) -> str:
    """A Pareto row's "meets the spec" cell: both budgets, or which misses."""
    if optimised and uniform:
        return "yes"
    return "no (no answer)" if not optimised and not uniform else ("uniform scaling misses" if optimised else "optimised misses")


def _report(study: Study, s: dict) -> list[str]:
    b = s["budget"]
    u = study.unit
    sym = UNIT_SYMBOLS[u]
    metric = study.metric.label
    cons = (
        f"yield P({metric} ≤ {b[f'spec_{u}']:g}{sym}) ≥ {b['target_yield']}"
        if b["constraint"] == "yield"
        else f"mean + {b['k']}σ ≤ {b[f'spec_{u}']:g}{sym}"
    )
    if "constraints" in b:
        cons = "; ".join(
            f"{c['constraint'].replace('_', ' ')} of {c['metric']} against {c['spec']:g} {c['spec_unit']} (target {c['target']:g})"
            for c in b["constraints"]
        )
    lines = [
        "## Tolerance budget",
        "",
        f"Cheapest tolerances with {cons}. Each budgeted value is its law's centre + tolerance × a standard draw "
        f"(common random numbers, {b['optimisation_samples']:,} samples, smoothed quantile); the budget is then scaled on a fresh "
        f"sample until every yield clears its target by four binomial standard errors (at most 1 − 1/n) and every mean ± kσ "
        f"meets its spec, and verified on another fresh sample of {b['verified_samples']:,}. Every source's tolerance is "
        "capped at its maximum (`maximum_factor` × nominal). The uniform scaling (the baseline) is the nominal tolerances "
        "times one common factor, calibrated the same way; a source's share of the statistic is ∂statistic/∂T · T of the "
        "first constraint at the budget (for a TE linear in the errors the shares add up to the statistic). "
        f"The optimiser {'converged' if b['solver_converged'] else 'did not converge'} ({b['solver_result']}).",
        "",
        f"| source | nominal | optimised | uniform scaling | ISO grade | cost model | share of the statistic ({sym}) |",
        "|---|---|---|---|---|---|---|",
    ]
    specs = study.errors.specs

    def angular(n: str) -> bool:
        return n in specs and specs[n].unit == "rad"

    def tol(n: str, value: float, fmt: str = ".2f") -> str:
        """A tolerance as the report shows it: µm, or ″ for an angular source (held in rad)."""
        return f"{value * ARCSEC_PER_RAD:.3g}″" if angular(n) else format(value, fmt)

    capped = [n for n, t in b["tolerances_um"].items() if t >= b["maximum_tolerances_um"][n] * (1 - 1e-12)]
    for n, t in b["tolerances_um"].items():
        cost_model = b["cost_models"][n].replace("T in µm", "T in rad") if angular(n) else b["cost_models"][n]
        lines.append(
            f"| {n} | {tol(n, b['nominal_tolerances_um'][n], 'g')} | {tol(n, t)}{' (maximum)' if n in capped else ''} | "
            f"{tol(n, b['baseline_tolerances_um'][n])} | "
            f"{b['grades'].get(n, '—')} | {cost_model} | {b[f'contributions_{u}'][n]:.2f} |"
        )
    if capped:
        lines += [
            "",
            f"**At their maximum:** {', '.join(capped)}: the constraints do not limit {'it' if len(capped) == 1 else 'them'} "
            "within `maximum_factor` × nominal (a TE that hardly depends on a source, or not at all under this model and "
            "assembly rule). Check that the model holds every effect of such a source before releasing that tolerance.",
        ]
    if b.get("optimised_direction_misses_the_spec"):
        lines += [
            "",
            "The optimiser's direction, scaled on the fresh samples, could not meet the spec (the smoothed statistics of "
            "the common samples were too optimistic); the uniform scaling of the nominal tolerances, which does, is "
            "reported as the budget.",
        ]
    elif b.get("optimised_direction_beaten_by_uniform_scaling"):
        lines += [
            "",
            "The optimiser's direction, once calibrated on the exact metrics, cost more than uniform scaling of the "
            "nominal tolerances; the uniform scaling is reported as the budget.",
        ]
    lines += [
        "",
        "Tolerances in µm, those of angular sources in ″ (summary.json holds them in rad).",
        "",
        f"Cost {b['cost']:.4f} against {b['baseline_cost']:.4f} for the cheapest uniform scaling of the nominal tolerances "
        f"(× {b['baseline_scale']:.3f}"
        + ("" if b.get("baseline_meets_spec", True) else ", which misses the spec on the fresh samples: no answer")
        + f"); verified yield {b['verified_yield']:.5f} (baseline {b['baseline_verified_yield']:.5f}; "
        f"± {binomial_se(_yield_target(b), b['verified_samples']):.5f}, one binomial standard error at a yield of "
        f"{_yield_target(b):g} on {b['verified_samples']:,} fresh samples).",
        "",
    ]
    lines += _constraint_rows(study, b)
    lines += _below_target(b)
    if b.get("verified_samples_with_failed_solves"):
        lines += [
            f"**{b['verified_samples_with_failed_solves']:,} of the {b['verified_samples']:,} verification samples have a failed "
            "solve**: a yield counts them as missing its spec, a mean ± kσ is taken over the samples that solved.",
            "",
        ]
    if "random_assembly" in b:
        r = b["random_assembly"]
        misses = [what for what, key in (("optimised", "meets_spec"), ("uniform-scaling", "baseline_meets_spec")) if not r.get(key, True)]
        lines += [
            f"Without the assembly rule (every phase random) the same spec costs {r['cost']:.4f} optimised, {r['baseline_cost']:.4f} "
            f"by uniform scaling: the rule changes which tolerances matter."
            + (f" **The {' and the '.join(misses)} budget misses the spec on the fresh samples** (no answer)." if misses else ""),
            "",
            "| source | with the rule | random assembly |",
            "|---|---|---|",
        ]
        lines += [f"| {n} | {tol(n, b['tolerances_um'][n])} | {tol(n, r['tolerances_um'][n])} |" for n in b["tolerances_um"]]
        lines.append("")
    lines += ["![contributions](contributions.png)", ""]
    if "pareto" in b:
        lines += [
            "Cost against the first constraint's spec: each point optimised and verified afresh on half the samples of the "
            "budget above (its own Monte Carlo noise: a point at the budget's spec differs from it by that much).",
            "",
            f"| spec ({sym}) | optimised cost | uniform-scaling cost | verified yield | meets the spec |",
            "|---|---|---|---|---|",
        ]
        lines += [
            f"| {r[f'spec_{u}']:g} | {r['cost']:.4f} | {r['baseline_cost']:.4f} | {r['verified_yield']:.5f} | "
            f"{_meets(r.get('meets_spec', True), r.get('baseline_meets_spec', True))} |"
            for r in b["pareto"]
        ]
        lines += ["", "![cost vs spec](pareto.png)", ""]
    lines += ["The statistics above are a further Monte Carlo at the optimised tolerances (the study's own samples and seed).", ""]
    return lines
