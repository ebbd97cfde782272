"""`gearte run` for a cycloid-pin reducer: a study file with ``[drive] type = "cycloid_pin"``.

    [study]                      name, title, description, samples, seed, notes
    [drive]                      type = "cycloid_pin", z_pins, z_lobes (optional, = z_pins − 1),
                                 pin_circle_radius_mm, pin_radius_mm, eccentricity_mm (or K1)
    [drive.wheel]                the profile the grinding wheel is dressed to:
                                 pin_circle_radius_mm (R_Z), pin_radius_mm (r_Z), rotation_arcsec (optional)
      (or [drive.modification]   shift_mm, equidistant_mm, rotation_arcsec)
    [analysis]                   deformation_budget_mm, input_angle_deg (default half a pin pitch),
                                 pitch_points (64), revolution_points_per_pitch (16), revolutions (1)
    [errors]                     the reducer analysed: FIELD_um / FIELD_arcsec / FIELD_deg per `CycloidErrors`
                                 field (a number; per space or pin also a list, or a table
                                 { amplitude_um | amplitude_arcsec, phase_deg, order } for A sin(2π·order·n/N + φ))
    [tolerances]                 optional, the Monte Carlo: FIELD = { law = ..., ... } (see `_law`)
    [monte_carlo]                positions_per_pitch (2), revolutions (1), normal (true)
    [sensitivity]                samples (64; tolerance sensitivities by Monte Carlo; 0 turns them off)
    [optimise]                   optional: lost_motion_max_arcmin, lost_motion_min_arcmin (0),
                                 radial_clearance_min_mm (0), rotation (false), positions_per_pitch (2)

Outputs (written atomically): summary.json, report.md, clearance_per_pin.png,
clearance_vs_input.png, rotation_error.png, curves.npz and, with tolerances, samples.npz and
monte_carlo.png.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import platform
import time
import tomllib
import warnings
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ._config import ConfigError, _Table, read_toml, study_header
from ._distributions import FixedPhase, Normal, Rayleigh, TruncatedNormal, UniformPhase
from ._io import atomic_output_dir, write_json
from ._montecarlo import monte_carlo, statistics
from .drives.cycloid_pin import (ERROR_FIELDS, PER_PIN, PER_SPACE, CycloidErrors, CycloidPin, CycloidModification, clearances,
                                 loaded_pairs, pitch_angles, revolution_angles, sweep, theoretical_pairs)
from .drives.cycloid_pin_studies import (CycloidStudy, CycloidTolerances, Exactly, SignedUniform, Sinusoid, sensitivities,
                                         tolerance_gradient_rows, tolerance_sensitivities)
from .units import ARCMIN_PER_RAD, ARCSEC_PER_RAD

DRIVE_TYPE = "cycloid_pin"


def drive_type(path: str | Path) -> str | None:
    """The ``[drive] type`` of a study file, or None if it cannot be read (the normal loader then reports why)."""
    try:
        raw = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None
    drive = raw.get("drive") if isinstance(raw, dict) else None
    t = drive.get("type") if isinstance(drive, dict) else None
    return t if isinstance(t, str) else None


# ---------------------------------------------------------------- units of the error fields


def _unit_of(field: str) -> str:
    if field.endswith("_phase"):
        return "deg"
    if field in ("index_offset", "indexing"):
        return "arcsec"
    return "um"


_TO_INTERNAL = {"um": 1.0, "arcsec": 1.0 / ARCSEC_PER_RAD, "deg": math.pi / 180.0}


@dataclasses.dataclass(frozen=True)
class CycloidStudyConfig:
    """A validated cycloid-pin study."""

    name: str
    title: str
    description: str
    samples: int
    seed: int
    chunk_size: int | None
    notes: tuple[str, ...]
    drive: CycloidPin
    errors: CycloidErrors
    errors_given: dict[str, Any]
    tolerances: CycloidTolerances | None
    budget_mm: float
    input_angle: float
    pitch_points: int
    revolution_points_per_pitch: int
    revolutions: int
    mc_positions_per_pitch: int
    mc_revolutions: int
    mc_normal: bool
    sensitivity_samples: int
    optimise: dict | None
    source_path: str


# ---------------------------------------------------------------- reading the file


def load_cycloid_study(path: str | Path, *, samples: int | None = None, seed: int | None = None) -> CycloidStudyConfig:
    """Read and validate a cycloid-pin study file; `samples` and `seed` override the file's."""
    path = Path(path)
    raw = read_toml(path)
    try:
        return _build(raw, str(path), samples=samples, seed=seed)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def _build(raw: dict, source: str, *, samples: int | None, seed: int | None) -> CycloidStudyConfig:
    top = _Table(raw, "config")
    st = top.table("study")
    h = study_header(st, samples=samples, seed=seed)
    name, title, description, n, s, chunk, notes = (h[k] for k in ("name", "title", "description", "samples", "seed", "chunk_size", "notes"))
    st.finish()

    drive = _drive(top.table("drive"))

    an = top.table("analysis")
    budget = an.number("deformation_budget_mm", minimum=0)
    input_angle = math.radians(an.number("input_angle_deg")) if an.has("input_angle_deg") else drive.pitch / 2
    pitch_points = an.integer("pitch_points", 64, minimum=2)
    rev_ppp = an.integer("revolution_points_per_pitch", 16, minimum=1)
    revs = an.integer("revolutions", 1, minimum=1)
    if revs > drive.z_lobes:
        raise ConfigError(f"[analysis] revolutions: the pairing of pins and tooth spaces repeats after z_a = {drive.z_lobes} "
                          f"input revolutions; give at most {drive.z_lobes}, got {revs}")
    an.finish()

    errors, given = _errors(top.table("errors", {}) if top.has("errors") else _Table({}, "[errors]"), drive)
    tolerances = _tolerances(top.table("tolerances"), drive) if top.has("tolerances") else None

    mc = top.table("monte_carlo") if top.has("monte_carlo") else _Table({}, "[monte_carlo]")
    mc_ppp = mc.integer("positions_per_pitch", 2, minimum=1)
    mc_revs = mc.integer("revolutions", 1, minimum=1)
    mc_normal = mc.boolean("normal", True)
    mc.finish()

    se = top.table("sensitivity") if top.has("sensitivity") else _Table({}, "[sensitivity]")
    sens_samples = se.integer("samples", 64, minimum=0)
    se.finish()

    opt = None
    if top.has("optimise"):
        ot = top.table("optimise")
        lm_hi = ot.number("lost_motion_max_arcmin", positive=True)
        lm_lo = ot.number("lost_motion_min_arcmin", 0.0, minimum=0)
        if not lm_hi > lm_lo:
            raise ConfigError(f"[optimise] lost_motion_max_arcmin: must exceed lost_motion_min_arcmin ({lm_lo:g}′), got {lm_hi:g}′")
        opt = {"lost_motion_max_arcmin": lm_hi, "lost_motion_min_arcmin": lm_lo,
               "radial_clearance_min_mm": ot.number("radial_clearance_min_mm", 0.0, minimum=0),
               "rotation": ot.boolean("rotation", False), "positions_per_pitch": ot.integer("positions_per_pitch", 2, minimum=1)}
        ot.finish()
    top.finish()
    return CycloidStudyConfig(name=name, title=title, description=description, samples=n, seed=s, chunk_size=chunk,
                              notes=tuple(notes), drive=drive, errors=errors, errors_given=given, tolerances=tolerances,
                              budget_mm=budget, input_angle=input_angle, pitch_points=pitch_points,
                              revolution_points_per_pitch=rev_ppp, revolutions=revs, mc_positions_per_pitch=mc_ppp,
                              mc_revolutions=mc_revs, mc_normal=mc_normal, sensitivity_samples=sens_samples, optimise=opt,
                              source_path=source)


