"""gearte: transmission error of precision gear drives from their manufacturing and assembly errors.

Importing gearte changes no global state. gearte needs JAX's 64-bit mode: call
``jax.config.update("jax_enable_x64", True)`` (or `gearte.enable_x64()`) once, before
building arrays; the `gearte` command does it itself.

Importing gearte is quick and imports neither JAX nor matplotlib: each name below is loaded from its
module the first time it is used (`gearte.Planetary2KH` imports the drives, and JAX with them).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from . import drives as drives
    from . import units as units
    from .cli.config import Study as Study, build_study as build_study, load_study as load_study
    from .core.extrema import (
        Extrema as Extrema,
        Spectrum as Spectrum,
        extrema as extrema,
        peak as peak,
        peak_to_peak as peak_to_peak,
        rms as rms,
        smooth_peak as smooth_peak,
        spectrum as spectrum,
    )
    from .core.metrics import AbstractMetric as AbstractMetric, Peak as Peak, PeakToPeak as PeakToPeak, RMS as RMS
    from .core.cache import default_cache_dir as default_cache_dir, enable_compilation_cache as enable_compilation_cache
    from .core.precision import enable_x64 as enable_x64, require_x64 as require_x64, x64_enabled as x64_enabled
    from .core.records import (
        AbstractWindow as AbstractWindow,
        FlatTopWindow as FlatTopWindow,
        HannWindow as HannWindow,
        Record as Record,
        RecordSpectrum as RecordSpectrum,
        RectangularWindow as RectangularWindow,
        SpectralLines as SpectralLines,
        band_envelope as band_envelope,
        record as record,
        record_envelope as record_envelope,
        record_spectrum as record_spectrum,
        spectral_lines as spectral_lines,
    )
    from .core.schema import ConfigError as ConfigError
    from .core.signal import (
        Components as Components,
        TESignal as TESignal,
        as_frequency as as_frequency,
        evaluate as evaluate,
        to_signal as to_signal,
    )
    from .core.solution import RESULTS as RESULTS, result_name as result_name
    from .core.twoscale import TwoScaleExtrema as TwoScaleExtrema, extrema_two_scale as extrema_two_scale
    from .drives import (
        AbstractGrindingProcess as AbstractGrindingProcess,
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
    from .drives import (
        AbstractDrive as AbstractDrive,
        AbstractGridDrive as AbstractGridDrive,
        AbstractSinusoidalDrive as AbstractSinusoidalDrive,
        Eccentricity as Eccentricity,
        ExplicitDrive as ExplicitDrive,
        ExplicitTerm as ExplicitTerm,
        HarmonicDrive as HarmonicDrive,
        HarmonicSource as HarmonicSource,
        AbstractHelicalAnalysis as AbstractHelicalAnalysis,
        Dynamic as Dynamic,
        HarmonicRunSettings as HarmonicRunSettings,
        HelicalErrorPeakToPeak as HelicalErrorPeakToPeak,
        HelicalPeakToPeak as HelicalPeakToPeak,
        HelicalPlanetaryDrive as HelicalPlanetaryDrive,
        HelicalResponse as HelicalResponse,
        QuasiStatic as QuasiStatic,
        AbstractPlanetCoupling as AbstractPlanetCoupling,
        LoadSharing as LoadSharing,
        Planetary2KH as Planetary2KH,
        SinglePath as SinglePath,
        SourceSpec as SourceSpec,
    )
    from .drives.rv_khv import (
        RVKHV as RVKHV,
        RVLostMotion as RVLostMotion,
        RVPeakToPeak as RVPeakToPeak,
        RVPeakToPeakReverse as RVPeakToPeakReverse,
        RVResponse as RVResponse,
    )
    from .drives.helical import DynamicResponse as DynamicResponse, HelicalPlanetary as HelicalPlanetary, load_helical as load_helical
    from .drives.helical_geometry import HelicalStage as HelicalStage
    from .drives.helical_modifications import (
        StageModifications as StageModifications,
        ToothModification as ToothModification,
        modifications_from_amounts as modifications_from_amounts,
    )
    from .drives.helical_solve import PeriodicSolver as PeriodicSolver
    from .drives.helical_stiffness import (
        AbstractStiffnessModel as AbstractStiffnessModel,
        MeanStiffness as MeanStiffness,
        SinglePairStiffness as SinglePairStiffness,
        SlicedStiffness as SlicedStiffness,
        TransverseStiffness as TransverseStiffness,
    )
    from .identification import (
        BatchAssembly as BatchAssembly,
        Diagnosis as Diagnosis,
        Identification as Identification,
        IdentificationProblem as IdentificationProblem,
        MeasuredRecord as MeasuredRecord,
        RecordError as RecordError,
        assemble_batch as assemble_batch,
        diagnose as diagnose,
        identification_problem as identification_problem,
        identify as identify,
        read_record as read_record,
        reassemble as reassemble,
        synthetic_record as synthetic_record,
        write_record as write_record,
    )
    from .optimise.rv_assembly import AssemblyPhases as AssemblyPhases, best_planet_assembly as best_planet_assembly
    from .optimise.allocation import (
        RuleAllocation as RuleAllocation,
        RuleProblem as RuleProblem,
        allocate_rule as allocate_rule,
        evaluate_rule as evaluate_rule,
        expected as expected,
        rule_problem as rule_problem,
        worst_case as worst_case,
    )
    from .optimise.rule_objectives import (
        AbstractRuleObjective as AbstractRuleObjective,
        Expected as Expected,
        Robust as Robust,
        WorstCase as WorstCase,
    )
    from .optimise.allocation_measured import MeasuredAllocation as MeasuredAllocation, allocate_measured as allocate_measured
    from .optimise.budget import (
        BudgetResult as BudgetResult,
        contributions as contributions,
        optimise_budget as optimise_budget,
        pareto_front as pareto_front,
        uniform_scaling as uniform_scaling,
    )
    from .optimise.budget_model import BudgetProblem as BudgetProblem, Constraint as Constraint, budget_problem as budget_problem
    from .optimise.statistics import (
        AbstractStatistic as AbstractStatistic,
        MeanKSigma as MeanKSigma,
        Yield as Yield,
        smooth_quantile as smooth_quantile,
    )
    from .optimise.costs import (
        AbstractCostModel as AbstractCostModel,
        Exponential as Exponential,
        GradeTable as GradeTable,
        Power as Power,
        Reciprocal as Reciprocal,
        ReciprocalSquare as ReciprocalSquare,
    )
    from .optimise.modification import (
        ModificationSolution as ModificationSolution,
        ModificationSpec as ModificationSpec,
        optimise_modification as optimise_modification,
    )
    from .optimise.sensitivity_table import SensitivityTable as SensitivityTable, sensitivity_table as sensitivity_table
    from .standards.iso1328 import (
        eccentricity_from_runout as eccentricity_from_runout,
        grade_for_tolerance as grade_for_tolerance,
        grade_range as grade_range,
        iso1328_tolerance as iso1328_tolerance,
        iso1328_tolerances as iso1328_tolerances,
        nearest_grade as nearest_grade,
        round_tolerance as round_tolerance,
    )
    from .studies.doe import (
        AbstractCCDKind as AbstractCCDKind,
        AbstractDesign as AbstractDesign,
        BoxBehnken as BoxBehnken,
        CentralComposite as CentralComposite,
        Circumscribed as Circumscribed,
        DesignRun as DesignRun,
        FaceCentred as FaceCentred,
        FullFactorial as FullFactorial,
        Inscribed as Inscribed,
        LatinHypercube as LatinHypercube,
        SobolSequence as SobolSequence,
        Variable as Variable,
        run_design as run_design,
    )
    from .studies.errors import ErrorModel as ErrorModel, ErrorSource as ErrorSource
    from .studies.laws import (
        AbstractLaw as AbstractLaw,
        AbstractPhase as AbstractPhase,
        AbstractValueLaw as AbstractValueLaw,
        Fixed as Fixed,
        FixedPhase as FixedPhase,
        Normal as Normal,
        Optimised as Optimised,
        Rayleigh as Rayleigh,
        RelativePhase as RelativePhase,
        Sinusoid as Sinusoid,
        TruncatedNormal as TruncatedNormal,
        Uniform as Uniform,
        UniformPhase as UniformPhase,
    )
    from .studies.montecarlo import (
        MonteCarloResult as MonteCarloResult,
        Statistics as Statistics,
        TEStudy as TEStudy,
        as_key as as_key,
        monte_carlo as monte_carlo,
        sample_keys as sample_keys,
        statistics as statistics,
    )
    from .studies.response_surface import (
        CanonicalAnalysis as CanonicalAnalysis,
        ResponseSurface as ResponseSurface,
        SurfaceOptimum as SurfaceOptimum,
        fit_response_surface as fit_response_surface,
    )
    from .studies.sensitivity import SobolIndices as SobolIndices, sobol_indices as sobol_indices
    from .studies.sensitivity_pathwise import (
        GradientRow as GradientRow,
        PathwiseSensitivity as PathwiseSensitivity,
        gradient_rows as gradient_rows,
        pathwise_sensitivities as pathwise_sensitivities,
    )

__version__ = "0.2.0"

#: Submodules reachable as attributes (`gearte.drives`, `gearte.cli`, …).
_SUBMODULES = frozenset({"cli", "core", "drives", "identification", "optimise", "standards", "studies", "units"})

#: Each public name → the module it is loaded from (relative to gearte).
_LAZY: dict[str, str] = {
    "Study": ".cli.config",
    "build_study": ".cli.config",
    "load_study": ".cli.config",
    "Extrema": ".core.extrema",
    "Spectrum": ".core.extrema",
    "extrema": ".core.extrema",
    "peak": ".core.extrema",
    "peak_to_peak": ".core.extrema",
    "rms": ".core.extrema",
    "smooth_peak": ".core.extrema",
    "spectrum": ".core.extrema",
    "AbstractMetric": ".core.metrics",
    "Peak": ".core.metrics",
    "PeakToPeak": ".core.metrics",
    "RMS": ".core.metrics",
    "default_cache_dir": ".core.cache",
    "enable_compilation_cache": ".core.cache",
    "enable_x64": ".core.precision",
    "require_x64": ".core.precision",
    "x64_enabled": ".core.precision",
    "AbstractWindow": ".core.records",
    "FlatTopWindow": ".core.records",
    "HannWindow": ".core.records",
    "RectangularWindow": ".core.records",
    "Record": ".core.records",
    "RecordSpectrum": ".core.records",
    "SpectralLines": ".core.records",
    "band_envelope": ".core.records",
    "record": ".core.records",
    "record_envelope": ".core.records",
    "record_spectrum": ".core.records",
    "spectral_lines": ".core.records",
    "ConfigError": ".core.schema",
    "Components": ".core.signal",
    "TESignal": ".core.signal",
    "as_frequency": ".core.signal",
    "evaluate": ".core.signal",
    "to_signal": ".core.signal",
    "RESULTS": ".core.solution",
    "result_name": ".core.solution",
    "TwoScaleExtrema": ".core.twoscale",
    "extrema_two_scale": ".core.twoscale",
    "CycloidAnalysis": ".drives",
    "CycloidErrors": ".drives",
    "CycloidModification": ".drives",
    "CycloidPin": ".drives",
    "AbstractGrindingProcess": ".drives",
    "FormGrinding": ".drives",
    "GeneratingGrinding": ".drives",
    "LoadedPairs": ".drives",
    "LoadedPairsMin": ".drives",
    "LostMotion": ".drives",
    "LostMotionMin": ".drives",
    "RotationErrorPeakToPeak": ".drives",
    "AbstractDrive": ".drives",
    "AbstractGridDrive": ".drives",
    "AbstractSinusoidalDrive": ".drives",
    "Eccentricity": ".drives",
    "ExplicitDrive": ".drives",
    "ExplicitTerm": ".drives",
    "HarmonicDrive": ".drives",
    "HarmonicSource": ".drives",
    "AbstractPlanetCoupling": ".drives",
    "LoadSharing": ".drives",
    "Planetary2KH": ".drives",
    "SinglePath": ".drives",
    "SourceSpec": ".drives",
    "DynamicResponse": ".drives.helical",
    "HelicalPlanetary": ".drives.helical",
    "RVKHV": ".drives.rv_khv",
    "RVLostMotion": ".drives.rv_khv",
    "RVPeakToPeak": ".drives.rv_khv",
    "RVPeakToPeakReverse": ".drives.rv_khv",
    "RVResponse": ".drives.rv_khv",
    "load_helical": ".drives.helical",
    "AbstractHelicalAnalysis": ".drives",
    "Dynamic": ".drives",
    "HarmonicRunSettings": ".drives",
    "QuasiStatic": ".drives",
    "HelicalErrorPeakToPeak": ".drives",
    "HelicalPeakToPeak": ".drives",
    "HelicalPlanetaryDrive": ".drives",
    "HelicalResponse": ".drives",
    "HelicalStage": ".drives.helical_geometry",
    "StageModifications": ".drives.helical_modifications",
    "ToothModification": ".drives.helical_modifications",
    "modifications_from_amounts": ".drives.helical_modifications",
    "PeriodicSolver": ".drives.helical_solve",
    "AbstractStiffnessModel": ".drives.helical_stiffness",
    "SlicedStiffness": ".drives.helical_stiffness",
    "TransverseStiffness": ".drives.helical_stiffness",
    "MeanStiffness": ".drives.helical_stiffness",
    "SinglePairStiffness": ".drives.helical_stiffness",
    "BatchAssembly": ".identification",
    "Diagnosis": ".identification",
    "Identification": ".identification",
    "IdentificationProblem": ".identification",
    "MeasuredRecord": ".identification",
    "RecordError": ".identification",
    "assemble_batch": ".identification",
    "diagnose": ".identification",
    "identification_problem": ".identification",
    "identify": ".identification",
    "read_record": ".identification",
    "reassemble": ".identification",
    "synthetic_record": ".identification",
    "write_record": ".identification",
    "AssemblyPhases": ".optimise.rv_assembly",
    "best_planet_assembly": ".optimise.rv_assembly",
    "RuleAllocation": ".optimise.allocation",
    "RuleProblem": ".optimise.allocation",
    "allocate_rule": ".optimise.allocation",
    "AbstractRuleObjective": ".optimise.rule_objectives",
    "Expected": ".optimise.rule_objectives",
    "Robust": ".optimise.rule_objectives",
    "WorstCase": ".optimise.rule_objectives",
    "evaluate_rule": ".optimise.allocation",
    "expected": ".optimise.allocation",
    "rule_problem": ".optimise.allocation",
    "worst_case": ".optimise.allocation",
    "MeasuredAllocation": ".optimise.allocation_measured",
    "allocate_measured": ".optimise.allocation_measured",
    "BudgetProblem": ".optimise.budget_model",
    "BudgetResult": ".optimise.budget",
    "Constraint": ".optimise.budget_model",
    "budget_problem": ".optimise.budget_model",
    "contributions": ".optimise.budget",
    "optimise_budget": ".optimise.budget",
    "pareto_front": ".optimise.budget",
    "uniform_scaling": ".optimise.budget",
    "AbstractStatistic": ".optimise.statistics",
    "MeanKSigma": ".optimise.statistics",
    "Yield": ".optimise.statistics",
    "smooth_quantile": ".optimise.statistics",
    "AbstractCostModel": ".optimise.costs",
    "Exponential": ".optimise.costs",
    "GradeTable": ".optimise.costs",
    "Power": ".optimise.costs",
    "Reciprocal": ".optimise.costs",
    "ReciprocalSquare": ".optimise.costs",
    "ModificationSolution": ".optimise.modification",
    "ModificationSpec": ".optimise.modification",
    "optimise_modification": ".optimise.modification",
    "SensitivityTable": ".optimise.sensitivity_table",
    "sensitivity_table": ".optimise.sensitivity_table",
    "eccentricity_from_runout": ".standards.iso1328",
    "grade_for_tolerance": ".standards.iso1328",
    "grade_range": ".standards.iso1328",
    "iso1328_tolerance": ".standards.iso1328",
    "iso1328_tolerances": ".standards.iso1328",
    "nearest_grade": ".standards.iso1328",
    "round_tolerance": ".standards.iso1328",
    "AbstractCCDKind": ".studies.doe",
    "AbstractDesign": ".studies.doe",
    "BoxBehnken": ".studies.doe",
    "CentralComposite": ".studies.doe",
    "Circumscribed": ".studies.doe",
    "DesignRun": ".studies.doe",
    "FaceCentred": ".studies.doe",
    "FullFactorial": ".studies.doe",
    "Inscribed": ".studies.doe",
    "LatinHypercube": ".studies.doe",
    "SobolSequence": ".studies.doe",
    "Variable": ".studies.doe",
    "run_design": ".studies.doe",
    "CanonicalAnalysis": ".studies.response_surface",
    "ResponseSurface": ".studies.response_surface",
    "SurfaceOptimum": ".studies.response_surface",
    "fit_response_surface": ".studies.response_surface",
    "ErrorModel": ".studies.errors",
    "ErrorSource": ".studies.errors",
    "AbstractLaw": ".studies.laws",
    "AbstractPhase": ".studies.laws",
    "AbstractValueLaw": ".studies.laws",
    "Fixed": ".studies.laws",
    "FixedPhase": ".studies.laws",
    "Normal": ".studies.laws",
    "Optimised": ".studies.laws",
    "Rayleigh": ".studies.laws",
    "RelativePhase": ".studies.laws",
    "Sinusoid": ".studies.laws",
    "TruncatedNormal": ".studies.laws",
    "Uniform": ".studies.laws",
    "UniformPhase": ".studies.laws",
    "MonteCarloResult": ".studies.montecarlo",
    "Statistics": ".studies.montecarlo",
    "TEStudy": ".studies.montecarlo",
    "as_key": ".studies.montecarlo",
    "monte_carlo": ".studies.montecarlo",
    "sample_keys": ".studies.montecarlo",
    "statistics": ".studies.montecarlo",
    "SobolIndices": ".studies.sensitivity",
    "sobol_indices": ".studies.sensitivity",
    "PathwiseSensitivity": ".studies.sensitivity_pathwise",
    "pathwise_sensitivities": ".studies.sensitivity_pathwise",
    "GradientRow": ".studies.sensitivity_pathwise",
    "gradient_rows": ".studies.sensitivity_pathwise",
}

#: The public names: every lazily loaded name, the public submodules and the version.
__all__ = sorted([*_LAZY, "__version__", "drives", "units"])


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__, *_SUBMODULES})
