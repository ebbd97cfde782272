"""Cycloid-pin reducer: its study-file table, ``[drive] type = "cycloid_pin"``.

    [drive]             type = "cycloid_pin", z_pins, z_lobes (optional, = z_pins − 1),
                        pin_circle_radius_mm, pin_radius_mm, eccentricity_mm (or K1),
                        process ("form", the default, or "generating": how the disc is ground)
    [drive.wheel]       the profile the grinding wheel is dressed to: pin_circle_radius_mm (R_Z),
                        pin_radius_mm (r_Z), rotation_arcsec (optional)
      (or [drive.modification]   shift_mm, equidistant_mm, rotation_arcsec)
    [drive.analysis]    deformation_budget_mm (required), smoothing_width_mm (budget/10),
                        input_angle_deg (default half a pin pitch), pitch_points (64),
                        revolution_points_per_pitch (16), revolutions (1), monte_carlo_normal (true)
    [drive.grid]        the input angles every metric is taken on: positions_per_pitch (2), revolutions (1)
    [drive.reference]   the reducer analysed in detail: FIELD_um / FIELD_arcsec / FIELD_deg per
                        `CycloidErrors` field (a number; per space or pin also a list, or a table
                        { amplitude_um | amplitude_arcsec, phase_deg, order } for A sin(2π·order·n/N + φ))

Angles of the error fields: ``index_offset``, ``indexing``, ``generating_chain`` and
``pitch_accumulated`` in arcseconds, the ``*_phase`` fields in degrees; every other field in µm.
The fields of ``[drive.reference]`` and ``[errors.NAME]`` are those of the disc's process
(a form-ground disc has no generating-machine errors). The Monte Carlo laws of the errors are the study
file's ``[errors.NAME]`` tables (one per field; see docs/study-files.md).
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from ..core.schema import MAX_MICROMETRES, ConfigError, Table
from ..core.units import ARCSEC_PER_RAD
from .cycloid_pin_geometry import ANGLE_FIELDS, ERROR_FIELDS, PER_PIN, PER_SPACE, PROCESSES, CycloidModification


def unit_of(field: str) -> str:
    """The unit suffix of an error field in ``[drive.reference]``: deg for phases, arcsec for index angles, else um."""
    if field.endswith("_phase"):
        return "deg"
    if field in ANGLE_FIELDS:
        return "arcsec"
    return "um"


#: Internal units (µm, rad) per unit of a ``[drive.reference]`` suffix.
TO_INTERNAL = {"um": 1.0, "arcsec": 1.0 / ARCSEC_PER_RAD, "deg": math.pi / 180.0}


def _sub(t: Table, key: str) -> Table:
    return t.table(key) if t.has(key) else Table({}, f"{t.where[:-1]}.{key}]" if t.where.endswith("]") else f"[{key}]")


def drive_arguments(t: Table) -> dict[str, Any]:
    """The keyword arguments of `CycloidPin` from its ``[drive]`` table and sub-tables (each sub-table finished here);
    ``analysis`` is the keyword arguments of `CycloidAnalysis`."""
    zb = t.integer("z_pins", minimum=1)
    zl = t.integer("z_lobes", minimum=1) if t.has("z_lobes") else None
    R = t.number("pin_circle_radius_mm", positive=True)
    r = t.number("pin_radius_mm", positive=True)
    if t.has("eccentricity_mm") and t.has("K1"):
        a, K = t.number("eccentricity_mm", positive=True), t.number("K1", positive=True)
        if abs(K - a * zb / R) > 1e-9 * max(1.0, K):
            raise ConfigError(
                f"{t.where} K1: {K:g} disagrees with eccentricity_mm × z_pins / pin_circle_radius_mm = {a * zb / R:.9g}; give one of them"
            )
        K = None
    else:
        a = t.number("eccentricity_mm", positive=True) if t.has("eccentricity_mm") else None
        K = t.number("K1", positive=True) if t.has("K1") else None
        if a is None and K is None:
            raise ConfigError(f"{t.where}: missing `eccentricity_mm` (crank eccentricity a, mm) or `K1` (= a z_b / R_z)")
    process = PROCESSES[t.string("process", "form", choices=tuple(PROCESSES))]()
    kw: dict[str, Any] = {"z_pins": zb, "z_lobes": zl, "pin_circle_radius": R, "pin_radius": r, "eccentricity": a, "K1": K}
    kw["process"] = process
    if t.has("wheel") and t.has("modification"):
        raise ConfigError(f"{t.where}: give [drive.wheel] (R_Z, r_Z) or [drive.modification] (shift, equidistant), not both")
    if t.has("wheel"):
        w = t.table("wheel")
        RZ = w.number("pin_circle_radius_mm", positive=True)
        rZ = w.number("pin_radius_mm", positive=True)
        rot = w.number("rotation_arcsec", 0.0) / ARCSEC_PER_RAD
        w.finish()
        kw["modification"] = CycloidModification(RZ - R, rZ - r, rot)
    elif t.has("modification"):
        m = t.table("modification")
        kw["modification"] = CycloidModification(
            m.number("shift_mm", 0.0), m.number("equidistant_mm", 0.0), m.number("rotation_arcsec", 0.0) / ARCSEC_PER_RAD
        )
        m.finish()
    kw["analysis"] = _analysis(t, zb)
    # z_b − 1 spaces whatever z_lobes says (the constructor refuses z_lobes ≠ z_b − 1, naming both); sizing the
    # per-space tables by an unchecked z_lobes would let a wrong count exhaust memory before that message.
    counts = {"space": zb - 1, "pin": zb}
    kw["reference"], given = reference_errors(_sub(t, "reference"), counts, process.fields)
    kw["reference_record"] = json.dumps(given)
    return kw


def _revolutions(t: Table, z_pins: int) -> int:
    """A table's input `revolutions` (default 1): at most z_a = z_pins − 1, after which pins and tooth spaces pair again."""
    revs = t.integer("revolutions", 1, minimum=1)
    if revs > z_pins - 1:
        raise ConfigError(
            f"{t.where} revolutions: the pairing of pins and tooth spaces repeats after z_a = {z_pins - 1} "
            f"input revolutions; give at most {z_pins - 1}, got {revs}"
        )
    return revs


