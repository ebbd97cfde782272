"""RV (K-H-V) reducer: its study-file table, ``[drive] type = "rv_khv"``.

    [drive]         type = "rv_khv", z_pins, pin_circle_radius_mm, pin_radius_mm, eccentricity_mm,
                    z_sun, z_planet, crank_circle_radius_mm, cranks (3), discs (2), pressure_angle_deg (20),
                    backlash_um, crank_disc_clearance_um, crank_carrier_clearance_um,
                    main_bearing_clearance_um (nominal values, default 0)
    [drive.modification]  shift_mm, equidistant_mm, rotation_arcsec (the discs' profile; default none)
    [drive.grid]    points (output angles over one output revolution, 360), trace_points (2 × points)
    [drive.model]   deflection_mm (1e-10; the regularisation follows it), pin_stiffness, mesh_stiffness, bearing_stiffness (1), bearing_faces (64)

The Monte Carlo laws of the errors are the study file's ``[errors.NAME]`` tables, one per error
source of `gearte.drives.rv_khv.SOURCES` (see docs/study-files.md).
"""

from __future__ import annotations

import math
from typing import Any

from ..core.schema import ConfigError, Table
from ..core.units import ARCSEC_PER_RAD
from .cycloid_pin_geometry import CycloidModification
from .rv_khv_contacts import DEFLECTION_MM, check_deflection
from .rv_khv_equilibrium import MAX_BEARING_FACES


def drive_arguments(t: Table) -> dict[str, Any]:
    """The keyword arguments of `RVKHV` from its ``[drive]`` table and sub-tables (each finished here)."""
    kw: dict[str, Any] = dict(
        z_pins=t.integer("z_pins", minimum=4),
        pin_circle_radius=t.number("pin_circle_radius_mm", positive=True),
        pin_radius=t.number("pin_radius_mm", positive=True),
        eccentricity=t.number("eccentricity_mm", positive=True),
        z_sun=t.integer("z_sun", minimum=6),
        z_planet=t.integer("z_planet", minimum=6),
        crank_circle_radius=t.number("crank_circle_radius_mm", positive=True),
        cranks=t.integer("cranks", 3, minimum=2),
        discs=t.integer("discs", 2, minimum=1),
        pressure_angle=math.radians(t.number("pressure_angle_deg", 20.0, positive=True)),
    )
    if not kw["pressure_angle"] < math.radians(45.0):
        raise ConfigError(f"{t.where} pressure_angle_deg: {math.degrees(kw['pressure_angle']):g}° is not a gear pressure angle (below 45°)")
    for key in ("backlash", "crank_disc_clearance", "crank_carrier_clearance", "main_bearing_clearance"):
        kw[f"{key}_mm"] = 1e-3 * t.number(f"{key}_um", 0.0, minimum=0)
    if t.has("modification"):
        m = t.table("modification")
        kw["modification"] = CycloidModification(
            m.number("shift_mm", 0.0), m.number("equidistant_mm", 0.0), m.number("rotation_arcsec", 0.0) / ARCSEC_PER_RAD
        )
        m.finish()
    if t.has("grid"):
        g = t.table("grid")
        kw["points"] = g.integer("points", 360, minimum=1)
        if g.has("trace_points"):
            kw["trace_points"] = g.integer("trace_points", minimum=2)
        g.finish()
    if t.has("model"):
        m = t.table("model")
        try:  # checked here, so that the message names [drive.model]
            kw["deflection_mm"] = check_deflection(m.number("deflection_mm", DEFLECTION_MM, positive=True))
        except ValueError as e:
            if isinstance(e, ConfigError):
                raise
            raise ConfigError(f"{m.where} {e}") from None
        for key in ("pin_stiffness", "mesh_stiffness", "bearing_stiffness"):
            kw[key] = m.number(key, 1.0, positive=True)
        if m.has("bearing_faces"):
            kw["bearing_faces"] = m.integer("bearing_faces", minimum=8, maximum=MAX_BEARING_FACES)
        m.finish()
    return kw


__all__ = ("drive_arguments",)
