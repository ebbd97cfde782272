"""``[doe]``: a designed experiment over error-source magnitudes and its quadratic response surface, on any drive.

Each run of the design fixes the chosen sources' magnitudes (an eccentricity's magnitude, or a deviation's
value, the same for every instance) and takes a statistic (mean, standard deviation or a percentile) of the
study's metric over a small Monte Carlo of everything else, drawn as in ``[errors]``. Every run uses the same
samples (the study's seed: common random numbers), so the differences between runs are the variables' effects,
not sampling noise. The quadratic surface is fitted to the runs (`gearte.fit_response_surface`), its optimum
found inside the variables' ranges, and the model run once more there to confirm it.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from typing import TYPE_CHECKING, Any

import jax
import numpy as np

from ..core.metrics import AbstractMetric
from ..core.schema import MAX_SAMPLES, ConfigError, Table
from ..core.units import ARCSEC_PER_RAD, UNIT_SYMBOLS, angle_from_rad, number_text
from ..core.validate import as_key
from ..drives.protocol import Figure
from ..studies.doe import (
    AbstractDesign,
    BoxBehnken,
    CentralComposite,
    Circumscribed,
    FaceCentred,
    FullFactorial,
    Inscribed,
    LatinHypercube,
    SobolSequence,
    Variable,
    run_design,
)
from ..studies.errors import ErrorSource
from ..studies.laws import Fixed
from ..studies.montecarlo import TEStudy, default_block_size, monte_carlo
from ..studies.response_surface import ResponseSurface, fit_response_surface
from .kind_base import AbstractStudyKind, KindOutcome

if TYPE_CHECKING:
    from .config import Study

DESIGNS = ("ccd", "box_behnken", "full_factorial", "latin_hypercube", "sobol")
#: Most centre points a design may repeat (replicates of the centre estimate pure error; more add nothing but runs).
MAX_CENTER_POINTS = 1000
CCD_KINDS = {"circumscribed": Circumscribed, "inscribed": Inscribed, "face_centred": FaceCentred}
#: The keys of ``[doe.design]`` and the design types each belongs to.
DESIGN_KEYS = {
    "kind": ("ccd",),
    "alpha": ("ccd",),
    "center_points": ("ccd", "box_behnken"),
    "levels": ("full_factorial",),
    "runs": ("latin_hypercube", "sobol"),
    "seed": ("latin_hypercube", "sobol"),
    "scramble": ("sobol",),
    "centred": ("latin_hypercube",),
}
#: Natural-unit suffix of a variable's keys, by the source's unit, and its factor to the model's unit (µm or rad).
VARIABLE_UNITS = {"µm": ("um", 1.0), "rad": ("arcsec", 1.0 / ARCSEC_PER_RAD)}
VARIABLE_KEYS = ("low", "high", "mean", "std")
DEFAULT_SAMPLES = 2000


@dataclasses.dataclass(frozen=True)
class DoeVariable:
    """One design variable: the error source it sets, its `Variable` (µm or ″) and the factor to the model's unit."""

    source: str
    variable: Variable
    to_model: float


@dataclasses.dataclass(frozen=True)
class DoeSpec:
    """`[doe]`: the design, the variables, and the response: `statistic` of `metric` over `samples` samples."""

    design: AbstractDesign
    variables: tuple[DoeVariable, ...]
    metric: AbstractMetric
    statistic: str
    samples: int
    goal: str


def _statistic(t: Table) -> str:
    s = t.string("response", "mean")
    if s in ("mean", "std"):
        return s
    m = re.fullmatch(r"p(\d+(?:\.\d+)?)", s)
    if not m or not 0 < float(m.group(1)) < 100:
        raise ConfigError(f'{t.where} response: "mean", "std" or a percentile "pQ" with 0 < Q < 100 (e.g. "p99.73"), got {s!r}')
    return s


