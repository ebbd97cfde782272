"""Study configuration files (TOML): read, validate, build the drive and the error model.

Everything is checked here, in Python, before anything is compiled: unknown keys,
missing fields, wrong types, negative tolerances, NaN, impossible tooth counts.
Each message names the table and key and says what to write instead.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
from pathlib import Path
from typing import Any, Callable

from ._distributions import (
    AbstractMagnitude,
    AbstractPhase,
    Fixed,
    FixedPhase,
    Normal,
    Optimised,
    Rayleigh,
    RelativePhase,
    TruncatedNormal,
    Uniform,
    UniformPhase,
)
from ._errors import ErrorModel, ErrorSource
from ._montecarlo import DEFAULT_SAMPLES
from .drives import ExplicitDrive, ExplicitTerm, Planetary2KH
from .drives._base import AbstractDrive


class ConfigError(ValueError):
    """A configuration file is invalid; the message names the field and the fix."""


_MISSING = object()


class _Table:
    """A TOML table being read: tracks which keys were used, so leftovers are reported."""

    def __init__(self, data: Any, where: str):
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a table (key = value pairs), got {type(data).__name__}")
        self.data, self.where, self.used = data, where, set()

    def _fail(self, key: str, msg: str):
        raise ConfigError(f"{self.where} {key}: {msg}")

    def has(self, key: str) -> bool:
        return key in self.data

    def get(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise ConfigError(f"{self.where}: missing required key `{key}`")
            return default
        return self.data[key]

    def string(self, key: str, default: Any = _MISSING, *, choices: tuple[str, ...] | None = None) -> str:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if not isinstance(v, str):
            self._fail(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            hint = difflib.get_close_matches(v, choices, n=1)
            self._fail(key, f"must be one of {', '.join(repr(c) for c in choices)}, got {v!r}" + (f" (did you mean {hint[0]!r}?)" if hint else ""))
        return v

    def integer(self, key: str, default: Any = _MISSING, *, minimum: int | None = None) -> int:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            self._fail(key, f"expected a whole number, got {v!r}")
        if minimum is not None and v < minimum:
            self._fail(key, f"must be ≥ {minimum}, got {v}")
        return v

    def number(self, key: str, default: Any = _MISSING, *, minimum: float | None = None, positive: bool = False) -> float:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self._fail(key, f"expected a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            self._fail(key, f"must be a finite number, got {v}")
        if positive and not v > 0:
            self._fail(key, f"must be > 0, got {v:g}")
        if minimum is not None and v < minimum:
            self._fail(key, f"must be ≥ {minimum:g}, got {v:g}" + (" (tolerances and magnitudes cannot be negative)" if minimum == 0 else ""))
        return v

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        v = self.get(key, default)
        if not isinstance(v, bool):
            self._fail(key, f"expected true or false, got {v!r}")
        return v

    def angle(self, stem: str, default: Any = _MISSING) -> float:
        """An angle given as `stem_deg` (number) or `stem_rad` (number, or a string like "7pi/9"); returns rad."""
        has_deg, has_rad = self.has(stem + "_deg"), self.has(stem + "_rad")
        if has_deg and has_rad:
            raise ConfigError(f"{self.where}: give `{stem}_deg` or `{stem}_rad`, not both")
        if has_deg:
            return math.radians(self.number(stem + "_deg"))
        if has_rad:
            v = self.get(stem + "_rad")
            if isinstance(v, str):
                return parse_angle(v, where=f"{self.where} {stem}_rad")
            return self.number(stem + "_rad")
        if default is _MISSING:
            raise ConfigError(f"{self.where}: missing `{stem}_deg` (degrees) or `{stem}_rad` (radians)")
        return default

    def table(self, key: str, default: Any = _MISSING) -> "_Table":
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        where = f"{self.where[:-1]}.{key}]" if self.where.startswith("[") and self.where.endswith("]") else f"[{key}]"
        return _Table(v, where)

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            k = unknown[0]
            hint = difflib.get_close_matches(k, sorted(self.used), n=1)
            raise ConfigError(
                f"{self.where}: unknown key `{k}`" + (f" (did you mean `{hint[0]}`?)" if hint else "")
                + f"; allowed here: {', '.join(sorted(self.used))}"
            )


_ANGLE_RE = re.compile(r"^\s*([+-]?)\s*(\d+(?:\.\d*)?|\.\d+)?\s*\*?\s*(pi|π)?\s*(?:/\s*(\d+(?:\.\d*)?))?\s*$")


def parse_angle(text: str, *, where: str = "angle") -> float:
    """Read an angle in rad written like "7pi/9", "-pi/9", "0.5", "2*pi/3"."""
    m = _ANGLE_RE.match(text)
    if not m or (m.group(2) is None and m.group(3) is None):
        raise ConfigError(f"{where}: cannot read {text!r} as an angle in rad; write a number or a form like '7pi/9'")
    sign = -1.0 if m.group(1) == "-" else 1.0
    coef = float(m.group(2)) if m.group(2) else 1.0
    value = sign * coef * (math.pi if m.group(3) else 1.0)
    if m.group(4):
        den = float(m.group(4))
        if den == 0:
            raise ConfigError(f"{where}: division by zero in {text!r}")
        value /= den
    return value


# ---------------------------------------------------------------- drives

def _planetary(t: _Table) -> Planetary2KH:
    angles = None
    if t.has("planet_angles_deg") or t.has("planet_angles_rad"):
        key = "planet_angles_deg" if t.has("planet_angles_deg") else "planet_angles_rad"
        raw = t.get(key)
        if not isinstance(raw, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in raw):
            raise ConfigError(f"{t.where} {key}: expected a list of numbers")
        angles = [math.radians(x) if key.endswith("deg") else float(x) for x in raw]
    centre = t.number("centre_distance_mm", None, positive=True) if t.has("centre_distance_mm") else None
    kwargs = dict(
        module=t.number("module_mm", positive=True),
        pressure_angle=t.angle("pressure_angle", math.radians(20.0)),
        n_planets=t.integer("n_planets", minimum=1),
        planet_angles=angles,
        centre_distance=centre,
        input=t.string("input", "sun", choices=("sun", "carrier", "ring")),
        output=t.string("output", "carrier", choices=("sun", "carrier", "ring")),
        fixed=t.string("fixed", "ring", choices=("sun", "carrier", "ring")),
        coupling=t.string("coupling", "single_path", choices=("single_path", "load_sharing")),
    )
    zs, zp, zr = (t.integer(k, minimum=1) for k in ("z_sun", "z_planet", "z_ring"))
    try:
        return Planetary2KH(zs, zp, zr, **kwargs)
    except ValueError as e:
        raise ConfigError(f"{t.where}: {e}") from None


def _explicit(t: _Table) -> ExplicitDrive:
    gain = t.number("gain_rad_per_um")
    name = t.string("name", "explicit components")
    raw = t.get("terms")
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{t.where} terms: give a list of [[drive.terms]] tables (source, frequency, phase_sign, offset_rad)")
    terms = []
    for i, item in enumerate(raw):
        tt = _Table(item, f"[[drive.terms]] #{i + 1}")
        freq = tt.get("frequency")
        if isinstance(freq, bool) or not isinstance(freq, (int, float, str)):
            raise ConfigError(f"{tt.where} frequency: expected a number or a fraction string like '7/24'")
        try:
            terms.append(ExplicitTerm(tt.string("source"), freq, phase_sign=tt.integer("phase_sign", 1),
                                      offset=tt.angle("offset", 0.0), scale=tt.number("scale", 1.0)))
        except ValueError as e:
            raise ConfigError(f"{tt.where}: {e}") from None
        tt.finish()
    try:
        return ExplicitDrive(terms, gain=gain, name=name)
    except ValueError as e:
        raise ConfigError(f"{t.where}: {e}") from None


#: Drive builders by `[drive] type`. Each reads its own keys from the table.
DRIVES: dict[str, Callable[[_Table], AbstractDrive]] = {"planetary_2kh": _planetary, "explicit": _explicit}


def _harmonic(t: _Table) -> AbstractDrive:
    from .drives._harmonic_config import build

    return build(t)


DRIVES["harmonic"] = _harmonic


# ---------------------------------------------------------------- error sources

MAGNITUDE_LAWS = ("fixed", "uniform", "normal", "truncated_normal", "rayleigh")
PHASE_RULES = ("uniform", "fixed", "relative", "optimise")


def _magnitude(t: _Table, tol: float | None) -> AbstractMagnitude:
    law = t.string("law", choices=MAGNITUDE_LAWS)

    def need_tol(what: str) -> float:
        if tol is None:
            raise ConfigError(f"{t.where}: {what} needs `tolerance_um` in the error source's table")
        return tol

    try:
        if law == "fixed":
            if t.has("fraction_of_tolerance"):
                return Fixed(t.number("fraction_of_tolerance", minimum=0) * need_tol("fraction_of_tolerance"))
            if tol is not None and not t.has("value_um"):
                return Fixed(tol)
            return Fixed(t.number("value_um", minimum=0))
        if law == "uniform":
            return Uniform(t.number("low_um", 0.0, minimum=0), t.number("high_um", tol if tol is not None else _MISSING, minimum=0))
        if law == "normal":
            return Normal(t.number("mean_um"), t.number("std_um", minimum=0))
        if law == "truncated_normal":
            return TruncatedNormal(t.number("mean_um"), t.number("std_um", positive=True), t.number("low_um", 0.0, minimum=0),
                                   t.number("high_um", tol if tol is not None else math.inf, minimum=0))
        # Rayleigh: scale from the tolerance (user's choice, stated in the report).
        if t.has("scale_um") and t.has("scale_fraction"):
            raise ConfigError(f"{t.where}: give `scale_um` or `scale_fraction` (× tolerance), not both")
        if t.has("scale_um"):
            scale = t.number("scale_um", positive=True)
        elif t.has("scale_fraction"):
            scale = t.number("scale_fraction", positive=True) * need_tol("scale_fraction")
        else:
            raise ConfigError(f"{t.where}: a Rayleigh law needs `scale_um`, or `scale_fraction` (scale = fraction × tolerance_um)")
        trunc = None
        if t.boolean("truncate_at_tolerance", False):
            trunc = need_tol("truncate_at_tolerance")
            if trunc <= 0:
                raise ConfigError(f"{t.where} truncate_at_tolerance: the tolerance is 0; there is nothing to draw below it")
        return Rayleigh(scale, trunc)
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"{t.where}: {e}") from None


def _phase(t: _Table, symbols: dict[str, str]) -> AbstractPhase:
    rule = t.string("rule", choices=PHASE_RULES)
    if rule == "uniform":
        return UniformPhase()
    if rule == "fixed":
        return FixedPhase(t.angle("value"))
    by_symbol = {sym: name for name, sym in symbols.items()}
    if rule == "optimise":
        # Chosen by the allocation optimiser: an offset from `relative_to`, or absolute.
        if not t.has("relative_to"):
            return Optimised(None)
        ref = t.string("relative_to")
        ref = by_symbol.get(ref, ref)
        if ref not in symbols:
            raise ConfigError(f"{t.where} relative_to: {ref!r} is not an error source; use one of {sorted(symbols)} or a symbol {sorted(by_symbol)}")
        return Optimised(ref)
    to = t.string("to")
    if to in by_symbol:
        to = by_symbol[to]
    if to not in symbols:
        raise ConfigError(f"{t.where} to: {to!r} is not an error source; use one of {sorted(symbols)} or a symbol {sorted(by_symbol)}")
    return RelativePhase(to, t.angle("offset", 0.0))


@dataclasses.dataclass(frozen=True)
class Study:
    """A validated study: what `gearte run` computes."""

    name: str
    title: str
    description: str
    metric: str
    samples: int
    seed: int
    unit: str
    chunk_size: int | None
    drive: AbstractDrive
    errors: ErrorModel
    tolerances_um: dict[str, float | None]
    notes: tuple[str, ...]
    source_path: str
    allocation: "AllocationSpec | None" = None
    budget: "BudgetSpec | None" = None


@dataclasses.dataclass(frozen=True)
class BudgetSpec:
    """`[budget]`: a tolerance-budget optimisation (see `gearte._budget`). Spec values in the study's unit."""

    spec: float
    constraint: str
    target: float
    samples: int
    check_samples: int
    costs: dict
    maximum_um: dict[str, float]
    grades: dict[str, dict]
    pareto_specs: tuple[float, ...]
    compare_random_assembly: bool


