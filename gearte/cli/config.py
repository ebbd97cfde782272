"""Study files (TOML): read, validate, and build the drive, the error model and the study kinds.

One format for every drive (reference: docs/study-files.md):

- ``[study]``: name, title, description, samples, seed, chunk_size, notes, metric (one the drive
  offers), unit.
- ``[drive]``: ``type`` (a name of `gearte.drives.DRIVES`) and the drive's own keys, read by the
  drive (`AbstractDrive.from_table`).
- ``[errors.NAME]``: one table per error source the drive declares: an optional tolerance, and
  the laws it is drawn with (``magnitude`` and ``phase`` for an eccentricity, ``value`` for a
  signed deviation; a deviation left out is fixed at 0).
- one table per study kind (``[allocation]``, ``[budget]``, …; see `gearte.cli.kinds`).

Everything is checked here, in Python, before anything is compiled; each message names the
file, the table, the key and what to write instead. The checks of the file itself (readable
UTF-8 TOML, known tables, the ``[study]`` header, a ``[drive]`` table with a ``type``) import
neither JAX nor the drives, so that `gearte check` answers at once when they fail; the drive,
its metric, the error laws and the study kinds are JAX objects, and are checked by building them.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import stat
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.schema import MAX_SAMPLES, ConfigError, OptionError, Table, parse_angle
from ..core.units import ANGLE_UNITS, ARCSEC_PER_RAD

if TYPE_CHECKING:
    from ..core.metrics import AbstractMetric
    from ..drives.protocol import AbstractDrive, SourceSpec
    from ..studies.errors import ErrorModel
    from ..studies.laws import AbstractLaw, AbstractPhase

__all__ = ["ConfigError", "Study", "check_file", "load_study", "parse_angle", "read_toml"]

MAGNITUDE_LAWS = ("fixed", "uniform", "normal", "truncated_normal", "rayleigh")
VALUE_LAWS = ("fixed", "uniform", "normal", "truncated_normal", "rayleigh", "sinusoid", "random_angle")
PHASE_RULES = ("uniform", "fixed", "relative", "optimise")
#: Keys of an angular value: unit suffix → rad per unit.
ANGLE_SUFFIXES = {"rad": 1.0, "deg": math.pi / 180.0, "arcsec": 1.0 / ARCSEC_PER_RAD, "arcmin": 60.0 / ARCSEC_PER_RAD}
#: The tables of the study kinds (`gearte.cli.kinds.STUDY_KINDS`, which imports JAX), for the file's
#: first checks; a test keeps the two in step.
KIND_TABLES = ("allocation", "budget", "sensitivity", "modification", "doe")


@dataclasses.dataclass(frozen=True)
class Study:
    """A validated study: what `gearte run` computes.

    `kinds` holds the validated table of each study kind present (by table name, in the order
    they run); `tolerances` the tolerance of each source (µm, or rad for angular sources) or None.
    """

    name: str
    title: str
    description: str
    samples: int
    seed: int
    unit: str
    chunk_size: int | None
    notes: tuple[str, ...]
    source_path: str
    drive: AbstractDrive
    errors: ErrorModel
    tolerances: dict[str, float | None]
    metric: AbstractMetric
    kinds: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def tolerances_um(self) -> dict[str, float | None]:
        """Alias of `tolerances` (µm for length sources)."""
        return self.tolerances


#: Largest study file read (bytes): a study file is a few kB of TOML.
MAX_STUDY_FILE_BYTES = 16 * 2**20


def read_toml(path: Path) -> dict:
    """The parsed TOML of a study file, or a ConfigError naming the file. Only a regular file is read (a pipe or a
    device could block or never end), and at most `MAX_STUDY_FILE_BYTES` of it."""
    try:
        info = path.stat()
        if stat.S_ISDIR(info.st_mode):
            raise ConfigError(f"{path}: is a folder, not a study file")
        if not stat.S_ISREG(info.st_mode):
            raise ConfigError(f"{path}: not a regular file (a pipe, device or socket); give the study file itself")
        with path.open("rb") as f:
            data = f.read(MAX_STUDY_FILE_BYTES + 1)  # the size on disk may be stale or 0 (a file of /proc)
        if max(info.st_size, len(data)) > MAX_STUDY_FILE_BYTES:
            raise ConfigError(f"{path}: over 16 MiB; a study file is TOML text of a few kB (at most 16 MiB)")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({e.strerror})") from None
    try:
        text = data.decode("utf-8").removeprefix("\ufeff")  # a byte-order mark some editors write: not TOML, dropped
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a UTF-8 text file; a study file is TOML text (see docs/study-files.md)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None


def study_header(st: Table, *, samples: int | None, seed: int | None) -> dict:
    """The keys every ``[study]`` table has (name, title, description, samples, seed, chunk_size, notes),
    with the command line's overrides."""
    name = st.string("name")
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise ConfigError(f"[study] name: use letters, digits, '_', '.', '-' only, got {name!r}")
    n = st.integer("samples", None, minimum=1) if st.has("samples") else None  # None: the default, set by build_study
    if n is not None and n > MAX_SAMPLES:
        raise ConfigError(f"[study] samples: at most 2³² − 1 samples per seed, got {n}")
    s = st.integer("seed", minimum=0)
    if s >= 2**63:
        raise ConfigError(f"[study] seed: must be below 2⁶³, got {s}")
    notes = st.get("notes", [])
    if not isinstance(notes, list) or not all(isinstance(x, str) for x in notes):
        raise ConfigError("[study] notes: expected a list of strings")
    if samples is not None:
        if not 1 <= samples <= MAX_SAMPLES:
            raise OptionError(f"--samples: must be in [1, 2³² − 1], got {samples}")
        n = samples
    if seed is not None:
        if not 0 <= seed < 2**63:
            raise OptionError(f"--seed: must be in [0, 2⁶³), got {seed}")
        s = seed
    return {
        "name": name,
        "title": st.string("title", name),
        "description": st.string("description", ""),
        "samples": n,
        "seed": s,
        "chunk_size": st.integer("chunk_size", None, minimum=1) if st.has("chunk_size") else None,
        "notes": tuple(notes),
    }


