"""Harmonic (strain-wave) drive: kinematic error from its error sources (seed 002).

Source: Liu Yuanping, "A study on the theory and measuring technique of
transmission error of harmonic gear drive" (Changchun Institute of Optics and Fine
Mechanics), sections 2–4.

Double-wave drive, elliptical-cam wave generator (WG) input, circular spline (CS,
z₂ teeth) fixed, flexspline (FS, z₁ teeth) output; ratio i = z₁/(z₂ − z₁). With θ the
input (WG) angle, each error source gives a mesh error along the line of action
(seed eq. 6):

| class | frequency (× input speed) | term |
|---|---|---|
| circular spline (CS) | 2 | e sin(2(θ + Θ + α_n)) / cos α_n   (eq. 2) |
| flexspline (FS) | 2 z₂/z₁ | e sin(2((z₂/z₁) θ + Θ + α_n)) / cos α_n   (eqs. 3–4) |
| wave generator (WG) | 1 | e sin(θ + Θ) / cos α_n   (eq. 5) |
| tooth-to-tooth | 2 z₂ | (f′/2) sin(2 z₂ θ + Θ)   (eq. 6) |

The FS class is at 2 z₂/z₁ because an FS eccentricity turns with the FS, at
−θ/i, while the cam turns at θ: their angle grows at (1 + 1/i) θ = (z₂/z₁) θ (seed
text after eq. 3), and the double wave doubles it. The output angle error is then
(eqs. 8–9)

    Δφ = (K_b / √N) · Δ · 412.8 / d      (″, Δ in µm, d = FS pitch diameter in mm)

with N = 0.1 (z₁ + z₂) teeth in mesh at once and K_b an experimental factor 0.8–1.0.
412.8/d is the seed's constant for µm on a circle of diameter d mm to ″ (2 · 206.265
= 412.53 exactly; gearte keeps the seed's 412.8, 0.07 % more).

**Magnitudes, tolerances and kinds.** Every source has a *magnitude* e (µm, the
`Eccentricity.magnitude` of the error model) that is half of the deviation its
tolerance limits, and a *kind* that says how it enters:

- ``"runout"``: a radial run-out or a fit clearance E; e is the eccentricity it
  causes, half of it (seed, after eq. 6); the term carries 1/cos α_n.
- ``"cumulative_pitch"``: a cumulative pitch deviation F_p of the CS or FS, which is
  how the seed measures a gear's own eccentricity; e = F_p/2, tangential already, so
  no 1/cos α_n (eq. 7 lists F_p without it).
- ``"tooth_to_tooth"``: the tangential tooth-to-tooth composite deviation f′ of the CS
  or FS teeth; e = f′/2, the amplitude of eq. (6)'s ``f′ sin(2 z₂ ω_b t)/2``.

**Phases.** `Eccentricity.phase` Θ is the angle (rad) from the error vector to the
cam's major axis at θ = 0 for the CS and FS classes (eq. 2's θ at the start), the
phase of eq. (5)'s ψ for the WG class, and the phase of the tooth-mesh term. Turning
the CS (or a part of the CS class) by δ at assembly changes its Θ by δ and its TE
phase by 2δ; turning the cam on the input shaft by δ changes a WG-class phase by δ.

**Statistics (seed sec. 2.3).** A Rayleigh magnitude of scale σ with a uniform phase
makes each term, at any instant, exactly normal with variance σ² (times the term's
factor squared). The seed's variance ``(E/6)²`` per source is therefore a Rayleigh
scale of *tolerance/6* on the magnitude e (then e ≤ E/2, i.e. within the tolerance,
with probability 1 − e^{−4.5} = 98.9 %). With that, the seed's estimate (eq. 7)
``Δ = ±½ √(F_p1² + F_p2² + f′₁² + f′₂² + ΣE²/cos² α_n)`` is exactly 3σ of the TE at any
given instant; `statistical_estimate` computes it, eq. (8) turns it into ″.

**Exact metrics and the tooth class.** The TE repeats over the hyper-period (45 input
revolutions for z₁ = 180, z₂ = 182), and the tooth class runs at 2z₂ = 364 times the input
speed: the foundation's `extrema` would grid 16 points per tooth period over the whole
hyper-period, 262,080 points per unit. The tooth class is one line (its sources share
the frequency) of amplitude b, far faster than the rest, so `te_extrema` uses
`extrema_two_scale`: exact extrema of the other classes (1,456 grid points, Newton),
then Newton on the whole TE from the tooth crests next to each of their best
candidates. The result equals the full-grid extrema (tested to ~1e-15); each value also
comes with a certified bound on its error, ``max S + b − max F`` (≤ ½ D₂ (π/2z₂)², where
D₂ bounds the curvature of the slower classes), which `gearte run` reports. Nothing is
dropped or approximated: the tooth class is in every figure.

**Per output revolution.** One output revolution is i input revolutions. When the
hyper-period divides into it (always for an integer ratio of a double-wave drive), the
peak-to-peak over any output revolution is the peak-to-peak over the hyper-period;
otherwise the figures are over the hyper-period, an upper bound (see `output_rev_note`).
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .._errors import Eccentricity, ErrorModel
from .._signal import Components, TESignal
from .._twoscale import TwoScaleExtrema, extrema_auto, fast_line_order
from ..units import ARCSEC_PER_RAD
from ._base import AbstractDrive
from .._validate import as_float, as_int

#: Error-source classes of seed 002, sec. 2.2, and the kinds of tolerance each may hold.
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
#: The seed's constant (eq. 8): µm on a circle of diameter d mm → ″ is 412.8 / d.
SEED_ARCSEC_PER_UM_MM = 412.8


def _finite(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a tolerance cannot be negative")


_whole = as_int


class HarmonicSource(eqx.Module):
    """One error source of a harmonic drive.

    **Arguments:**

    - `name`: the source's name (the key of its `Eccentricity` and of its error law).
    - `source_class`: ``"circular_spline"``, ``"flexspline"``, ``"wave_generator"`` or ``"tooth"``.
    - `kind`: ``"runout"`` (radial run-out or fit clearance), ``"cumulative_pitch"`` (F_p)
      or ``"tooth_to_tooth"`` (f′); see the module notes. Default: ``"runout"``, or
      ``"tooth_to_tooth"`` for the tooth class.
    - `tolerance`: the tolerance of the deviation (run-out, clearance, F_p or f′), µm;
      the magnitude e is half the actual deviation.
    """

    tolerance: Float[Array, ""]
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
            raise ValueError(f"HarmonicSource {name!r}: a {kind!r} source cannot be in the {source_class} class; "
                             f"that class takes {list(allowed)}")
        self.name, self.source_class, self.kind = name, source_class, kind
        self.tolerance = jnp.asarray(_finite(f"HarmonicSource {name!r}: tolerance (µm)", tolerance, nonnegative=True))


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

    def __init__(self, *, input_rpm: float, duration_s: float, sample_rate_hz: float, lines: int = 8,
                 adjustable: Sequence[str] = (), assembly_starts: int = 32):
        self.input_rpm = _finite("input_rpm", input_rpm, positive=True)
        self.duration_s = _finite("duration_s", duration_s, positive=True)
        self.sample_rate_hz = _finite("sample_rate_hz", sample_rate_hz, positive=True)
        self.lines = _whole("lines", lines, minimum=1)
        self.adjustable = tuple(adjustable)
        self.assembly_starts = _whole("assembly_starts", assembly_starts, minimum=1)


class HarmonicDrive(AbstractDrive):
    """Double-wave harmonic drive: WG input, CS fixed, FS output (seed 002).

    **Arguments:**

    - `z_flexspline`: z₁, FS teeth.
    - `z_circular_spline`: z₂ > z₁, CS teeth; z₂ − z₁ a multiple of the wave number.
    - `sources`: the `HarmonicSource`s (unique names).
    - `pitch_diameter`: d, pitch diameter of the driven wheel (the FS), mm.
    - `pressure_angle`: α_n, rad (default 20°).
    - `k_b`: K_b, the seed's experimental factor (0.8–1.0; default 1.0).
    - `teeth_in_mesh`: N, tooth pairs in mesh at once (default 0.1 (z₁ + z₂)).
    - `waves`: wave number; only 2 (double-wave, the seed's eq. 2) is supported.
    - `run_settings`: optional `HarmonicRunSettings` for `gearte run`.
    """

    z_flexspline: int
    z_circular_spline: int
    waves: int
    sources: tuple[HarmonicSource, ...]
    pitch_diameter: Float[Array, ""]
    pressure_angle: Float[Array, ""]
    k_b: Float[Array, ""]
    teeth_in_mesh: Float[Array, ""]
    run_settings: HarmonicRunSettings | None

    def __init__(
        self,
        z_flexspline: int,
        z_circular_spline: int,
        sources: Sequence[HarmonicSource],
        *,
        pitch_diameter: float,
        pressure_angle: float = math.radians(20.0),
        k_b: float = 1.0,
        teeth_in_mesh: float | None = None,
        waves: int = 2,
        run_settings: HarmonicRunSettings | None = None,
    ):
        z1 = _whole("z_flexspline", z_flexspline, minimum=3)
        z2 = _whole("z_circular_spline", z_circular_spline, minimum=3)
        w = _whole("waves", waves, minimum=1)
        if w != 2:
            raise ValueError(f"waves: only double-wave drives (waves = 2) are modelled — the seed's eq. (2) doubles the "
                             f"eccentricity angle because the two mesh zones are half a turn apart; got waves = {w}")
        if z2 <= z1:
            raise ValueError(f"tooth counts: the circular spline needs more teeth than the flexspline (z_circular_spline > "
                             f"z_flexspline) for a WG-in, CS-fixed, FS-out drive; got z_flexspline = {z1}, z_circular_spline = {z2}")
        if (z2 - z1) % w:
            raise ValueError(f"tooth counts: z_circular_spline − z_flexspline = {z2 - z1} must be a multiple of the wave "
                             f"number {w} (usually exactly {w})")
        d = _finite("pitch_diameter (mm)", pitch_diameter, positive=True)
        a = _finite("pressure_angle (rad)", pressure_angle, positive=True)
        if not a < math.radians(45):
            raise ValueError(f"pressure_angle: {math.degrees(a):g}° is not a gear pressure angle (give rad; 20° = {math.radians(20):.6f})")
        kb = _finite("k_b", k_b, positive=True)
        n = 0.1 * (z1 + z2) if teeth_in_mesh is None else _finite("teeth_in_mesh", teeth_in_mesh, positive=True)
        if n < 1.0:
            raise ValueError(f"teeth_in_mesh: N = {n:g} < 1; at least one tooth pair is always in mesh")
        sources = tuple(sources)
        if not sources:
            raise ValueError("sources: give at least one HarmonicSource")
        for s in sources:
            if not isinstance(s, HarmonicSource):
                raise ValueError(f"sources: expected HarmonicSource entries, got {type(s).__name__}")
        names = [s.name for s in sources]
        dup = sorted({x for x in names if names.count(x) > 1})
        if dup:
            raise ValueError(f"sources: names must be unique, {dup} repeated")
        if run_settings is not None:
            unknown = [x for x in run_settings.adjustable if x not in names]
            if unknown:
                raise ValueError(f"adjustable: {unknown} are not sources of this drive; use some of {names}")
            tooth = [x for x in run_settings.adjustable if dict(zip(names, sources))[x].source_class == "tooth"]
            if tooth:
                raise ValueError(f"adjustable: {tooth} are tooth-to-tooth sources, whose phase is not set at assembly")
        self.z_flexspline, self.z_circular_spline, self.waves = z1, z2, w
        self.sources = sources
        self.pitch_diameter = jnp.asarray(d)
        self.pressure_angle = jnp.asarray(a)
        self.k_b = jnp.asarray(kb)
        self.teeth_in_mesh = jnp.asarray(n)
        self.run_settings = run_settings

    # ------------------------------------------------------------ kinematics

    @property
    def error_sources(self) -> dict[str, int]:
        return {s.name: 1 for s in self.sources}

    @property
    def tolerances_um(self) -> dict[str, float]:
        return {s.name: float(s.tolerance) for s in self.sources}

    @property
    def ratio(self) -> Fraction:
        """i = z₁ / (z₂ − z₁): input revolutions per output revolution (the FS turns against the WG)."""
        return Fraction(self.z_flexspline, self.z_circular_spline - self.z_flexspline)

    def class_frequencies(self) -> dict[str, Fraction]:
        """Frequency of each class, as an exact multiple of the input (WG) speed (seed eqs. 2, 4, 5, 6)."""
        z1, z2, w = self.z_flexspline, self.z_circular_spline, self.waves
        return {
            "circular_spline": Fraction(w),
            "flexspline": Fraction(w * z2, z1),
            "wave_generator": Fraction(1),
            "tooth": Fraction(w * z2),
        }

    def frequencies_cpm(self, input_rpm: float) -> dict[str, float]:
        """Frequency of each class in cycles per minute at an input speed of `input_rpm` (seed sec. 4: 184, 368, 372 at 184 rpm)."""
        n = _finite("input_rpm", input_rpm, positive=True)
        return {c: float(f) * n for c, f in self.class_frequencies().items()}

    @property
    def beat_frequency(self) -> Fraction:
        """Difference of the FS and CS class frequencies, × input speed: w (z₂ − z₁)/z₁ = w/i."""
        f = self.class_frequencies()
        return abs(f["flexspline"] - f["circular_spline"])

    @property
    def beats_per_output_rev(self) -> Fraction:
        """Beats of the CS and FS terms per output revolution: (beat frequency) × i — the wave number, 2 (seed sec. 3)."""
        return self.beat_frequency * self.ratio

    def gain(self) -> Float[Array, ""]:
        """Output angle per µm of mesh error Δ, rad/µm: (K_b/√N) · 412.8/d ″/µm (eq. 8)."""
        return self.k_b / jnp.sqrt(self.teeth_in_mesh) * SEED_ARCSEC_PER_UM_MM / self.pitch_diameter / ARCSEC_PER_RAD

    def source_factor(self, source: HarmonicSource) -> Float[Array, ""]:
        """Mesh error per µm of magnitude: 1/cos α_n for run-outs and clearances, 1 for F_p and f′ (eqs. 6–7)."""
        return 1.0 / jnp.cos(self.pressure_angle) if source.kind == "runout" else jnp.ones(())

    def source_gains(self) -> dict[str, Float[Array, ""]]:
        """Output angle per µm of each source's magnitude, rad/µm."""
        g = self.gain()
        return {s.name: g * self.source_factor(s) for s in self.sources}

    def components(self, errors: Mapping[str, Eccentricity]) -> Components:
        """TE components at the output (seed eq. 6 with eq. 8), one per source."""
        e = self._checked(errors)
        freq = self.class_frequencies()
        g = self.gain()
        amp, phase, gain, fr, labels = [], [], [], [], []
        for s in self.sources:
            theta0 = e[s.name].phase[0]
            if s.source_class in ("circular_spline", "flexspline"):
                ph = self.waves * (theta0 + self.pressure_angle)  # eqs. (2), (4): sin(2(θ + α_n))
            else:
                ph = theta0  # eq. (5) for the WG class; eq. (6) for the tooth class
            amp.append(e[s.name].magnitude[0])
            phase.append(ph)
            gain.append(g * self.source_factor(s))
            fr.append(freq[s.source_class])
            labels.append(f"{s.name} ({CLASSES[s.source_class]['short']}, {freq[s.source_class]})")
        return Components(jnp.stack(amp, axis=-1), jnp.stack(phase, axis=-1), fr, gain=jnp.stack(gain, axis=-1), labels=labels)

    # ------------------------------------------------------------ metrics

    def te_extrema(self, signal: TESignal) -> TwoScaleExtrema:
        """Exact extrema of this drive's TE over the hyper-period (the tooth class handled as a fast line, see `extrema_two_scale`)."""
        return _extrema_jit(signal)

    def output_rev_note(self) -> str:
        """How the per-output-revolution figures relate to the hyper-period, for reports."""
        h = hyper_period_revs(self)
        i = self.ratio
        if h <= i:
            return (f"the TE repeats every {h} input revolutions, which one output revolution ({i} input revolutions) "
                    "covers, so the peak-to-peak over any output revolution equals that over the hyper-period")
        return (f"the TE repeats only every {h} input revolutions = {h / i} output revolutions: the figures are over that "
                "hyper-period, an upper bound of those of any single output revolution")

    def te_study(self, errors: ErrorModel, *, metric: str = "peak_to_peak") -> "HarmonicTEStudy":
        return HarmonicTEStudy(self, errors, metric=metric)

    def describe(self) -> list[tuple[str, str]]:
        f = self.class_frequencies()
        rows = [
            ("drive", "double-wave harmonic drive, WG input, CS fixed, FS output (seed 002: Liu)"),
            ("tooth counts z₁ (FS) / z₂ (CS)", f"{self.z_flexspline} / {self.z_circular_spline}"),
            ("ratio i = z₁/(z₂ − z₁)", f"{self.ratio} = {float(self.ratio):.6g}"),
            ("pressure angle α_n", f"{math.degrees(float(self.pressure_angle)):.6g}°"),
            ("FS pitch diameter d", f"{float(self.pitch_diameter):g} mm"),
            ("K_b / teeth in mesh N", f"{float(self.k_b):g} / {float(self.teeth_in_mesh):.6g}"),
            ("output angle per µm of mesh error, (K_b/√N)·412.8/d", f"{float(self.gain()) * ARCSEC_PER_RAD:.6g}″/µm"),
            ("hyper-period / one output revolution", f"{hyper_period_revs(self)} / {self.ratio} input revolutions"),
            ("beats per output revolution (CS and FS classes)", str(self.beats_per_output_rev)),
        ]
        rows += [(f"frequency of the {CLASSES[c]['title']} (× input speed)", f"{v} = {float(v):.6g}") for c, v in f.items()]
        rows += [(f"source {s.name}", f"{CLASSES[s.source_class]['short']} class, {s.kind}, tolerance {float(s.tolerance):g} µm")
                 for s in self.sources]
        return rows

    def study_outputs(self, study, values_rad, folder) -> tuple[dict, list[str]]:
        from ._harmonic_outputs import study_outputs

        return study_outputs(self, study, values_rad, folder)


_extrema_jit = eqx.filter_jit(extrema_auto)


def hyper_period_revs(drive: HarmonicDrive) -> Fraction:
    """Hyper-period of the TE, input revolutions, for the classes the drive has sources in."""
    used = sorted({drive.class_frequencies()[s.source_class] for s in drive.sources})
    num, den = 0, 1
    for v in used:
        num, den = math.gcd(num * v.denominator, v.numerator * den), den * v.denominator
    return Fraction(den, num) if num else Fraction(1)


# ---------------------------------------------------------------- Monte Carlo


class HarmonicTEStudy(eqx.Module):
    """One Monte Carlo sample of a harmonic drive's TE metric, for `monte_carlo`.

    Like `TEStudy`, but the extrema treat the tooth class as a fast line
    (`extrema_two_scale`): a grid at 16 points per tooth period over the hyper-period
    would be 16 · 2z₂ · (hyper-period) points per sample (262,080 for z₂ = 182 over 45
    input revolutions), here it is 16 points per period of the FS class (1,456).

    **Arguments:**

    - `drive`: the `HarmonicDrive`.
    - `errors`: how each source is drawn.
    - `metric`: ``"peak_to_peak"`` (over one output revolution, see
      `HarmonicDrive.output_rev_note`), ``"peak"`` or ``"rms"``.
    """

    drive: HarmonicDrive
    errors: ErrorModel
    metric: str = eqx.field(static=True)

    def __init__(self, drive: HarmonicDrive, errors: ErrorModel, *, metric: str = "peak_to_peak"):
        if metric not in ("peak", "peak_to_peak", "rms"):
            raise ValueError(f"metric: must be 'peak', 'peak_to_peak' or 'rms', got {metric!r}")
        if errors.counts != drive.error_sources:
            raise ValueError(f"errors: the error model's sources {sorted(errors.counts)} do not match the drive's {sorted(drive.error_sources)}")
        self.drive, self.errors, self.metric = drive, errors, metric

    def signal(self, key: PRNGKeyArray) -> TESignal:
        """The TE signal of the sample drawn with `key` (rad)."""
        return self.drive.signal(self.errors.sample(key))

    def _value_and_gap(self, key: PRNGKeyArray) -> tuple[Array, Array]:
        from .._metrics import rms

        sig = self.signal(key)
        if self.metric == "rms":
            v = rms(sig)
            return v, jnp.zeros_like(v)
        e = self.drive.te_extrema(sig)
        if self.metric == "peak_to_peak":
            return e.max - e.min, e.max_gap + e.min_gap
        return jnp.maximum(e.max, -e.min), jnp.maximum(e.max_gap, e.min_gap)

    def __call__(self, key: PRNGKeyArray) -> Float[Array, ""]:
        return self._value_and_gap(key)[0]

    def gap(self, key: PRNGKeyArray) -> Float[Array, ""]:
        """Certified bound (rad) on the error of the metric of this sample (0 without a tooth class)."""
        return self._value_and_gap(key)[1]

    def bytes_per_sample(self) -> int:
        """Rough peak working memory per sample (bytes), to size chunks."""
        from .._metrics import _grid_size

        sig = jax.eval_shape(self.signal, jax.random.key(0))
        k = fast_line_order(sig)
        slow = [o for o in sig.orders if o != k] or [1]
        m = _grid_size(tuple(slow), 16)
        return 8 * (12 * m + 64 * len(sig.orders) + 4096)


class CompanionStudy(eqx.Module):
    """For the same samples as a `HarmonicTEStudy`: ``key → [TE at input angle theta, certified error bound of the metric]`` (rad).

    The first is the seed's normal variable (sec. 2.3: the TE at one instant over the batch).
    """

    study: HarmonicTEStudy
    theta: Float[Array, ""]

    def __call__(self, key: PRNGKeyArray) -> Float[Array, " 2"]:
        from .._signal import evaluate

        return jnp.stack([evaluate(self.study.signal(key), self.theta), self.study.gap(key)])

    def bytes_per_sample(self) -> int:
        return self.study.bytes_per_sample()


# ---------------------------------------------------------------- statistical estimate


class Estimate(eqx.Module):
    """The seed's statistical design estimate (eqs. 7–8).

    **Fields:**

    - `delta_um`: Δ of eq. (7), µm: ± this at 3σ, for one tooth pair at the deepest mesh.
    - `arcsec`, `arcmin`: Δφ of eq. (8) = (K_b/√N) · Δ · 412.8/d, ″ and ′.
    - `sigma_arcsec`: the σ it stands for (Δφ/3), ″: the standard deviation of the TE at
      any instant when magnitudes are Rayleigh with scale tolerance/6 and phases uniform.
    - `by_class_um`: Δ of each class alone, µm (its share of eq. 7).
    - `terms_um2`: each source's term under the root of eq. (7), µm².
    """

    delta_um: float
    arcsec: float
    arcmin: float
    sigma_arcsec: float
    by_class_um: dict[str, float]
    terms_um2: dict[str, float]


def statistical_estimate(drive: HarmonicDrive, *, tolerances_um: Mapping[str, float] | None = None) -> Estimate:
    """The seed's ±3σ design estimate of the kinematic error (eqs. 7–8).

    ``Δ = ½ √(F_p1² + F_p2² + f′₁² + f′₂² + (ΣE₁² + ΣE₂² + ΣE₃²)/cos² α_n)`` (µm), then
    ``Δφ = (K_b/√N) · Δ · 412.8/d`` (″). Each source enters with its tolerance: run-outs
    and clearances as E (divided by cos α_n), cumulative pitch as F_p, tooth-to-tooth as f′.

    **Arguments:**

    - `drive`: the `HarmonicDrive` (its sources carry the tolerances).
    - `tolerances_um`: optional tolerances (µm) that replace the sources' own, by name.

    **Returns:** an `Estimate`.
    """
    tol = {s.name: float(s.tolerance) for s in drive.sources}
    if tolerances_um is not None:
        unknown = sorted(set(tolerances_um) - set(tol))
        if unknown:
            raise ValueError(f"tolerances_um: {unknown} are not sources of this drive; use some of {sorted(tol)}")
        for k, v in tolerances_um.items():
            tol[k] = _finite(f"tolerances_um[{k!r}]", v, nonnegative=True)
    cos_a = math.cos(float(drive.pressure_angle))
    terms, by_class = {}, {c: 0.0 for c in CLASSES}
    for s in drive.sources:
        t2 = tol[s.name] ** 2 / (cos_a**2 if s.kind == "runout" else 1.0)
        terms[s.name] = t2
        by_class[s.source_class] += t2
    delta = 0.5 * math.sqrt(sum(terms.values()))
    arcsec = delta * float(drive.gain()) * ARCSEC_PER_RAD
    return Estimate(delta_um=delta, arcsec=arcsec, arcmin=arcsec / 60.0, sigma_arcsec=arcsec / 3.0,
                    by_class_um={c: 0.5 * math.sqrt(v) for c, v in by_class.items()}, terms_um2=terms)


# ---------------------------------------------------------------- per-unit analysis


def class_phasors(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> dict[str, complex]:
    """Resultant of each class at the output, rad: ``Σ g a e^{iψ}`` over its sources (ψ the TE phase).

    Sources of one class share a frequency, so they add as phasors; |resultant| is the
    class's line amplitude in the spectrum.
    """
    comp = drive.components(errors)
    amp = np.asarray(comp.amplitude * comp.gain)
    ph = np.asarray(comp.phase)
    out = {c: 0j for c in CLASSES}
    for s, a, p in zip(drive.sources, amp, ph):
        out[s.source_class] += complex(a * np.exp(1j * p))
    return out


def beat_envelope_bounds(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> tuple[float, float]:
    """(largest, smallest) envelope of the CS + FS terms, rad: K(e₁ + e₂) and K|e₁ − e₂| (seed sec. 3)."""
    p = class_phasors(drive, errors)
    a, b = abs(p["circular_spline"]), abs(p["flexspline"])
    return a + b, abs(a - b)


def output_rev_peak_to_peak(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> Float[Array, ""]:
    """Peak-to-peak TE over one output revolution, rad (catalogue "transmission accuracy"; see `output_rev_note`)."""
    e = drive.te_extrema(drive.signal(errors))
    return e.max - e.min


def label_for_frequency(drive: HarmonicDrive, freq_cpm: float, *, input_rpm: float, tolerance_cpm: float) -> str | None:
    """The class whose frequency is within `tolerance_cpm` of `freq_cpm` (nearest), or None."""
    best, dist = None, tolerance_cpm
    for c, f in drive.frequencies_cpm(input_rpm).items():
        if abs(f - freq_cpm) <= dist:
            best, dist = c, abs(f - freq_cpm)
    return best


# ---------------------------------------------------------------- assembly phases


class AssemblyResult(eqx.Module):
    """Assembly phases chosen for one unit.

    **Fields:**

    - `errors`: the unit's errors with the adjusted phases.
    - `turns`: change of each adjustable source's angle Θ, rad (in (−π, π]).
    - `before`, `after`: peak-to-peak TE over one output revolution, rad.
    - `class_before`, `class_after`: |resultant| of each class, rad.
    - `class_least`: the least |resultant| each class can reach by turning its adjustable
      sources (closed form: a polygon closes only if no side exceeds the sum of the others).
    """

    errors: dict[str, Eccentricity]
    turns: dict[str, float]
    before: float
    after: float
    class_before: dict[str, float]
    class_after: dict[str, float]
    class_least: dict[str, float]


def _least_resultant(fixed: complex, adjustable: Sequence[float]) -> float:
    sides = [abs(fixed)] + [abs(a) for a in adjustable]
    return max(0.0, 2.0 * max(sides) - sum(sides))


def optimise_assembly(
    drive: HarmonicDrive,
    errors: Mapping[str, Eccentricity],
    *,
    adjustable: Sequence[str],
    starts: int = 32,
    key: int = 0,
    max_steps: int = 256,
) -> AssemblyResult:
    """Choose the phases of the `adjustable` sources at assembly to minimise the per-output-revolution peak-to-peak TE.

    Sources of one class share a frequency and can be turned against each other (e.g. the
    CS mounting orientation against the flexible-bearing run-out); the CS and FS classes
    differ by 2ω_o, so their relative phase turns through 2π every half output revolution
    (the beat) and no choice cancels them for all time. The objective is therefore the
    peak-to-peak over the whole hyper-period, never over a shorter stretch. It is
    minimised with optimistix's BFGS on a smooth log-sum-exp version of it (the foundation's
    `smooth_peak` idea applied to max − min, on the hyper-period grid of the non-tooth
    classes — the tooth class adds the same 2b to every assembly, see `extrema_two_scale`),
    from `starts` random starting phases plus the unit as assembled; every result is
    then re-evaluated exactly and the best kept (never worse than as assembled).

    **Arguments:**

    - `drive`: the `HarmonicDrive`.
    - `errors`: the unit's errors (magnitudes µm, phases rad).
    - `adjustable`: names of the sources whose angle Θ can be chosen (not tooth-class ones).
    - `starts`: random starting points (seeded by `key`).
    - `max_steps`: BFGS steps per start.

    **Returns:** an `AssemblyResult`.
    """
    import optimistix as optx

    from .._metrics import _basis, _grid_size, _grid_values
    from .._signal import to_signal

    names = [s.name for s in drive.sources]
    adjustable = list(adjustable)
    if not adjustable:
        raise ValueError("adjustable: name at least one source whose phase can be set at assembly")
    unknown = [a for a in adjustable if a not in names]
    if unknown:
        raise ValueError(f"adjustable: {unknown} are not sources of this drive; use some of {names}")
    if len(set(adjustable)) != len(adjustable):
        raise ValueError(f"adjustable: names repeated in {adjustable}")
    by_name = dict(zip(names, drive.sources))
    tooth = [a for a in adjustable if by_name[a].source_class == "tooth"]
    if tooth:
        raise ValueError(f"adjustable: {tooth} are tooth-to-tooth sources, whose phase is not set at assembly")
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 1:
        raise ValueError(f"starts: must be a whole number ≥ 1, got {starts!r}")
    base = drive._checked(errors)
    comp0 = drive.components(base)
    keep = [i for i, s in enumerate(drive.sources) if s.source_class != "tooth"]
    sig0 = to_signal(Components(comp0.amplitude[jnp.asarray(keep)], comp0.phase[jnp.asarray(keep)],
                                [comp0.freq[i] for i in keep], gain=comp0.gain[jnp.asarray(keep)]))
    m = _grid_size(sig0.orders, 16)
    cos_b, sin_b = _basis(sig0.orders, m)
    scale = float(jnp.sum(comp0.amplitude * comp0.gain)) or 1.0
    width = 1e-3 * scale
    adj_idx = [names.index(a) for a in adjustable]

    def errors_for(y):
        out = dict(base)
        for j, a in zip(range(len(adjustable)), adjustable):
            out[a] = Eccentricity(base[a].magnitude, base[a].phase + y[j])
        return out

    def smooth_p2p(y, args):
        del args
        comp = drive.components(errors_for(y))
        sig = to_signal(Components(comp.amplitude[jnp.asarray(keep)], comp.phase[jnp.asarray(keep)],
                                   [comp.freq[i] for i in keep], gain=comp.gain[jnp.asarray(keep)]))
        f = _grid_values(sig, cos_b, sin_b) / width
        return width * (jax.nn.logsumexp(f) + jax.nn.logsumexp(-f))

    def exact_p2p(y):
        e = drive.te_extrema(drive.signal(errors_for(y)))
        return e.max - e.min

    y0 = jax.random.uniform(jax.random.key(key), (starts, len(adjustable)), minval=0.0, maxval=2 * math.pi)
    y0 = jnp.concatenate([jnp.zeros((1, len(adjustable))), y0], axis=0)
    solver = optx.BFGS(rtol=1e-9, atol=1e-12 * scale)

    @jax.jit
    def solve_all(y0s):
        def one(y):
            sol = optx.minimise(smooth_p2p, solver, y, max_steps=max_steps, throw=False)
            return sol.value
        ys = jax.vmap(one)(y0s)
        return ys, jax.vmap(exact_p2p)(ys), jax.vmap(exact_p2p)(y0s[:1])

    ys, vals, before = solve_all(y0)
    vals = np.asarray(vals)
    best = int(np.argmin(vals))
    before = float(before[0])
    if vals[best] >= before:
        y_best, after = np.zeros(len(adjustable)), before
    else:
        y_best, after = np.asarray(ys[best]), float(vals[best])
    final = errors_for(jnp.asarray(y_best))
    turns = {a: float((y_best[j] + math.pi) % (2 * math.pi) - math.pi) for j, a in enumerate(adjustable)}
    # Closed-form least resultant per class (fixed sources as one phasor, adjustable ones free).
    comp = drive.components(base)
    amp = np.asarray(comp.amplitude * comp.gain)
    ph = np.asarray(comp.phase)
    least = {}
    for c in CLASSES:
        fixed = sum((amp[i] * np.exp(1j * ph[i]) for i, s in enumerate(drive.sources) if s.source_class == c and i not in adj_idx), 0j)
        adj = [amp[i] for i, s in enumerate(drive.sources) if s.source_class == c and i in adj_idx]
        least[c] = _least_resultant(fixed, adj)
    return AssemblyResult(errors=final, turns=turns, before=before, after=after,
                          class_before={c: abs(v) for c, v in class_phasors(drive, base).items()},
                          class_after={c: abs(v) for c, v in class_phasors(drive, final).items()},
                          class_least=least)


# ---------------------------------------------------------------- records


#: How each class's frequency reads in terms of the input speed n (rpm).
CLASS_FREQUENCY_TEXT = {"circular_spline": "2n", "flexspline": "2n·z₂/z₁", "wave_generator": "n", "tooth": "2z₂·n"}


def class_label(source_class: str) -> str:
    """E.g. ``"circular spline (CS) class, 2n"``."""
    return f"{CLASSES[source_class]['title']}, {CLASS_FREQUENCY_TEXT[source_class]}"


def labelled_lines(drive: HarmonicDrive, rec, *, count: int = 8, signal: TESignal | None = None) -> list[dict]:
    """Spectral lines of a record, labelled with their source class, largest first.

    The lines are found by `spectral_lines` (amplitudes fitted jointly, so close lines
    such as the CS and FS ones are resolved); each is labelled with the class whose
    frequency lies within half a bin. If fewer than `count` lines exist, the list is
    completed with the next-largest peaks of the Hann-windowed spectrum, which are the
    window's side lobes around the real lines — what an FFT analyser would show next —
    marked ``"kind": "side_lobe"`` and labelled as such (no error source makes them). They are
    read from the spectrum zero-padded 8 times: at the bare bin spacing a Hann side lobe
    shows no peak, every bin seeing the same |sin πδ|.

    **Arguments:**

    - `drive`: the `HarmonicDrive` (for the class frequencies).
    - `rec`: a `Record` (from `record`), at its own input speed.
    - `count`: list at least this many entries.
    - `signal`: the model TE the record was taken from, if any, to add each class's exact
      line (``model_freq_cpm``, ``model_amplitude_arcsec``).

    **Returns:** a list of dicts with ``freq_cpm``, ``amplitude_arcsec``, ``source`` (label),
    ``class`` (or None), ``kind`` (``"line"`` or ``"side_lobe"``) and, with `signal`, the model values.
    """
    from .._metrics import spectrum
    from .._records import record_spectrum, spectral_lines, spectrum_peaks

    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count: must be a whole number ≥ 1, got {count!r}")
    found = spectral_lines(rec, max_lines=max(16, count))
    res = rec.resolution_cpm
    model = {}
    if signal is not None:
        sp = spectrum(signal)
        amp = np.asarray(sp.amplitude)
        for f, a in zip(sp.freq, amp):
            cls = next((c for c, fc in drive.class_frequencies().items() if fc == f), None)
            if cls is not None:
                model[cls] = (float(f) * rec.input_rpm, float(a) * ARCSEC_PER_RAD)
    out = []
    for f, a in zip(found.freq_cpm, found.amplitude):
        cls = label_for_frequency(drive, float(f), input_rpm=rec.input_rpm, tolerance_cpm=0.5 * res)
        entry = {"freq_cpm": float(f), "amplitude_arcsec": float(a) * ARCSEC_PER_RAD,
                 "source": class_label(cls) if cls else "unassigned line (no source class at this frequency)",
                 "class": cls, "kind": "line"}
        if cls in model:
            entry["model_freq_cpm"], entry["model_amplitude_arcsec"] = model[cls]
        out.append(entry)
    if len(out) < count:
        spec = record_spectrum(rec, window="hann", zero_pad=8)
        # Exclude each line's Hann main lobe (±2 bins); its side lobes are the next peaks an analyser shows.
        peaks = spectrum_peaks(spec, exclude_cpm=list(found.freq_cpm), exclude_bins=2.0, count=count - len(out))
        real = list(out)
        for f, a in peaks:
            near = min(real, key=lambda e: abs(e["freq_cpm"] - f)) if real else None
            what = f"the {near['freq_cpm']:.2f} cpm line" if near else "no line"
            out.append({"freq_cpm": f, "amplitude_arcsec": a * ARCSEC_PER_RAD,
                        "source": f"none: side lobe of the Hann window around {what}", "class": None, "kind": "side_lobe"})
    out.sort(key=lambda e: -e["amplitude_arcsec"])
    return out