@dataclasses.dataclass(frozen=True)
class AllocationSpec:
    """`[allocation]`: how the phases marked `rule = "optimise"` are chosen (see `gearte._allocation`)."""

    objective: str
    datum: str
    adjust: dict[str, str]
    starts: int
    surrogate_samples: int
    check_samples: int
    seed_rule: dict[str, float] | None


def read_toml(path: Path) -> dict:
    """The parsed TOML of a study file, or a ConfigError naming the file."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({e.strerror})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None


def study_header(st: _Table, *, samples: int | None, seed: int | None) -> dict:
    """The keys every study file's [study] table has, with the command line's overrides.

    Reads name, title, description, samples, seed, chunk_size and notes; the caller reads its
    own further keys and then calls ``st.finish()``.
    """
    name = st.string("name")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise ConfigError(f"[study] name: use letters, digits, '_', '.', '-' only, got {name!r}")
    n = st.integer("samples", DEFAULT_SAMPLES, minimum=1)
    s = st.integer("seed", minimum=0)
    notes = st.get("notes", [])
    if not isinstance(notes, list) or not all(isinstance(x, str) for x in notes):
        raise ConfigError("[study] notes: expected a list of strings")
    if samples is not None:
        if samples < 1:
            raise ConfigError(f"--samples: must be ≥ 1, got {samples}")
        n = samples
    if seed is not None:
        if seed < 0:
            raise ConfigError(f"--seed: must be ≥ 0, got {seed}")
        s = seed
    return {"name": name, "title": st.string("title", name), "description": st.string("description", ""), "samples": n, "seed": s,
            "chunk_size": st.integer("chunk_size", None, minimum=1) if st.has("chunk_size") else None, "notes": notes}


def load_study(path: str | Path, *, samples: int | None = None, seed: int | None = None) -> Study:
    """Read and validate a study file; `samples` and `seed` override the file's values."""
    path = Path(path)
    raw = read_toml(path)
    try:
        return _build(raw, str(path), samples=samples, seed=seed)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def _build(raw: dict, source: str, *, samples: int | None, seed: int | None) -> Study:
    top = _Table(raw, "config")
    st = top.table("study")
    h = study_header(st, samples=samples, seed=seed)
    name, title, description, n, s, chunk, notes_raw = (h[k] for k in ("name", "title", "description", "samples", "seed", "chunk_size", "notes"))
    metric = st.string("metric", "peak", choices=("peak", "peak_to_peak", "rms"))
    unit = st.string("unit", "arcsec", choices=("arcsec", "arcmin", "urad"))
    st.finish()

    dt = top.table("drive")
    kind = dt.string("type", choices=tuple(DRIVES))
    drive = DRIVES[kind](dt)
    dt.finish()

    et = top.table("errors")
    counts = drive.error_sources
    symbols = drive.phase_symbols
    missing = [k for k in counts if not et.has(k)]
    if missing:
        raise ConfigError(f"[errors]: missing error source(s) {missing}; give each a table [errors.NAME] with `magnitude` and `phase` (magnitude law 'fixed' with value_um = 0 leaves one out)")
    sources, tolerances = {}, {}
    for src in counts:
        t = et.table(src)
        t.where = f"[errors.{src}]"
        declared = drive.tolerances_um.get(src)
        tol = t.number("tolerance_um", None, minimum=0) if t.has("tolerance_um") else declared
        if declared is not None and tol != declared:
            raise ConfigError(f"[errors.{src}] tolerance_um: {tol:g} µm, but the drive declares {declared:g} µm for this "
                              "source; give it in one place (or make them agree)")
        mt, pt = t.table("magnitude"), t.table("phase")
        mag, ph = _magnitude(mt, tol), _phase(pt, symbols)
        mt.finish()
        pt.finish()
        t.finish()
        sources[src], tolerances[src] = ErrorSource(mag, ph), tol
    for k in et.data:
        if k not in counts:
            hint = difflib.get_close_matches(k, list(counts), n=1)
            raise ConfigError(f"[errors]: unknown error source `{k}`" + (f" (did you mean `{hint[0]}`?)" if hint else "") + f"; this drive has {list(counts)}")
    et.used.update(counts)
    et.finish()
    allocation = _allocation(top, sources, tolerances, symbols, metric)
    budget = _budget(top, sources, tolerances, metric)
    if allocation is not None and budget is not None:
        raise ConfigError("[budget]: give the assembly rule as concrete phases (rule = \"relative\" or \"fixed\") in a budget study; optimise the rule in its own study first")
    top.finish()
    try:
        model = ErrorModel(sources, counts)
    except ValueError as e:
        raise ConfigError(f"[errors]: {e}") from None
    return Study(name=name, title=title, description=description, metric=metric, samples=n, seed=s, unit=unit,
                 chunk_size=chunk, drive=drive, errors=model, tolerances_um=tolerances, notes=tuple(notes_raw), source_path=source,
                 allocation=allocation, budget=budget)