def load_study(path: str | Path, *, samples: int | None = None, seed: int | None = None) -> Study:
    """Read and validate a study file (docs/study-files.md) into a `Study`: its drive, error model, metric and study
    kinds, what `gearte run` computes (`gearte.load_study`). `samples` and `seed` (the command line's) override the
    file's values. A mistake raises a `ConfigError` (a ValueError) naming the file, table and key."""
    path = Path(path)
    raw = read_toml(path)
    try:
        return build_study(raw, str(path), samples=samples, seed=seed)
    except OptionError:
        raise
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def _refuse_unknown_tables(raw: dict, kinds) -> None:
    # Unknown tables first: a misspelt [errors] or [budget] would otherwise be reported as missing.
    allowed = ["study", "drive", "errors", *kinds]
    for k in raw:
        if k not in allowed:
            hint = difflib.get_close_matches(k, allowed, n=1)
            raise ConfigError(
                f"study file: unknown table `[{k}]`"
                + (f" (did you mean `[{hint[0]}]`?)" if hint else "")
                + f"; allowed: {', '.join(f'[{a}]' for a in allowed)}"
            )


def _read_file(raw: dict, *, samples: int | None, seed: int | None) -> tuple[Table, Table, Table, dict]:
    """The checks that need no JAX: known tables, the [study] header, a [drive] table naming a type.
    Returns the top-level, [study] and [drive] tables (still being read) and the header."""
    _refuse_unknown_tables(raw, KIND_TABLES)
    top = Table(raw, "study file")
    st = top.table("study")
    h = study_header(st, samples=samples, seed=seed)
    dt = top.table("drive")
    dt.string("type")
    return top, st, dt, h


def check_file(path: str | Path, *, samples: int | None = None, seed: int | None = None) -> None:
    """The checks of a study file that need no JAX (`load_study` makes them first, then the rest)."""
    path = Path(path)
    raw = read_toml(path)
    try:
        _read_file(raw, samples=samples, seed=seed)
    except OptionError:
        raise
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def _check_hyper_period(drive, where: str) -> None:
    """A sinusoidal drive's exact extrema (traced, not computed: the drive's own search, e.g. the harmonic drive's
    two-scale one) must fit in memory (`gearte.core.extrema`'s bound on their tables): refused here, naming the table,
    rather than when the study compiles."""
    import jax

    from ..drives.protocol import AbstractSinusoidalDrive

    if isinstance(drive, AbstractSinusoidalDrive):
        try:
            jax.eval_shape(lambda: drive.extrema(drive.signal(drive.zero_errors())))
        except ValueError as e:
            raise ConfigError(f"{where}: {e}") from None


