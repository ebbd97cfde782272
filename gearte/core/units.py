"""Units: the one place for conversion constants, and how a report writes a number.

Inside gearte: error lengths in µm, geometry in mm, angles in rad. Reports use arcseconds
(″) by default, arcminutes (′) or µrad on request.
"""

import math

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi  # 206264.806…″ per rad
ARCMIN_PER_RAD = 180.0 * 60.0 / math.pi
URAD_PER_RAD = 1e6
MM_PER_UM = 1e-3
TWO_PI = 2.0 * math.pi

_PER_RAD = {"rad": 1.0, "arcsec": ARCSEC_PER_RAD, "arcmin": ARCMIN_PER_RAD, "urad": URAD_PER_RAD}
UNIT_SYMBOLS = {"rad": "rad", "arcsec": "″", "arcmin": "′", "urad": "µrad"}
ANGLE_UNITS = tuple(_PER_RAD)


def angle_from_rad(value, unit: str = "arcsec"):
    """Convert an angle in rad to `unit` ("rad", "arcsec", "arcmin" or "urad")."""
    try:
        return value * _PER_RAD[unit]
    except KeyError:
        raise ValueError(f"unknown angle unit {unit!r}; use one of {sorted(_PER_RAD)}") from None


def angle_to_rad(value, unit: str = "arcsec"):
    """Convert an angle in `unit` to rad."""
    try:
        return value / _PER_RAD[unit]
    except KeyError:
        raise ValueError(f"unknown angle unit {unit!r}; use one of {sorted(_PER_RAD)}") from None


def number_text(value, spec: str = ".3f") -> str:
    """`value` formatted by `spec` (None: "—"), without the minus sign of a value that rounds to zero: a report's
    "-0.0000" reads "0.0000"."""
    if value is None:
        return "—"
    text = format(value, spec)
    if text.startswith("-") and text[1:] == format(0.0, spec):
        return text[1:]
    return text
