"""gearte: transmission error of precision gear drives from their manufacturing and assembly errors.

Importing gearte changes no global state. gearte needs JAX's 64-bit mode: call
``jax.config.update("jax_enable_x64", True)`` (or `gearte.enable_x64()`) once, before
building arrays; the `gearte` command does it itself.
"""

from . import drives as drives
from . import units as units
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
    Record as Record,
    RecordSpectrum as RecordSpectrum,
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
from .drives import (
    AbstractDrive as AbstractDrive,
    AbstractGridDrive as AbstractGridDrive,
    AbstractSinusoidalDrive as AbstractSinusoidalDrive,
    Eccentricity as Eccentricity,
    ExplicitDrive as ExplicitDrive,
    ExplicitTerm as ExplicitTerm,
    HarmonicDrive as HarmonicDrive,
    HarmonicSource as HarmonicSource,
    Planetary2KH as Planetary2KH,
    SourceSpec as SourceSpec,
)
from .drives.helical import DynamicResponse as DynamicResponse, HelicalPlanetary as HelicalPlanetary, load_helical as load_helical
from .drives.helical_geometry import HelicalStage as HelicalStage
from .drives.helical_modifications import (
    StageModifications as StageModifications,
    ToothModification as ToothModification,
    modifications_from_amounts as modifications_from_amounts,
)
from .drives.helical_solve import PeriodicSolver as PeriodicSolver
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
from .optimise.allocation import (
    RuleAllocation as RuleAllocation,
    RuleProblem as RuleProblem,
    allocate_rule as allocate_rule,
    evaluate_rule as evaluate_rule,
    expected as expected,
    rule_problem as rule_problem,
    worst_case as worst_case,
)
from .optimise.allocation_measured import MeasuredAllocation as MeasuredAllocation, allocate_measured as allocate_measured
from .optimise.budget import (
    BudgetProblem as BudgetProblem,
    BudgetResult as BudgetResult,
    Constraint as Constraint,
    budget_problem as budget_problem,
    contributions as contributions,
    optimise_budget as optimise_budget,
    pareto_front as pareto_front,
    uniform_scaling as uniform_scaling,
)
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
from .studies.sensitivity import SobolIndices as SobolIndices, sobol_indices as sobol_indices
from .studies.sensitivity_pathwise import (
    PathwiseSensitivity as PathwiseSensitivity,
    pathwise_sensitivities as pathwise_sensitivities,
)

__version__ = "0.2.0"