def _allocation(top: _Table, sources: dict, tolerances: dict, symbols: dict[str, str], metric: str) -> AllocationSpec | None:
    optimised = {n: s.phase for n, s in sources.items() if isinstance(s.phase, Optimised)}
    if not top.has("allocation"):
        if optimised:
            raise ConfigError(f"[allocation]: phases of {sorted(optimised)} are to be optimised; add an [allocation] table (objective = \"worst_case\" | \"expected\" | \"robust\")")
        return None
    t = top.table("allocation")
    if not optimised:
        raise ConfigError("[allocation]: no phase is marked `rule = \"optimise\"` in [errors]; mark the assembly phases to choose")
    if metric != "peak":
        raise ConfigError("[allocation]: assembly rules are optimised for the peak metric; set [study] metric = \"peak\"")
    datums = {r.relative_to for r in optimised.values() if r.relative_to is not None}
    if len(datums) > 1:
        raise ConfigError(f"[errors]: optimised phases must share one datum, got relative_to {sorted(datums)}")
    by_symbol = {sym: nm for nm, sym in symbols.items()}
    datum = datums.pop() if datums else None
    if t.has("datum"):
        d = t.string("datum")
        d = by_symbol.get(d, d)
        if datum is not None and d != datum:
            raise ConfigError(f"[allocation] datum: {d!r} differs from the optimised phases' relative_to {datum!r}")
        datum = d
    if datum is None:
        raise ConfigError("[allocation] datum: name the error source whose phase is the assembly datum (e.g. \"ring_manufacturing\")")
    if datum not in sources or not isinstance(sources[datum].phase, UniformPhase):
        raise ConfigError(f"[allocation] datum: {datum!r} must be an error source with a uniform (unknown) phase")
    missing = sorted(n for n, tol in tolerances.items() if tol is None)
    if missing:
        raise ConfigError(f"[allocation]: every error source needs `tolerance_um` for the allocation objectives; missing in {missing}")
    seed_rule = None
    if t.has("seed_rule"):
        sr = t.table("seed_rule")
        seed_rule = {n: sr.angle(n) for n in optimised}
        sr.finish()
    spec = AllocationSpec(
        objective=t.string("objective", "worst_case", choices=("worst_case", "expected", "robust")),
        datum=datum,
        adjust={n: ("relative" if r.relative_to is not None else "absolute") for n, r in optimised.items()},
        starts=t.integer("starts", 16, minimum=1),
        surrogate_samples=t.integer("surrogate_samples", 512, minimum=16),
        check_samples=t.integer("check_samples", 50_000, minimum=100),
        seed_rule=seed_rule,
    )
    t.finish()
    return spec


