"""Drive models: one file per drive."""

from ._base import AbstractDrive as AbstractDrive
from .explicit import ExplicitDrive as ExplicitDrive, ExplicitTerm as ExplicitTerm
from .planetary_2kh import Planetary2KH as Planetary2KH, member_speeds as member_speeds
from . import wang2013 as wang2013
