"""Helical stage parameter files (the layout of ``examples/dynamics/helical_wind_turbine.toml``).

A parameter file describes one stage: ``[operation]`` (power, carrier speed), ``[gears]``, ``[mesh]``,
``[members.M]`` and ``[supports.M]`` for M = carrier, ring, sun, planet, and ``[model]`` (slices, stiffness
model, contact smoothing, the integrator's periods and steps). `read_stage_file` reads it without
importing the ODE solver, so a study file of the registered drive (`gearte.drives.helical_drive`) is
checked without it; `gearte.drives.helical.load_helical` builds the dynamic model from it.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path

from ..core.validate import as_float, as_int
from .helical_geometry import MEMBERS, HelicalStage
from .helical_stiffness import STIFFNESS_MODELS, AbstractStiffnessModel, SlicedStiffness


@dataclasses.dataclass(frozen=True)
class StageFile:
    """What a parameter file says: the `HelicalStage` and the options of its model (``[model]``, with defaults)."""

    stage: HelicalStage
    n_slices: int
    stiffness_model: AbstractStiffnessModel
    contact_smoothing: float
    n_periods: int
    steps_per_period: int
    samples_per_period: int


_DIRS = ("x", "y", "z", "tilt_x", "tilt_y", "torsion")


def _section(data: Mapping, key: str, where: str) -> Mapping:
    v = data.get(key)
    if not isinstance(v, Mapping):
        raise ValueError(f"{where}: missing table [{key}]")
    return v


def _num(table: Mapping, key: str, where: str) -> float:
    if key not in table:
        raise ValueError(f"{where}: missing key {key!r}")
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"{where}.{key}: expected a number, got {v!r}")
    return float(v)


#: Bounds of the counts that size every solve of a parameter or study file (slices across the face, mesh periods,
#: steps and samples per period): generous, so that a slip of a few digits is refused when the file is read rather
#: than found after hours.
MAX_SLICES = 256
MAX_PERIODS = 10_000
MAX_STEPS_PER_PERIOD = 16_384


def _whole(table: Mapping, key: str, where: str, default: int | None = None, *, minimum: int = 1, maximum: int | None = None) -> int:
    """A whole number ≥ `minimum` (and ≤ `maximum`) from a parameter file (the constructors check the rest); ``default``
    when absent."""
    if key not in table and default is not None:
        return default
    if key not in table:
        raise ValueError(f"{where}: missing key {key!r}")
    v = as_int(f"{where}.{key}", table[key], minimum=minimum)
    if maximum is not None and v > maximum:
        raise ValueError(f"{where}.{key}: must be ≤ {maximum:,} (it sizes every solve), got {v:,}")
    return v


def _stiffness_model(model: Mapping, where: str) -> AbstractStiffnessModel:
    """The stiffness model named by the file's ``stiffness_model`` key (the models' `name`s; "slices" when absent)."""
    by_name = {cls.name: cls for cls in STIFFNESS_MODELS}
    name = model.get("stiffness_model", SlicedStiffness.name)
    if not isinstance(name, str) or name not in by_name:
        raise ValueError(f"{where}.stiffness_model: one of {', '.join(repr(n) for n in by_name)}, got {name!r}")
    return by_name[name]()


#: Every table of a stage parameter file and its keys (`read_stage_file`); members and supports have one table per
#: member (`MEMBERS`).
_KEYS = {
    "gears": {"z_sun", "z_planet", "z_ring", "n_planets", "normal_module_mm", "normal_pressure_angle_deg", "helix_angle_deg",
              "face_width_mm", "sun_hand"},
    "mesh": {"stiffness_external", "stiffness_internal", "damping_ratio", "lead_mismatch_external_um", "lead_mismatch_internal_um"},
    "operation": {"power_kw", "carrier_speed_rpm"},
    "model": {"n_slices", "stiffness_model", "contact_smoothing_um", "n_periods", "steps_per_period", "samples_per_period"},
    "members": {"mass_kg", "polar_inertia_kgm2", "tilt_inertia_kgm2"},
    "supports": {*_DIRS, "damping_ratio"},
}  # fmt: skip


def _unknown(keys, allowed, where: str) -> None:
    for k in keys:
        if k not in allowed:
            near = difflib.get_close_matches(str(k), sorted(allowed), n=1)
            hint = f" (did you mean `{near[0]}`?)" if near else ""
            raise ValueError(f"{where}: unknown key `{k}`{hint}; allowed: {', '.join(sorted(allowed))}")


def _known_keys(data: Mapping, w: str) -> None:
    """Refuse a table or key the file format does not have, naming it (a misspelt key would leave its default)."""
    for k in data:
        if k not in _KEYS:
            near = difflib.get_close_matches(str(k), sorted(_KEYS), n=1)
            hint = f" (did you mean `[{near[0]}]`?)" if near else ""
            raise ValueError(f"{w}: unknown table `[{k}]`{hint}; allowed: {', '.join(f'[{t}]' for t in _KEYS)}")
    for name, allowed in _KEYS.items():
        t = data.get(name)
        if not isinstance(t, Mapping):
            continue  # missing or not a table: reported where it is read
        if name in ("members", "supports"):
            _unknown(t, set(MEMBERS), f"{w} [{name}]")
            for m, sub in t.items():
                if isinstance(sub, Mapping):
                    _unknown(sub, allowed, f"{w} [{name}.{m}]")
        else:
            _unknown(t, allowed, f"{w} [{name}]")


def read_stage_file(path: str | Path) -> StageFile:
    """Read a helical stage parameter file. A missing table or key, or a value of the wrong kind, raises a
    ValueError naming the file, table and key; a file that is not TOML, one naming the line."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise ValueError(f"{path.name}: not a valid TOML file: {e}") from None
    w = path.name
    _known_keys(data, w)
    g = _section(data, "gears", w)
    members = _section(data, "members", w)
    sup = _section(data, "supports", w)
    mesh = _section(data, "mesh", w)
    op = _section(data, "operation", w)
    model = data.get("model", {})
    gw, meshw, opw, mw = (f"{w} [{t}]" for t in ("gears", "mesh", "operation", "model"))
    if not isinstance(model, Mapping):
        raise ValueError(f"{mw}: expected a table, got {model!r}")

    def per_member(key):
        return [_num(_section(members, m, f"{w} [members]"), key, f"{w} [members.{m}]") for m in MEMBERS]

    stiff, zeta = [], []
    for m in MEMBERS:
        t = _section(sup, m, f"{w} [supports]")
        stiff.append([_num(t, d, f"{w} [supports.{m}]") for d in _DIRS])
        zeta.append(_num(t, "damping_ratio", f"{w} [supports.{m}]"))
    speed = as_float(f"{opw}.carrier_speed_rpm", _num(op, "carrier_speed_rpm", opw), positive=True)
    power = as_float(f"{opw}.power_kw", _num(op, "power_kw", opw))
    fields = _stage_fields(g, gw, meshw, mesh, per_member, stiff, zeta, power, speed)
    try:
        stage = HelicalStage(**fields)
    except ValueError as e:  # the stage's own checks name its fields; the file's name goes first
        raise ValueError(f"{w}: {e}") from None
    return StageFile(
        stage,
        n_slices=_whole(model, "n_slices", mw, 8, maximum=MAX_SLICES),
        stiffness_model=_stiffness_model(model, mw),
        contact_smoothing=_num(model, "contact_smoothing_um", mw) if "contact_smoothing_um" in model else 0.02,
        # the solver's own bounds (`PeriodicSolver`), checked here where the study's analysis takes them as defaults
        n_periods=_whole(model, "n_periods", mw, 20, minimum=2, maximum=MAX_PERIODS),
        steps_per_period=_whole(model, "steps_per_period", mw, 256, minimum=4, maximum=MAX_STEPS_PER_PERIOD),
        samples_per_period=_whole(model, "samples_per_period", mw, 128, minimum=4, maximum=MAX_STEPS_PER_PERIOD),
    )