COST_MODELS = ("reciprocal", "reciprocal_square", "exponential", "power", "grade_table")


def _cost_model(t: _Table, nominal: float):
    """A cost model from its table; without coefficients, normalised to cost 1 at the nominal tolerance."""
    from . import _costs

    kind = t.string("model", choices=COST_MODELS)
    try:
        if kind == "grade_table":
            raw = t.table("costs_by_grade")
            costs = {int(k): raw.number(k, minimum=0) for k in list(raw.data)}
            g = _costs.GradeTable(costs, quantity=t.string("quantity"), standard=t.string("standard"), module=t.number("module_mm", positive=True),
                                  diameter=t.number("diameter_mm", positive=True), face_width=t.number("face_width_mm", None, positive=True) if t.has("face_width_mm") else None)
            return g
        cls = {"reciprocal": _costs.Reciprocal, "reciprocal_square": _costs.ReciprocalSquare, "exponential": _costs.Exponential,
               "power": _costs.Power}[kind]
        params = {"reciprocal": ("a", "b"), "reciprocal_square": ("a", "b"), "exponential": ("a", "b", "k"), "power": ("a", "k")}[kind]
        if not any(t.has(k) for k in params):
            if kind == "power":
                return cls.normalised(nominal, k=t.number("exponent", 1.0, positive=True))
            return cls.normalised(nominal)
        return cls(*[t.number(k) for k in params])
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"{t.where}: {e}") from None


