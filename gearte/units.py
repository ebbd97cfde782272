"""Units (µm, mm, rad inside; ″ and ′ in reports): the public name of `gearte.core.units`, where the constants are defined once."""

from .core.units import (
    ANGLE_UNITS as ANGLE_UNITS,
    ARCMIN_PER_RAD as ARCMIN_PER_RAD,
    ARCSEC_PER_RAD as ARCSEC_PER_RAD,
    MM_PER_UM as MM_PER_UM,
    TWO_PI as TWO_PI,
    UNIT_SYMBOLS as UNIT_SYMBOLS,
    URAD_PER_RAD as URAD_PER_RAD,
    angle_from_rad as angle_from_rad,
    angle_to_rad as angle_to_rad,
)