def build_study(raw: dict, source: str, *, samples: int | None = None, seed: int | None = None) -> Study:
    """A `Study` from a parsed study file (the dict `tomllib` reads; `source` names it in messages and reports, and
    file names in `[drive]` are relative to its folder), e.g. a file's tables edited in Python (`gearte.build_study`)."""
    top, st, dt, h = _read_file(raw, samples=samples, seed=seed)
    dt.folder = Path(source).parent  # file names in [drive] are relative to the study file
    # Everything from here on builds JAX objects (the drive, its metrics, the error laws, the study kinds).
    from ..drives.registry import DRIVES
    from ..studies.montecarlo import DEFAULT_SAMPLES
    from .kinds import STUDY_KINDS

    _refuse_unknown_tables(raw, (k.table for k in STUDY_KINDS))
    if h["samples"] is None:
        h["samples"] = DEFAULT_SAMPLES
    kind = dt.string("type", choices=tuple(DRIVES))
    drive = DRIVES[kind].from_table(dt)
    dt.finish()
    _check_hyper_period(drive, dt.where)

    offered = drive.metrics
    metric = offered[st.string("metric", next(iter(offered)), choices=tuple(offered))]
    unit = st.string("unit", "arcsec", choices=tuple(u for u in ANGLE_UNITS if u != "rad"))
    st.finish()

    model, tolerances = read_errors(top, drive)
    study = Study(
        name=h["name"],
        title=h["title"],
        description=h["description"],
        samples=h["samples"],
        seed=h["seed"],
        unit=unit,
        chunk_size=h["chunk_size"],
        notes=h["notes"],
        source_path=source,
        drive=drive,
        errors=model,
        tolerances=tolerances,
        metric=metric,
    )
    kinds = {}
    for k in STUDY_KINDS:
        if top.has(k.table):
            kt = top.table(k.table)
            kinds[k.table] = k.read(kt, study)
            kt.finish()
        else:
            k.check_absent(study)
    study = dataclasses.replace(study, kinds=kinds)
    for k in STUDY_KINDS:
        k.check_together(study)
    top.finish()
    return study


# ---------------------------------------------------------------- error sources


def read_errors(top: Table, drive: AbstractDrive) -> tuple[ErrorModel, dict[str, float | None]]:
    """The ``[errors.NAME]`` tables: one per declared source (deviations may be left out: fixed at 0)."""
    from ..studies.errors import ErrorModel, ErrorSource
    from ..studies.laws import Fixed

    specs = drive.error_sources
    et = top.table("errors", {}) if top.has("errors") else Table({}, "[errors]")
    et.where = "[errors]"
    for k in et.data:
        if k not in specs:
            hint = difflib.get_close_matches(k, list(specs), n=1)
            raise ConfigError(
                f"[errors]: unknown error source `{k}`"
                + (f" (did you mean `{hint[0]}`?)" if hint else "")
                + f"; this drive has {list(specs)}"
            )
    missing = [k for k, s in specs.items() if s.kind == "eccentricity" and not et.has(k)]
    if missing:
        raise ConfigError(
            f"[errors]: missing error source(s) {missing}; give each a table [errors.NAME] with `magnitude` and "
            "`phase` (magnitude law 'fixed' with value_um = 0 leaves one out)"
        )
    symbols = {s.symbol: n for n, s in specs.items()}
    sources, tolerances = {}, {}
    for name, spec in specs.items():
        if not et.has(name):
            sources[name], tolerances[name] = ErrorSource(Fixed(0.0)), spec.tolerance
            continue
        t = et.table(name)
        t.where = f"[errors.{name}]"
        tol = _tolerance(t, spec)
        try:
            if spec.kind == "eccentricity":
                mt, pt = t.table("magnitude"), t.table("phase")
                src = ErrorSource(_magnitude(mt, tol), _phase(pt, specs, symbols))
                mt.finish()
                pt.finish()
            else:
                vt = t.table("value")
                src = ErrorSource(_value(vt, spec, tol))
                vt.finish()
        except ValueError as e:
            if isinstance(e, ConfigError):
                raise
            raise ConfigError(f"{t.where}: {e}") from None
        t.finish()
        sources[name], tolerances[name] = src, tol
    et.used.update(specs)
    et.finish()
    try:
        return ErrorModel(sources, specs), tolerances
    except ValueError as e:
        raise ConfigError(f"[errors]: {e}") from None


def _tolerance(t: Table, spec: SourceSpec) -> float | None:
    declared = spec.tolerance
    # tolerance_um for a length, tolerance_arcsec (…) for an angle; the other unit is refused, naming the one to give.
    tol = _length_or_angle(t, "tolerance", spec, None, minimum=0)
    if tol is None:
        return declared
    if declared is not None and tol != declared:
        u = "µm" if spec.unit == "µm" else "rad"
        raise ConfigError(
            f"{t.where} tolerance: {tol:g} {u}, but the drive declares {declared:g} {u} for this source; give it in "
            "one place (or make them agree)"
        )
    return tol


