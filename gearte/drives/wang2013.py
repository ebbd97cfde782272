"""The worked example of Wang et al. (2013, Table 1, eq. 9, Table 3)."""

from __future__ import annotations

import math

from .explicit import ExplicitDrive, ExplicitTerm
from .planetary_2kh import AbstractPlanetCoupling, Planetary2KH, SinglePath

ALPHA = math.pi / 9  # 20°, Table 1

#: Table 1 tolerances (µm): manufacturing E and assembly A eccentricities.
TABLE1_TOLERANCES_UM = {
    "sun_manufacturing": 13.0,
    "planet_manufacturing": 16.0,
    "ring_manufacturing": 21.0,
    "sun_assembly": 12.0,
    "planet_assembly": 8.0,
    "carrier_assembly": 15.0,
}

#: Table 3 assembly rule (β_r is the housing datum): γ_p = 0, γ_s = β_r + 7π/9, γ_c = β_r + 8π/9.
TABLE3_RULE = {
    "planet_assembly": ("fixed", 0.0),
    "sun_assembly": ("ring_manufacturing", 7 * math.pi / 9),
    "carrier_assembly": ("ring_manufacturing", 8 * math.pi / 9),
}


def table1_drive(*, coupling: AbstractPlanetCoupling = SinglePath()) -> Planetary2KH:
    """Table 1's train: z = 12/36/84, m = 1 mm, α = π/9, three planets; sun in, carrier out, ring fixed; `coupling`
    `SinglePath()` (the paper's) or `LoadSharing()`."""
    return Planetary2KH(12, 36, 84, module=1.0, pressure_angle=ALPHA, n_planets=3, coupling=coupling)


def eq9_drive(*, literal: bool = True) -> ExplicitDrive:
    """The paper's eq. (9) as explicit terms (sun input; θ = input angle).

    `literal=True` keeps the printed planet frequency 11/24; `literal=False` uses
    the physical 7/24 (the erratum: |ω_p − ω_c| = 7/24 ω_s for these tooth counts).
    """
    fp = "11/24" if literal else "7/24"
    pi = math.pi
    terms = [
        ExplicitTerm("sun_manufacturing", "7/8", phase_sign=1, offset=pi / 9),
        ExplicitTerm("planet_manufacturing", fp, phase_sign=-1, offset=8 * pi / 9),
        ExplicitTerm("sun_assembly", "1/8", phase_sign=-1, offset=8 * pi / 9),
        ExplicitTerm("planet_assembly", 0, phase_sign=1, offset=10 * pi / 9),
        ExplicitTerm("carrier_assembly", "1/8", phase_sign=-1, offset=-pi / 9),
        ExplicitTerm("ring_manufacturing", "1/8", phase_sign=-1, offset=pi / 9),
        ExplicitTerm("planet_manufacturing", fp, phase_sign=-1, offset=pi / 9),
        ExplicitTerm("planet_assembly", 0, phase_sign=1, offset=8 * pi / 9),
        ExplicitTerm("carrier_assembly", "1/8", phase_sign=-1, offset=pi / 9),
    ]
    name = "Wang et al. (2013) eq. (9), " + ("literal (planet terms at 11/24)" if literal else "planet terms at the physical 7/24")
    return ExplicitDrive(terms, gain=-1.0 / (48000.0 * math.cos(ALPHA)), name=name)