def _analysis(t: Table, z_pins: int) -> dict[str, Any]:
    an = t.table("analysis")
    budget = an.number("deformation_budget_mm", minimum=0)
    width = an.number("smoothing_width_mm", positive=True) if an.has("smoothing_width_mm") else None
    angle = math.radians(an.number("input_angle_deg")) if an.has("input_angle_deg") else None
    # Counts that size the grids (the cost of every sample grows with them): generous bounds, so that a slip of a few
    # digits is refused here rather than found after hours.
    pitch_points = an.integer("pitch_points", 64, minimum=2, maximum=65_536)
    sweep_ppp = an.integer("revolution_points_per_pitch", 16, minimum=1, maximum=4096)
    revs = _revolutions(an, z_pins)
    normal = an.boolean("monte_carlo_normal", True)
    an.finish()
    g = _sub(t, "grid")
    ppp = g.integer("positions_per_pitch", 2, minimum=1, maximum=4096)
    grid_revs = _revolutions(g, z_pins)
    g.finish()
    return dict(
        budget_mm=budget,
        width_mm=width,
        positions_per_pitch=ppp,
        revolutions=grid_revs,
        input_angle=angle,
        pitch_points=pitch_points,
        sweep_points_per_pitch=sweep_ppp,
        sweep_revolutions=revs,
        normal=normal,
    )


def _field_key(t: Table, field: str) -> str | None:
    """The key naming `field` in table `t` (FIELD_um / FIELD_arcsec / FIELD_deg), checking the unit suffix."""
    unit = unit_of(field)
    want = f"{field}_{unit}"
    for other in ("um", "arcsec", "deg", "mm", "rad"):
        k = f"{field}_{other}"
        if other != unit and t.has(k):
            t.used.add(k)
            raise ConfigError(f"{t.where} {k}: give this error as `{want}` ({'µm' if unit == 'um' else unit})")
    return want if t.has(want) else None


#: Largest size of a ``[drive.reference]`` value in each unit: 100 mm (`gearte.core.schema.MAX_MICROMETRES`), a full
#: turn of arc seconds; phases (deg) are angles of any size.
_LIMITS = {"um": MAX_MICROMETRES, "arcsec": 360.0 * 3600.0}


def _in_range(t: Table, key: str, unit: str, x: float) -> None:
    limit = _LIMITS.get(unit)
    if limit is not None and abs(x) > limit:
        raise ConfigError(f"{t.where} {key}: {x:g} is larger than {limit:,.0f} {unit} in size; check the unit of the key")


def reference_errors(t: Table, counts: dict[str, int], fields: tuple[str, ...] = ERROR_FIELDS) -> tuple[dict[str, Any], dict[str, Any]]:
    """The error fields of ``[drive.reference]`` (internal units) and how they were given (for summaries).

    `counts`: ``{"space": z_a, "pin": z_b}``; `fields`: the error fields of the disc's process.
    """
    values, given = {}, {}
    for field in fields:
        key = _field_key(t, field)
        if key is None:
            continue
        unit = unit_of(field)
        scale = TO_INTERNAL[unit]
        v = t.get(key)
        count = counts["space"] if field in PER_SPACE else counts["pin"] if field in PER_PIN else None
        if isinstance(v, bool):
            raise ConfigError(f"{t.where} {key}: expected a number, got {v!r}")
        if isinstance(v, (int, float)):
            x = float(v)
            if not math.isfinite(x):
                raise ConfigError(f"{t.where} {key}: must be finite, got {v}")
            _in_range(t, key, unit, x)
            values[field] = x * scale
            given[key] = x
        elif isinstance(v, list):
            if count is None:
                raise ConfigError(f"{t.where} {key}: a single value is expected here, got a list")
            if len(v) != count or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
                raise ConfigError(
                    f"{t.where} {key}: give {count} finite numbers (one per {'tooth space' if field in PER_SPACE else 'pin'}), "
                    f"got {len(v)} values"
                )
            _in_range(t, key, unit, max(v, key=abs))
            values[field] = np.asarray(v, dtype=float) * scale
            given[key] = list(map(float, v))
        elif isinstance(v, dict):
            if count is None:
                raise ConfigError(
                    f"{t.where} {key}: a pattern table is only for per-space or per-pin errors ({', '.join(PER_SPACE + PER_PIN)})"
                )
            pt = Table(v, f"{t.where} {key}")
            amp = pt.number(f"amplitude_{unit}")
            _in_range(t, f"{key} amplitude_{unit}", unit, amp)
            phase = math.radians(pt.number("phase_deg", 0.0))
            order = pt.integer("order", 1, minimum=1)
            pt.finish()
            k = np.arange(1, count + 1)
            values[field] = amp * scale * np.sin(2 * math.pi * order * k / count + phase)
            given[key] = {f"amplitude_{unit}": amp, "phase_deg": math.degrees(phase), "order": order}
        else:
            raise ConfigError(f"{t.where} {key}: expected a number, a list or a table, got {v!r}")
    t.finish()
    return values, given


__all__ = ("TO_INTERNAL", "drive_arguments", "reference_errors", "unit_of")