def _design(t: Table, n_vars: int, seed: int) -> AbstractDesign:
    """The `design` key: a name (that design with its defaults), or a table ``[doe.design]`` with `type` and that
    type's keys."""
    raw = t.get("design", "ccd")
    if isinstance(raw, dict):
        dt = t.table("design")
        kind = dt.string("type", choices=DESIGNS)
    elif isinstance(raw, str):
        kind = t.string("design", "ccd", choices=DESIGNS)  # the documented default where the key is absent
        dt = Table({}, "[doe.design]")
    else:
        raise ConfigError(f"{t.where} design: a design name ({', '.join(repr(d) for d in DESIGNS)}) or a table [doe.design], got {raw!r}")
    design = _design_of(dt, kind, n_vars, seed)
    dt.finish()
    return design


def _design_of(dt: Table, kind: str, n_vars: int, seed: int) -> AbstractDesign:
    for key, types in DESIGN_KEYS.items():
        if dt.has(key) and kind not in types:
            dt.used.add(key)
            raise ConfigError(f"{dt.where} {key}: applies to type = {' or '.join(repr(x) for x in types)}, not {kind!r}; remove it")
    p = (n_vars + 1) * (n_vars + 2) // 2
    if kind == "ccd":
        ccd_kind = CCD_KINDS[dt.string("kind", "circumscribed", choices=tuple(CCD_KINDS))]()
        a = dt.get("alpha", "rotatable")
        if a != "rotatable" and (isinstance(a, bool) or not isinstance(a, (int, float)) or not math.isfinite(a) or a <= 0):
            raise ConfigError(f'{dt.where} alpha: "rotatable" or a number > 0, got {a!r}')
        if isinstance(ccd_kind, FaceCentred) and a not in ("rotatable", 1, 1.0):
            raise ConfigError(f"{dt.where} alpha: a face-centred design has α = 1; remove alpha")
        alpha = None if a == "rotatable" or isinstance(ccd_kind, FaceCentred) else float(a)
        return CentralComposite(ccd_kind, alpha=alpha, center_points=dt.integer("center_points", 1, minimum=1, maximum=MAX_CENTER_POINTS))
    if kind == "box_behnken":
        if not 3 <= n_vars <= 7:
            raise ConfigError(f'{dt.where} type: a Box-Behnken design needs 3 to 7 variables, got {n_vars}; use "ccd"')
        return BoxBehnken(center_points=dt.integer("center_points", 3, minimum=1, maximum=MAX_CENTER_POINTS))
    if kind == "full_factorial":
        levels = dt.integer("levels", 3, minimum=3)
        if levels**n_vars > 100_000:
            raise ConfigError(f"{dt.where} levels: {levels}^{n_vars} runs is too many; use fewer levels or a CCD")
        return FullFactorial(levels)
    s = dt.integer("seed", seed, minimum=0)
    if s >= 2**63:
        raise ConfigError(f"{dt.where} seed: must be below 2⁶³, got {s}")
    if kind == "latin_hypercube":
        runs = dt.integer("runs", 2 * p, minimum=p)
        if runs > 100_000:
            raise ConfigError(f"{dt.where} runs: at most 100000, got {runs}")
        return LatinHypercube(runs, seed=s, centred=dt.boolean("centred", False))
    runs = dt.integer("runs", 1 << (2 * p - 1).bit_length(), minimum=2)
    if runs & (runs - 1) or runs < p or runs > 2**16:
        raise ConfigError(f"{dt.where} runs: a Sobol' design needs a power of two from {p} (the model's terms) to 65536, got {runs}")
    return SobolSequence(runs, scramble=dt.boolean("scramble", True), seed=s)


