"""Drive models: one file per drive."""

from ._base import AbstractDrive as AbstractDrive
from .explicit import ExplicitDrive as ExplicitDrive, ExplicitTerm as ExplicitTerm
from .planetary_2kh import Planetary2KH as Planetary2KH, member_speeds as member_speeds
from . import wang2013 as wang2013
from .harmonic import (
    AssemblyResult as AssemblyResult,
    Estimate as Estimate,
    HarmonicDrive as HarmonicDrive,
    HarmonicRunSettings as HarmonicRunSettings,
    HarmonicSource as HarmonicSource,
    HarmonicTEStudy as HarmonicTEStudy,
    beat_envelope_bounds as beat_envelope_bounds,
    class_phasors as class_phasors,
    labelled_lines as labelled_lines,
    optimise_assembly as optimise_assembly,
    output_rev_peak_to_peak as output_rev_peak_to_peak,
    statistical_estimate as statistical_estimate,
)
from . import cycloid_pin as cycloid_pin, cycloid_pin_optimise as cycloid_pin_optimise, cycloid_pin_studies as cycloid_pin_studies
from .cycloid_pin import (
    Clearances as Clearances,
    CycloidErrors as CycloidErrors,
    CycloidModification as CycloidModification,
    CycloidPin as CycloidPin,
)
from .cycloid_pin_studies import CycloidStudy as CycloidStudy, CycloidTolerances as CycloidTolerances
