"""Units (µm, mm, rad inside; ″ and ′ in reports): the public name of `gearte.core.units`, where the constants are defined once."""

from .core.units import (
    ANGLE_UNITS as ANGLE_UNITS,
)
from .core.units import (
    ARCMIN_PER_RAD as ARCMIN_PER_RAD,
)
from .core.units import (
    ARCSEC_PER_RAD as ARCSEC_PER_RAD,
)
from .core.units import (
    MM_PER_UM as MM_PER_UM,
)
from .core.units import (
    TWO_PI as TWO_PI,
)
from .core.units import (
    UNIT_SYMBOLS as UNIT_SYMBOLS,
)
from .core.units import (
    URAD_PER_RAD as URAD_PER_RAD,
)
from .core.units import (
    angle_from_rad as angle_from_rad,
)
from .core.units import (
    angle_to_rad as angle_to_rad,
)