def _variable(vt: Table, study: Study, seen: set[str]) -> DoeVariable:
    specs = study.drive.error_sources
    source = vt.string("source")
    if source not in specs:
        hint = difflib.get_close_matches(source, list(specs), n=1)
        raise ConfigError(
            f"{vt.where} source: {source!r} is not an error source of {study.drive.type_name}"
            + (f" (did you mean {hint[0]!r}?)" if hint else "")
            + f"; use one of {list(specs)}"
        )
    if source in seen:
        raise ConfigError(f"{vt.where} source: {source!r} is already a variable; give each source once")
    seen.add(source)
    spec = specs[source]
    suffix, factor = VARIABLE_UNITS[spec.unit]
    for other, _ in VARIABLE_UNITS.values():
        for k in VARIABLE_KEYS:
            if other != suffix and vt.has(f"{k}_{other}"):
                vt.used.add(f"{k}_{other}")
                raise ConfigError(f"{vt.where} {k}_{other}: {source!r} is in {spec.unit}; give `{k}_{suffix}`")
    name = vt.string("name", source)
    unit = "µm" if suffix == "um" else "″"
    has_range = vt.has(f"low_{suffix}") or vt.has(f"high_{suffix}")
    has_normal = vt.has(f"mean_{suffix}") or vt.has(f"std_{suffix}")
    if has_range == has_normal:
        raise ConfigError(
            f"{vt.where}: give a range (`low_{suffix}`, `high_{suffix}`) or a normal model (`mean_{suffix}`, `std_{suffix}`: "
            "levels at its 1 %, 50 % and 99 % quantiles), one of the two"
        )
    try:
        if has_range:
            low, high = vt.number(f"low_{suffix}"), vt.number(f"high_{suffix}")
            if not high > low:
                raise ConfigError(f"{vt.where} high_{suffix}: must be above low_{suffix} ({low:g}), got {high:g}")
            var = Variable(name, low, high, unit=unit)
        else:
            var = Variable.normal(name, vt.number(f"mean_{suffix}"), vt.number(f"std_{suffix}", positive=True), unit=unit)
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"{vt.where}: {e}") from None
    return DoeVariable(source, var, factor)