def _drive(t: _Table) -> CycloidPin:
    t.string("type", choices=(DRIVE_TYPE,))
    zb = t.integer("z_pins", minimum=1)
    zl = t.integer("z_lobes", minimum=1) if t.has("z_lobes") else None
    R = t.number("pin_circle_radius_mm", positive=True)
    r = t.number("pin_radius_mm", positive=True)
    if t.has("eccentricity_mm") and t.has("K1"):
        a, K = t.number("eccentricity_mm", positive=True), t.number("K1", positive=True)
        if abs(K - a * zb / R) > 1e-9 * max(1.0, K):
            raise ConfigError(f"{t.where} K1: {K:g} disagrees with eccentricity_mm × z_pins / pin_circle_radius_mm = "
                              f"{a * zb / R:.9g}; give one of them")
        K = None
    else:
        a = t.number("eccentricity_mm", positive=True) if t.has("eccentricity_mm") else None
        K = t.number("K1", positive=True) if t.has("K1") else None
        if a is None and K is None:
            raise ConfigError(f"{t.where}: missing `eccentricity_mm` (crank eccentricity a, mm) or `K1` (= a z_b / R_z)")
    kw: dict[str, Any] = {}
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
        kw["modification"] = CycloidModification(m.number("shift_mm", 0.0), m.number("equidistant_mm", 0.0),
                                          m.number("rotation_arcsec", 0.0) / ARCSEC_PER_RAD)
        m.finish()
    try:
        return CycloidPin(zb, pin_circle_radius=R, pin_radius=r, eccentricity=a, K1=K, z_lobes=zl, **kw)
    except ValueError as e:
        raise ConfigError(f"{t.where} {e}") from None


def _field_key(t: _Table, field: str) -> str | None:
    """The key naming `field` in table `t` (FIELD_um / FIELD_arcsec / FIELD_deg), checking the unit suffix."""
    unit = _unit_of(field)
    want = f"{field}_{unit}"
    for other in ("um", "arcsec", "deg", "mm", "rad"):
        k = f"{field}_{other}"
        if other != unit and t.has(k):
            t.used.add(k)
            raise ConfigError(f"{t.where} {k}: give this error as `{want}` ({'µm' if unit == 'um' else unit})")
    return want if t.has(want) else None


