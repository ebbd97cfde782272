"""Drive models: the protocol every drive implements, one file per drive, and the registry."""

from . import cycloid_pin as cycloid_pin, harmonic as harmonic, wang2013 as wang2013
from .cycloid_pin import (
    Clearances as Clearances,
    CycloidAnalysis as CycloidAnalysis,
    CycloidErrors as CycloidErrors,
    CycloidModification as CycloidModification,
    CycloidPin as CycloidPin,
    LoadedPairs as LoadedPairs,
    LoadedPairsMin as LoadedPairsMin,
    LostMotion as LostMotion,
    LostMotionMin as LostMotionMin,
    RotationErrorPeakToPeak as RotationErrorPeakToPeak,
)
from .explicit import ExplicitDrive as ExplicitDrive, ExplicitTerm as ExplicitTerm
from .harmonic import HarmonicDrive as HarmonicDrive, HarmonicRunSettings as HarmonicRunSettings, HarmonicSource as HarmonicSource
from .planetary_2kh import Planetary2KH as Planetary2KH, member_speeds as member_speeds
from .protocol import (
    AbstractDrive as AbstractDrive,
    AbstractGridDrive as AbstractGridDrive,
    AbstractSinusoidalDrive as AbstractSinusoidalDrive,
    AbstractStudyContext as AbstractStudyContext,
    Eccentricity as Eccentricity,
    Figure as Figure,
    SourceSpec as SourceSpec,
    StudyOutputs as StudyOutputs,
    Trace as Trace,
)
from .registry import DRIVES as DRIVES