def _angle_value(t: Table, stem: str, default: Any = None, *, minimum: float | None = None) -> Any:
    """An angle given as `stem_rad`, `stem_deg`, `stem_arcmin` or `stem_arcsec` (one of them); returns rad."""
    given = [u for u in ANGLE_SUFFIXES if t.has(f"{stem}_{u}")]
    if len(given) > 1:
        raise ConfigError(f"{t.where}: give `{stem}` in one unit only, got {', '.join(f'{stem}_{u}' for u in given)}")
    if not given:
        return default
    u = given[0]
    v = t.get(f"{stem}_{u}")
    if u == "rad" and isinstance(v, str):
        x = parse_angle(v, where=f"{t.where} {stem}_rad")
    else:
        x = t.number(f"{stem}_{u}", minimum=minimum) * ANGLE_SUFFIXES[u]
    return x


def _length_or_angle(
    t: Table, stem: str, spec: SourceSpec, default: Any = ..., *, minimum: float | None = None, positive: bool = False
) -> Any:
    """A value of the source's unit: `stem_um` for µm sources, an angle suffix for rad sources."""
    if spec.unit == "µm":
        for u in ANGLE_SUFFIXES:
            if t.has(f"{stem}_{u}"):
                t.used.add(f"{stem}_{u}")
                raise ConfigError(f"{t.where} {stem}_{u}: this source is a length; give `{stem}_um`")
        if default is ...:
            return t.number(f"{stem}_um", minimum=minimum, positive=positive)
        return t.number(f"{stem}_um", default, minimum=minimum, positive=positive) if t.has(f"{stem}_um") else default
    if t.has(f"{stem}_um"):
        t.used.add(f"{stem}_um")
        raise ConfigError(f"{t.where} {stem}_um: this source is an angle; give `{stem}_arcsec`, `{stem}_deg` or `{stem}_rad`")
    v = _angle_value(t, stem, None, minimum=minimum)
    if v is None:
        if default is ...:
            raise ConfigError(f"{t.where}: missing `{stem}_arcsec` (or `{stem}_deg`, `{stem}_rad`)")
        return default
    if positive and not v > 0:
        raise ConfigError(f"{t.where} {stem}: must be > 0, got {v:g} rad")
    return v


def _magnitude(t: Table, tol: float | None) -> AbstractLaw:
    """The magnitude law of an eccentricity (µm, ≥ 0)."""
    from ..studies.laws import Fixed, Normal, Rayleigh, TruncatedNormal, Uniform

    law = t.string("law", choices=MAGNITUDE_LAWS)

    def need_tol(what: str) -> float:
        if tol is None:
            raise ConfigError(f"{t.where}: {what} needs `tolerance_um` in the error source's table")
        return tol

    if law == "fixed":
        if t.has("fraction_of_tolerance"):
            return Fixed(t.number("fraction_of_tolerance", minimum=0) * need_tol("fraction_of_tolerance"))
        if tol is not None and not t.has("value_um"):
            return Fixed(tol)
        return Fixed(t.number("value_um", minimum=0))
    if law == "uniform":
        high = t.number("high_um", tol, minimum=0) if tol is not None else t.number("high_um", minimum=0)
        return Uniform(t.number("low_um", 0.0, minimum=0), high)
    if law == "normal":
        return Normal(t.number("mean_um"), t.number("std_um", minimum=0))
    if law == "truncated_normal":
        return TruncatedNormal(
            t.number("mean_um"),
            t.number("std_um", positive=True),
            t.number("low_um", 0.0, minimum=0),
            t.number("high_um", tol if tol is not None else math.inf, minimum=0),
        )
    # Rayleigh: scale from the tolerance (user's choice, stated in the report).
    if t.has("scale_um") and t.has("scale_fraction"):
        raise ConfigError(f"{t.where}: give `scale_um` or `scale_fraction` (× tolerance), not both")
    if t.has("scale_um"):
        scale = t.number("scale_um", positive=True)
    elif t.has("scale_fraction"):
        scale = t.number("scale_fraction", positive=True) * need_tol("scale_fraction")
        if not scale > 0:
            raise ConfigError(
                f"{t.where} scale_fraction: × tolerance_um {need_tol('scale_fraction'):g} µm gives a Rayleigh scale of 0; "
                "give the source a tolerance_um > 0, or `scale_um`"
            )
    else:
        raise ConfigError(f"{t.where}: a Rayleigh law needs `scale_um`, or `scale_fraction` (scale = fraction × tolerance_um)")
    trunc = None
    if t.boolean("truncate_at_tolerance", False):
        trunc = need_tol("truncate_at_tolerance")
        if trunc <= 0:
            raise ConfigError(f"{t.where} truncate_at_tolerance: the tolerance is 0; there is nothing to draw below it")
    return Rayleigh(scale, trunc)