class Doe(AbstractStudyKind):
    """A designed experiment over error-source magnitudes and its quadratic response surface, on any drive."""

    table = "doe"

    def read(self, t: Table, study: Study) -> DoeSpec:
        raw = t.get("variables")
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"{t.where} variables: a list of [[doe.variables]] tables (source, and a range or a normal model)")
        seen: set[str] = set()
        variables = []
        for i, item in enumerate(raw):
            vt = Table(item, f"[[doe.variables]] #{i + 1}")
            variables.append(_variable(vt, study, seen))
            vt.finish()
        names = [v.variable.name for v in variables]
        if len(set(names)) < len(names):
            raise ConfigError(f"[[doe.variables]] name: the names must differ, got {names}")
        design = _design(t, len(variables), study.seed)
        offered = study.drive.metrics
        metric = offered[t.string("metric", study.metric.name, choices=tuple(offered))]
        goal = t.string("goal", "maximise" if metric.higher_is_better else "minimise", choices=("minimise", "maximise"))
        statistic = _statistic(t)
        samples = t.integer("samples", DEFAULT_SAMPLES, minimum=1)
        if samples > MAX_SAMPLES:
            raise ConfigError(f"{t.where} samples: at most 2³² − 1, got {samples}")
        if statistic == "std" and samples < 2:
            raise ConfigError(f'{t.where} samples: response = "std" needs at least 2 samples, got {samples}')
        # An eccentricity's magnitude cannot be negative at any run (a CCD's axial points lie beyond the range).
        coded = design.points(len(variables))
        for j, v in enumerate(variables):
            lowest = float(v.variable.natural(coded[:, j].min()))
            if study.drive.error_sources[v.source].kind == "eccentricity" and lowest < 0:
                raise ConfigError(
                    f"[[doe.variables]] #{j + 1}: the design's lowest level of {v.source!r} is {lowest:.4g} µm (coded "
                    f"{coded[:, j].min():.4g}), a negative magnitude; raise its low end (or its mean), or use "
                    '`kind = "face_centred"` or "inscribed" so that no run lies outside the range'
                )
        return DoeSpec(design, tuple(variables), metric, statistic, samples, goal)

    def evaluations(self, study: Study, spec: DoeSpec) -> int:
        # every run of the design, and the optimum twice (the design's random numbers and fresh ones)
        return (spec.design.runs(len(spec.variables)) + 2) * spec.samples

    def run(self, study: Study, spec: DoeSpec, *, progress: bool | None) -> KindOutcome:
        unit = study.unit if spec.metric.quantity == "angle" else "pairs"

        def response(x, key):
            sources = {}
            for v, xi in zip(spec.variables, x):
                src = study.errors.sources[v.source]
                sources[v.source] = ErrorSource(Fixed(float(xi) * v.to_model), src.phase)
            fn = TEStudy(study.drive, study.errors.replace(**sources), metric=spec.metric)
            # Blocks no larger than a run: a small Monte Carlo per run computes no samples it drops.
            block = min(default_block_size(fn.bytes_per_sample()), spec.samples)
            values = monte_carlo(
                fn, key=study.seed if key is None else key, n_samples=spec.samples, block_size=block, progress=False
            ).values
            values = np.asarray(angle_from_rad(values, study.unit) if spec.metric.quantity == "angle" else values)
            return statistic(values, spec.statistic)

        variables = [v.variable for v in spec.variables]
        run = run_design(response, spec.design, variables, vectorise=False, progress=progress, desc=f"{study.name} doe")
        surface = fit_response_surface(run.natural, run.responses, variables=run.variables)
        opt = surface.optimum(spec.goal)  # pyright: ignore[reportArgumentType]
        # The model at the optimum with the design's random numbers (what the surface was fitted to: its residual there)
        # and with fresh ones (a batch the design never saw: the Monte Carlo's own noise on the response as well).
        confirmed = float(response(opt.natural, None))
        fresh = float(response(opt.natural, jax.random.fold_in(as_key(study.seed), 1)))
        entry = doe_summary(study, spec, run.coded, surface, opt, confirmed, unit=unit, seconds=run.seconds)
        entry["optimum"]["confirmed_fresh_samples"] = fresh
        return KindOutcome(
            study=study, key="doe", summary=entry, figures=doe_figures(surface, opt, unit=unit), report=lambda s: doe_report(s["doe"])
        )


def statistic(values: np.ndarray, name: str) -> float:
    """`name` ("mean", "std" (n − 1) or "pQ", a percentile by linear interpolation) of the values."""
    if name == "mean":
        return float(np.mean(values))
    if name == "std":
        return float(np.std(values, ddof=1))
    return float(np.percentile(values, float(name[1:])))


def _num(x: float) -> float | None:
    """A number for JSON (None for NaN: a statistic that is not defined)."""
    return None if not math.isfinite(x) else float(x)


