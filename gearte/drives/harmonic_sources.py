"""Harmonic drive: its error-source classes (Liu, sec. 2.2), one error source, and the run settings.

Liu sorts the error sources of a double-wave harmonic drive by *what the error vector
turns with*: the circular spline (CS) class (fixed), the flexspline (FS) class (turns with
the output), the wave-generator (WG) class (turns with the input) and the tooth-to-tooth
class. Every source of one class shares its frequency (`HarmonicDrive.class_frequencies`).
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx

from ..core.validate import as_float, as_int

#: Error-source classes (Liu, sec. 2.2), and the kinds of tolerance each may hold.
CLASSES: dict[str, dict] = {
    "circular_spline": {
        "short": "CS",
        "title": "circular spline (CS) class",
        "kinds": ("runout", "cumulative_pitch"),
        "symbol": "e_2i",
        "examples": "CS eccentricity (cumulative pitch), CS mounting bore run-out and fit clearance, output-shaft fit; "
        "WG-side errors that do not turn with the WG: input bearing bore run-out, input shaft–housing clearance, "
        "flexible-bearing radial run-out and clearance",
    },
    "flexspline": {
        "short": "FS",
        "title": "flexspline (FS) class",
        "kinds": ("runout", "cumulative_pitch"),
        "symbol": "e_1i",
        "examples": "FS eccentricity (cumulative pitch), output-shaft run-out, shaft–FS fit clearance",
    },
    "wave_generator": {
        "short": "WG",
        "title": "wave-generator (WG) class",
        "kinds": ("runout",),
        "symbol": "e_3i",
        "examples": "WG shaft run-out, cam profile error, input shaft–cam clearance",
    },
    "tooth": {
        "short": "tooth",
        "title": "tooth-to-tooth class",
        "kinds": ("tooth_to_tooth",),
        "symbol": "f'_i",
        "examples": "tangential tooth-to-tooth composite deviations of the CS and FS teeth",
    },
}
KINDS = ("runout", "cumulative_pitch", "tooth_to_tooth")
#: Liu's constant (eq. 8): µm on a circle of diameter d mm → ″ is 412.8 / d.
LIU_ARCSEC_PER_UM_MM = 412.8
#: How each class's frequency reads in terms of the input speed n (rpm).
CLASS_FREQUENCY_TEXT = {"circular_spline": "2n", "flexspline": "2n·z₂/z₁", "wave_generator": "n", "tooth": "2z₂·n"}


def finite(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    """A finite float (> 0 or ≥ 0 when asked), or a ValueError naming `name`."""
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a tolerance cannot be negative")


whole = as_int


def class_label(source_class: str) -> str:
    """E.g. ``"circular spline (CS) class, 2n"``."""
    return f"{CLASSES[source_class]['title']}, {CLASS_FREQUENCY_TEXT[source_class]}"


class HarmonicSource(eqx.Module):
    """One error source of a harmonic drive.

    **Arguments:**

    - `name`: the source's name (the key of its `Eccentricity` and of its error law).
    - `source_class`: ``"circular_spline"``, ``"flexspline"``, ``"wave_generator"`` or ``"tooth"``.
    - `kind`: ``"runout"`` (radial run-out or fit clearance), ``"cumulative_pitch"`` (F_p)
      or ``"tooth_to_tooth"`` (f′); see `gearte.drives.harmonic`. Default: ``"runout"``, or
      ``"tooth_to_tooth"`` for the tooth class.
    - `tolerance`: the tolerance of the deviation (run-out, clearance, F_p or f′), µm;
      the magnitude e is half the actual deviation. It is a declaration (the drive's
      default tolerance of the source, `SourceSpec.tolerance`), not a traced parameter.
    """

    tolerance: float = eqx.field(static=True)
    name: str = eqx.field(static=True)
    source_class: str = eqx.field(static=True)
    kind: str = eqx.field(static=True)

    def __init__(self, name: str, source_class: str, *, tolerance: float, kind: str | None = None):
        if not isinstance(name, str) or not name:
            raise ValueError("HarmonicSource.name: give the source a name (a non-empty string)")
        if source_class not in CLASSES:
            raise ValueError(f"HarmonicSource {name!r}: class must be one of {list(CLASSES)}, got {source_class!r}")
        allowed = CLASSES[source_class]["kinds"]
        kind = allowed[0] if kind is None else kind
        if kind not in KINDS:
            raise ValueError(f"HarmonicSource {name!r}: kind must be one of {list(KINDS)}, got {kind!r}")
        if kind not in allowed:
            raise ValueError(
                f"HarmonicSource {name!r}: a {kind!r} source cannot be in the {source_class} class; that class takes {list(allowed)}"
            )
        self.name, self.source_class, self.kind = name, source_class, kind
        self.tolerance = finite(f"HarmonicSource {name!r}: tolerance (µm)", tolerance, nonnegative=True)


class HarmonicRunSettings(eqx.Module):
    """What `gearte run` reports for a harmonic drive beyond the TE statistics.

    **Arguments:**

    - `input_rpm`: input (WG) speed of the record, rpm.
    - `duration_s`: record length, s.
    - `sample_rate_hz`: record sample rate, Hz.
    - `lines`: how many spectral peaks to list at least.
    - `adjustable`: sources whose phase can be set at assembly (optimised on the typical unit).
    - `assembly_starts`: starting points of that optimisation.
    """

    input_rpm: float = eqx.field(static=True)
    duration_s: float = eqx.field(static=True)
    sample_rate_hz: float = eqx.field(static=True)
    lines: int = eqx.field(static=True)
    adjustable: tuple[str, ...] = eqx.field(static=True)
    assembly_starts: int = eqx.field(static=True)

    def __init__(
        self,
        *,
        input_rpm: float,
        duration_s: float,
        sample_rate_hz: float,
        lines: int = 8,
        adjustable: Sequence[str] = (),
        assembly_starts: int = 32,
    ):
        self.input_rpm = finite("input_rpm", input_rpm, positive=True)
        self.duration_s = finite("duration_s", duration_s, positive=True)
        self.sample_rate_hz = finite("sample_rate_hz", sample_rate_hz, positive=True)
        self.lines = whole("lines", lines, minimum=1)
        self.adjustable = tuple(adjustable)
        self.assembly_starts = whole("assembly_starts", assembly_starts, minimum=1)
