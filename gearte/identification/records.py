"""Measured TE records: reading them (CSV, NPZ), checking them, resampling them, and synthetic ones.

A bench gives, at each sample, the input angle (or the time at a constant input speed) and either
the output angle or the TE itself. gearte reads any of these column sets (units in the column
names, or given to `read_record`):

| columns | TE |
|---|---|
| ``input_angle_<u>, te_<v>`` | as given |
| ``input_angle_<u>, output_angle_<u>`` | ``s·(θ_out − s·θ_in/i)``, s the sign of the output's turning |
| ``time_s, te_<v>`` or ``time_s, output_angle_<u>`` | the same, with θ_in = 2π n t/60 (`input_rpm` needed) |

with ``<u>`` one of rad, deg, rev and ``<v>`` one of rad, urad, arcsec, arcmin, deg. The TE is positive
when the output leads in its own direction of turning. A CSV file may state ``# input_rpm = 184`` and
``# ratio = 8`` on comment lines before the header; an NPZ file holds the columns as arrays (and
optionally ``input_rpm``, ``ratio`` as scalars).

Every record is checked (finite values, input angle strictly increasing, no gaps, plausible
units) and put on a uniform grid of input angles (`MeasuredRecord`), the grid a sinusoidal
drive's model is evaluated on. Records are NumPy arrays: reading is not part of the compiled model.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import NoReturn

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PRNGKeyArray

from ..core.records import Record
from ..core.signal import evaluate
from ..core.units import ARCMIN_PER_RAD, ARCSEC_PER_RAD, TWO_PI
from ..core.validate import as_float, as_int, is_traced
from ..drives.protocol import AbstractGridDrive, AbstractSinusoidalDrive, Eccentricity, Errors
from ..studies.montecarlo import as_key

ANGLE_UNITS = {"rad": 1.0, "deg": math.pi / 180.0, "rev": TWO_PI}
TE_UNITS = {"rad": 1.0, "urad": 1e-6, "arcsec": 1.0 / ARCSEC_PER_RAD, "arcmin": 1.0 / ARCMIN_PER_RAD, "deg": math.pi / 180.0}
COLUMNS = ("time", "input_angle", "output_angle", "te")
MAX_TE_RAD = 0.05  # 2.9°: no drive gearte models has a TE near this; a larger one is a unit slip
GAP_FACTOR = 1.5  # a step more than 1.5 × the median step is a gap


class RecordError(ValueError):
    """A measured record cannot be used; the message names the file, the column or row, and the fix."""


#: A `MeasuredRecord`'s steps may differ from its first by this fraction of it (rounding of a computed grid).
UNIFORM_STEP = 1e-6


class MeasuredRecord(eqx.Module):
    """A TE record on a uniform grid of input angles.

    **Fields:**

    - `theta`: input angle at each sample, rad (uniform, increasing).
    - `te`: TE at the output, rad (positive when the output leads).
    - `input_rpm`: input speed, rpm, when known (for spectra in cycles per minute), else None.
    - `source`: where the record came from (a file name), for messages and reports.
    """

    theta: np.ndarray
    te: np.ndarray
    input_rpm: float | None = eqx.field(static=True, default=None)
    source: str = eqx.field(static=True, default="record")

    def __check_init__(self):
        if is_traced(self.theta) or is_traced(self.te):
            return
        shapes = {k: np.shape(v) for k, v in (("theta", self.theta), ("te", self.te))}
        for k, shp in shapes.items():
            if len(shp) != 1:
                _fail(self.source, f"{k} must be 1-D (one value per sample), got shape {shp}")
        if shapes["theta"] != shapes["te"]:
            _fail(
                self.source,
                f"theta has {shapes['theta'][0]} samples but te has {shapes['te'][0]}: give one TE value per input angle",
            )
        for k in ("theta", "te"):
            _check_finite(k, np.asarray(getattr(self, k), dtype=np.float64), self.source)
        theta = np.asarray(self.theta, dtype=np.float64)
        if theta.size < 2:
            _fail(self.source, f"theta: a record needs at least 2 samples, got {theta.size}")
        d = np.diff(theta)
        if not np.all(d > 0):
            _fail(self.source, f"theta, sample {int(np.argmin(d > 0)) + 2}: input angles must increase from sample to sample")
        # Uniform to a millionth of a step (a grid from np.arange or np.linspace is uniform to rounding, far below it);
        # a record read from a file is put on such a grid by `read_record`.
        if np.any(np.abs(d - d[0]) > UNIFORM_STEP * d[0]):
            k = int(np.argmax(np.abs(d - d[0]) > UNIFORM_STEP * d[0]))
            _fail(
                self.source,
                f"theta, sample {k + 2}: the input angles must be a uniform grid (step {d[0]:.6g} rad from the first two "
                f"samples, {d[k]:.6g} rad here); gearte.read_record interpolates a measured record onto one",
            )

    @property
    def revolutions(self) -> float:
        """Input revolutions the record spans (samples × step / 2π)."""
        return len(self.theta) * self.step / TWO_PI

    @property
    def step(self) -> float:
        """Input angle between samples, rad."""
        return float(self.theta[1] - self.theta[0])

    @property
    def points_per_rev(self) -> float:
        """Samples per input revolution."""
        return TWO_PI / self.step

    def as_record(self) -> Record:
        """The record as a `gearte.Record` (time at `input_rpm`, or at 60 rpm when unknown, so that cycles per
        minute / 60 are multiples of the input speed), for `gearte.spectral_lines` and `gearte.record_spectrum`."""
        rpm = self.input_rpm or 60.0
        t = (self.theta - self.theta[0]) / TWO_PI * 60.0 / rpm
        return Record(time=t, theta=np.asarray(self.theta), te=np.asarray(self.te), input_rpm=rpm, sample_rate_hz=1.0 / float(t[1]))


def _fail(source: str, msg: str) -> NoReturn:
    raise RecordError(f"{source}: {msg}")


def _check_finite(what: str, values: np.ndarray, source: str) -> None:
    """Raise `RecordError` at the first value of `what` (a column, or a `MeasuredRecord` field) that is not finite."""
    bad = np.nonzero(~np.isfinite(values))[0]
    if bad.size:
        _fail(source, f"{what}, data row {bad[0] + 1}: not a finite number; drop or repair the row")


def _column(name: str, source: str, units: Mapping[str, str]) -> tuple[str, float] | None:
    """(quantity, factor to rad or s) of a column name such as ``te_arcsec``; None for an unknown name."""
    name = name.strip()
    if name in ("time", "time_s"):
        u = units.get("time", "s")
        if u != "s" or (name == "time_s" and "time" in units and units["time"] != "s"):
            _fail(source, f"column {name!r}: time must be in s (time_s)")
        return "time", 1.0
    for q in ("input_angle", "output_angle", "te"):
        if name == q or name.startswith(q + "_"):
            table = TE_UNITS if q == "te" else ANGLE_UNITS
            given = name[len(q) + 1 :] if name != q else None
            stated = units.get(q)
            if given is not None and stated is not None and given != stated:
                _fail(source, f"column {name!r} says {given!r} but the unit given for {q} is {stated!r}; drop one")
            u = given or stated
            if u is None:
                _fail(source, f"column {name!r} has no unit: name it {q}_<unit> ({', '.join(table)}) or give the unit ({q}=<unit>)")
            if u not in table:
                _fail(source, f"column {name!r}: unknown unit {u!r} for {q}; use one of {', '.join(table)}")
            return q, table[u]
    return None


def _read_csv(path: Path) -> tuple[list[str], np.ndarray, dict[str, float]]:
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        _fail(src, "no such file")
    except (OSError, UnicodeDecodeError) as e:
        _fail(src, f"cannot read ({e})")
    lines = text.splitlines()
    meta: dict[str, float] = {}
    body_start = 0
    for i, line in enumerate(lines):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            kv = s.lstrip("#").replace(":", "=", 1).split("=", 1)
            if len(kv) == 2 and kv[0].strip() in ("input_rpm", "ratio"):
                try:
                    meta[kv[0].strip()] = float(kv[1].strip())
                except ValueError:
                    _fail(src, f"line {i + 1}: {kv[0].strip()} must be a number, got {kv[1].strip()!r}")
            continue
        body_start = i
        break
    else:
        _fail(src, "no header line (e.g. input_angle_rad,te_arcsec)")
    header = [h.strip() for h in lines[body_start].split(",")]
    rows = []
    for n, line in enumerate(lines[body_start + 1 :], start=body_start + 2):  # the file's own line numbers
        s = line.split("#", 1)[0].strip()
        if not s:
            continue
        cells = [c.strip() for c in s.split(",")]
        if len(cells) != len(header):
            _fail(src, f"line {n}: {len(cells)} values but {len(header)} column names in the header")
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            bad = next(c for c in cells if not _is_number(c))
            _fail(src, f"line {n}: {bad!r} is not a number")
    if not rows:
        _fail(src, "no data rows below the header")
    return header, np.asarray(rows, dtype=np.float64), meta


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_npz(path: Path) -> tuple[list[str], np.ndarray, dict[str, float]]:
    src = str(path)
    try:
        z = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        _fail(src, "no such file")
    except (OSError, ValueError) as e:
        _fail(src, f"cannot read as .npz ({e})")
    meta = {k: float(z[k]) for k in ("input_rpm", "ratio") if k in z.files}
    names = [k for k in z.files if k not in meta]
    cols = [np.asarray(z[k], dtype=np.float64).reshape(-1) for k in names]
    if len({len(c) for c in cols}) > 1:
        _fail(src, "the arrays have different lengths: " + ", ".join(f"{k} {len(c)}" for k, c in zip(names, cols)))
    return names, np.stack(cols, axis=1) if cols else np.zeros((0, 0)), meta


def read_record(
    path: str | Path,
    *,
    units: Mapping[str, str] | None = None,
    input_rpm: float | None = None,
    ratio: float | None = None,
) -> MeasuredRecord:
    """Read a measured record (CSV or NPZ; see the module notes) and put it on a uniform input-angle grid.

    **Arguments:**

    - `path`: a ``.csv`` or ``.npz`` file.
    - `units`: units of columns named without one, e.g. ``{"te": "arcsec", "input_angle": "deg"}``.
    - `input_rpm`: input speed, rpm (needed with a time column; overrides the file's).
    - `ratio`: transmission ratio i (input turns per output turn; needed with an output-angle column;
      overrides the file's). Its sign is read from the record.

    **Returns:** a `MeasuredRecord`. Raises `RecordError` naming the problem and the fix.
    """
    path = Path(path)
    reader = _read_npz if path.suffix.lower() == ".npz" else _read_csv
    header, data, meta = reader(path)
    if input_rpm is not None:
        meta["input_rpm"] = float(input_rpm)
    if ratio is not None:
        meta["ratio"] = float(ratio)
    return record_from_columns(header, data, units=units or {}, source=str(path), **meta)


def record_from_columns(
    names, data: np.ndarray, *, units: Mapping[str, str] | None = None, source: str = "record", input_rpm=None, ratio=None
) -> MeasuredRecord:
    """A `MeasuredRecord` from named columns (`names`, `data` of shape (rows, columns)); see `read_record`."""
    units = dict(units or {})
    for k in units:
        if k not in COLUMNS:
            _fail(source, f"units: unknown quantity {k!r}; use {', '.join(COLUMNS)}")
    cols: dict[str, np.ndarray] = {}
    for j, name in enumerate(names):
        q = _column(name, source, units)
        if q is None:
            _fail(source, f"unknown column {name!r}; use time_s, input_angle_<unit>, output_angle_<unit>, te_<unit>")
        if q[0] in cols:
            _fail(source, f"two {q[0]} columns")
        v = np.asarray(data[:, j], dtype=np.float64) * q[1]
        _check_finite(f"column {name!r}", v, source)
        cols[q[0]] = v
    rpm = None if input_rpm is None else float(input_rpm)
    if rpm is not None and not (math.isfinite(rpm) and rpm > 0):
        _fail(source, f"input_rpm: must be > 0, got {input_rpm!r}")
    if "input_angle" not in cols:
        if "time" not in cols:
            _fail(source, "give the input angle (input_angle_<unit>) or the time (time_s, with input_rpm)")
        if rpm is None:
            _fail(source, "a time column needs the input speed: give input_rpm (# input_rpm = … in the file, or --input-rpm)")
        cols["input_angle"] = TWO_PI * rpm / 60.0 * cols["time"]
    elif "time" in cols and rpm is None:
        dt = np.diff(cols["time"])
        if np.all(dt > 0):
            rpm = float((cols["input_angle"][-1] - cols["input_angle"][0]) / (cols["time"][-1] - cols["time"][0]) * 60.0 / TWO_PI)
    theta = cols["input_angle"]
    if len(theta) < 16:
        _fail(source, f"only {len(theta)} samples; a record needs at least 16")
    _check_grid(theta, source)
    if "te" in cols:
        if "output_angle" in cols:
            _fail(source, "give either the output angle or the TE, not both")
        te = cols["te"]
    elif "output_angle" in cols:
        te = _te_from_angles(theta, cols["output_angle"], ratio, source)
    else:
        _fail(source, "give the TE (te_<unit>) or the output angle (output_angle_<unit>)")
    big = float(np.max(np.abs(te - np.mean(te))))
    if big > MAX_TE_RAD:
        _fail(
            source,
            f"the TE varies by {big:.3g} rad ({math.degrees(big):.3g}°), far more than any gear drive's: check the TE column's unit "
            "(e.g. arcsec given as rad)",
        )
    return _uniform(theta, te, input_rpm=rpm, source=source)


def _check_grid(theta: np.ndarray, source: str) -> None:
    d = np.diff(theta)
    bad = np.nonzero(d <= 0)[0]
    if bad.size:
        i = int(bad[0])
        _fail(
            source,
            f"the input angle must increase strictly: data row {i + 2} ({theta[i + 1]:.9g} rad) does not exceed row {i + 1} "
            f"({theta[i]:.9g} rad); sort the record (a reversed run: reverse it and negate the angles)",
        )
    med = float(np.median(d))
    gaps = np.nonzero(d > GAP_FACTOR * med)[0]
    if gaps.size:
        i = int(gaps[0])
        _fail(
            source,
            f"gap in the record after data row {i + 1}: the input angle jumps by {d[i]:.4g} rad where the usual step is {med:.4g} rad "
            f"(about {d[i] / med - 1:.0f} samples missing); give a record without gaps, or split it in two",
        )


def _te_from_angles(theta: np.ndarray, out: np.ndarray, ratio, source: str) -> np.ndarray:
    if ratio is None:
        _fail(source, "an output-angle column needs the transmission ratio: give ratio (# ratio = … in the file, or --ratio)")
    i = abs(float(ratio))
    if not (math.isfinite(i) and i > 0):
        _fail(source, f"ratio: must be a non-zero number, got {ratio!r}")
    slope = float(np.polyfit(theta - theta[0], out, 1)[0])
    if slope == 0 or not 0.99 < abs(slope) * i < 1.01:
        _fail(
            source,
            f"the output turns {abs(slope):.6g} per input turn but the ratio {i:g} says {1 / i:.6g}: check the angle units "
            "(deg read as rad is a factor 57.3) or the ratio",
        )
    s = math.copysign(1.0, slope)
    return s * (out - s * theta / i)


def resample(rec: MeasuredRecord, *, points_per_rev: float | None = None) -> MeasuredRecord:
    """`rec` on the uniform grid of `points_per_rev` samples per input revolution from its first sample (default: its
    own, returned as it is), by linear interpolation."""
    if points_per_rev is None:
        return rec
    ppr = float(points_per_rev)
    if not (math.isfinite(ppr) and ppr > 0):
        raise RecordError(f"{rec.source}: points_per_rev must be a finite number > 0, got {points_per_rev!r}")
    theta = np.asarray(rec.theta, dtype=np.float64)
    step = TWO_PI / ppr
    n = int(math.floor((theta[-1] - theta[0]) / step + 1e-9)) + 1
    if n < 2:
        raise RecordError(f"{rec.source}: points_per_rev = {ppr:g} leaves fewer than 2 samples in the record")
    grid = theta[0] + step * np.arange(n)
    return MeasuredRecord(theta=grid, te=np.interp(grid, theta, np.asarray(rec.te)), input_rpm=rec.input_rpm, source=rec.source)


def _uniform(theta: np.ndarray, te: np.ndarray, *, input_rpm: float | None, source: str) -> MeasuredRecord:
    """A record (strictly increasing input angles `theta`) on a uniform grid of input angles from its first sample at
    its median step, by linear interpolation; one already uniform (to 1e-9 of a step) is kept as it is."""
    theta = np.asarray(theta, dtype=np.float64)
    d = np.diff(theta)
    step = float(np.median(d))
    if not np.all(np.abs(d - step) <= 1e-9 * step):
        n = int(math.floor((theta[-1] - theta[0]) / step + 1e-9)) + 1
        grid = theta[0] + step * np.arange(n)
        theta, te = grid, np.interp(grid, theta, np.asarray(te))
    return MeasuredRecord(theta=theta, te=te, input_rpm=input_rpm, source=source)


def write_record(path: str | Path, rec: MeasuredRecord, *, unit: str = "arcsec", digits: int = 6) -> None:
    """Write a record as CSV: ``input_angle_rad, te_<unit>``, with ``# input_rpm`` when known."""
    if unit not in TE_UNITS:
        raise ValueError(f"unit: use one of {', '.join(TE_UNITS)}, got {unit!r}")
    head = [f"# gearte TE record: {rec.source}"] + ([f"# input_rpm = {rec.input_rpm:g}"] if rec.input_rpm else [])
    rows = [f"{t:.17g},{v:.{digits}g}" for t, v in zip(np.asarray(rec.theta), np.asarray(rec.te) / TE_UNITS[unit])]
    Path(path).write_text("\n".join(head + [f"input_angle_rad,te_{unit}"] + rows) + "\n", encoding="utf-8")


def synthetic_record(
    drive: AbstractSinusoidalDrive | AbstractGridDrive,
    errors: Errors,
    *,
    key: int | PRNGKeyArray,
    revolutions: float | None = None,
    points_per_rev: int | None = None,
    noise: float = 0.0,
    counts_per_rev: int | None = None,
    input_rpm: float | None = None,
    turns: Mapping[str, float] | None = None,
) -> MeasuredRecord:
    """A record of `drive` with these `errors`, as a bench with two encoders would give it.

    Sampling is triggered by the input encoder (the input angle is exact at each of the
    `points_per_rev` samples per input revolution, over `revolutions` revolutions); the output
    encoder adds Gaussian noise of standard deviation `noise` (rad) and rounds the output angle to
    its `counts_per_rev` counts (None: no rounding). `turns` turns sources at assembly (source →
    rad added to its phase), as `identify` takes them. `key` (a seed or a JAX key) makes it reproducible.

    A grid drive's record lies on the angles of its `trace` (for `gearte.CycloidPin`: `analysis.sweep_points_per_pitch`
    per pin pitch over `analysis.sweep_revolutions`), the TE exact there; leave `revolutions` and `points_per_rev` out.
    """
    noise = as_float("synthetic_record: noise", noise, nonnegative=True, hint="rad")
    if counts_per_rev is not None:
        counts_per_rev = as_int("synthetic_record: counts_per_rev", counts_per_rev, minimum=1)
    if isinstance(drive, AbstractGridDrive):
        if revolutions is not None or points_per_rev is not None:
            raise ValueError(
                "synthetic_record: a grid drive's record lies on the angles of its trace (set them in the drive's analysis); "
                "leave revolutions and points_per_rev out"
            )
        errs = turned(drive, {**drive.zero_errors(), **dict(errors)}, turns) if turns else errors
        tr = drive.trace(errs)
        theta = np.asarray(tr.theta, dtype=np.float64)
        ratio = float(getattr(drive, "ratio", 1.0))
        te = encoder_noise(theta, tr.te, key=key, ratio=ratio, noise=noise, counts_per_rev=counts_per_rev)
        return _uniform(theta, te, input_rpm=input_rpm, source="synthetic record")
    if not isinstance(drive, AbstractSinusoidalDrive):
        raise ValueError("synthetic_record: needs a sinusoidal drive (planetary_2kh, harmonic, explicit) or a grid drive (cycloid_pin)")
    if revolutions is None or points_per_rev is None:
        raise ValueError("synthetic_record: give revolutions and points_per_rev for a sinusoidal drive's record")
    revolutions = as_float("synthetic_record: revolutions", revolutions, positive=True)
    points_per_rev = as_int("synthetic_record: points_per_rev", points_per_rev, minimum=1)
    n = int(round(revolutions * points_per_rev))
    if n < 16:
        raise ValueError(f"synthetic_record: {revolutions} revolutions at {points_per_rev} points per revolution is under 16 samples")
    theta = TWO_PI / int(points_per_rev) * np.arange(n)
    errs = turned(drive, errors, turns or {})
    te = np.asarray(evaluate(drive.signal(errs), jnp.asarray(theta)))
    ratio = float(getattr(drive, "ratio", 1.0))
    te = encoder_noise(theta, te, key=key, ratio=ratio, noise=noise, counts_per_rev=counts_per_rev)
    return MeasuredRecord(theta=theta, te=te, input_rpm=input_rpm, source="synthetic record")


def encoder_noise(theta, te, *, key, ratio: float, noise: float = 0.0, counts_per_rev: int | None = None) -> np.ndarray:
    """The TE (rad) an output encoder reads: output angle θ/i + TE, plus Gaussian noise of standard deviation
    `noise` (rad), rounded to `counts_per_rev` counts, less θ/i (see `synthetic_record`)."""
    theta = np.asarray(theta, dtype=np.float64)
    out = theta / ratio + np.asarray(te, dtype=np.float64)
    if noise:
        out = out + float(noise) * np.asarray(jax.random.normal(as_key(key), theta.shape, dtype=float))
    if counts_per_rev is not None:
        q = TWO_PI / int(counts_per_rev)
        out = np.round(out / q) * q
    return out - theta / ratio


def turned(drive, errors: Errors, turns: Mapping[str, float]) -> dict:
    """`errors` with each source in `turns` turned at assembly: its phase plus the turn (rad)."""
    out = dict(drive.checked(errors))
    specs = drive.error_sources
    for name, turn in turns.items():
        if name not in specs:
            raise ValueError(f"turns: {name!r} is not an error source of this drive; use one of {sorted(specs)}")
        if specs[name].kind != "eccentricity":
            raise ValueError(f"turns: {name!r} is a signed deviation, not a part that can be turned")
        e = out[name]
        out[name] = Eccentricity(e.magnitude, e.phase + jnp.asarray(turn, dtype=float))
    return out