def _budget(top: _Table, sources: dict, tolerances: dict, metric: str) -> BudgetSpec | None:
    if not top.has("budget"):
        return None
    t = top.table("budget")
    missing = sorted(n for n, tol in tolerances.items() if not tol)
    if missing:
        raise ConfigError(f"[budget]: every error source needs a nominal `tolerance_um` > 0; missing or zero in {missing}")
    spec = t.number("spec", positive=True)
    constraint = t.string("constraint", "yield", choices=("yield", "mean_k_sigma"))
    target = t.number("target", 0.9973 if constraint == "yield" else 3.0, minimum=0)
    if constraint == "yield" and not 0.5 <= target < 1:
        raise ConfigError(f"[budget] target: a yield in [0.5, 1), got {target:g}")
    default = t.string("cost_model", "reciprocal", choices=COST_MODELS[:-1])
    overrides = t.table("costs", {}) if t.has("costs") else None
    costs = {}
    for n in sources:
        if overrides is not None and overrides.has(n):
            ct = overrides.table(n)
            costs[n] = _cost_model(ct, tolerances[n])
            ct.finish()
        else:
            costs[n] = _cost_model(_Table({"model": default}, f"[budget] cost_model"), tolerances[n])
    if overrides is not None:
        overrides.finish()
    factor = t.number("maximum_factor", 10.0, positive=True)
    if factor <= 1:
        raise ConfigError(f"[budget] maximum_factor: must be > 1 (largest tolerance = factor × nominal), got {factor:g}")
    grades = {}
    if t.has("grades"):
        gt = t.table("grades")
        for n in list(gt.data):
            if n not in sources:
                raise ConfigError(f"[budget.grades]: {n!r} is not an error source; use one of {sorted(sources)}")
            g = gt.table(n)
            grades[n] = {"quantity": g.string("quantity", "F_r", choices=("f_pt", "F_p", "F_alpha", "F_beta", "F_r")),
                         "factor": g.number("factor", 2.0, positive=True),
                         "standard": g.string("standard", "1328-1:2013", choices=("1328-1:2013", "1328-1:1995")),
                         "module": g.number("module_mm", positive=True), "diameter": g.number("diameter_mm", positive=True),
                         "face_width": g.number("face_width_mm", positive=True) if g.has("face_width_mm") else None}
            g.finish()
        gt.finish()
    specs = t.get("pareto_specs", [])
    if not isinstance(specs, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and x > 0 for x in specs):
        raise ConfigError("[budget] pareto_specs: expected a list of positive numbers (TE specs in the study's unit)")
    spec_obj = BudgetSpec(spec=spec, constraint=constraint, target=target, samples=t.integer("samples", 4096, minimum=64),
                          check_samples=t.integer("check_samples", 50_000, minimum=1000), costs=costs,
                          maximum_um={n: factor * tolerances[n] for n in sources}, grades=grades, pareto_specs=tuple(float(x) for x in specs),
                          compare_random_assembly=t.boolean("compare_random_assembly", True))
    t.finish()
    return spec_obj
