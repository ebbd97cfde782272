"""Harmonic (strain-wave) drive: kinematic error from its error sources (Liu).

Source: Liu Yuanping, "A study on the theory and measuring technique of transmission
error of harmonic gear drive" (Changchun Institute of Optics and Fine Mechanics),
sections 2–4.

Double-wave drive, elliptical-cam wave generator (WG) input, circular spline (CS,
z₂ teeth) fixed, flexspline (FS, z₁ teeth) output; ratio i = z₁/(z₂ − z₁). With θ the
input (WG) angle, each error source gives a mesh error along the line of action
(Liu's eq. 6):

| class | frequency (× input speed) | term |
|---|---|---|
| circular spline (CS) | 2 | e sin(2(θ + Θ + α_n)) / cos α_n   (eq. 2) |
| flexspline (FS) | 2 z₂/z₁ | e sin(2((z₂/z₁) θ + Θ + α_n)) / cos α_n   (eqs. 3–4) |
| wave generator (WG) | 1 | e sin(θ + Θ) / cos α_n   (eq. 5) |
| tooth-to-tooth, harmonic h | h z₂ | (f′/2) sin(h z₂ θ + Θ) in each zone, times the zone factor (below) |

The FS class is at 2 z₂/z₁ because an FS eccentricity turns with the FS, at
−θ/i, while the cam turns at θ: their angle grows at (1 + 1/i) θ = (z₂/z₁) θ (Liu's
text after eq. 3), and the double wave doubles it.

**The tooth-mesh line (where gearte differs from Liu).** z₂ CS teeth pass each of the two
mesh zones per WG turn, so a tooth-periodic error runs at z₂ in each zone; zone 2 is at π of
the WG, where the CS tooth phase is z₂ π. Each zone has its own term and the output takes their
mean, so harmonic h of the tooth-mesh error reaches the TE times ``½ (1 + e^{i h z₂ π})``
(`tooth_zone_factor`): for an even z₂ (Liu's 182) the zones mesh in phase and the fundamental
z₂ n is the line (33,488 cpm at 184 rpm), 2 z₂ n its harmonic; for an odd z₂ the zones are half a
tooth pitch apart, the fundamental cancels and 2 z₂ n stays. Liu's eq. (6) writes
``f′ sin(2 z₂ ω_b t)/2`` for any z₂ (66,976 cpm), counting 2 z₂ meshing events per WG turn;
gearte keeps Liu's amplitude f′/2 for a tooth source's own harmonic (`HarmonicSource.harmonic`,
default 1) and puts it where the two zones put it. See docs/harmonic.md.

The output angle error is then
(eqs. 8–9)

    Δφ = (K_b / √N) · Δ · 412.8 / d      (″, Δ in µm, d = FS pitch diameter in mm)

with N = 0.1 (z₁ + z₂) teeth in mesh at once and K_b an experimental factor 0.8–1.0.
412.8/d is Liu's constant for µm on a circle of diameter d mm to ″ (2 · 206.265
= 412.53 exactly; gearte keeps Liu's 412.8, 0.07 % more).

**Magnitudes, tolerances and kinds.** Every source has a *magnitude* e (µm, the
`Eccentricity.magnitude` of the error model) that is half of the deviation its
tolerance limits, and a *kind* that says how it enters:

- ``"runout"``: a radial run-out or a fit clearance E; e is the eccentricity it
  causes, half of it (Liu, after eq. 6); the term carries 1/cos α_n.
- ``"cumulative_pitch"``: a cumulative pitch deviation F_p of the CS or FS, which is
  how Liu measures a gear's own eccentricity; e = F_p/2, tangential already, so
  no 1/cos α_n (eq. 7 lists F_p without it).
- ``"tooth_to_tooth"``: the tangential tooth-to-tooth composite deviation f′ of the CS
  or FS teeth; e = f′/2, the amplitude of eq. (6)'s ``f′ sin(2 z₂ ω_b t)/2``, here the
  amplitude of the source's tooth-mesh harmonic in each zone.

**Phases.** `Eccentricity.phase` Θ is the angle (rad) from the error vector to the
cam's major axis at θ = 0 for the CS and FS classes (eq. 2's θ at the start), the
phase of eq. (5)'s ψ for the WG class, and the phase of the tooth-mesh term. Turning
the CS (or a part of the CS class) by δ at assembly changes its Θ by δ and its TE
phase by 2δ; turning the cam on the input shaft by δ changes a WG-class phase by δ.

**Statistics (Liu, sec. 2.3).** A Rayleigh magnitude of scale σ with a uniform phase
makes each term, at any instant, exactly normal with variance σ² (times the term's
factor squared). Liu's variance ``(E/6)²`` per source is therefore a Rayleigh
scale of *tolerance/6* on the magnitude e (then e ≤ E/2, i.e. within the tolerance,
with probability 1 − e^{−4.5} = 98.9 %). With that, Liu's estimate (eq. 7)
``Δ = ±½ √(F_p1² + F_p2² + f′₁² + f′₂² + ΣE²/cos² α_n)`` is exactly 3σ of the TE at any
given instant; `statistical_estimate` computes it, eq. (8) turns it into ″.

**Exact metrics and the tooth class.** The TE repeats over the hyper-period (45 input
revolutions for z₁ = 180, z₂ = 182), and the tooth line runs at z₂ = 182 times the input
speed: the generic `gearte.extrema` would grid 16 points per tooth period over the whole
hyper-period, 131,040 points per unit. When the tooth sources make one line (one harmonic
that the zones do not cancel) of amplitude b, far faster than the rest, `HarmonicDrive.extrema` uses
`gearte.extrema_two_scale`: exact extrema of the other classes (1,456 grid points, Newton),
then Newton on the whole TE from the tooth crests next to each of their best
candidates. gearte's metrics (`gearte.Peak`, `gearte.PeakToPeak`) take the drive's
extrema, so every study uses it. The result equals the full-grid extrema (tested to
~1e-12); each value also comes with a certified bound on its error, ``max S + b − max F``
(≤ ½ D₂ (π/k)² for the tooth line at k = h z₂, where D₂ bounds the curvature of the slower classes), which `gearte run`
reports. Nothing is dropped or approximated: the tooth class is in every figure. (Tooth sources
of two surviving harmonics make two fast lines; the extrema then take the full grid, exact but slower.)

**Per output revolution.** One output revolution is i input revolutions. When the
hyper-period divides into it (always for an integer ratio of a double-wave drive), the
peak-to-peak over any output revolution is the peak-to-peak over the hyper-period;
otherwise the figures are over the hyper-period, an upper bound (see `output_rev_note`).

The rest of the harmonic drive: `harmonic_sources` (classes, `HarmonicSource`, run
settings), `harmonic_estimate` (Liu's estimate, class lines, beats, labelled record
lines), `harmonic_assembly` (assembly phases of one unit), `harmonic_outputs` and `harmonic_readings` (what
`gearte run` writes); their public names are re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..core.grid import grid_size
from ..core.metrics import RMS, AbstractMetric, Peak, PeakToPeak
from ..core.programs import kept_jit
from ..core.schema import ConfigError, Table
from ..core.signal import Components, TESignal, evaluate
from ..core.twoscale import TwoScaleExtrema, extrema_auto, fast_line_order
from ..core.units import ARCSEC_PER_RAD
from .harmonic_assembly import AssemblyResult, optimise_assembly
from .harmonic_estimate import (
    LIU_COMPUTED_ARCMIN,
    LIU_MEASURED_ARCMIN,
    Estimate,
    beat_envelope_bounds,
    class_phasors,
    delta_for_arcmin,
    label_for_frequency,
    labelled_lines,
    output_rev_peak_to_peak,
    source_phasors,
    statistical_estimate,
)
from .harmonic_outputs import study_outputs
from .harmonic_sources import (
    CLASS_FREQUENCY_TEXT,
    CLASSES,
    KINDS,
    LIU_ARCSEC_PER_UM_MM,
    HarmonicRunSettings,
    HarmonicSource,
    class_label,
    finite,
    line_key,
    line_title,
    tooth_zone_factor,
    whole,
)
from .protocol import AbstractSinusoidalDrive, AbstractStudyContext, Eccentricity, Errors, SourceSpec, StudyOutputs

__all__ = [
    "CLASSES",
    "CLASS_FREQUENCY_TEXT",
    "KINDS",
    "LIU_ARCSEC_PER_UM_MM",
    "LIU_COMPUTED_ARCMIN",
    "LIU_MEASURED_ARCMIN",
    "AssemblyResult",
    "Estimate",
    "HarmonicDrive",
    "HarmonicRunSettings",
    "HarmonicSource",
    "beat_envelope_bounds",
    "class_label",
    "class_phasors",
    "delta_for_arcmin",
    "hyper_period_revs",
    "label_for_frequency",
    "labelled_lines",
    "line_key",
    "optimise_assembly",
    "output_rev_peak_to_peak",
    "source_phasors",
    "statistical_estimate",
    "tooth_zone_factor",
]

_extrema_jit = kept_jit(extrema_auto)


class HarmonicDrive(AbstractSinusoidalDrive):
    """Double-wave harmonic drive: WG input, CS fixed, FS output (Liu).

    **Arguments:**

    - `z_flexspline`: z₁, FS teeth.
    - `z_circular_spline`: z₂ > z₁, CS teeth; z₂ − z₁ a multiple of the wave number.
    - `sources`: the `HarmonicSource`s (unique names); each is an eccentricity error source
      of the drive (`error_sources`), with its tolerance as the default.
    - `pitch_diameter`: d, pitch diameter of the driven wheel (the FS), mm.
    - `pressure_angle`: α_n, rad (default 20°).
    - `k_b`: K_b, Liu's experimental factor (0.8–1.0; default 1.0).
    - `teeth_in_mesh`: N, tooth pairs in mesh at once (default 0.1 (z₁ + z₂)).
    - `waves`: wave number; only 2 (double-wave, Liu's eq. 2) is supported.
    - `run_settings`: optional `HarmonicRunSettings` for `gearte run`.
    """

    z_flexspline: int = eqx.field(static=True)
    z_circular_spline: int = eqx.field(static=True)
    waves: int = eqx.field(static=True)
    sources: tuple[HarmonicSource, ...]
    pitch_diameter: Float[Array, ""]
    pressure_angle: Float[Array, ""]
    k_b: Float[Array, ""]
    teeth_in_mesh: Float[Array, ""]
    run_settings: HarmonicRunSettings | None

    type_name: ClassVar[str] = "harmonic"

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
        z1 = whole("z_flexspline", z_flexspline, minimum=3)
        z2 = whole("z_circular_spline", z_circular_spline, minimum=3)
        w = whole("waves", waves, minimum=1)
        if w != 2:
            raise ValueError(
                f"waves: only double-wave drives (waves = 2) are modelled — Liu's eq. (2) doubles the "
                f"eccentricity angle because the two mesh zones are half a turn apart; got waves = {w}"
            )
        if z2 <= z1:
            raise ValueError(
                f"tooth counts: the circular spline needs more teeth than the flexspline (z_circular_spline > "
                f"z_flexspline) for a WG-in, CS-fixed, FS-out drive; got z_flexspline = {z1}, z_circular_spline = {z2}"
            )
        if (z2 - z1) % w:
            raise ValueError(
                f"tooth counts: z_circular_spline − z_flexspline = {z2 - z1} must be a multiple of the wave "
                f"number {w} (usually exactly {w})"
            )
        d = finite("pitch_diameter (mm)", pitch_diameter, positive=True)
        a = finite("pressure_angle (rad)", pressure_angle, positive=True)
        if not a < math.radians(45):
            raise ValueError(f"pressure_angle: {math.degrees(a):g}° is not a gear pressure angle (give rad; 20° = {math.radians(20):.6f})")
        kb = finite("k_b", k_b, positive=True)
        n = 0.1 * (z1 + z2) if teeth_in_mesh is None else finite("teeth_in_mesh", teeth_in_mesh, positive=True)
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

    # ------------------------------------------------------------ protocol: sources, metrics, study file

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        return {
            s.name: SourceSpec(
                s.name,
                "eccentricity",
                shape=(1,),
                tolerance=s.tolerance,
                description=f"{CLASSES[s.source_class]['title']}, {s.kind.replace('_', ' ')}",
            )
            for s in self.sources
        }

    @property
    def metrics(self) -> dict[str, AbstractMetric]:
        """Peak-to-peak over one output revolution (the catalogue figure; see `output_rev_note`) first, then peak and RMS."""
        return {"peak_to_peak": PeakToPeak(), "peak": Peak(), "rms": RMS()}

    @classmethod
    def from_table(cls, table: Table) -> HarmonicDrive:
        """``[drive] type = "harmonic"``::

            z_flexspline = 180            # z₁
            z_circular_spline = 182       # z₂
            pitch_diameter_mm = 90        # d, FS pitch diameter
            pressure_angle_deg = 20       # α_n (or pressure_angle_rad; default 20°)
            K_b = 1.0                     # optional, default 1.0
            teeth_in_mesh = 36.2          # optional, default 0.1 (z₁ + z₂)
            waves = 2                     # optional; only 2 is supported

            [[drive.sources]]             # one table per error source
            name = "cs_pitch"
            class = "circular_spline"     # circular_spline | flexspline | wave_generator | tooth
            kind = "cumulative_pitch"     # runout (default) | cumulative_pitch | tooth_to_tooth
            tolerance_um = 25
            basis = "ISO 1328-1:2013 class 6"   # optional: where the tolerance comes from
            # harmonic = 2                # tooth class only: tooth-mesh harmonic (default 1)

            [drive.record]                # optional: the encoder record and spectrum of `gearte run`
            input_rpm = 184
            duration_s = 80
            sample_rate_hz = 4000
            lines = 8                     # list at least this many spectral peaks

            [drive.assembly]              # optional: assembly phases to optimise on the typical unit
            adjustable = ["cs_bore_runout"]
            starts = 32

        Each source then needs its ``[errors.NAME]`` table (magnitude law and phase rule); its
        ``tolerance_um`` there may be left out (the drive's is used) or must agree.
        """
        t = table
        z1 = t.integer("z_flexspline", minimum=1)
        z2 = t.integer("z_circular_spline", minimum=1)
        waves = t.integer("waves", 2, minimum=1)
        d = t.number("pitch_diameter_mm", positive=True)
        alpha = t.angle("pressure_angle", math.radians(20.0))
        kb = t.number("K_b", 1.0, positive=True)
        n_mesh = t.number("teeth_in_mesh", positive=True) if t.has("teeth_in_mesh") else None
        raw = t.get("sources")
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"{t.where} sources: give the error sources as [[drive.sources]] tables (name, class, kind, tolerance_um)")
        sources = []
        for i, item in enumerate(raw):
            st = Table(item, f"[[drive.sources]] #{i + 1}")
            name = st.string("name")
            st.where = f"[[drive.sources]] #{i + 1} ({name})"
            src_cls = st.string("class", choices=tuple(CLASSES))
            kind = st.string("kind", CLASSES[src_cls]["kinds"][0], choices=KINDS)
            tol = st.number("tolerance_um", minimum=0)
            harmonic = st.integer("harmonic", 1, minimum=1)
            basis = st.string("basis", "")
            st.finish()
            try:
                sources.append(HarmonicSource(name, src_cls, kind=kind, tolerance=tol, harmonic=harmonic, basis=basis))
            except ValueError as e:
                raise ConfigError(f"{st.where}: {e}") from None
        settings = _run_settings(t)
        try:
            return cls(
                z1, z2, sources, pitch_diameter=d, pressure_angle=alpha, k_b=kb, teeth_in_mesh=n_mesh, waves=waves, run_settings=settings
            )
        except ValueError as e:
            raise ConfigError(f"{t.where}: {e}") from None

    # ------------------------------------------------------------ kinematics

    @property
    def ratio(self) -> Fraction:
        """i = z₁ / (z₂ − z₁): input revolutions per output revolution (the FS turns against the WG)."""
        return Fraction(self.z_flexspline, self.z_circular_spline - self.z_flexspline)

    def class_frequencies(self) -> dict[str, Fraction]:
        """Frequency of each class, as an exact multiple of the input (WG) speed (Liu's eqs. 2, 4, 5).

        ``"tooth"`` is the tooth-mesh frequency of *one* zone, z₂ (teeth passing it per WG turn);
        whether a harmonic of it reaches the TE depends on the two zones' relative phase
        (`tooth_zone_factor`, `line_frequencies`). Liu's eq. (6) has 2 z₂.
        """
        z1, z2, w = self.z_flexspline, self.z_circular_spline, self.waves
        return {
            "circular_spline": Fraction(w),
            "flexspline": Fraction(w * z2, z1),
            "wave_generator": Fraction(1),
            "tooth": Fraction(z2),
        }

    def zone_factor(self, source: HarmonicSource) -> complex:
        """The two mesh zones' factor on a source's line: 1 except for the tooth class (`tooth_zone_factor`, identical zones)."""
        if source.source_class != "tooth":
            return complex(1.0)  # Liu's eq. (2) already takes both zones into account
        return tooth_zone_factor(self.z_circular_spline, source.harmonic)

    def source_line(self, source: HarmonicSource) -> tuple[str, Fraction]:
        """(line key, frequency × input speed) of a source: its class's line, or harmonic h of the tooth-mesh line at h z₂."""
        f = self.class_frequencies()[source.source_class]
        return line_key(source.source_class, source.harmonic), f * source.harmonic

    def line_frequencies(self) -> dict[str, Fraction]:
        """Every line of the TE, × input speed: the CS, FS and WG classes, and each tooth-mesh harmonic of the
        tooth sources that the two zones do not cancel (key ``"tooth"`` for h = 1, ``"tooth_h2"``, … above)."""
        out = {c: f for c, f in self.class_frequencies().items() if c != "tooth"}
        tooth = sorted({s.harmonic for s in self.sources if s.source_class == "tooth" and self.zone_factor(s) != 0})
        for h in tooth:
            key, f = self.source_line(HarmonicSource("_", "tooth", tolerance=0.0, harmonic=h))
            out[key] = f
        return out

    def frequencies_cpm(self, input_rpm: float) -> dict[str, float]:
        """Frequency of each line (`line_frequencies`) in cycles per minute at an input speed of `input_rpm`
        (Liu, sec. 4: 184, 368, 372 at 184 rpm; the tooth line of z₂ = 182 at 33,488)."""
        n = finite("input_rpm", input_rpm, positive=True)
        return {c: float(f) * n for c, f in self.line_frequencies().items()}

    @property
    def beat_frequency(self) -> Fraction:
        """Difference of the FS and CS class frequencies, × input speed: w (z₂ − z₁)/z₁ = w/i."""
        f = self.class_frequencies()
        return abs(f["flexspline"] - f["circular_spline"])

    @property
    def beats_per_output_rev(self) -> Fraction:
        """Beats of the CS and FS lines per output revolution: (beat frequency) × i — the wave number, 2 (Liu, sec. 3)."""
        return self.beat_frequency * self.ratio

    def gain(self) -> Float[Array, ""]:
        """Output angle per µm of mesh error Δ, rad/µm: (K_b/√N) · 412.8/d ″/µm (eq. 8)."""
        return self.k_b / jnp.sqrt(self.teeth_in_mesh) * LIU_ARCSEC_PER_UM_MM / self.pitch_diameter / ARCSEC_PER_RAD

    def source_factor(self, source: HarmonicSource) -> Float[Array, ""]:
        """Mesh error per µm of magnitude: 1/cos α_n for run-outs and clearances, 1 for F_p and f′ (eqs. 6–7)."""
        return 1.0 / jnp.cos(self.pressure_angle) if source.kind == "runout" else jnp.ones(())

    def source_gains(self) -> dict[str, Float[Array, ""]]:
        """Output angle per µm of each source's magnitude, rad/µm."""
        g = self.gain()
        return {s.name: g * self.source_factor(s) for s in self.sources}

    def source_term(self, source: HarmonicSource, error: Eccentricity) -> tuple[Array, Array, Array, Fraction] | None:
        """(amplitude µm, TE phase rad, gain rad/µm, frequency) of one source's term at the output, or None when the
        two zones cancel it (a tooth harmonic of odd h z₂)."""
        zf = self.zone_factor(source)
        if zf == 0:
            return None
        theta0 = error.phase[0]
        if source.source_class in ("circular_spline", "flexspline"):
            ph = self.waves * (theta0 + self.pressure_angle)  # eqs. (2), (4): sin(2(θ + α_n))
        else:
            ph = theta0  # eq. (5) for the WG class; zone 1's tooth-mesh phase for the tooth class
        gain = self.gain() * self.source_factor(source) * abs(zf)
        return error.magnitude[0], ph + math.atan2(zf.imag, zf.real), gain, self.source_line(source)[1]

    def components(self, errors: Mapping[str, Eccentricity], *, tooth: bool = True) -> Components:
        """TE components at the output (Liu's eq. 6 with eq. 8), one per source whose line the two zones do not
        cancel (a tooth source of an odd h z₂ has none); `tooth=False` leaves the tooth class out."""
        e = self.checked(errors)
        amp, phase, gain, fr, labels = [], [], [], [], []
        for s in self.sources:
            term = self.source_term(s, e[s.name])
            if term is None or (s.source_class == "tooth" and not tooth):
                continue
            a, ph, g, f = term
            amp.append(a)
            phase.append(ph)
            gain.append(g)
            fr.append(f)
            labels.append(f"{s.name} ({line_title(self.source_line(s)[0])}, {f})")
        if not amp:  # only tooth sources, all cancelled by the zones: a zero TE
            return Components(jnp.zeros((1,)), jnp.zeros((1,)), [self.class_frequencies()["tooth"]], gain=jnp.zeros((1,)), labels=["none"])
        return Components(jnp.stack(amp, axis=-1), jnp.stack(phase, axis=-1), fr, gain=jnp.stack(gain, axis=-1), labels=labels)

    # ------------------------------------------------------------ exact extrema

    def extrema(self, signal: TESignal) -> TwoScaleExtrema:  # pyright: ignore[reportIncompatibleMethodOverride]
        """Exact extrema of this drive's TE over the hyper-period, with certified error bounds (`max_gap`, `min_gap`):
        the tooth class as a fast line (`gearte.extrema_two_scale`). gearte's metrics take the drive's extrema."""
        return _extrema_jit(signal)

    def sample_outputs(self, errors: Errors, response: TESignal) -> dict[str, Array]:
        """Per sample of a `gearte run`: the TE at θ = 0 (Liu's normal variable, sec. 2.3) and the certified error
        bounds of the extrema (`max_gap`, `min_gap`, rad), from the same response as the study's metric."""
        del errors
        e = self.extrema(response)
        return {"te_at_zero": evaluate(response, jnp.zeros(())), "max_gap": e.max_gap, "min_gap": e.min_gap}

    def accuracy(self) -> str:
        return (
            "exact over the whole hyper-period: two-scale extrema (gearte.extrema_two_scale) — the tooth-mesh line "
            "(z₂ × input speed for an even z₂) as a fast line on the exact extrema of the other classes (a grid of 16 points per "
            "period of their fastest term, Newton refinement), with a certified bound on the error of every value, the "
            "largest stated with the run"
        )

    def bytes_per_sample(self) -> int:
        """Peak working memory of one Monte Carlo sample: the grid of the slow classes (16 points per period), not of the tooth line."""
        sig = jax.eval_shape(lambda: self.signal(self.zero_errors()))
        k = fast_line_order(sig)
        slow = [o for o in sig.orders if o != k] or [1]
        m = grid_size(tuple(slow), 16)
        return 8 * (12 * m + 64 * len(sig.orders) + 4096)

    def output_rev_note(self) -> str:
        """How the per-output-revolution figures relate to the hyper-period, for reports."""
        h = hyper_period_revs(self)
        i = self.ratio
        if h <= i:
            return (
                f"the TE repeats every {h} input revolutions, which one output revolution ({i} input revolutions) "
                "covers, so the peak-to-peak over any output revolution equals that over the hyper-period"
            )
        return (
            f"the TE repeats only every {h} input revolutions = {h / i} output revolutions: the figures are over that "
            "hyper-period, an upper bound of those of any single output revolution"
        )

    # ------------------------------------------------------------ reports

    def describe(self) -> list[tuple[str, str]]:
        f = self.line_frequencies()
        rows = [
            ("drive", "double-wave harmonic drive, WG input, CS fixed, FS output (Liu)"),
            ("tooth counts z₁ (FS) / z₂ (CS)", f"{self.z_flexspline} / {self.z_circular_spline}"),
            ("ratio i = z₁/(z₂ − z₁)", f"{self.ratio} = {float(self.ratio):.6g}"),
            ("pressure angle α_n", f"{math.degrees(float(self.pressure_angle)):.6g}°"),
            ("FS pitch diameter d", f"{float(self.pitch_diameter):g} mm"),
            ("K_b / teeth in mesh N", f"{float(self.k_b):g} / {float(self.teeth_in_mesh):.6g}"),
            ("output angle per µm of mesh error, (K_b/√N)·412.8/d", f"{float(self.gain()) * ARCSEC_PER_RAD:.6g}″/µm"),
            ("hyper-period / one output revolution", f"{hyper_period_revs(self)} / {self.ratio} input revolutions"),
            ("beats per output revolution (CS and FS classes)", str(self.beats_per_output_rev)),
        ]
        rows += [(f"frequency of the {line_title(c)} (× input speed)", f"{v} = {float(v):.6g}") for c, v in f.items()]
        z2 = self.z_circular_spline
        rows.append(
            (
                "tooth-mesh line (two zones, CS tooth phase z₂π apart)",
                f"z₂ = {z2} is {'even: the zones mesh in phase, fundamental z₂' if z2 % 2 == 0 else 'odd: the zones are half a tooth apart, the fundamental cancels, 2z₂ stays'}",
            )
        )
        rows += [
            (
                f"source {s.name}",
                f"{CLASSES[s.source_class]['short']} class, {s.kind}"
                + (f", tooth-mesh harmonic {s.harmonic}" if s.source_class == "tooth" else "")
                + f", tolerance {float(s.tolerance):g} µm"
                + (f" ({s.basis})" if s.basis else ""),
            )
            for s in self.sources
        ]
        return rows

    def study_outputs(self, context: AbstractStudyContext) -> StudyOutputs:
        """Liu's estimate against the Monte Carlo, the typical unit's lines, beats and record, its assembly phases
        (`gearte.drives.harmonic_outputs`)."""
        return study_outputs(self, context)


def hyper_period_revs(drive: HarmonicDrive) -> Fraction:
    """Hyper-period of the TE, input revolutions, for the classes the drive has sources in."""
    used = sorted({drive.source_line(s)[1] for s in drive.sources if drive.zone_factor(s) != 0})
    num, den = 0, 1
    for v in used:
        num, den = math.gcd(num * v.denominator, v.numerator * den), den * v.denominator
    return Fraction(den, num) if num else Fraction(1)


def _run_settings(t: Table) -> HarmonicRunSettings | None:
    """``[drive.record]`` and ``[drive.assembly]``: what `gearte run` adds (None without a record)."""
    rec = t.table("record", None)
    asm = t.table("assembly", None)
    if asm is not None and rec is None:
        raise ConfigError(f"{t.where}: [drive.assembly] needs a [drive.record] table too (the record shows the assembled unit)")
    if rec is None:
        return None
    adjustable, starts = (), 32
    if asm is not None:
        adj = asm.get("adjustable")
        if not isinstance(adj, list) or not all(isinstance(x, str) for x in adj) or not adj:
            raise ConfigError(f'{asm.where} adjustable: expected a list of source names, e.g. ["cs_bore_runout"]')
        adjustable = tuple(adj)
        starts = asm.integer("starts", 32, minimum=1, maximum=4096)
        asm.finish()
    try:
        settings = HarmonicRunSettings(
            input_rpm=rec.number("input_rpm", positive=True),
            duration_s=rec.number("duration_s", positive=True),
            sample_rate_hz=rec.number("sample_rate_hz", positive=True),
            lines=rec.integer("lines", 8, minimum=1),
            adjustable=adjustable,
            assembly_starts=starts,
        )
    except ValueError as e:
        if isinstance(e, ConfigError):
            raise
        if asm is not None and str(e).startswith("adjustable:"):  # the key's own table
            raise ConfigError(f"{asm.where} {e}") from None
        raise ConfigError(f"{rec.where}: {e}") from None
    rec.finish()
    return settings