def _value(t: Table, spec: SourceSpec, tol: float | None, *, pattern_ok: bool = True) -> AbstractLaw:
    """The law of a signed deviation, in the source's unit (µm, or an angle)."""
    from ..drives.protocol import SourceSpec
    from ..studies.laws import Fixed, FixedPhase, Normal, Rayleigh, Sinusoid, TruncatedNormal, Uniform, UniformPhase

    law = t.string("law", choices=VALUE_LAWS)
    v = lambda stem, *a, **k: _length_or_angle(t, stem, spec, *a, **k)
    if law == "fixed":
        return Fixed(v("value"))
    if law == "random_angle":
        if spec.unit != "rad":
            raise ConfigError(f"{t.where} law: 'random_angle' (uniform on [0, 2π)) is for angular sources")
        return UniformPhase()
    if law == "uniform":
        half = v("half_width", None, minimum=0)
        if half is not None:
            for stem in ("low", "high"):
                if v(stem, None) is not None:
                    raise ConfigError(f"{t.where}: give `half_width` (and `centre`) or `low` and `high`, not both")
            return Uniform.centred(half, v("centre", 0.0))
        if tol is not None and v("low", None) is None and v("high", None) is None:
            return Uniform.centred(tol, v("centre", 0.0))
        lo, hi = v("low"), v("high")
        if not hi >= lo:
            raise ConfigError(f"{t.where} high: must be ≥ low ({lo:g}), got {hi:g}")
        # A band written by its ends is the same law as centre ± half-width.
        return Uniform.centred(0.5 * (hi - lo), 0.5 * (hi + lo))
    if law == "normal":
        return Normal(v("mean"), v("std", minimum=0))
    if law == "truncated_normal":
        return TruncatedNormal(v("mean"), v("std", positive=True), v("low"), v("high"))
    if law == "rayleigh":
        return Rayleigh(v("scale", positive=True), v("truncate_at", None, positive=True))
    # A sinusoidal pattern over the instances (tooth spaces, pins).
    if not pattern_ok or not spec.shape or spec.count < 2:
        raise ConfigError(f"{t.where} law: 'sinusoid' is a pattern over several instances (per tooth space or per pin)")
    if t.has("amplitude"):
        at = t.table("amplitude")
        amp = _value(at, SourceSpec(spec.name, "deviation", shape=(), unit=spec.unit), None, pattern_ok=False)
        at.finish()
    else:
        amp = Fixed(v("amplitude"))
    if t.has("phase") and any(t.has(f"phase_{u}") for u in ANGLE_SUFFIXES):
        raise ConfigError(f'{t.where}: give a fixed `phase_deg` or `phase = "uniform"`, not both')
    if t.has("phase"):
        t.string("phase", choices=("uniform",))
        phase: AbstractPhase = UniformPhase()
    else:
        phase = FixedPhase(_angle_value(t, "phase", 0.0))
    return Sinusoid(amp, phase, order=t.integer("order", 1, minimum=1))  # pyright: ignore[reportArgumentType]


def _phase(t: Table, specs: dict[str, SourceSpec], by_symbol: dict[str, str]) -> AbstractPhase:
    from ..studies.laws import FixedPhase, Optimised, RelativePhase, UniformPhase

    rule = t.string("rule", choices=PHASE_RULES)
    if rule == "uniform":
        return UniformPhase()
    if rule == "fixed":
        return FixedPhase(t.angle("value"))
    symbols = sorted(by_symbol)
    if rule == "optimise":
        # Chosen by the allocation optimiser: an offset from `relative_to`, or absolute.
        if not t.has("relative_to"):
            return Optimised(None)
        ref = t.string("relative_to")
        ref = by_symbol.get(ref, ref)
        if ref not in specs:
            raise ConfigError(f"{t.where} relative_to: {ref!r} is not an error source; use one of {list(specs)} or a symbol {symbols}")
        return Optimised(ref)
    to = t.string("to")
    to = by_symbol.get(to, to)
    if to not in specs:
        raise ConfigError(f"{t.where} to: {to!r} is not an error source; use one of {list(specs)} or a symbol {symbols}")
    return RelativePhase(to, t.angle("offset", 0.0))
