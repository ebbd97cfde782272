"""Cycloid-pin reducer: the drive, its tooth profile, errors and tooth-clearance analysis (Yao & Liang 2001).

Source: Yao Wenxi, Liang Zhe (2001), "Tooth profile clearance distribution of a
cycloid-pin reducer", Machine Design 18(5):22-25. The RV (K-H-V) model reuses this geometry.

**Frame and conventions (the converted mechanism, turning arm fixed).** Origin at the
crank's eccentric centre O_a (the nominal centre of the cycloid disc); the y axis
points along the crank, from the pin-wheel centre O_b = (0, −a) to O_a, i.e. towards
the pitch point. Angles are counter-clockwise (CCW), in rad.

- Pin j (j = 0 … z_b − 1) sits at angle ψ_j = θ_T + 2πj/z_b about O_b, measured from
  the +y axis (ψ = 0: the pin deepest in a tooth space; ψ = π: the pin at a tooth
  tip): its centre is O_b + R (−sin ψ_j, cos ψ_j). θ_T is the input position, the
  angle the pin wheel has turned relative to the arm.
- The disc turns by θ_a; in theory θ_a = (z_b/z_a) θ_T. In the real reducer (pin
  wheel fixed, input on the arm) the output turns by θ_a − θ_T = θ_T/z_a against
  an input of −θ_T, so a disc-angle error is an output-angle error: the rotation
  error (TE) of the stage.
- **Profile** (Li Lixing's handbook form; Blanche & Yang 1989 write the same curve).
  For a pin circle R, pin radius r, eccentricity a, K_1 = a z_b/R and the flank
  parameter φ (the pin's angle ψ relative to the crank, valley centre at φ = 0), the
  theoretical (pin-centre) curve and its unit outward normal are

      P(φ) = (R sin(φ/z_a) − a sin(z_b φ/z_a),  R cos(φ/z_a) − a cos(z_b φ/z_a))
      N(φ) = (sin(φ/z_a) − K_1 sin(z_b φ/z_a),  cos(φ/z_a) − K_1 cos(z_b φ/z_a)) / S
      S    = (1 + K_1² − 2 K_1 cos φ)^{1/2},

  and the tooth flank is the equidistant E = P − r N. One tooth space is
  φ ∈ [−π, π]; tooth space n (n = 0 … z_a − 1) is that space turned by −2πn/z_a
  (clockwise). The half φ > 0 of every space is its **driving flank**: a pin on it
  pushes the disc clockwise (the outward normal's moment about O_a is
  P × N = a z_a sin φ / S > 0, the contact's lever arm l); the half φ < 0 is the
  **reverse flank**. At θ_T the pins with ψ ∈ (0, π) sit on driving flanks, those with
  ψ ∈ (−π, 0) on reverse flanks: z_b/2 each for an even z_b.
- **Modifications** (the wheel is dressed to R_Z = R + ΔR_Z, r_Z = r + Δr_Z): the
  profile is the one above with R_Z, r_Z and the *same* eccentricity a (so
  K_Z = a z_b / R_Z), as in the handbook's modified-profile equations. ΔR_Z < 0 is a
  negative shift, Δr_Z > 0 a positive equidistant. gearte adds a **rotation
  modification** δ: each half of every tooth space is turned about the disc centre
  by δ away from its pins (a uniform tangential clearance δ on both flanks), which the
  shift/equidistant pair approximates.
- **Form-grinding errors** (Yao & Liang 2001, eqs. 1–2): dressing errors (δX_4, δY_4) and the
  per-space infeed error ΔY_4(n) shift the wheel profile (in the space's own frame,
  Y_4 along its centre line, outwards); space n is ground at the index angle
  β_n = 2πn/z_a + β_0 + Δβ(n) (the paper's 2π(n−1)/z_a with its 1-based n); the blank
  set-up eccentricity ΔA at φ_A and the mandrel run-out ΔB at φ_B (eq. 2 puts it along
  X′_2: φ_B = 0) displace the ground profile from the bore by −(ΔA e^{iφ_A} + ΔB e^{iφ_B}).
- **Reducer errors** (Yao & Liang 2001, sec. 2): actual pin-circle radius R′ = R + ΔR′, pin radius
  r′ = r + Δr′ (the sleeve's contact surface from the pin centre), crank eccentricity
  A′ = a + ΔA′; per-pin tangential δ_j (and, a gearte extension, radial) position
  errors; the disc centre displaced by Δ_1 at α_1 (turning-arm bearing) and the
  pin-wheel centre by Δ_2 at α_2 (input-shaft bearings, spigot fits), both fixed in
  the converted mechanism as in the paper; and (extension) a pin-circle eccentricity
  that turns with the pin wheel (housing-fixed in the real reducer): at angle
  α_e + θ_T in the converted frame.

**Clearance analysis** (`gearte.drives.cycloid_pin_contact`). For pin j, the
rotation θ_a at which its flank touches it: the pin centre c (relative to the disc
centre) must lie on the pin-centre locus of the actual flank,
Q(φ) = (transformed) P_Z(φ) − (r_Z − r′) N_Z(φ) (the flank's equidistant at r′). As
the disc turns, c moves on the circle |c| about the disc centre, so the 2-unknown solve
(φ, θ_a) reduces to one equation, |Q(φ)| = |c| on the pin's half of its
tooth space, then θ_a = arg c − arg Q(φ). The solve is a bracketed Newton iteration of
fixed length (vmaps over pins, positions and samples), differentiated by the implicit
function theorem; its convergence is reported per pin. A pin further out than the tooth
tip can never touch (rotation to contact ±∞).

At no load only one pair touches. Driving flanks bound the disc from above
(θ_a ≤ θ_j), reverse flanks from below (θ_a ≥ θ_j): under a forward load the disc
rests at min over driving pins (the **contacting pair**), under a reverse load at max
over reverse pins. Rotation error Δθ = θ_a − (z_b/z_a) θ_T of the contacting pair;
**lost motion** = (driving contact) − (reverse contact), the rotation of the output
between the two flanks with the input held. **Tangential clearance** of a pin: the
extra rotation before it touches, from its own flank's contact (the paper's
|Δθ_N| − |Δθ|_min, eq. 7), as an angle and as an arc on the pin circle (× R′; the garbled eq. 7 seems to carry a
factor z_a/z_b, a pin-wheel angle of the converted mechanism, which would make the arcs
1/z_b smaller).
**Normal clearance**: min over the flank of |pin centre − flank point| − r′ at that
contacting configuration (the paper's eq. 8), by a 1-D Newton search near the contact point.
A pin can also reach the far flank of its tooth space, but only after the disc turns
through the space's width at the pin's radius; gearte, like the paper, pairs each pin
with its own flank.

**Generating grinding** (`GeneratingGrinding()`, `process = "generating"` in a study file, `gearte.drives.cycloid_pin_grinding`): the wheel is one
pin moved by the grinder's generating crank and work drive; its errors move the flank along the normal by
e_n(φ). **The paper's numbering** (K = n − J, `paper_position`, `paper_pin`, `paper_tooth`,
`errors_from_paper` in `gearte.drives.cycloid_pin_geometry`) and the **disc centre** held at a fixed offset or
floating (`gearte.drives.cycloid_pin_metrics.floating_disc`) are set out in docs/cycloid.md.

**The drive** (`CycloidPin`, a grid drive of the drive protocol): its 20 error sources (26 for a
generating-ground disc) are the fields of `CycloidErrors`, each a signed deviation (µm, or rad for angles; one value
per tooth space or per pin where the field has one), in the order of `ERROR_FIELDS`. Its
response to a set of errors is the clearance analysis at every angle of its grid
(`input_angles`: one input revolution or more, `positions_per_pitch` per pin pitch), and
its metrics (`gearte.drives.cycloid_pin_metrics`) are taken over that grid: lost motion,
rotation error peak-to-peak, loaded pairs. The drive also carries the settings of its
analysis (`CycloidAnalysis`: the tangential deformation budget, the grid, the input position
and sweeps of the report) and one reducer to analyse in detail (`reference`); its study
file table is described in `gearte.drives.cycloid_pin_table`, its report in
`gearte.drives.cycloid_pin_outputs`.

Units: geometry in mm, errors in µm, angles in rad inside; reports in ″ and ′.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.metrics import AbstractMetric
from ..core.schema import ConfigError
from ..core.units import ARCSEC_PER_RAD, TWO_PI
from ..core.validate import as_float, as_int, check_option
from .cycloid_pin_contact import (
    Clearances,
    PinLayout,
    _sweep_jit,
    clearances,
    first_order_clearance,
    loaded_pairs,
    normal_clearance,
    pin_layout,
    pitch_angles,
    revolution_angles,
    smooth_loaded_pairs,
    sweep,
    theoretical_pairs,
)
from .cycloid_pin_geometry import (
    ALL_ERROR_FIELDS,
    ERROR_FIELDS,
    ERROR_UNITS,
    GENERATING_ERROR_FIELDS,
    GENERATING_ONLY,
    PER_PIN,
    PER_SPACE,
    PROCESSES,
    AbstractGrindingProcess,
    CycloidErrors,
    CycloidModification,
    FormGrinding,
    GeneratingGrinding,
    _number,
    as_cycloid_errors,
    check_modification,
    checked_errors,
    disc_outline,
    min_curvature_radius,
    theoretical_profile,
    tooth_profile,
)
from .cycloid_pin_metrics import (
    METRICS,
    LoadedPairs,
    LoadedPairsMin,
    LostMotion,
    LostMotionMin,
    RotationErrorPeakToPeak,
    Sensitivity,
    sensitivities,
    unit_metrics,
)
from .cycloid_pin_outputs import input_angle, sample_vector, study_outputs
from .cycloid_pin_table import drive_arguments
from .protocol import AbstractGridDrive, AbstractStudyContext, SourceSpec, StudyOutputs, Trace

if TYPE_CHECKING:
    from ..core.schema import Table

#: Symbol and description of each error source (the fields of `CycloidErrors`), for reports.
SOURCE_TEXT = {
    "dressing_x": ("δX_4", "dresser error along X_4 (form grinding)"),
    "dressing_y": ("δY_4", "dresser error along Y_4 (form grinding)"),
    "infeed": ("ΔY_4(n)", "infeed error of each tooth space"),
    "index_offset": ("β_0", "initial index angle of the grinder"),
    "indexing": ("Δβ(n)", "indexing error of each tooth space"),
    "setup_eccentricity": ("ΔA", "blank set-up eccentricity"),
    "setup_phase": ("φ", "angle of the set-up eccentricity"),
    "mandrel_runout": ("ΔB", "mandrel run-out"),
    "mandrel_phase": ("φ_B", "angle of the mandrel run-out"),
    "pin_circle_radius": ("ΔR′", "pin-circle radius error"),
    "pin_radius": ("Δr′", "pin (sleeve contact surface) radius error"),
    "eccentricity": ("ΔA′", "crank eccentricity error"),
    "pin_tangential": ("δ_j", "tangential position error of each pin"),
    "pin_radial": ("δr_j", "radial position error of each pin"),
    "disc_offset": ("Δ_1", "disc centre offset from the eccentric (turning-arm bearing)"),
    "disc_offset_phase": ("α_1", "angle of the disc centre offset"),
    "pin_wheel_offset": ("Δ_2", "pin-wheel centre offset from the input axis"),
    "pin_wheel_offset_phase": ("α_2", "angle of the pin-wheel centre offset"),
    "pin_circle_eccentricity": ("e_p", "pin-circle eccentricity fixed in the housing"),
    "pin_circle_eccentricity_phase": ("α_e", "angle of the pin-circle eccentricity"),
    "wheel_radius": ("δr_w", "wheel working-radius error (generating grinding)"),
    "generating_eccentricity": ("δa_g", "generating crank radius error"),
    "generating_chain": ("A_c", "generating chain's once-per-crank-revolution angular error"),
    "generating_chain_phase": ("p_c", "phase of the generating chain's error"),
    "pitch_accumulated": ("A_p", "work drive's once-per-revolution error (accumulated pitch F_p = 2 A_p R_z)"),
    "pitch_accumulated_phase": ("p_p", "phase of the accumulated pitch error"),
}
#: How the meaning of the wheel's errors changes for a generating-ground disc.
GENERATING_SOURCE_TEXT = {
    "dressing_x": ("δX", "wheel centre offset across the wheel slide (generating grinding)"),
    "dressing_y": ("δR", "wheel centre offset along the wheel slide (generating grinding)"),
    "infeed": ("δR(n)", "wheel-slide position error while each tooth space is ground"),
    "indexing": ("Δβ(n)", "single pitch (indexing) error of each tooth space"),
}


class CycloidAnalysis(eqx.Module):
    """How a `CycloidPin` is analysed (every field static: changing one recompiles).

    **Arguments:**

    - `budget_mm`: the tangential elastic deformation a loaded pair can take, on the pin
      circle, mm (Yao & Liang 2001: 0.2 mm): a pin within it counts as a loaded pair.
    - `width_mm`: smoothing width of the loaded-pair surrogate, mm (default `budget_mm`/10).
    - `positions_per_pitch`, `revolutions`: the grid of input angles every metric is taken on
      (the response of `CycloidPin`: Monte Carlo, sensitivities, budgets): `revolutions` whole
      input revolutions, `positions_per_pitch` per pin pitch (default 2 and 1).
    - `input_angle`: θ_T of the per-pin report (clearance of every pin), rad (default half a pin pitch).
    - `pitch_points`: points of the report's sweep over one pin pitch (64).
    - `sweep_points_per_pitch`, `sweep_revolutions`: the report's sweep of the rotation error and
      lost motion over whole revolutions (16 per pitch, 1 revolution).
    - `normal`: also the per-pin normal clearances at `input_angle` in the Monte Carlo outputs.
    """

    budget_mm: float = eqx.field(static=True)
    width_mm: float = eqx.field(static=True)
    positions_per_pitch: int = eqx.field(static=True)
    revolutions: int = eqx.field(static=True)
    input_angle: float | None = eqx.field(static=True)
    pitch_points: int = eqx.field(static=True)
    sweep_points_per_pitch: int = eqx.field(static=True)
    sweep_revolutions: int = eqx.field(static=True)
    normal: bool = eqx.field(static=True)

    def __init__(
        self,
        *,
        budget_mm: float = 0.2,
        width_mm: float | None = None,
        positions_per_pitch: int = 2,
        revolutions: int = 1,
        input_angle: float | None = None,
        pitch_points: int = 64,
        sweep_points_per_pitch: int = 16,
        sweep_revolutions: int = 1,
        normal: bool = True,
    ):
        self.budget_mm = as_float("budget_mm", budget_mm, nonnegative=True, hint="the tangential deformation budget is a length ≥ 0 mm")
        w = self.budget_mm / 10.0 if width_mm is None else as_float("width_mm", width_mm, positive=True)
        if not w > 0:
            raise ValueError("width_mm: the smoothing width of the loaded-pair count must be > 0 mm (give one when the budget is 0)")
        self.width_mm = w
        self.positions_per_pitch = as_int("positions_per_pitch", positions_per_pitch, minimum=1)
        self.revolutions = as_int("revolutions", revolutions, minimum=1)
        self.input_angle = None if input_angle is None else as_float("input_angle", input_angle)
        self.pitch_points = as_int("pitch_points", pitch_points, minimum=2)
        self.sweep_points_per_pitch = as_int("sweep_points_per_pitch", sweep_points_per_pitch, minimum=1)
        self.sweep_revolutions = as_int("sweep_revolutions", sweep_revolutions, minimum=1)
        self.normal = bool(normal)


@functools.lru_cache(maxsize=64)
def _error_sources(process: type[AbstractGrindingProcess], z_pins: int) -> dict[str, SourceSpec]:
    """`CycloidPin.error_sources` of a disc of this process and pin count, built once (a study asks for them many
    times; callers get a copy of the dict, and `SourceSpec` is immutable)."""
    out = {}
    for name in process.fields:
        shape = (z_pins - 1,) if name in PER_SPACE else (z_pins,) if name in PER_PIN else ()
        symbol, text = GENERATING_SOURCE_TEXT[name] if process.flank_errors and name in GENERATING_SOURCE_TEXT else SOURCE_TEXT[name]
        out[name] = SourceSpec(name, "deviation", shape=shape, unit=ERROR_UNITS[name], symbol=symbol, description=text)
    return out


class CycloidPin(AbstractGridDrive):
    """One cycloid-pin stage: z_b pins on a pin circle, a disc of z_a = z_b − 1 lobes (Yao & Liang 2001).

    **Arguments:**

    - `z_pins`: z_b, number of pins (sleeves).
    - `pin_circle_radius`: R_z, mm.
    - `pin_radius`: r_z, mm (sleeve radius when there are sleeves).
    - `eccentricity`: crank eccentricity a, mm; or give `K1` = a z_b / R_z instead.
    - `K1`: short-width coefficient, 0 < K_1 < 1.
    - `z_lobes`: z_a; optional, must be z_b − 1.
    - `modification`: the profile modification (default none); or give the wheel:
    - `wheel_pin_circle_radius`, `wheel_pin_radius`: R_Z, r_Z (mm) the grinding wheel is
      dressed to (shift R_Z − R_z, equidistant r_Z − r_z).
    - `rotation_modification`: δ (rad), with the wheel form.
    - `analysis`: the `CycloidAnalysis` settings (deformation budget, grid; default `CycloidAnalysis()`).
    - `reference`: one reducer's errors to analyse in detail in study reports (a `CycloidErrors`
      or a mapping of its fields; default none), e.g. the reducer of Yao & Liang's figures 3–8.
    - `reference_record`: how a study file gave `reference` (JSON text, for summaries).
    - `process`: how the disc is ground: `FormGrinding()` (Yao & Liang's form grinding, the default) or
      `GeneratingGrinding()` (`gearte.drives.cycloid_pin_grinding`): it decides the error sources.

    Raises `ValueError`, naming the field, for tooth counts that do not mesh, K_1 ≥ 1,
    non-positive radii, overlapping pins, and undercut (looped) profiles.
    """

    z_pins: int = eqx.field(static=True)
    z_lobes: int = eqx.field(static=True)
    pin_circle_radius: Float[Array, ""]
    pin_radius: Float[Array, ""]
    eccentricity: Float[Array, ""]
    modification: CycloidModification
    analysis: CycloidAnalysis
    reference: CycloidErrors
    reference_record: str = eqx.field(static=True)
    process: AbstractGrindingProcess

    type_name: ClassVar[str] = "cycloid_pin"
    linear: ClassVar[bool] = False

    def __init__(
        self,
        z_pins: int,
        *,
        pin_circle_radius: float,
        pin_radius: float,
        eccentricity: float | None = None,
        K1: float | None = None,
        z_lobes: int | None = None,
        modification: CycloidModification | None = None,
        wheel_pin_circle_radius: float | None = None,
        wheel_pin_radius: float | None = None,
        rotation_modification: float | None = None,
        analysis: CycloidAnalysis | None = None,
        reference: CycloidErrors | Mapping[str, Any] | None = None,
        reference_record: str | None = None,
        process: AbstractGrindingProcess = FormGrinding(),
    ):
        self.process = check_option("process", process, AbstractGrindingProcess, PROCESSES, what="the disc is ground by")
        zb = as_int("z_pins", z_pins, minimum=4)
        za = zb - 1
        if z_lobes is not None:
            zl = as_int("z_lobes", z_lobes, minimum=1)
            if zl != za:
                raise ValueError(
                    f"z_lobes: a cycloid-pin stage has one lobe fewer than pins, z_lobes = z_pins − 1 = {za}; "
                    f"got z_lobes = {zl} with z_pins = {zb}"
                )
        R = _number("pin_circle_radius", pin_circle_radius, positive=True)
        r = _number("pin_radius", pin_radius, positive=True)
        if (eccentricity is None) == (K1 is None):
            raise ValueError("eccentricity / K1: give exactly one of them (K_1 = a z_b / R_z)")
        if eccentricity is not None:
            a = _number("eccentricity", eccentricity, positive=True)
        else:
            k = _number("K1", K1, positive=True)
            a = k * R / zb
        K = a * zb / R
        if not K < 1.0:
            raise ValueError(
                f"K1: the short-width coefficient K_1 = a z_b / R_z = {K:.6g} must be < 1 (a curtate "
                f"epicycloid); reduce the eccentricity below R_z / z_b = {R / zb:.6g} mm"
            )
        if not 2.0 * r < 2.0 * R * math.sin(math.pi / zb):
            raise ValueError(
                f"pin_radius: pins of radius {r:g} mm overlap on a pin circle of radius {R:g} mm with "
                f"{zb} pins; it must be < R_z sin(π/z_b) = {R * math.sin(math.pi / zb):.6g} mm"
            )
        rho = min_curvature_radius(R, a, zb)
        if not r < rho:
            raise ValueError(
                f"pin_radius: r_z = {r:g} mm is not below the smallest radius of curvature of the "
                f"theoretical profile, {rho:.6g} mm: the tooth profile would be undercut (looped); "
                "use smaller pins, a larger pin circle or another K_1"
            )
        if modification is not None and (
            wheel_pin_circle_radius is not None or wheel_pin_radius is not None or rotation_modification is not None
        ):
            raise ValueError(
                "modification: give a CycloidModification or the wheel radii (wheel_pin_circle_radius, "
                "wheel_pin_radius, rotation_modification), not both"
            )
        if modification is None:
            RZ = R if wheel_pin_circle_radius is None else _number("wheel_pin_circle_radius", wheel_pin_circle_radius, positive=True)
            rZ = r if wheel_pin_radius is None else _number("wheel_pin_radius", wheel_pin_radius, positive=True)
            rot = 0.0 if rotation_modification is None else _number("rotation_modification", rotation_modification)
            modification = CycloidModification(RZ - R, rZ - r, rot)
        if not isinstance(modification, CycloidModification):
            raise ValueError(f"modification: expected a CycloidModification, got {type(modification).__name__}")
        self.z_pins, self.z_lobes = zb, za
        self.pin_circle_radius = jnp.asarray(R, dtype=float)
        self.pin_radius = jnp.asarray(r, dtype=float)
        self.eccentricity = jnp.asarray(a, dtype=float)
        self.modification = modification
        check_modification(self)
        if analysis is None:
            analysis = CycloidAnalysis()
        if not isinstance(analysis, CycloidAnalysis):
            raise ValueError(f"analysis: expected a CycloidAnalysis, got {type(analysis).__name__}")
        self.analysis = analysis
        self.reference = checked_errors(self, reference)
        self.reference_record = "{}" if reference_record is None else str(reference_record)

    @property
    def K1(self) -> Float[Array, ""]:
        """Short-width coefficient K_1 = a z_b / R_z."""
        return self.eccentricity * self.z_pins / self.pin_circle_radius

    @property
    def ratio(self) -> int:
        """Reduction ratio of the stage with the pin wheel fixed (input: crank, output: disc): z_a (output reversed)."""
        return self.z_lobes

    @property
    def pitch(self) -> float:
        """Pin pitch 2π/z_b, rad of input angle θ_T."""
        return TWO_PI / self.z_pins

    @property
    def wheel_pin_circle_radius(self) -> Float[Array, ""]:
        """R_Z, mm."""
        return self.pin_circle_radius + self.modification.shift

    @property
    def wheel_pin_radius(self) -> Float[Array, ""]:
        """r_Z, mm."""
        return self.pin_radius + self.modification.equidistant

    def radial_clearance(self) -> Float[Array, ""]:
        """Radial clearance (mm) of the modified, error-free profile at the tooth root and tip: Δr_Z − ΔR_Z (exact)."""
        return self.modification.equidistant - self.modification.shift

    def describe(self) -> list[tuple[str, str]]:
        m = self.modification
        return [
            ("disc ground by", self.process.description),
            ("pins z_b", str(self.z_pins)),
            ("lobes z_a", str(self.z_lobes)),
            ("pin-circle radius R_z", f"{float(self.pin_circle_radius):g} mm"),
            ("pin radius r_z", f"{float(self.pin_radius):g} mm"),
            ("eccentricity a", f"{float(self.eccentricity):g} mm"),
            ("K_1 = a z_b / R_z", f"{float(self.K1):.6g}"),
            ("wheel R_Z (shift ΔR_Z)", f"{float(self.wheel_pin_circle_radius):.6g} mm ({float(m.shift):+.6g} mm)"),
            ("wheel r_Z (equidistant Δr_Z)", f"{float(self.wheel_pin_radius):.6g} mm ({float(m.equidistant):+.6g} mm)"),
            ("rotation modification δ", f"{float(m.rotation) * ARCSEC_PER_RAD:.6g}″"),
            ("radial clearance at root and tip Δr_Z − ΔR_Z", f"{float(self.radial_clearance()):.6g} mm"),
        ]

    # ------------------------------------------------------------ the drive protocol

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        """The fields of `CycloidErrors` of the disc's process, each a signed deviation: for form grinding the 20 of
        `ERROR_FIELDS`, for generating grinding the 26 of `GENERATING_ERROR_FIELDS`, in that order."""
        return dict(_error_sources(type(self.process), self.z_pins))

    def input_angles(self) -> Float[Array, " p"]:
        """The grid the metrics are taken on: `analysis.revolutions` input revolutions, `analysis.positions_per_pitch`
        input positions per pin pitch, rad."""
        a = self.analysis
        return jnp.asarray(revolution_angles(self, a.positions_per_pitch, revolutions=a.revolutions), dtype=float)

    def response(self, errors: CycloidErrors | Mapping[str, Any] | None) -> Clearances:
        """The clearance analysis (no normal clearances) at every angle of `input_angles` for these errors.

        `errors`: source name → value (µm or rad; names left out are 0), or a `CycloidErrors`, or None.
        """
        err = checked_errors(self, errors)
        thetas = self.input_angles()
        return _sweep_jit(self, err, thetas, False)

    def te(self, response: Clearances) -> Float[Array, " p"]:
        """The rotation error under a forward load (rad) at each angle of `input_angles`: the stage's TE."""
        return response.rotation_error

    @property
    def metrics(self) -> dict[str, AbstractMetric]:
        return {m.name: m() for m in METRICS}

    def trace(self, errors: CycloidErrors | Mapping[str, Any] | None) -> Trace:
        """The rotation error (forward load) of the reducer with these errors over the report's sweep
        (`analysis.sweep_revolutions` input revolutions, `analysis.sweep_points_per_pitch` per pin pitch)."""
        a = self.analysis
        theta = revolution_angles(self, a.sweep_points_per_pitch, revolutions=a.sweep_revolutions)
        te = np.asarray(sweep(self, errors, theta, normal=False).rotation_error)
        return Trace.of_grid(theta, te, str(a.sweep_revolutions))

    @classmethod
    def from_table(cls, table: Table) -> CycloidPin:
        """``[drive] type = "cycloid_pin"``: see `gearte.drives.cycloid_pin_table` for the keys and sub-tables."""
        kwargs = drive_arguments(table)
        try:
            kwargs["analysis"] = CycloidAnalysis(**kwargs["analysis"])
            return cls(**kwargs)
        except ValueError as e:
            raise ConfigError(f"{table.where} {e}") from None

    def accuracy(self) -> str:
        a = self.analysis
        n = a.positions_per_pitch * self.z_pins * a.revolutions
        return (
            f"taken on a grid of {n} input angles ({a.positions_per_pitch} per pin pitch of {360 / self.z_pins:.4g}° over "
            f"{a.revolutions} input revolution(s) of the {self.z_lobes} after which pins and tooth spaces pair again), not "
            "between them; at each angle the contact of every pin is solved "
            "by a bracketed Newton iteration to a radius residual below 1e-9 mm (convergence checked and reported)"
        )

    def bytes_per_sample(self) -> int:
        n = self.analysis.positions_per_pitch * self.z_pins * self.analysis.revolutions
        return 8 * (n + 1) * self.z_pins * 64

    def sample_outputs(self, errors, response: Clearances) -> dict[str, Array]:
        """Per sample of a `gearte run`: the report's clearance vector (`gearte.drives.cycloid_pin_outputs.sample_vector`),
        from the same sweep as the metric."""
        return {
            "clearances": sample_vector(self, checked_errors(self, errors), response, jnp.asarray(input_angle(self)), self.analysis.normal)
        }

    def study_outputs(self, context: AbstractStudyContext) -> StudyOutputs:
        """The clearance analysis of the reference reducer, the Monte Carlo of clearances and loaded pairs, and the
        plots (see `gearte.drives.cycloid_pin_outputs`)."""
        return study_outputs(self, context)

    # ------------------------------------------------------------ helpers

    def reference_errors(self) -> CycloidErrors:
        """The errors of the reducer analysed in detail (`reference`)."""
        return self.reference

    def given_reference(self) -> dict:
        """The reference reducer's errors as the study file gave them (empty when built in Python)."""
        return json.loads(self.reference_record)

    def errors_dict(self, errors: CycloidErrors | Mapping[str, Any] | None) -> dict[str, Array]:
        """`errors` as the protocol's mapping source name → value (every field, broadcast to its shape)."""
        err = checked_errors(self, errors)
        return {name: getattr(err, name) for name in self.error_fields}

    @property
    def error_fields(self) -> tuple[str, ...]:
        """The error fields of this disc's process (`ERROR_FIELDS` or `GENERATING_ERROR_FIELDS`)."""
        return self.process.fields


# The public API of the cycloid-pin modules, in one place (``gearte.drives.cycloid_pin.clearances`` etc.).
__all__ = (
    "ALL_ERROR_FIELDS",
    "ERROR_FIELDS",
    "ERROR_UNITS",
    "GENERATING_ERROR_FIELDS",
    "GENERATING_ONLY",
    "PER_PIN",
    "PER_SPACE",
    "PROCESSES",
    "SOURCE_TEXT",
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
    "PinLayout",
    "RotationErrorPeakToPeak",
    "Sensitivity",
    "as_cycloid_errors",
    "check_modification",
    "checked_errors",
    "clearances",
    "disc_outline",
    "first_order_clearance",
    "loaded_pairs",
    "min_curvature_radius",
    "normal_clearance",
    "pin_layout",
    "pitch_angles",
    "revolution_angles",
    "sensitivities",
    "smooth_loaded_pairs",
    "sweep",
    "theoretical_pairs",
    "theoretical_profile",
    "tooth_profile",
    "unit_metrics",
)
