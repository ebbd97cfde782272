"""Drive models: the protocol every drive implements, one file per drive, and the registry.

The helical dynamic model's names (`HelicalPlanetary` and its parts) load on first use: they import
diffrax, which the kinematic drives do not need.
"""

import importlib
from typing import TYPE_CHECKING, Any

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
from .helical_drive import HelicalPlanetaryDrive as HelicalPlanetaryDrive, HelicalResponse as HelicalResponse
from .registry import DRIVES as DRIVES
from .rv_khv import RVKHV as RVKHV, RVResponse as RVResponse

if TYPE_CHECKING:
    from .helical import DynamicResponse as DynamicResponse, HelicalPlanetary as HelicalPlanetary, load_helical as load_helical
    from .helical_geometry import HelicalStage as HelicalStage
    from .helical_modifications import StageModifications as StageModifications, ToothModification as ToothModification
    from .helical_solve import PeriodicSolver as PeriodicSolver
    from .helical_stiffness import (
        AbstractStiffnessModel as AbstractStiffnessModel,
        MeanStiffness as MeanStiffness,
        SinglePairStiffness as SinglePairStiffness,
        SlicedStiffness as SlicedStiffness,
        TransverseStiffness as TransverseStiffness,
    )

_LAZY = {
    "DynamicResponse": ".helical",
    "HelicalPlanetary": ".helical",
    "load_helical": ".helical",
    "HelicalStage": ".helical_geometry",
    "StageModifications": ".helical_modifications",
    "ToothModification": ".helical_modifications",
    "PeriodicSolver": ".helical_solve",
    "AbstractStiffnessModel": ".helical_stiffness",
    "MeanStiffness": ".helical_stiffness",
    "SinglePairStiffness": ".helical_stiffness",
    "SlicedStiffness": ".helical_stiffness",
    "TransverseStiffness": ".helical_stiffness",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
