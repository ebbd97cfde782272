"""gearte: transmission error of precision gear drives from their manufacturing and assembly errors."""

from . import _precision  # noqa: F401  (turns on float64 unless GEARTE_X64=0; see _precision)
from ._distributions import (
    AbstractMagnitude as AbstractMagnitude,
    AbstractPhase as AbstractPhase,
    Fixed as Fixed,
    FixedPhase as FixedPhase,
    Normal as Normal,
    Rayleigh as Rayleigh,
    RelativePhase as RelativePhase,
    TruncatedNormal as TruncatedNormal,
    Uniform as Uniform,
    UniformPhase as UniformPhase,
)
from ._costs import (
    AbstractCostModel as AbstractCostModel,
    Exponential as Exponential,
    GradeTable as GradeTable,
    Power as Power,
    Reciprocal as Reciprocal,
    ReciprocalSquare as ReciprocalSquare,
)
from ._errors import Eccentricity as Eccentricity, ErrorModel as ErrorModel, ErrorSource as ErrorSource
from ._iso1328 import (
    eccentricity_from_runout as eccentricity_from_runout,
    grade_for_tolerance as grade_for_tolerance,
    grade_range as grade_range,
    iso1328_tolerance as iso1328_tolerance,
    iso1328_tolerances as iso1328_tolerances,
    nearest_grade as nearest_grade,
    round_tolerance as round_tolerance,
)
from ._metrics import (
    Extrema as Extrema,
    Spectrum as Spectrum,
    extrema as extrema,
    peak as peak,
    peak_to_peak as peak_to_peak,
    rms as rms,
    smooth_peak as smooth_peak,
    spectrum as spectrum,
    te_metric as te_metric,
)
from ._montecarlo import (
    MonteCarloResult as MonteCarloResult,
    Statistics as Statistics,
    TEStudy as TEStudy,
    monte_carlo as monte_carlo,
    statistics as statistics,
)
from ._precision import require_x64 as require_x64, x64_enabled as x64_enabled
from ._sensitivity import (
    SensitivityTable as SensitivityTable,
    SobolIndices as SobolIndices,
    sensitivity_table as sensitivity_table,
    sobol_indices as sobol_indices,
)
from ._signal import Components as Components, TESignal as TESignal, as_frequency as as_frequency, evaluate as evaluate, to_signal as to_signal
from ._records import (
    Record as Record,
    RecordSpectrum as RecordSpectrum,
    SpectralLines as SpectralLines,
    band_envelope as band_envelope,
    record as record,
    record_envelope as record_envelope,
    record_spectrum as record_spectrum,
    spectral_lines as spectral_lines,
)
from ._twoscale import TwoScaleExtrema as TwoScaleExtrema, extrema_two_scale as extrema_two_scale
from . import drives as drives, units as units
from .drives import ExplicitDrive as ExplicitDrive, ExplicitTerm as ExplicitTerm, Planetary2KH as Planetary2KH
from .drives import HarmonicDrive as HarmonicDrive, HarmonicSource as HarmonicSource
from .drives import (
    CycloidErrors as CycloidErrors,
    CycloidModification as CycloidModification,
    CycloidPin as CycloidPin,
    CycloidStudy as CycloidStudy,
    CycloidTolerances as CycloidTolerances,
)

__version__ = "0.1.0"
