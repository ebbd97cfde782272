"""Harmonic drive: its error-source classes (Liu, sec. 2.2), one error source, and the run settings.

Liu sorts the error sources of a double-wave harmonic drive by *what the error vector
turns with*: the circular spline (CS) class (fixed), the flexspline (FS) class (turns with
the output), the wave-generator (WG) class (turns with the input) and the tooth-to-tooth
class. Every source of one class shares its frequency (`HarmonicDrive.class_frequencies`), except
that a tooth-class source may hold any harmonic h of the tooth-mesh frequency (`HarmonicSource.harmonic`):
each harmonic is a line of its own (`line_key`).

**The two mesh zones and the tooth-mesh line.** In one wave-generator (WG) turn z₂ circular-spline
(CS) teeth pass each of the two diametral mesh zones (and z₁ · z₂/z₁ = z₂ flexspline teeth, the FS
turning back at 1/i): a tooth-periodic mesh error runs at z₂ × the input speed *in each zone*. Zone 2
lies at π of the WG, where the CS tooth phase is z₂·π, so harmonic h of a zone's tooth-mesh error reads

    zone 1: e sin(h z₂ θ + Θ),     zone 2: e sin(h z₂ (θ + π) + Θ) = e sin(h z₂ θ + Θ + h z₂ π)

(for FS teeth the shift is h z₁ π, the same angle modulo 2π since z₂ − z₁ is even). The output takes
the zones' mean (they share the load alike), so the line of harmonic h is e times the *zone factor*
``½ (1 + e^{i h z₂ π})`` (`tooth_zone_factor`): 1 for even h z₂ (zones in phase), 0 for odd h z₂ (half
a tooth pitch apart: they cancel). For an even z₂ the fundamental z₂ n survives and 2 z₂ n is its
harmonic; for an odd z₂ the fundamental and every odd harmonic cancel, the even ones (2 z₂ n, …) stay.
Liu (eq. 6) puts the line at 2 z₂ n for any z₂, counting 2 z₂ meshing events per WG turn.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx

from ..core.records import record_samples
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
CLASS_FREQUENCY_TEXT = {"circular_spline": "2n", "flexspline": "2n·z₂/z₁", "wave_generator": "n", "tooth": "z₂·n"}


def tooth_zone_factor(z_circular_spline: int, harmonic: int, *, share: float = 0.5) -> complex:
    """Factor of harmonic h of the tooth-mesh error of one zone on the drive's TE: ``w₁ + w₂ e^{i h z₂ π}``.

    Zone 2 is at π of the wave generator, where the CS tooth phase is z₂ π; `share` = w₁ is
    zone 1's share of the load (w₂ = 1 − w₁; ½ for identical zones, gearte's model). Identical
    zones give exactly 1 for even h z₂ and 0 for odd h z₂.
    """
    z2 = as_int("z_circular_spline", z_circular_spline, minimum=1)
    h = as_int("harmonic", harmonic, minimum=1)
    w1 = as_float("share", share, nonnegative=True)
    if w1 > 1.0:
        raise ValueError(f"share: zone 1's share of the load must lie in [0, 1], got {w1:g}")
    if (h * z2) % 2 == 0:
        return complex(1.0)  # in phase: w₁ + w₂
    return complex(2.0 * w1 - 1.0)  # half a tooth pitch apart: w₁ − w₂


def line_key(source_class: str, harmonic: int = 1) -> str:
    """Key of a spectral line: the class, or ``"tooth_h2"``, … for tooth-mesh harmonics above the first."""
    return source_class if harmonic == 1 else f"{source_class}_h{harmonic}"


def line_harmonic(key: str) -> tuple[str, int]:
    """(class, harmonic) of a line key (`line_key`'s inverse)."""
    if key in CLASSES:
        return key, 1
    cls, _, h = key.rpartition("_h")
    return cls, int(h)


def finite(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    """A finite float (> 0 or ≥ 0 when asked), or a ValueError naming `name`."""
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a tolerance cannot be negative")


whole = as_int


def class_label(source_class: str) -> str:
    """E.g. ``"circular spline (CS) class, 2n"``; a line key (`line_key`) gives its harmonic, e.g. ``"…, 2·z₂·n"``."""
    cls, h = line_harmonic(source_class)
    if h == 1:
        return f"{CLASSES[cls]['title']}, {CLASS_FREQUENCY_TEXT[cls]}"
    return f"{CLASSES[cls]['title']}, {h}·{CLASS_FREQUENCY_TEXT[cls]} (tooth-mesh harmonic {h})"


def line_short(key: str) -> str:
    """Short name of a line: ``"CS"``, ``"tooth"``, ``"tooth×2"``."""
    cls, h = line_harmonic(key)
    return CLASSES[cls]["short"] + ("" if h == 1 else f"×{h}")


def line_title(key: str) -> str:
    """Title of a line: the class's, with its tooth-mesh harmonic above the first."""
    cls, h = line_harmonic(key)
    return CLASSES[cls]["title"] + ("" if h == 1 else f", tooth-mesh harmonic {h}")


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
    - `harmonic`: tooth class only: the harmonic h of the tooth-mesh frequency this source
      holds (default 1, the fundamental at z₂ × the input speed in each zone); its line is
      at h z₂ when the two zones do not cancel it (`tooth_zone_factor`).
    - `basis`: where the tolerance value comes from (a paper, a standard, an assumption), for reports.
    """

    tolerance: float = eqx.field(static=True)
    name: str = eqx.field(static=True)
    source_class: str = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    harmonic: int = eqx.field(static=True)
    basis: str = eqx.field(static=True)

    def __init__(self, name: str, source_class: str, *, tolerance: float, kind: str | None = None, harmonic: int = 1, basis: str = ""):
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
        h = as_int(f"HarmonicSource {name!r}: harmonic", harmonic, minimum=1)
        if h != 1 and source_class != "tooth":
            raise ValueError(
                f"HarmonicSource {name!r}: harmonic = {h} is for tooth-class sources only (the tooth-mesh harmonic); "
                f"a {source_class} source has one line, leave harmonic out"
            )
        if not isinstance(basis, str):
            raise ValueError(
                f"HarmonicSource {name!r}: basis must be a string (where the tolerance comes from), got {type(basis).__name__}"
            )
        self.name, self.source_class, self.kind, self.harmonic, self.basis = name, source_class, kind, h, basis
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
        record_samples(self.duration_s, self.sample_rate_hz)  # the record `gearte run` will take: checked now
        self.lines = whole("lines", lines, minimum=1)
        self.adjustable = tuple(adjustable)
        repeated = sorted({x for x in self.adjustable if self.adjustable.count(x) > 1})
        if repeated:
            raise ValueError(f"adjustable: {repeated} named more than once; name each source once")
        self.assembly_starts = whole("assembly_starts", assembly_starts, minimum=1)