def _errors(t: _Table, drive: CycloidPin) -> tuple[CycloidErrors, dict]:
    values, given = {}, {}
    for field in ERROR_FIELDS:
        key = _field_key(t, field)
        if key is None:
            continue
        unit = _unit_of(field)
        scale = _TO_INTERNAL[unit]
        v = t.get(key)
        count = drive.z_lobes if field in PER_SPACE else drive.z_pins if field in PER_PIN else None
        if isinstance(v, bool):
            raise ConfigError(f"{t.where} {key}: expected a number, got {v!r}")
        if isinstance(v, (int, float)):
            x = float(v)
            if not math.isfinite(x):
                raise ConfigError(f"{t.where} {key}: must be finite, got {v}")
            values[field] = x * scale
            given[key] = x
        elif isinstance(v, list):
            if count is None:
                raise ConfigError(f"{t.where} {key}: a single value is expected here, got a list")
            if len(v) != count or not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
                raise ConfigError(f"{t.where} {key}: give {count} finite numbers (one per {'tooth space' if field in PER_SPACE else 'pin'}), "
                                  f"got {len(v)} values")
            values[field] = np.asarray(v, dtype=float) * scale
            given[key] = list(map(float, v))
        elif isinstance(v, dict):
            if count is None:
                raise ConfigError(f"{t.where} {key}: a pattern table is only for per-space or per-pin errors ({', '.join(PER_SPACE + PER_PIN)})")
            pt = _Table(v, f"{t.where} {key}")
            amp = pt.number(f"amplitude_{unit}")
            phase = math.radians(pt.number("phase_deg", 0.0))
            order = pt.integer("order", 1, minimum=1)
            pt.finish()
            k = np.arange(1, count + 1)
            values[field] = amp * scale * np.sin(2 * math.pi * order * k / count + phase)
            given[key] = {f"amplitude_{unit}": amp, "phase_deg": math.degrees(phase), "order": order}
        else:
            raise ConfigError(f"{t.where} {key}: expected a number, a list or a table, got {v!r}")
    t.finish()
    return CycloidErrors(**values), given


def _law(t: _Table, field: str, count: int | None):
    unit = _unit_of(field)
    scale = _TO_INTERNAL[unit]
    u = unit
    if field.endswith("_phase"):
        law = t.string("law", choices=("uniform", "fixed"))
        if law == "uniform":
            return UniformPhase()
        return FixedPhase(math.radians(t.number("value_deg")))
    law = t.string("law", choices=("fixed", "uniform", "normal", "truncated_normal", "rayleigh", "sinusoid"))
    try:
        if law == "fixed":
            return Exactly(t.number(f"value_{u}") * scale)
        if law == "uniform":
            if t.has(f"half_width_{u}"):
                if t.has(f"low_{u}") or t.has(f"high_{u}"):
                    raise ConfigError(f"{t.where}: give `half_width_{u}` (and `centre_{u}`) or `low_{u}` and `high_{u}`, not both")
                return SignedUniform(t.number(f"half_width_{u}", minimum=0) * scale, t.number(f"centre_{u}", 0.0) * scale)
            lo, hi = t.number(f"low_{u}"), t.number(f"high_{u}")
            if not hi >= lo:
                raise ConfigError(f"{t.where} high_{u}: must be ≥ low_{u} ({lo:g}), got {hi:g}")
            return SignedUniform(0.5 * (hi - lo) * scale, 0.5 * (hi + lo) * scale)
        if law == "normal":
            return Normal(t.number(f"mean_{u}") * scale, t.number(f"std_{u}", minimum=0) * scale)
        if law == "truncated_normal":
            return TruncatedNormal(t.number(f"mean_{u}") * scale, t.number(f"std_{u}", positive=True) * scale,
                                   t.number(f"low_{u}") * scale, t.number(f"high_{u}") * scale)
        if law == "rayleigh":
            trunc = t.number(f"truncate_at_{u}", positive=True) * scale if t.has(f"truncate_at_{u}") else None
            return Rayleigh(t.number(f"scale_{u}", positive=True) * scale, trunc)
        # sinusoid pattern over spaces / pins
        if count is None:
            raise ConfigError(f"{t.where} law: 'sinusoid' is only for per-space or per-pin errors ({', '.join(PER_SPACE + PER_PIN)})")
        if t.has("amplitude"):
            amp = _law(t.table("amplitude"), field, None)
            if isinstance(amp, Sinusoid):
                raise ConfigError(f"{t.where} amplitude: the amplitude of a pattern cannot itself be a pattern")
        else:
            amp = Exactly(t.number(f"amplitude_{u}") * scale)
        if t.has("phase_deg") and t.has("phase"):
            raise ConfigError(f"{t.where}: give `phase_deg` (fixed) or `phase = \"uniform\"`, not both")
        if t.has("phase"):
            t.string("phase", choices=("uniform",))
            phase = UniformPhase()
        else:
            phase = FixedPhase(math.radians(t.number("phase_deg", 0.0)))
        return Sinusoid(amp, phase, order=t.integer("order", 1, minimum=1))
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(f"{t.where}: {e}") from None


def _tolerances(t: _Table, drive: CycloidPin) -> CycloidTolerances:
    laws = {}
    for field in ERROR_FIELDS:
        if not t.has(field):
            continue
        lt = t.table(field)
        lt.where = f"[tolerances.{field}]"
        count = drive.z_lobes if field in PER_SPACE else drive.z_pins if field in PER_PIN else None
        laws[field] = _law(lt, field, count)
        lt.finish()
    t.finish()
    return CycloidTolerances(**laws)


# ---------------------------------------------------------------- running


def _versions() -> dict:
    import equinox
    import optimistix

    from . import __version__

    return {"gearte": __version__, "jax": jax.__version__, "equinox": equinox.__version__,
            "optimistix": optimistix.__version__, "numpy": np.__version__, "python": platform.python_version()}


