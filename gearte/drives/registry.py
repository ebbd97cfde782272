"""Drives by their study-file name (``[drive] type``): a new drive adds one line here."""

from __future__ import annotations

from .cycloid_pin import CycloidPin
from .explicit import ExplicitDrive
from .harmonic import HarmonicDrive
from .helical_drive import HelicalPlanetaryDrive
from .planetary_2kh import Planetary2KH
from .protocol import AbstractDrive
from .rv_khv import RVKHV

DRIVES: dict[str, type[AbstractDrive]] = {
    cls.type_name: cls
    for cls in (
        Planetary2KH,
        ExplicitDrive,
        HarmonicDrive,
        CycloidPin,
        RVKHV,
        HelicalPlanetaryDrive,
    )
}