def doe_summary(study: Study, spec: DoeSpec, coded, s: ResponseSurface, opt, confirmed: float, *, unit: str, seconds: float) -> dict:
    """The `doe` entry of summary.json."""
    names = [v.variable.name for v in spec.variables]
    ca = s.canonical()
    natural = [v.variable.natural(coded[:, j]) for j, v in enumerate(spec.variables)]
    return {
        "design": {"description": spec.design.describe(), "runs": int(coded.shape[0]), "coded": coded.tolist()},
        "variables": [
            {
                "name": v.variable.name,
                "source": v.source,
                "kind": study.drive.error_sources[v.source].kind,
                "unit": v.variable.unit,
                "low": v.variable.low,
                "high": v.variable.high,
                "basis": v.variable.basis,
            }
            for v in spec.variables
        ],
        "response": {
            "metric": spec.metric.name,
            "statistic": spec.statistic,
            "samples": spec.samples,
            "seed": study.seed,
            "unit": unit,
            "goal": spec.goal,
            "common_random_numbers": True,
        },
        "runs": [
            {
                "x": {n: float(natural[j][i]) for j, n in enumerate(names)},
                "response": float(s.y[i]),
                "fitted": float(s.fitted[i]),
                "residual": float(s.residuals[i]),
                "leverage": float(s.leverage[i]),
            }
            for i in range(s.n_runs)
        ],
        "coefficients_coded": s.named(),
        "r2": _num(s.r2),
        "adj_r2": _num(s.adj_r2),
        "press": _num(s.press),
        "pred_r2": _num(s.pred_r2),
        "canonical": {
            "eigenvalues": ca.eigenvalues.tolist(),
            "nature": ca.nature,
            "stationary_point": None if ca.nature in ("ridge", "plane") else {n: float(x) for n, x in zip(names, ca.stationary_natural)},
            "stationary_value": _num(ca.stationary_value),
        },
        "optimum": {
            "goal": spec.goal,
            "x": {n: float(x) for n, x in zip(names, opt.natural)},
            "coded": opt.coded.tolist(),
            "predicted": float(opt.value),
            "confirmed": confirmed,
            "at_bounds": [list(b) for b in opt.at_bounds],
            "interior": opt.interior,
        },
        "seconds": seconds,
    }


def doe_figures(s: ResponseSurface, opt, *, unit: str) -> list[Figure]:
    """The residual plots and the surface over the first two variables (the others at the optimum)."""
    figs = [
        Figure(
            "doe_residuals.png",
            "gearte.cli.doe_plots:residuals",
            {"actual": s.y, "fitted": s.fitted, "residuals": s.residuals, "unit": unit},
            "residuals of the response surface",
        )
    ]
    vs = s.variables
    if len(vs) >= 2:
        # Over the ranges, or the runs where they lie beyond (a circumscribed CCD's axial points).
        e0, e1 = (max(1.0, float(np.abs(s.coded[:, j]).max())) for j in (0, 1))
        g0, g1 = np.linspace(-e0, e0, 61), np.linspace(-e1, e1, 61)
        c = np.tile(opt.coded, (61, 61, 1))
        c[..., 0], c[..., 1] = np.meshgrid(g0, g1, indexing="xy")
        x0, x1 = vs[0].natural(g0), vs[1].natural(g1)
        figs.append(
            Figure(
                "doe_surface.png",
                "gearte.cli.doe_plots:surface",
                {
                    "x": x0,
                    "y": x1,
                    "z": s.predict_coded(c),
                    "points": np.stack([vs[0].natural(s.coded[:, 0]), vs[1].natural(s.coded[:, 1])], axis=1),
                    "optimum": opt.natural[:2],
                    "labels": (f"{vs[0].name} ({vs[0].unit})", f"{vs[1].name} ({vs[1].unit})"),
                    "unit": unit,
                    "others": ", ".join(f"{v.name} = {x:.4g} {v.unit}" for v, x in zip(vs[2:], opt.natural[2:])),
                },
                "the response surface",
            )
        )
    return figs


def _fmt(x: Any, spec: str = ".4g") -> str:
    return number_text(x, spec)