def _num(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def run_cycloid_study(study: CycloidStudyConfig, out: str | Path, *, progress: bool | None = None,
                      command: str | None = None) -> dict:
    """Run a cycloid-pin study and write its results folder `out` atomically. Returns the summary dict."""
    from . import plotting

    t_start = time.perf_counter()
    d, err = study.drive, study.errors
    zb = d.z_pins
    budget = study.budget_mm
    ARCSEC, ARCMIN = ARCSEC_PER_RAD, ARCMIN_PER_RAD

    # The reducer analysed: one position, one pitch, the revolution.
    at = clearances(d, err, study.input_angle)
    pitch = sweep(d, err, pitch_angles(d, study.pitch_points, start=0.0))
    rev_angles = revolution_angles(d, study.revolution_points_per_pitch, revolutions=study.revolutions)
    rev = sweep(d, err, rev_angles, normal=False)
    conv = bool(np.all(np.asarray(at.converged)) and np.all(np.asarray(pitch.converged)) and np.all(np.asarray(rev.converged)))

    arc = np.asarray(at.tangential_arc)
    tang = np.asarray(at.tangential_clearance)
    normal = np.asarray(at.normal_clearance)
    drv = np.asarray(at.on_driving_flank)
    space = np.asarray(at.space)
    rot = np.asarray(at.rotation_to_contact)
    loaded_mask = drv & (arc <= budget * (1 + 1e-12) + 1e-12)
    pairs = [{"pin": j + 1, "tooth_space": int(space[j]) + 1, "flank": "driving" if drv[j] else "reverse",
              "on_driving_flank": bool(drv[j]), "can_touch": bool(np.isfinite(arc[j])),
              "tangential_clearance_mm": _num(arc[j]), "tangential_clearance_arcsec": _num(tang[j] * ARCSEC),
              "normal_clearance_mm": float(normal[j]), "rotation_to_contact_arcsec": _num(rot[j] * ARCSEC),
              "loaded": bool(loaded_mask[j])} for j in range(zb)]
    n_loaded = int(loaded_pairs(at, budget_mm=budget))
    pitch_loaded = np.asarray(loaded_pairs(pitch, budget_mm=budget))
    rev_loaded = np.asarray(loaded_pairs(rev, budget_mm=budget))
    te_f = np.asarray(rev.rotation_error) * ARCSEC
    te_r = np.asarray(rev.reverse_rotation_error) * ARCSEC
    lm = np.asarray(rev.lost_motion) * ARCMIN
    ci, ri = int(at.contact_pin), int(at.reverse_contact_pin)

    summary: dict[str, Any] = {
        "gearte_version": _versions()["gearte"],
        "study": {"name": study.name, "title": study.title, "description": study.description, "config": study.source_path,
                  "command": command},
        "drive": dict(d.describe()) | {"type": DRIVE_TYPE},
        "errors": study.errors_given,
        "input_angle_deg": math.degrees(study.input_angle),
        "deformation_budget_mm": budget,
        "pairs": pairs,
        "contact_pair": {"pin": ci + 1, "tooth_space": int(space[ci]) + 1, "flank": "driving"},
        "reverse_contact_pair": {"pin": ri + 1, "tooth_space": int(space[ri]) + 1, "flank": "reverse"},
        "loaded_pairs": n_loaded,
        "loaded_pairs_out_of": theoretical_pairs(d),
        "loaded_pairs_over_pitch": {"min": int(pitch_loaded.min()), "max": int(pitch_loaded.max()), "mean": float(pitch_loaded.mean())},
        "loaded_pairs_over_revolution": {"min": int(rev_loaded.min()), "max": int(rev_loaded.max()), "mean": float(rev_loaded.mean())},
        "lost_motion_arcmin": float(lm.max()),
        "lost_motion_range_arcmin": [float(lm.min()), float(lm.max())],
        "lost_motion_at_input_angle_arcmin": float(at.lost_motion) * ARCMIN,
        "interference": bool(lm.min() < 0),
        "rotation_error_p2p_arcsec": float(te_f.max() - te_f.min()),
        "rotation_error_reverse_p2p_arcsec": float(te_r.max() - te_r.min()),
        "rotation_error_at_input_angle_arcsec": float(at.rotation_error) * ARCSEC,
        "rotation_error_mean_arcsec": float(te_f.mean()),
        "sweep": {"pitch_points": study.pitch_points, "revolution_points_per_pitch": study.revolution_points_per_pitch,
                  "revolutions": study.revolutions, "all_solves_converged": conv},
        "assumptions": {
            "frame": "converted mechanism (arm fixed); pins numbered 1…z_b counter-clockwise from the crank direction at "
                     "θ_T = 0; the input angle θ_T turns the pin wheel relative to the arm",
            "driving_flank": "the tooth-space half whose contacts push the disc clockwise; a forward load holds the disc "
                             "against the driving flanks",
            "rotation_error": "Δθ = θ_a − (z_b/z_a) θ_T of the contacting pair = output rotation error",
            "lost_motion": "driving contact − reverse contact with the input held; the headline is its maximum over "
                           "the revolution sweep",
            "tangential_clearance": "from the contact of the pin's own flank (forward load for driving pins, reverse "
                                    "for reverse pins), as an angle of the output and × R′ on the pin circle",
            "normal_clearance": "min over the pin's flank of |pin centre − flank point| − r′, at that contacting configuration",
            "loaded_pairs": "driving-flank pins whose tangential clearance on the pin circle ≤ the deformation budget",
            "precision": "float64 throughout (jax_enable_x64)",
            "notes": list(study.notes),
        },
        "versions": _versions(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "timing_s": {},
    }

    # Sensitivities of the reducer analysed (gradients, over the revolution sweep at 2 points per pitch).
    t0 = time.perf_counter()
    sens_pos = revolution_angles(d, 2, revolutions=study.revolutions)
    sens = sensitivities(d, err, budget_mm=budget, positions=sens_pos,
                         metrics=("lost_motion_max", "rotation_error_p2p", "loaded_pairs_smooth"))
    summary["sensitivities"] = _sensitivity_summary(sens)
    summary["timing_s"]["sensitivities"] = time.perf_counter() - t0

    mc_values = None
    study_fn = None
    if study.tolerances is not None:
        t0 = time.perf_counter()
        positions = revolution_angles(d, study.mc_positions_per_pitch, revolutions=study.mc_revolutions)
        study_fn = CycloidStudy(d, study.tolerances, budget_mm=budget, positions=positions,
                                analysis_angle=study.input_angle, normal=study.mc_normal)
        mc = monte_carlo(study_fn, key=study.seed, n_samples=study.samples, chunk_size=study.chunk_size,
                         progress=progress, desc=study.name)
        mc_values = study_fn.unpack(mc.values)
        summary["monte_carlo"] = _mc_summary(study, mc_values, mc, positions)
        summary["timing_s"]["monte_carlo"] = mc.seconds
        if study.sensitivity_samples > 0:
            t0 = time.perf_counter()
            ts = tolerance_sensitivities(d, study.tolerances, key=study.seed, n_samples=study.sensitivity_samples,
                                         budget_mm=budget, positions=positions,
                                         metrics=("lost_motion_max", "rotation_error_p2p", "loaded_pairs_smooth"))
            summary["tolerance_sensitivities"] = _tolerance_sensitivity_summary(study, ts)
            summary["timing_s"]["tolerance_sensitivities"] = time.perf_counter() - t0

    if study.optimise is not None:
        from .drives.cycloid_pin_optimise import optimise_modification

        t0 = time.perf_counter()
        o = study.optimise
        res = optimise_modification(d, err, lost_motion_max=o["lost_motion_max_arcmin"] / ARCMIN,
                                    lost_motion_min=o["lost_motion_min_arcmin"] / ARCMIN,
                                    radial_clearance_min=o["radial_clearance_min_mm"], budget_mm=budget,
                                    positions=revolution_angles(d, o["positions_per_pitch"], revolutions=study.revolutions),
                                    rotation=o["rotation"])
        summary["optimised_modification"] = _optimise_summary(d, o, res)
        summary["timing_s"]["optimise"] = time.perf_counter() - t0

    with atomic_output_dir(out) as tmp:
        plotting.cycloid_clearance_per_pin(arc, normal, drv, budget_mm=budget, contact_pin=ci + 1, reverse_contact_pin=ri + 1,
                                           title=f"{study.name}: clearances at θ_T = {math.degrees(study.input_angle):.4g}°; "
                                                 f"{n_loaded} of {theoretical_pairs(d)} driving pairs within {budget:g} mm",
                                           path=tmp / "clearance_per_pin.png")
        pdeg = np.degrees(np.asarray(pitch.input_angle))
        drive_pins = [j + 1 for j in range(zb) if bool(np.all(np.asarray(pitch.on_driving_flank)[:, j]))]
        plotting.cycloid_clearance_vs_input(pdeg, np.asarray(pitch.tangential_arc), np.asarray(pitch.normal_clearance),
                                            drive_pins, budget_mm=budget, path=tmp / "clearance_vs_input.png",
                                            title=f"{study.name}: driving-flank pairs over one pin pitch (cf. the seed's figures 3–8)")
        plotting.cycloid_rotation_error(np.asarray(rev_angles) / (2 * math.pi), te_f, te_r, path=tmp / "rotation_error.png",
                                        title=f"{study.name}: rotation error over {study.revolutions} input revolution(s), "
                                              f"lost motion {lm.min():.2f}′ … {lm.max():.2f}′")
        np.savez_compressed(tmp / "curves.npz", pitch_input_angle_rad=np.asarray(pitch.input_angle),
                            pitch_tangential_clearance_mm=np.asarray(pitch.tangential_arc),
                            pitch_normal_clearance_mm=np.asarray(pitch.normal_clearance),
                            pitch_on_driving_flank=np.asarray(pitch.on_driving_flank),
                            revolution_input_angle_rad=np.asarray(rev_angles), rotation_error_arcsec=te_f,
                            reverse_rotation_error_arcsec=te_r, lost_motion_arcmin=lm, contact_pin=np.asarray(rev.contact_pin) + 1)
        if mc_values is not None:
            plotting.cycloid_distributions(
                [("lost motion, max over the cycle (′)", mc_values["lost_motion_max"] * ARCMIN, "′"),
                 ("rotation error p-p (″)", mc_values["rotation_error_p2p"] * ARCSEC, "″"),
                 (f"loaded pairs at θ_T (of {theoretical_pairs(d)})", mc_values["loaded_pairs"], "")],
                title=f"{study.name}: Monte Carlo over {study.samples:,} reducers", path=tmp / "monte_carlo.png")
            np.savez_compressed(tmp / "samples.npz", seed=study.seed, index=np.arange(study.samples),
                                lost_motion_max_arcmin=mc_values["lost_motion_max"] * ARCMIN,
                                lost_motion_min_arcmin=mc_values["lost_motion_min"] * ARCMIN,
                                rotation_error_p2p_arcsec=mc_values["rotation_error_p2p"] * ARCSEC,
                                loaded_pairs=mc_values["loaded_pairs"], loaded_pairs_min=mc_values["loaded_pairs_min"],
                                contact_pin=mc_values["contact_pin"] + 1, tangential_clearance_mm=mc_values["tangential_arc"],
                                normal_clearance_mm=mc_values["normal_clearance"])
        summary["timing_s"]["total"] = time.perf_counter() - t_start
        (tmp / "report.md").write_text(_report(study, summary), encoding="utf-8")
        write_json(tmp / "summary.json", summary)
    return summary


def _sensitivity_summary(sens) -> dict:
    units = {"lost_motion_max": ("arcmin", ARCMIN_PER_RAD), "rotation_error_p2p": ("arcsec", ARCSEC_PER_RAD),
             "loaded_pairs_smooth": ("pairs", 1.0)}
    out = {}
    for name, s in sens.items():
        unit, k = units[name]
        rows = {}
        for field in ERROR_FIELDS:
            g = float(np.sum(np.asarray(getattr(s.errors, field))))
            u = _unit_of(field)
            per = {"um": "µm", "arcsec": "″", "deg": "°"}[u]
            rows[field] = {"per": per, "value": g * k * _TO_INTERNAL[u]}
        m = s.modification
        rows["modification.shift"] = {"per": "mm", "value": float(m.shift) * k}
        rows["modification.equidistant"] = {"per": "mm", "value": float(m.equidistant) * k}
        rows["modification.rotation"] = {"per": "″", "value": float(m.rotation) * k / ARCSEC_PER_RAD}
        out[name] = {"unit": unit, "value": float(s.value) * k, "derivatives": rows}
    return out


def _stats(v, unit: str) -> dict:
    v = np.asarray(v, dtype=float)
    return statistics(v[np.isfinite(v)], unit=unit).to_dict()


def _mc_summary(study: CycloidStudyConfig, u: dict, mc, positions) -> dict:
    zb = study.drive.z_pins
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        arc = u["tangential_arc"]
        nrm = u["normal_clearance"]
        per_pin = []
        for j in range(zb):
            a = arc[:, j]
            fin = np.isfinite(a)
            per_pin.append({"pin": j + 1, "can_touch_fraction": float(np.mean(fin)),
                            "tangential_clearance_mm": {"mean": _num(np.nanmean(a)) if fin.any() else None,
                                                        "p5": _num(np.nanpercentile(a, 5)) if fin.any() else None,
                                                        "p95": _num(np.nanpercentile(a, 95)) if fin.any() else None},
                            "normal_clearance_mm": {"mean": _num(np.nanmean(nrm[:, j])), "p5": _num(np.nanpercentile(nrm[:, j], 5)),
                                                    "p95": _num(np.nanpercentile(nrm[:, j], 95))}})
    counts = np.bincount(u["loaded_pairs"].astype(int), minlength=zb // 2 + 1)
    return {"samples": study.samples, "seed": study.seed, "chunk_size": mc.chunk_size, "block_size": mc.block_size,
            "positions": {"count": int(np.size(positions)), "per_pitch": study.mc_positions_per_pitch,
                          "revolutions": study.mc_revolutions},
            "tolerances": dict(study.tolerances.describe()),
            "lost_motion_max_arcmin": _stats(u["lost_motion_max"] * ARCMIN_PER_RAD, "arcmin"),
            "lost_motion_min_arcmin": _stats(u["lost_motion_min"] * ARCMIN_PER_RAD, "arcmin"),
            "rotation_error_p2p_arcsec": _stats(u["rotation_error_p2p"] * ARCSEC_PER_RAD, "arcsec"),
            "loaded_pairs": _stats(u["loaded_pairs"], "pairs") | {"histogram": {str(i): int(c) for i, c in enumerate(counts) if c}},
            "loaded_pairs_min_over_cycle": _stats(u["loaded_pairs_min"], "pairs"),
            "interference_fraction": float(np.mean(u["lost_motion_min"] < 0)),
            # For a reducer that interferes somewhere the rigid contacts are not those of the deformed reducer.
            "loaded_pairs_without_interference": (_stats(u["loaded_pairs"][u["lost_motion_min"] >= 0], "pairs")
                                                  if np.any(u["lost_motion_min"] >= 0) else None),
            "not_converged_solves": int(np.sum(u["not_converged"])),
            "per_pin_at_input_angle": per_pin}


def _tolerance_sensitivity_summary(study: CycloidStudyConfig, ts) -> dict:
    units = {"lost_motion_max": ("arcmin", ARCMIN_PER_RAD), "rotation_error_p2p": ("arcsec", ARCSEC_PER_RAD),
             "loaded_pairs_smooth": ("pairs", 1.0)}
    given = {name for name, _ in study.tolerances.describe()}
    out = {"samples": study.sensitivity_samples, "what": "d(mean over reducers)/d(law parameter), pathwise (reparametrised draws)"}
    for name, (mean, grad) in ts.items():
        unit, k = units[name]
        rows = {}
        for label, g in tolerance_gradient_rows(grad):
            field = label.split(".")[0]
            if field not in given:
                continue
            u = _unit_of(field)
            scale = _TO_INTERNAL[u] if not label.endswith(".value") or not field.endswith("_phase") else math.pi / 180
            per = {"um": "µm", "arcsec": "″", "deg": "°"}[u]
            rows[label] = {"per": per, "value": g * k * scale}
        out[name] = {"unit": unit, "mean": float(mean) * k, "derivatives": rows}
    return out


def _optimise_summary(d: CycloidPin, o: dict, res) -> dict:
    R = float(d.pin_circle_radius)

    def row(end, s, results=(), steps=()):
        r = {"shift_mm": end[0], "equidistant_mm": end[1], "wheel_pin_circle_radius_mm": R + end[0],
             "wheel_pin_radius_mm": float(d.pin_radius) + end[1],
             "loaded_pairs_min": s.loaded_pairs_min, "loaded_pairs_mean": s.loaded_pairs_mean,
             "lost_motion_max_arcmin": s.lost_motion_max * ARCMIN_PER_RAD, "lost_motion_min_arcmin": s.lost_motion_min * ARCMIN_PER_RAD,
             "radial_clearance_mm": s.radial_clearance, "feasible": s.feasible}
        if len(end) > 2:
            r["rotation_arcsec"] = end[2] / R * ARCSEC_PER_RAD
        if results:
            r["solver_results"] = list(results)
            r["solver_steps"] = list(steps)
        return r

    m = res.modification
    best_end = [float(m.shift), float(m.equidistant)] + ([float(m.rotation) * R] if o["rotation"] else [])
    return {"constraints": o, "best": row(best_end, res), "initial": row(list(res.initial.end), res.initial),
            "starts": [row(list(s.end), s, s.results, s.steps) | {"start": list(s.start)} for s in res.starts]}


def _fmt(x, spec=".3f") -> str:
    return "—" if x is None else format(x, spec)


def _report(study: CycloidStudyConfig, s: dict) -> str:
    d = study.drive
    L = [f"# {study.title}", ""]
    if study.description:
        L += [study.description, ""]
    L += [f"Study `{study.name}` from `{study.source_path}`, run with gearte {s['versions']['gearte']} "
          f"(JAX {s['versions']['jax']}) on {s['created']}.", ""]
    if s["study"]["command"]:
        L += ["Reproduce with:", "", f"    {s['study']['command']}", ""]
    L += ["## Result for the reducer analysed", "",
          f"At the input position θ_T = {s['input_angle_deg']:.4f}° (pin wheel relative to the arm):", "",
          f"- contacting pair (forward load): pin {s['contact_pair']['pin']} with tooth space {s['contact_pair']['tooth_space']}; "
          f"reverse load: pin {s['reverse_contact_pair']['pin']} with tooth space {s['reverse_contact_pair']['tooth_space']};",
          f"- loaded pairs (tangential clearance ≤ {s['deformation_budget_mm']:g} mm on the pin circle): "
          f"**{s['loaded_pairs']} of the {s['loaded_pairs_out_of']}** theoretical pairs "
          f"(over one pitch {s['loaded_pairs_over_pitch']['min']}–{s['loaded_pairs_over_pitch']['max']}, over the revolution "
          f"{s['loaded_pairs_over_revolution']['min']}–{s['loaded_pairs_over_revolution']['max']});",
          f"- lost motion: **{s['lost_motion_arcmin']:.3f}′** at most over the revolution "
          f"(range {s['lost_motion_range_arcmin'][0]:.3f}′ … {s['lost_motion_range_arcmin'][1]:.3f}′; "
          f"{s['lost_motion_at_input_angle_arcmin']:.3f}′ at θ_T)" + ("; **negative somewhere: the disc interferes (jams) there**" if s["interference"] else "") + ";",
          f"- rotation error (TE) of the stage, forward load: peak-to-peak **{s['rotation_error_p2p_arcsec']:.2f}″** over "
          f"{study.revolutions} input revolution(s) (reverse load {s['rotation_error_reverse_p2p_arcsec']:.2f}″).", "",
          "![clearance per pin](clearance_per_pin.png)", "",
          "| pin | tooth space | flank | tangential clearance (mm) | tangential clearance (″) | normal clearance (mm) | within budget |",
          "|---|---|---|---|---|---|---|"]
    for p in s["pairs"]:
        L.append(f"| {p['pin']} | {p['tooth_space']} | {p['flank']} | {_fmt(p['tangential_clearance_mm'], '.4f') if p['can_touch'] else 'never touches'} | "
                 f"{_fmt(p['tangential_clearance_arcsec'], '.1f')} | {p['normal_clearance_mm']:.4f} | {'yes' if p['loaded'] else ''} |")
    L += ["", "![clearance against the input angle](clearance_vs_input.png)", "",
          "![rotation error](rotation_error.png)", "", "## Drive", "", "| parameter | value |", "|---|---|"]
    L += [f"| {k} | {v} |" for k, v in d.describe()]
    L += ["", "## Errors of the reducer analysed", "", "| field | value |", "|---|---|"]
    L += [f"| {k} | {v} |" for k, v in s["errors"].items()] or ["| (none) | |"]
    L += ["", "## Sensitivities of the reducer analysed", "",
          "Derivatives at the errors above (per-space and per-pin errors: the same change on all of them); "
          "lost motion = its maximum over the revolution, loaded pairs = the smooth surrogate (mean over positions).", "",
          "| quantity | d lost motion (′ per) | d TE p-p (″ per) | d loaded pairs (per) |", "|---|---|---|---|"]
    sens = s["sensitivities"]
    for key in sens["lost_motion_max"]["derivatives"]:
        a, b, c = (sens[m]["derivatives"][key] for m in ("lost_motion_max", "rotation_error_p2p", "loaded_pairs_smooth"))
        L.append(f"| {key} (per {a['per']}) | {a['value']:.4g} | {b['value']:.4g} | {c['value']:.4g} |")
    if "monte_carlo" in s:
        mc = s["monte_carlo"]
        L += ["", "## Monte Carlo over the tolerances", "",
              f"{mc['samples']:,} reducers, seed {mc['seed']}; the cycle: {mc['positions']['count']} input positions "
              f"({mc['positions']['per_pitch']} per pin pitch over {mc['positions']['revolutions']} revolution(s)).", "",
              "| tolerance | law |", "|---|---|"]
        L += [f"| {k} | {v} |" for k, v in mc["tolerances"].items()]
        L += ["", "| quantity | mean | std | P5 | P50 | P95 | max |", "|---|---|---|---|---|---|---|"]
        for label, key in (("lost motion, max over the cycle (′)", "lost_motion_max_arcmin"),
                           ("lost motion, min over the cycle (′)", "lost_motion_min_arcmin"),
                           ("rotation error p-p (″)", "rotation_error_p2p_arcsec"),
                           (f"loaded pairs at θ_T (of {s['loaded_pairs_out_of']})", "loaded_pairs"),
                           ("loaded pairs, min over the cycle", "loaded_pairs_min_over_cycle")):
            q = mc[key]
            L.append(f"| {label} | {q['mean']:.3f} | {q['std']:.3f} | {q['percentiles']['5']:.3f} | {q['percentiles']['50']:.3f} | "
                     f"{q['percentiles']['95']:.3f} | {q['max']:.3f} |")
        L += ["", f"Reducers that interfere somewhere in the cycle (lost motion < 0): {100 * mc['interference_fraction']:.2f} %"
              + (f"; the others have {mc['loaded_pairs_without_interference']['mean']:.2f} loaded pairs at θ_T on average."
                 if mc["loaded_pairs_without_interference"] and mc["interference_fraction"] > 0 else "."), "",
              "![Monte Carlo](monte_carlo.png)"]
        if "tolerance_sensitivities" in s:
            ts = s["tolerance_sensitivities"]
            L += ["", f"Sensitivity of the Monte Carlo means to the law parameters (pathwise, {ts['samples']} reducers):", "",
                  "| parameter | d mean lost motion (′ per) | d mean TE p-p (″ per) | d mean loaded pairs (per) |", "|---|---|---|---|"]
            for key in ts["lost_motion_max"]["derivatives"]:
                a, b, c = (ts[m]["derivatives"][key] for m in ("lost_motion_max", "rotation_error_p2p", "loaded_pairs_smooth"))
                L.append(f"| {key} (per {a['per']}) | {a['value']:.4g} | {b['value']:.4g} | {c['value']:.4g} |")
    if "optimised_modification" in s:
        o = s["optimised_modification"]
        c = o["constraints"]
        L += ["", "## Optimised modification", "",
              f"Maximise the loaded pairs (budget {s['deformation_budget_mm']:g} mm) with the lost motion in "
              f"[{c['lost_motion_min_arcmin']:g}′, {c['lost_motion_max_arcmin']:g}′] and a radial clearance ≥ {c['radial_clearance_min_mm']:g} mm, "
              "for the reducer analysed; exact counts over the revolution (2 positions per pitch).", "",
              "| | R_Z (mm) | r_Z (mm) | loaded pairs mean (min) | lost motion (′) | radial clearance (mm) | feasible |", "|---|---|---|---|---|---|---|"]
        for label, r in (("as designed", o["initial"]), ("optimised", o["best"])):
            if r is None:
                continue
            L.append(f"| {label} | {r['wheel_pin_circle_radius_mm']:.4f} | {r['wheel_pin_radius_mm']:.4f} | {r['loaded_pairs_mean']:.2f} "
                     f"({r['loaded_pairs_min']}) | {r['lost_motion_min_arcmin']:.2f} … {r['lost_motion_max_arcmin']:.2f} | "
                     f"{r['radial_clearance_mm']:.4f} | {'yes' if r['feasible'] else 'no'} |")
    L += ["", "## Assumptions", ""]
    L += [f"- {k.replace('_', ' ')}: {v}." for k, v in s["assumptions"].items() if k != "notes"]
    L += [f"- {n}" for n in study.notes]
    L += [f"- All solves converged: {'yes' if s['sweep']['all_solves_converged'] else 'NO (see summary.json)'}.", "",
          "## Files", "", "- `summary.json`: every number above, machine-readable.",
          "- `clearance_per_pin.png`, `clearance_vs_input.png`, `rotation_error.png`" + (", `monte_carlo.png`" if "monte_carlo" in s else "") + ": the plots.",
          "- `curves.npz`: the pitch sweep (clearances of every pin, mm) and the revolution sweep (rotation error ″, "
          "lost motion ′, contacting pin) behind the plots."]
    if "monte_carlo" in s:
        L.append("- `samples.npz`: the per-reducer Monte Carlo values.")
    L += ["", f"Total time {s['timing_s']['total']:.1f} s.", ""]
    return "\n".join(L)


def main_run(args, argv) -> int:
    """`gearte run` for a cycloid-pin study (called by `gearte.cli`)."""
    import shlex
    import sys

    study = load_cycloid_study(args.config, samples=args.samples, seed=args.seed)
    if args.chunk_size is not None:
        study = dataclasses.replace(study, chunk_size=args.chunk_size)
    command = "gearte " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    s = run_cycloid_study(study, args.out, progress=args.progress, command=command)
    print(f"{study.name}: contacting pair: pin {s['contact_pair']['pin']}; loaded pairs {s['loaded_pairs']} of "
          f"{s['loaded_pairs_out_of']} (budget {s['deformation_budget_mm']:g} mm); lost motion {s['lost_motion_arcmin']:.3f}′; "
          f"rotation error p-p {s['rotation_error_p2p_arcsec']:.2f}″")
    print(f"report: {args.out}/report.md")
    return 0


def main_check(path) -> int:
    """`gearte check` for a cycloid-pin study."""
    study = load_cycloid_study(path)
    print(f"{path}: OK ({study.name}: CycloidPin z_b = {study.drive.z_pins}, "
          f"{'Monte Carlo ' + format(study.samples, ',') + ' samples' if study.tolerances is not None else 'no Monte Carlo'}, "
          f"seed {study.seed})")
    return 0