def _stage_fields(g, gw, meshw, mesh, per_member, stiff, zeta, power, speed) -> dict:
    """The arguments of the `HelicalStage` of a parameter file's tables, each read and checked against its key."""
    return dict(
        z_sun=_whole(g, "z_sun", gw),
        z_planet=_whole(g, "z_planet", gw),
        z_ring=_whole(g, "z_ring", gw),
        normal_module=_num(g, "normal_module_mm", gw),
        normal_pressure_angle=math.radians(_num(g, "normal_pressure_angle_deg", gw)),
        helix_angle=math.radians(_num(g, "helix_angle_deg", gw)),
        face_width=_num(g, "face_width_mm", gw),
        n_planets=_whole(g, "n_planets", gw),
        sun_hand=str(g.get("sun_hand", "right")),
        mass=per_member("mass_kg"),
        polar_inertia=per_member("polar_inertia_kgm2"),
        tilt_inertia=per_member("tilt_inertia_kgm2"),
        support_stiffness=stiff,
        support_damping_ratio=[[z] * 6 for z in zeta],
        mesh_stiffness=[_num(mesh, "stiffness_external", meshw), _num(mesh, "stiffness_internal", meshw)],
        mesh_damping_ratio=_num(mesh, "damping_ratio", meshw),
        carrier_torque=power * 1e3 / (speed * 2 * math.pi / 60),
        carrier_speed=speed,
        lead_mismatch=[
            _num(mesh, "lead_mismatch_external_um", meshw) if "lead_mismatch_external_um" in mesh else 0.0,
            _num(mesh, "lead_mismatch_internal_um", meshw) if "lead_mismatch_internal_um" in mesh else 0.0,
        ],
    )