def doe_report(d: dict) -> list[str]:
    """The report's section."""
    r = d["response"]
    sym = UNIT_SYMBOLS.get(r["unit"], f" {r['unit']}")
    stat = {"mean": "mean", "std": "standard deviation"}.get(r["statistic"], f"{r['statistic'][1:]} % percentile")
    names = [v["name"] for v in d["variables"]]
    lines = [
        "",
        "## Designed experiment and response surface",
        "",
        f"Response: the {stat} of `{r['metric']}` over {r['samples']:,} Monte Carlo samples per run (seed {r['seed']}, the same "
        "samples at every run: common random numbers), in " + (r["unit"] if r["unit"] != "pairs" else "loaded pairs") + ".",
        f"Design: {d['design']['description']}, {d['design']['runs']} runs.",
        "",
        "| variable | error source | kind | low (coded −1) | high (coded +1) | basis |",
        "|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {v['name']} | {v['source']} | {v['kind']} | {v['low']:.4g} {v['unit']} | {v['high']:.4g} {v['unit']} | {v['basis']} |"
        for v in d["variables"]
    ]
    lines += [
        "",
        "A variable fixes the source's magnitude (an eccentricity) or value (a deviation), the same for each instance; "
        "every other law, and the source's phase, is drawn as in [errors].",
        "",
        "| run | " + " | ".join(names) + f" | response ({sym.strip()}) | fitted | residual | leverage |",
        "|---" * (len(names) + 5) + "|",
    ]
    for i, run in enumerate(d["runs"]):
        xs = " | ".join(f"{run['x'][n]:.4g}" for n in names)
        lines.append(f"| {i + 1} | {xs} | {run['response']:.4f} | {run['fitted']:.4f} | {run['residual']:.3g} | {run['leverage']:.3f} |")
    lines += [
        "",
        "Quadratic surface with cross terms, least squares (QR), coefficients in coded units:",
        "",
        "| term | coefficient |",
        "|---|---|",
    ]
    lines += [f"| {t} | {c:.6g} |" for t, c in d["coefficients_coded"].items()]
    lines += [
        "",
        f"R² = {_fmt(d['r2'], '.5f')}, adjusted R² = {_fmt(d['adj_r2'], '.5f')}, PRESS = {_fmt(d['press'])}, "
        f"predicted R² = {_fmt(d['pred_r2'], '.5f')}"
        + (" (PRESS undefined: a run has leverage 1, e.g. a single centre point; add centre points)" if d["press"] is None else "")
        + ".",
        "",
    ]
    ca, o = d["canonical"], d["optimum"]
    eig = ", ".join(f"{x:.4g}" for x in ca["eigenvalues"])
    var = {v["name"]: v for v in d["variables"]}
    stationary = ""
    if ca["stationary_point"]:
        stationary = (
            "; stationary point "
            + ", ".join(f"{n} = {x:.4g} {var[n]['unit']}" for n, x in ca["stationary_point"].items())
            + f" ({_fmt(ca['stationary_value'])}{sym})"
        )
        coded = max(abs(2 * (x - var[n]["low"]) / (var[n]["high"] - var[n]["low"]) - 1) for n, x in ca["stationary_point"].items())
        reach = max(1.0, float(np.max(np.abs(np.asarray(d["design"]["coded"])))))  # a circumscribed design's axial runs
        if coded > reach * (1 + 1e-9):
            stationary += (
                f", outside the runs (|coded| up to {coded:.3g}, the design's runs reaching {reach:.3g}): the fitted "
                "surface extrapolated, not a design point"
            )
    lines += [f"Canonical analysis: eigenvalues of the quadratic part {eig} (coded units): a {ca['nature']}{stationary}.", ""]
    where = (
        "inside the ranges (the stationary point)"
        if o["interior"]
        else "on the ranges' boundary (" + ", ".join(f"{n} at its {b}" for n, b in o["at_bounds"]) + ")"
    )
    lines += [
        f"Optimum ({o['goal']}) within the variables' ranges, {where}: "
        + ", ".join(f"{n} = {x:.4g} {var[n]['unit']}" for n, x in o["x"].items())
        + f"; predicted {o['predicted']:.4f}{sym}; the model run there gives {o['confirmed']:.4f}{sym} with the design's "
        f"random numbers (the surface's own error there) and {o['confirmed_fresh_samples']:.4f}{sym} on {r['samples']:,} fresh "
        "samples (with the Monte Carlo's noise on the response).",
        "",
        "![residuals](doe_residuals.png)",
        "",
    ]
    if len(names) >= 2:
        lines += ["![response surface](doe_surface.png)", ""]
    return lines
