"""Drive models: the protocol every drive implements, one file per drive, and the registry.

Every name loads its module on first use (`gearte.drives.registry` too imports a drive's module only when its class
is asked for): a study of one drive imports that drive, and the helical dynamic model's names import diffrax only
when used.
"""

import importlib
import importlib.util
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from . import cycloid_pin as cycloid_pin, harmonic as harmonic, wang2013 as wang2013
    from .cycloid_pin import (
        AbstractGrindingProcess as AbstractGrindingProcess,
        Clearances as Clearances,
        CycloidAnalysis as CycloidAnalysis,
        CycloidErrors as CycloidErrors,
        CycloidModification as CycloidModification,
        CycloidPin as CycloidPin,
        FormGrinding as FormGrinding,
        GeneratingGrinding as GeneratingGrinding,
        LoadedPairs as LoadedPairs,
        LoadedPairsMin as LoadedPairsMin,
        LostMotion as LostMotion,
        LostMotionMin as LostMotionMin,
        RotationErrorPeakToPeak as RotationErrorPeakToPeak,
    )
    from .explicit import ExplicitDrive as ExplicitDrive, ExplicitTerm as ExplicitTerm
    from .harmonic import HarmonicDrive as HarmonicDrive, HarmonicRunSettings as HarmonicRunSettings, HarmonicSource as HarmonicSource
    from .helical import DynamicResponse as DynamicResponse, HelicalPlanetary as HelicalPlanetary, load_helical as load_helical
    from .helical_drive import (
        AbstractHelicalAnalysis as AbstractHelicalAnalysis,
        Dynamic as Dynamic,
        HelicalErrorPeakToPeak as HelicalErrorPeakToPeak,
        HelicalPeakToPeak as HelicalPeakToPeak,
        HelicalPlanetaryDrive as HelicalPlanetaryDrive,
        HelicalResponse as HelicalResponse,
        QuasiStatic as QuasiStatic,
    )
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
    from .planetary_2kh import (
        AbstractPlanetCoupling as AbstractPlanetCoupling,
        LoadSharing as LoadSharing,
        Planetary2KH as Planetary2KH,
        SinglePath as SinglePath,
        member_speeds as member_speeds,
    )
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
    from .rv_khv import (
        RVKHV as RVKHV,
        RVLostMotion as RVLostMotion,
        RVPeakToPeak as RVPeakToPeak,
        RVPeakToPeakReverse as RVPeakToPeakReverse,
        RVResponse as RVResponse,
    )

#: The submodules that are names of this package (``gearte.drives.wang2013``).
_SUBMODULES = ("cycloid_pin", "harmonic", "wang2013")
_LAZY = {
    **dict.fromkeys(
        (
            "AbstractGrindingProcess",
            "Clearances",
            "CycloidAnalysis",
            "CycloidErrors",
            "CycloidModification",
            "CycloidPin",
            "FormGrinding",
            "GeneratingGrinding",
            "LoadedPairs",
            "LoadedPairsMin",
            "LostMotion",
            "LostMotionMin",
            "RotationErrorPeakToPeak",
        ),
        ".cycloid_pin",
    ),
    "ExplicitDrive": ".explicit",
    "ExplicitTerm": ".explicit",
    "HarmonicDrive": ".harmonic",
    "HarmonicRunSettings": ".harmonic",
    "HarmonicSource": ".harmonic",
    "DynamicResponse": ".helical",
    "HelicalPlanetary": ".helical",
    "load_helical": ".helical",
    "AbstractHelicalAnalysis": ".helical_drive",
    "Dynamic": ".helical_drive",
    "QuasiStatic": ".helical_drive",
    "HelicalErrorPeakToPeak": ".helical_drive",
    "HelicalPeakToPeak": ".helical_drive",
    "HelicalPlanetaryDrive": ".helical_drive",
    "HelicalResponse": ".helical_drive",
    "HelicalStage": ".helical_geometry",
    "StageModifications": ".helical_modifications",
    "ToothModification": ".helical_modifications",
    "PeriodicSolver": ".helical_solve",
    "AbstractStiffnessModel": ".helical_stiffness",
    "MeanStiffness": ".helical_stiffness",
    "SinglePairStiffness": ".helical_stiffness",
    "SlicedStiffness": ".helical_stiffness",
    "TransverseStiffness": ".helical_stiffness",
    "AbstractPlanetCoupling": ".planetary_2kh",
    "LoadSharing": ".planetary_2kh",
    "Planetary2KH": ".planetary_2kh",
    "SinglePath": ".planetary_2kh",
    "member_speeds": ".planetary_2kh",
    **dict.fromkeys(
        (
            "AbstractDrive",
            "AbstractGridDrive",
            "AbstractSinusoidalDrive",
            "AbstractStudyContext",
            "Eccentricity",
            "Figure",
            "SourceSpec",
            "StudyOutputs",
            "Trace",
        ),
        ".protocol",
    ),
    "DRIVES": ".registry",
    "RVKHV": ".rv_khv",
    "RVLostMotion": ".rv_khv",
    "RVPeakToPeak": ".rv_khv",
    "RVPeakToPeakReverse": ".rv_khv",
    "RVResponse": ".rv_khv",
}


__all__ = sorted([*_LAZY, *_SUBMODULES])


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _SUBMODULES or (not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None):
        value = importlib.import_module(f".{name}", __name__)  # a module of the package (gearte.drives.rv_khv)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY, *_SUBMODULES})
