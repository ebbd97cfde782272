"""Cycloid-pin reducer: tooth profile, errors, and the tooth-clearance analysis (seed 003).

Source: Yao Wenxi, Liang Zhe (2001), "Tooth profile clearance distribution of a
cycloid-pin reducer", Machine Design 18(5):22-25 (seed 003), restated in
``spec/cycloid_pin.md``. The RV (K-H-V) model reuses this geometry.

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
- **Form-grinding errors** (seed eqs. 1–2): dressing errors (δX_4, δY_4) and the
  per-space infeed error ΔY_4(n) shift the wheel profile (in the space's own frame,
  Y_4 along its centre line, outwards); space n is ground at the index angle
  β_n = 2πn/z_a + β_0 + Δβ(n) (the seed's 2π(n−1)/z_a with its 1-based n); the blank
  set-up eccentricity ΔA at φ_A and the mandrel run-out ΔB at φ_B (eq. 2 puts it along
  X′_2: φ_B = 0) displace the ground profile from the bore by −(ΔA e^{iφ_A} + ΔB e^{iφ_B}).
- **Reducer errors** (seed sec. 2): actual pin-circle radius R′ = R + ΔR′, pin radius
  r′ = r + Δr′ (the sleeve's contact surface from the pin centre), crank eccentricity
  A′ = a + ΔA′; per-pin tangential δ_j (and, a gearte extension, radial) position
  errors; the disc centre displaced by Δ_1 at α_1 (turning-arm bearing) and the
  pin-wheel centre by Δ_2 at α_2 (input-shaft bearings, spigot fits), both fixed in
  the converted mechanism as in the seed; and (extension) a pin-circle eccentricity
  that turns with the pin wheel (housing-fixed in the real reducer): at angle
  α_e + θ_T in the converted frame.

**Clearance analysis** (spec "Clearances and the contacting pair"). For pin j, the
rotation θ_a at which its flank touches it: the pin centre c (relative to the disc
centre) must lie on the pin-centre locus of the actual flank,
Q(φ) = (transformed) P_Z(φ) − (r_Z − r′) N_Z(φ) (the flank's equidistant at r′). As
the disc turns, c moves on the circle |c| about the disc centre, so the 2-unknown solve
(φ, θ_a) of the spec reduces to one equation, |Q(φ)| = |c| on the pin's half of its
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
extra rotation before it touches, from its own flank's contact (the seed's
|Δθ_N| − |Δθ|_min, eq. 7), as an angle and as an arc on the pin circle (× R′, as the spec
says; the garbled eq. 7 seems to carry a factor z_a/z_b, a pin-wheel angle of the converted
mechanism, which would make the arcs 1/z_b smaller).
**Normal clearance**: min over the flank of |pin centre − flank point| − r′ at that
contacting configuration (seed eq. 8), by a 1-D Newton search near the contact point.
A pin can also reach the far flank of its tooth space, but only after the disc turns
through the space's width at the pin's radius; gearte, like the seed, pairs each pin
with its own flank.

Units: geometry in mm, errors in µm, angles in rad inside; reports in ″ and ′.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._precision import require_x64
from .._validate import as_float, as_int

UM = 1e-3  # mm per µm
TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------- validation helpers


def _number(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a radius or length cannot be zero or negative" if positive else "")


_whole = as_int


def min_curvature_radius(pin_circle_radius: float, eccentricity: float, z_pins: int, *, points: int = 20001) -> float:
    """Smallest radius of curvature (mm) of the convex part of the theoretical (pin-centre) curve.

    The equidistant E = P − r N is free of loops (undercut) exactly when r is below this
    radius: E′ = |P′| (1 + r κ) T, with κ the signed curvature (negative where the curve
    is convex, towards the tooth tips).

    **Arguments:**

    - `pin_circle_radius`: R (mm); `eccentricity`: a (mm); `z_pins`: z_b.
    """
    R, a, zb = float(pin_circle_radius), float(eccentricity), int(z_pins)
    za = zb - 1
    K = a * zb / R
    phi = np.linspace(0.0, math.pi, points)
    u, v = phi / za, zb * phi / za
    dx = (R / za) * (np.cos(u) - K * np.cos(v))
    dy = (R / za) * (-np.sin(u) + K * np.sin(v))
    ddx = (R / za**2) * (-np.sin(u) + K * zb * np.sin(v))
    ddy = (R / za**2) * (-np.cos(u) + K * zb * np.cos(v))
    kappa = (dx * ddy - dy * ddx) / np.hypot(dx, dy) ** 3
    convex = kappa < 0
    if not np.any(convex):
        return math.inf
    return float(1.0 / np.max(-kappa[convex]))


# ---------------------------------------------------------------- models


class CycloidModification(eqx.Module):
    """Profile modification of the cycloid disc (the dressed grinding wheel).

    **Arguments:**

    - `shift`: ΔR_Z = R_Z − R_z, mm (negative: "negative shift", more clearance).
    - `equidistant`: Δr_Z = r_Z − r_z, mm (positive: "positive equidistant", more clearance).
    - `rotation`: δ, rad ≥ 0 for clearance: each flank half turned away from its pins
      by δ (gearte's rotation modification; 0 for the seed's profiles).
    """

    shift: Float[Array, ""]
    equidistant: Float[Array, ""]
    rotation: Float[Array, ""]

    def __init__(self, shift: ArrayLike = 0.0, equidistant: ArrayLike = 0.0, rotation: ArrayLike = 0.0):
        self.shift = jnp.asarray(shift, dtype=float)
        self.equidistant = jnp.asarray(equidistant, dtype=float)
        self.rotation = jnp.asarray(rotation, dtype=float)


class CycloidPin(eqx.Module):
    """One cycloid-pin stage: z_b pins on a pin circle, a disc of z_a = z_b − 1 lobes.

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

    Raises `ValueError`, naming the field, for tooth counts that do not mesh, K_1 ≥ 1,
    non-positive radii, overlapping pins, and undercut (looped) profiles.
    """

    z_pins: int
    z_lobes: int
    pin_circle_radius: Float[Array, ""]
    pin_radius: Float[Array, ""]
    eccentricity: Float[Array, ""]
    modification: CycloidModification

    def __init__(self, z_pins: int, *, pin_circle_radius: float, pin_radius: float, eccentricity: float | None = None,
                 K1: float | None = None, z_lobes: int | None = None, modification: CycloidModification | None = None,
                 wheel_pin_circle_radius: float | None = None, wheel_pin_radius: float | None = None,
                 rotation_modification: float | None = None):
        zb = _whole("z_pins", z_pins, minimum=4)
        za = zb - 1
        if z_lobes is not None:
            zl = _whole("z_lobes", z_lobes, minimum=1)
            if zl != za:
                raise ValueError(f"z_lobes: a cycloid-pin stage has one lobe fewer than pins, z_lobes = z_pins − 1 = {za}; "
                                 f"got z_lobes = {zl} with z_pins = {zb}")
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
            raise ValueError(f"K1: the short-width coefficient K_1 = a z_b / R_z = {K:.6g} must be < 1 (a curtate "
                             f"epicycloid); reduce the eccentricity below R_z / z_b = {R / zb:.6g} mm")
        if not 2.0 * r < 2.0 * R * math.sin(math.pi / zb):
            raise ValueError(f"pin_radius: pins of radius {r:g} mm overlap on a pin circle of radius {R:g} mm with "
                             f"{zb} pins; it must be < R_z sin(π/z_b) = {R * math.sin(math.pi / zb):.6g} mm")
        rho = min_curvature_radius(R, a, zb)
        if not r < rho:
            raise ValueError(f"pin_radius: r_z = {r:g} mm is not below the smallest radius of curvature of the "
                             f"theoretical profile, {rho:.6g} mm: the tooth profile would be undercut (looped); "
                             "use smaller pins, a larger pin circle or another K_1")
        if modification is not None and (wheel_pin_circle_radius is not None or wheel_pin_radius is not None
                                         or rotation_modification is not None):
            raise ValueError("modification: give a CycloidModification or the wheel radii (wheel_pin_circle_radius, "
                             "wheel_pin_radius, rotation_modification), not both")
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
        return [("pins z_b", str(self.z_pins)), ("lobes z_a", str(self.z_lobes)),
                ("pin-circle radius R_z", f"{float(self.pin_circle_radius):g} mm"),
                ("pin radius r_z", f"{float(self.pin_radius):g} mm"),
                ("eccentricity a", f"{float(self.eccentricity):g} mm"), ("K_1 = a z_b / R_z", f"{float(self.K1):.6g}"),
                ("wheel R_Z (shift ΔR_Z)", f"{float(self.wheel_pin_circle_radius):.6g} mm ({float(m.shift):+.6g} mm)"),
                ("wheel r_Z (equidistant Δr_Z)", f"{float(self.wheel_pin_radius):.6g} mm ({float(m.equidistant):+.6g} mm)"),
                ("rotation modification δ", f"{float(m.rotation) * 180 * 3600 / math.pi:.6g}″"),
                ("radial clearance at root and tip Δr_Z − ΔR_Z", f"{float(self.radial_clearance()):.6g} mm")]


def check_modification(drive: CycloidPin) -> None:
    """Raise `ValueError` if the dressed wheel gives an impossible or undercut profile (Python floats; before jit)."""
    R, a, zb = float(drive.pin_circle_radius), float(drive.eccentricity), drive.z_pins
    RZ = float(drive.wheel_pin_circle_radius)
    rZ = float(drive.wheel_pin_radius)
    rot = float(drive.modification.rotation)
    for name, v in (("modification.shift", RZ - R), ("modification.equidistant", rZ - float(drive.pin_radius)), ("modification.rotation", rot)):
        if not math.isfinite(v):
            raise ValueError(f"{name}: must be finite, got {v}")
    if not RZ > 0:
        raise ValueError(f"modification.shift: the wheel's pin-circle radius R_Z = {RZ:g} mm must be > 0")
    if not rZ > 0:
        raise ValueError(f"modification.equidistant: the wheel's pin radius r_Z = {rZ:g} mm must be > 0")
    KZ = a * zb / RZ
    if not KZ < 1.0:
        raise ValueError(f"modification.shift: with R_Z = {RZ:g} mm the wheel's K = a z_b / R_Z = {KZ:.6g} is ≥ 1; "
                         "use a smaller negative shift")
    rho = min_curvature_radius(RZ, a, zb)
    if not rZ < rho:
        raise ValueError(f"modification.equidistant: the wheel's pin radius r_Z = {rZ:g} mm is not below the smallest "
                         f"radius of curvature of its theoretical profile, {rho:.6g} mm: the ground profile would be "
                         "undercut (looped); reduce the equidistant modification")
    if abs(rot) >= math.pi / (2 * (zb - 1)):
        raise ValueError(f"modification.rotation: {rot:g} rad is not a small rotation; it must be below a quarter of a "
                         f"tooth space, π/(2 z_a) = {math.pi / (2 * (zb - 1)):.6g} rad")


class CycloidErrors(eqx.Module):
    """The errors of one reducer: its disc's form-grinding errors and its own (seed 003, eqs. 1–3).

    Lengths in µm, angles in rad. Per-space fields take a scalar (the same for every
    space) or z_a values (space n = 0 … z_a − 1, the seed's n + 1); per-pin fields a scalar
    or z_b values. Every field defaults to 0.

    **Form grinding (seed eqs. 1–2):**

    - `dressing_x`, `dressing_y`: δX_4, δY_4, the dresser's errors, µm.
    - `infeed`: ΔY_4(n), infeed error of each tooth space, µm (positive: less cut).
    - `index_offset`: β_0, the initial index angle, rad.
    - `indexing`: Δβ(n), the grinder's indexing error of each space, rad.
    - `setup_eccentricity`, `setup_phase`: ΔA (µm) at φ (rad), blank set-up eccentricity.
    - `mandrel_runout`, `mandrel_phase`: ΔB (µm) at its angle (rad; 0 as in eq. 2).

    **Reducer (seed sec. 2):**

    - `pin_circle_radius`: R′_z − R_z, µm.
    - `pin_radius`: r′_z − r_z, µm (sleeve contact surface from the pin centre, fits included).
    - `eccentricity`: A′ − a, µm.
    - `pin_tangential`: δ_j, tangential position error of each pin, µm (positive: CCW).
    - `pin_radial`: radial position error of each pin, µm (positive: outwards).
    - `disc_offset`, `disc_offset_phase`: Δ_1 (µm) at α_1 (rad), disc centre from the eccentric.
    - `pin_wheel_offset`, `pin_wheel_offset_phase`: Δ_2 (µm) at α_2 (rad), pin-wheel centre
      from the input axis, fixed in the converted mechanism (seed eq. 3).
    - `pin_circle_eccentricity`, `pin_circle_eccentricity_phase`: (µm) at α_e (rad), a
      pin-circle eccentricity fixed in the housing: at α_e + θ_T in the converted frame.
    """

    dressing_x: Float[Array, ""]
    dressing_y: Float[Array, ""]
    infeed: Float[Array, "*za"]
    index_offset: Float[Array, ""]
    indexing: Float[Array, "*za"]
    setup_eccentricity: Float[Array, ""]
    setup_phase: Float[Array, ""]
    mandrel_runout: Float[Array, ""]
    mandrel_phase: Float[Array, ""]
    pin_circle_radius: Float[Array, ""]
    pin_radius: Float[Array, ""]
    eccentricity: Float[Array, ""]
    pin_tangential: Float[Array, "*zb"]
    pin_radial: Float[Array, "*zb"]
    disc_offset: Float[Array, ""]
    disc_offset_phase: Float[Array, ""]
    pin_wheel_offset: Float[Array, ""]
    pin_wheel_offset_phase: Float[Array, ""]
    pin_circle_eccentricity: Float[Array, ""]
    pin_circle_eccentricity_phase: Float[Array, ""]

    def __init__(self, *, dressing_x: ArrayLike = 0.0, dressing_y: ArrayLike = 0.0, infeed: ArrayLike = 0.0,
                 index_offset: ArrayLike = 0.0, indexing: ArrayLike = 0.0, setup_eccentricity: ArrayLike = 0.0,
                 setup_phase: ArrayLike = 0.0, mandrel_runout: ArrayLike = 0.0, mandrel_phase: ArrayLike = 0.0,
                 pin_circle_radius: ArrayLike = 0.0, pin_radius: ArrayLike = 0.0, eccentricity: ArrayLike = 0.0,
                 pin_tangential: ArrayLike = 0.0, pin_radial: ArrayLike = 0.0, disc_offset: ArrayLike = 0.0,
                 disc_offset_phase: ArrayLike = 0.0, pin_wheel_offset: ArrayLike = 0.0,
                 pin_wheel_offset_phase: ArrayLike = 0.0, pin_circle_eccentricity: ArrayLike = 0.0,
                 pin_circle_eccentricity_phase: ArrayLike = 0.0):
        f = lambda x: jnp.asarray(x, dtype=float)  # noqa: E731
        self.dressing_x, self.dressing_y, self.infeed = f(dressing_x), f(dressing_y), f(infeed)
        self.index_offset, self.indexing = f(index_offset), f(indexing)
        self.setup_eccentricity, self.setup_phase = f(setup_eccentricity), f(setup_phase)
        self.mandrel_runout, self.mandrel_phase = f(mandrel_runout), f(mandrel_phase)
        self.pin_circle_radius, self.pin_radius, self.eccentricity = f(pin_circle_radius), f(pin_radius), f(eccentricity)
        self.pin_tangential, self.pin_radial = f(pin_tangential), f(pin_radial)
        self.disc_offset, self.disc_offset_phase = f(disc_offset), f(disc_offset_phase)
        self.pin_wheel_offset, self.pin_wheel_offset_phase = f(pin_wheel_offset), f(pin_wheel_offset_phase)
        self.pin_circle_eccentricity = f(pin_circle_eccentricity)
        self.pin_circle_eccentricity_phase = f(pin_circle_eccentricity_phase)


#: Fields of `CycloidErrors` with one value per tooth space / per pin.
PER_SPACE = ("infeed", "indexing")
PER_PIN = ("pin_tangential", "pin_radial")
ERROR_FIELDS = tuple(f.name for f in dataclasses.fields(CycloidErrors))
#: Unit of each error field, for reports.
ERROR_UNITS = {name: ("rad" if name in ("index_offset", "indexing") or name.endswith("_phase") else "µm") for name in ERROR_FIELDS}


def checked_errors(drive: CycloidPin, errors: CycloidErrors | None) -> CycloidErrors:
    """`errors` with per-space and per-pin fields broadcast to z_a and z_b values; shapes checked (trace time)."""
    if errors is None:
        errors = CycloidErrors()
    if not isinstance(errors, CycloidErrors):
        raise ValueError(f"errors: expected a CycloidErrors, got {type(errors).__name__}")
    out = {}
    for name in ERROR_FIELDS:
        v = jnp.asarray(getattr(errors, name))
        if name in PER_SPACE or name in PER_PIN:
            n = drive.z_lobes if name in PER_SPACE else drive.z_pins
            what = "tooth space (z_a)" if name in PER_SPACE else "pin (z_b)"
            if v.shape not in ((), (1,), (n,)):
                raise ValueError(f"errors.{name}: give a scalar or one value per {what} = {n} values, got shape {v.shape}")
            v = jnp.broadcast_to(v.reshape(-1) if v.ndim else v, (n,))
        elif v.shape != ():
            raise ValueError(f"errors.{name}: must be a scalar, got shape {v.shape}")
        out[name] = v
    return CycloidErrors(**out)


# ---------------------------------------------------------------- geometry (jit/vmap friendly)


def _rot(x, y, angle):
    c, s = jnp.cos(angle), jnp.sin(angle)
    return c * x - s * y, s * x + c * y


def _wheel_curve(R, a, za: int, zb: int, phi, d):
    """P(φ) − d N(φ) for a wheel with pin circle R and eccentricity a (see the module notes)."""
    u = phi / float(za)
    v = phi * (float(zb) / float(za))
    K = a * float(zb) / R
    su, cu, sv, cv = jnp.sin(u), jnp.cos(u), jnp.sin(v), jnp.cos(v)
    S = jnp.sqrt(1.0 + K * K - 2.0 * K * jnp.cos(phi))
    x = R * su - a * sv - d * (su - K * sv) / S
    y = R * cu - a * cv - d * (cu - K * cv) / S
    return x, y


def theoretical_profile(drive: CycloidPin, phi: ArrayLike, *, wheel: bool = False) -> Float[Array, "... 2"]:
    """Theoretical (pin-centre) curve P(φ), mm, in the disc frame (tooth space 0).

    With `wheel=True` the curve of the dressed wheel (R_Z, same a).
    """
    R = drive.wheel_pin_circle_radius if wheel else drive.pin_circle_radius
    x, y = _wheel_curve(R, drive.eccentricity, drive.z_lobes, drive.z_pins, jnp.asarray(phi, dtype=float), 0.0)
    return jnp.stack([x, y], axis=-1)


class _Placement(eqx.Module):
    """Rigid placement of one tooth-space half in the disc frame: the rotation modification, the wheel
    offsets (δX_4, δY_4 + ΔY_4(n)), the index rotation −β_n and the bore eccentricity (seed eqs. 1–2)."""

    cos_mod: Array
    sin_mod: Array
    dx: Array
    dy: Array
    cos_beta: Array
    sin_beta: Array
    ex: Array
    ey: Array


def _placement(drive: CycloidPin, err: CycloidErrors, n, side) -> _Placement:
    m = drive.modification
    beta = jnp.asarray(n).astype(float) * (TWO_PI / drive.z_lobes) + err.index_offset + err.indexing[n]
    ex = err.setup_eccentricity * jnp.cos(err.setup_phase) + err.mandrel_runout * jnp.cos(err.mandrel_phase)
    ey = err.setup_eccentricity * jnp.sin(err.setup_phase) + err.mandrel_runout * jnp.sin(err.mandrel_phase)
    return _Placement(jnp.cos(side * m.rotation), -jnp.sin(side * m.rotation), err.dressing_x * UM,
                      (err.dressing_y + err.infeed[n]) * UM, jnp.cos(beta), -jnp.sin(beta), ex * UM, ey * UM)


def _placed_curve(drive: CycloidPin, pl: _Placement, phi, d):
    """Tooth-space half placed by `pl`: the wheel's P_Z − d N_Z in the disc frame centred on the bore, mm.
    d = r_Z: the flank; d = r_Z − r′: the pin-centre locus."""
    x, y = _wheel_curve(drive.wheel_pin_circle_radius, drive.eccentricity, drive.z_lobes, drive.z_pins, phi, d)
    x, y = pl.cos_mod * x - pl.sin_mod * y, pl.sin_mod * x + pl.cos_mod * y
    x, y = x + pl.dx, y + pl.dy
    x, y = pl.cos_beta * x - pl.sin_beta * y, pl.sin_beta * x + pl.cos_beta * y
    return x - pl.ex, y - pl.ey


def _space_curve(drive: CycloidPin, err: CycloidErrors, n, side, phi, d):
    """Tooth space n, half `side` (±1): see `_placed_curve`."""
    return _placed_curve(drive, _placement(drive, err, n, side), phi, d)


def tooth_profile(drive: CycloidPin, phi: ArrayLike, *, errors: CycloidErrors | None = None, space: int = 0) -> Float[Array, "... 2"]:
    """Points of the actual flank of tooth space `space` (mm, disc frame centred on the bore).

    `phi` ∈ [−π, π] is the flank parameter (φ > 0: driving half, φ < 0: reverse half).
    """
    err = checked_errors(drive, errors)
    phi = jnp.asarray(phi, dtype=float)
    side = jnp.where(phi >= 0, 1.0, -1.0)
    x, y = _space_curve(drive, err, jnp.asarray(space % drive.z_lobes), side, phi, drive.wheel_pin_radius)
    return jnp.stack([x, y], axis=-1)


def disc_outline(drive: CycloidPin, *, errors: CycloidErrors | None = None, points_per_space: int = 200) -> Float[Array, "m 2"]:
    """The whole actual disc outline (mm), all z_a tooth spaces in order, for plotting."""
    phi = jnp.linspace(-math.pi, math.pi, points_per_space)
    pts = [tooth_profile(drive, phi, errors=errors, space=n) for n in range(drive.z_lobes)]
    return jnp.concatenate(pts, axis=0)


class _Pins(eqx.Module):
    centre: Float[Array, "zb 2"]     # pin centres relative to the disc centre, converted frame, mm
    space: Int[Array, " zb"]         # tooth space each pin sits in
    side: Float[Array, " zb"]        # +1 driving flank, −1 reverse flank
    phi: Float[Array, " zb"]         # nominal flank parameter (pin angle from the crank), rad
    radius: Float[Array, ""]         # r′, mm
    pin_circle: Float[Array, ""]     # R′, mm


def _pins(drive: CycloidPin, err: CycloidErrors, theta_T) -> _Pins:
    zb, za = drive.z_pins, drive.z_lobes
    j = jnp.arange(zb, dtype=float)
    R1 = drive.pin_circle_radius + err.pin_circle_radius * UM
    psi_nom = theta_T + j * (TWO_PI / zb)
    psi = psi_nom + err.pin_tangential * UM / R1
    rad = R1 + err.pin_radial * UM
    A1 = drive.eccentricity + err.eccentricity * UM
    obx = (err.pin_wheel_offset * jnp.cos(err.pin_wheel_offset_phase)
           + err.pin_circle_eccentricity * jnp.cos(err.pin_circle_eccentricity_phase + theta_T)) * UM
    oby = -A1 + (err.pin_wheel_offset * jnp.sin(err.pin_wheel_offset_phase)
                 + err.pin_circle_eccentricity * jnp.sin(err.pin_circle_eccentricity_phase + theta_T)) * UM
    cx = obx - rad * jnp.sin(psi) - err.disc_offset * jnp.cos(err.disc_offset_phase) * UM
    cy = oby + rad * jnp.cos(psi) - err.disc_offset * jnp.sin(err.disc_offset_phase) * UM
    # Pin j meets the theoretical curve at parameter ψ_j − 2πj (module notes): space n, local φ. A tiny
    # offset breaks ties (a pin exactly at a valley bottom or a tooth tip) the same way in every fusion
    # XLA makes of this expression; the barrier keeps one copy of the result.
    glob = jax.lax.stop_gradient(psi_nom) - j * TWO_PI
    w = glob / TWO_PI + 1e-9
    k = jnp.floor(w + 0.5)
    side = jnp.where(w - k >= 0.0, 1.0, -1.0)
    phi = glob - k * TWO_PI
    space = jnp.mod(k.astype(jnp.int32), za)
    space, side, phi = jax.lax.optimization_barrier((space, side, phi))
    return _Pins(jnp.stack([cx, cy], axis=-1), space, side, phi, drive.pin_radius + err.pin_radius * UM, R1)


def _wrap(x):
    return jnp.mod(x + math.pi, TWO_PI) - math.pi


#: Fixed iteration counts of the solves (Newton in cos t, then in t; convergence is checked and reported).
NEWTON_STEPS = 8
POLISH_STEPS = 4
DISTANCE_STEPS = 12
#: A pin-to-locus radius residual below this (mm) counts as converged.
RESIDUAL_TOL_MM = 1e-9


class _Contact(eqx.Module):
    rotation: Float[Array, " zb"]      # θ_j − θ_theory, rad (finite; see `reachable`)
    phi: Float[Array, " zb"]           # flank parameter of the contact point
    reachable: Bool[Array, " zb"]      # the pin is not beyond the tooth tip
    interference: Bool[Array, " zb"]   # the pin is deeper than the tooth-space bottom at every rotation
    converged: Bool[Array, " zb"]


def _stop(tree):
    return jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, tree)


def _contacts(drive: CycloidPin, err: CycloidErrors, pins: _Pins, theta_T) -> _Contact:
    """Rotation to contact of every pin against its own flank (module notes)."""
    sg = jax.lax.stop_gradient

    def make_h(drive, err, pins):
        c = pins.centre
        rho2 = c[:, 0] ** 2 + c[:, 1] ** 2
        d = drive.wheel_pin_radius - pins.radius
        pl = _placement(drive, err, pins.space, pins.side)

        def h(t):  # |Q(side·t)|² − |c|², increasing in t ∈ [0, π]
            x, y = _placed_curve(drive, pl, pins.side * t, d)
            return x * x + y * y - rho2

        return h

    h = make_h(drive, err, pins)
    hs = make_h(*_stop((drive, err, pins)))  # the iteration is not differentiated
    ones = jnp.ones(pins.side.shape)
    interference = hs(jnp.zeros_like(ones)) > 0.0
    reachable = hs(jnp.full_like(ones, math.pi)) >= 0.0

    # Newton in c = cos t: for the error-free profile |P|² = R² + a² − 2Ra cos φ is linear in c, so the
    # iteration converges in a few steps everywhere, also at the fold t = 0 (a pin at the valley bottom).
    def hc(c):
        return hs(jnp.arccos(jnp.clip(c, -1.0 + 1e-15, 1.0 - 1e-15)))

    def body(_, state):
        c, lo, hi, was_clipped = state  # h(lo) ≥ 0 ≥ h(hi); h decreases in c
        val, der = jax.jvp(hc, (c,), (ones,))
        hi = jnp.where(val <= 0, c, hi)
        lo = jnp.where(val > 0, c, lo)
        cn = c - val / jnp.where(der != 0, der, 1.0)
        inside = (cn >= lo) & (cn <= hi)
        usable = (der < 0) & jnp.isfinite(cn)
        # A Newton step just past the bracket (a root next to c = ±1) is pulled back just inside it, once;
        # otherwise bisect.
        clip_now = usable & ~inside & ~was_clipped
        eps = 1e-6 * (hi - lo)
        cn = jnp.where(usable & inside, cn, jnp.where(clip_now, jnp.clip(cn, lo + eps, hi - eps), 0.5 * (lo + hi)))
        # A root stays (|c| = 1, a pin exactly at a valley bottom or tooth tip, is a fold where the clipped
        # derivative vanishes); 1e-9 mm² is a radius residual of ~3e-12 mm.
        done = jnp.abs(val) <= 1e-9
        return jnp.where(done, c, cn), lo, hi, clip_now & ~done

    c0 = jnp.cos(jnp.abs(pins.phi))
    cfin, lo_c, hi_c, _ = jax.lax.fori_loop(0, NEWTON_STEPS, body, (c0, -ones, ones, jnp.zeros(ones.shape, dtype=bool)))
    t = jnp.arccos(jnp.clip(cfin, -1.0, 1.0))

    # Polish in t, bracketed: the errors make h(c) behave like √(1 ± c) next to a fold, where the
    # iteration in c slows down; Newton in t (bisection when it leaves the bracket) finishes the job.
    def polish(_, state):
        t, a, b = state  # h(a) ≤ 0 ≤ h(b), a ≤ b
        val, der = jax.jvp(hs, (t,), (ones,))
        a = jnp.where(val <= 0, t, a)
        b = jnp.where(val >= 0, t, b)
        tn = t - val / jnp.where(der != 0, der, 1.0)
        bad = ~((tn >= a) & (tn <= b)) | (der <= 0) | ~jnp.isfinite(tn)
        tn = jnp.where(bad, 0.5 * (a + b), tn)
        return jnp.where(jnp.abs(val) <= 1e-9, t, tn), a, b

    t_a = jnp.arccos(jnp.clip(hi_c, -1.0, 1.0))
    t_b = jnp.arccos(jnp.clip(lo_c, -1.0, 1.0))
    t, _, _ = jax.lax.fori_loop(0, POLISH_STEPS, polish, (jnp.clip(t, t_a, t_b), t_a, t_b))
    t = sg(jnp.where(interference, 0.0, jnp.where(reachable, t, math.pi)))
    # One Newton step with the derivative held: the value stays, the gradient is the implicit one.
    der = jax.jvp(hs, (t,), (ones,))[1]
    ok = (jnp.abs(der) > 1e-12) & reachable & ~interference
    t_imp = t - jnp.where(ok, h(t) / jnp.where(ok, der, 1.0), 0.0)
    phi = pins.side * t_imp
    d = drive.wheel_pin_radius - pins.radius
    x, y = _space_curve(drive, err, pins.space, pins.side, phi, d)
    c = pins.centre
    rho = jnp.sqrt(c[:, 0] ** 2 + c[:, 1] ** 2)
    resid = jnp.abs(jnp.sqrt(x * x + y * y) - rho)
    converged = (resid < RESIDUAL_TOL_MM) | ~reachable | interference
    theta = jnp.arctan2(c[:, 1], c[:, 0]) - jnp.arctan2(y, x)
    rotation = _wrap(theta - theta_T * (drive.z_pins / drive.z_lobes))
    return _Contact(rotation, phi, reachable, interference, converged)


def _normal(drive: CycloidPin, err: CycloidErrors, pins: _Pins, phi0, turn):
    """min over the pin's flank half of |pin centre − flank point| − r′ (mm) with the disc turned by `turn`
    (rad, per pin) from its theoretical zero (seed eq. 8), and whether the search converged."""
    sg = jax.lax.stop_gradient

    def make_f(drive, err, pins, turn):
        c = pins.centre
        cx, cy = _rot(c[:, 0], c[:, 1], -turn)
        pl = _placement(drive, err, pins.space, pins.side)

        def f(t):
            x, y = _placed_curve(drive, pl, pins.side * t, drive.wheel_pin_radius)
            return (x - cx) ** 2 + (y - cy) ** 2

        return f

    f = make_f(drive, err, pins, turn)
    fs = make_f(*_stop((drive, err, pins, turn)))
    ones = jnp.ones(pins.side.shape)
    fd = lambda s: jax.jvp(fs, (s,), (ones,))[1]  # noqa: E731

    def body(_, t):
        g, gg = jax.jvp(fd, (t,), (ones,))
        step = jnp.where(gg > 0, g / jnp.where(gg > 0, gg, 1.0), jnp.sign(g) * 0.05)  # concave: a plain step downhill
        step = jnp.clip(step, -0.1, 0.1)
        return jnp.clip(t - step, 0.0, math.pi)

    t0 = jnp.clip(jnp.abs(sg(phi0)), 0.0, math.pi)
    t = sg(jax.lax.fori_loop(0, DISTANCE_STEPS, body, t0))
    # Converged: a stationary point (|d distance/dt| below 1e-10 mm per rad), or an end of the flank half
    # with the distance growing inwards.
    g = fd(t) / (2.0 * jnp.sqrt(fs(t)))
    ok = (jnp.abs(g) < 1e-10) | ((t <= 0.0) & (g > 0)) | ((t >= math.pi) & (g < 0))
    # Envelope theorem: the minimum's derivative is the partial one at the minimiser.
    return jnp.sqrt(f(t)) - pins.radius, ok


# ---------------------------------------------------------------- the analysis


class Clearances(eqx.Module):
    """Clearance analysis at one input position (every field has a leading axis for a sweep).

    Pins are numbered j = 0 … z_b − 1 (reports print j + 1). Angles in rad of the disc
    (= output), lengths in mm.

    - `input_angle`: θ_T, rad.
    - `space`: the tooth space (0 … z_a − 1, the seed's n − 1) each pin sits in.
    - `rotation_to_contact`: Δθ_j = θ_j − (z_b/z_a) θ_T, the rotation error if pin j alone
      carried the motion (+∞ / −∞ for a driving / reverse pin that can never touch).
    - `on_driving_flank`: the pin sits on a driving flank (ψ_j ∈ [0, π)).
    - `reachable`, `interference`: per pin (see the module notes).
    - `converged`: the pin's contact solve (and normal-clearance search, when computed) converged.
    - `contact_pin`, `reverse_contact_pin`: the contacting pair under a forward / reverse load.
    - `rotation_error`, `reverse_rotation_error`: Δθ of those pairs, rad.
    - `lost_motion`: `rotation_error − reverse_rotation_error`, rad.
    - `tangential_clearance`: extra rotation before the pin touches, from the contact of
      its own flank, rad (≥ 0; +∞ if it never touches).
    - `tangential_arc`: the same × R′, mm on the pin circle.
    - `normal_clearance`: at that contacting configuration, mm (NaN if not computed).
    - `pin_circle_radius`: R′, mm.

    A negative lost motion means interference: the rigid disc cannot sit between the flanks
    there (the contacts are then those of the rigid model, not of the deformed reducer).
    """

    input_angle: Float[Array, "*p"]
    space: Int[Array, "*p zb"]
    rotation_to_contact: Float[Array, "*p zb"]
    on_driving_flank: Bool[Array, "*p zb"]
    reachable: Bool[Array, "*p zb"]
    interference: Bool[Array, "*p zb"]
    converged: Bool[Array, "*p zb"]
    contact_pin: Int[Array, "*p"]
    reverse_contact_pin: Int[Array, "*p"]
    rotation_error: Float[Array, "*p"]
    reverse_rotation_error: Float[Array, "*p"]
    lost_motion: Float[Array, "*p"]
    tangential_clearance: Float[Array, "*p zb"]
    tangential_arc: Float[Array, "*p zb"]
    normal_clearance: Float[Array, "*p zb"]
    pin_circle_radius: Float[Array, "*p"]


def _analyse(drive: CycloidPin, err: CycloidErrors, theta_T, normal: bool) -> Clearances:
    theta_T = jnp.asarray(theta_T, dtype=float)
    pins = _pins(drive, err, theta_T)
    con = _contacts(drive, err, pins, theta_T)
    drive_side = pins.side > 0
    inf = jnp.inf
    fwd = jnp.where(drive_side & con.reachable, con.rotation, inf)
    rev = jnp.where(~drive_side & con.reachable, con.rotation, -inf)
    i_f = jnp.argmin(fwd)
    i_r = jnp.argmax(rev)
    te_f = fwd[i_f]
    te_r = rev[i_r]
    # Own-flank tangential clearance (seed eq. 7, signed form: no assumption on the sign of Δθ).
    tang = jnp.where(drive_side, fwd - te_f, te_r - rev)
    finite = jnp.isfinite(tang)
    # Double `where`: no inf × 0 = NaN in the gradient of the never-touching pins.
    arc = jnp.where(finite, jnp.where(finite, tang, 0.0) * pins.pin_circle, jnp.inf)
    if normal:
        turn = theta_T * (drive.z_pins / drive.z_lobes) + jnp.where(drive_side, te_f, te_r)
        nc, nc_ok = _normal(drive, err, pins, con.phi, turn)
    else:
        nc, nc_ok = jnp.full(pins.side.shape, jnp.nan), True
    return Clearances(input_angle=theta_T, space=pins.space, rotation_to_contact=jnp.where(con.reachable, con.rotation, jnp.where(drive_side, inf, -inf)),
                      on_driving_flank=drive_side, reachable=con.reachable, interference=con.interference,
                      converged=con.converged & nc_ok, contact_pin=i_f, reverse_contact_pin=i_r, rotation_error=te_f,
                      reverse_rotation_error=te_r, lost_motion=te_f - te_r, tangential_clearance=tang,
                      tangential_arc=arc, normal_clearance=nc, pin_circle_radius=pins.pin_circle)


@eqx.filter_jit
def _clearances_jit(drive, err, theta_T, normal):
    return _analyse(drive, err, theta_T, normal)


@eqx.filter_jit
def _sweep_jit(drive, err, thetas, normal):
    return jax.vmap(lambda t: _analyse(drive, err, t, normal))(thetas)


def clearances(drive: CycloidPin, errors: CycloidErrors | None, input_angle: ArrayLike, *, normal: bool = True) -> Clearances:
    """Clearance analysis of every pin at input position θ_T = `input_angle` (rad).

    **Arguments:**

    - `drive`: the stage.
    - `errors`: its errors (None: none).
    - `input_angle`: θ_T, rad (pin wheel relative to the arm in the converted mechanism).
    - `normal`: also compute the normal clearances (a second 1-D search per pin).

    **Returns:** a `Clearances`. Differentiable with respect to the drive's arrays and the errors.
    """
    require_x64()
    err = checked_errors(drive, errors)
    return _clearances_jit(drive, err, jnp.asarray(input_angle, dtype=float), bool(normal))


def sweep(drive: CycloidPin, errors: CycloidErrors | None, input_angles: ArrayLike, *, normal: bool = True) -> Clearances:
    """`clearances` at every input angle of `input_angles` (rad); fields gain a leading axis."""
    require_x64()
    err = checked_errors(drive, errors)
    thetas = jnp.asarray(input_angles, dtype=float)
    if thetas.ndim != 1 or thetas.size == 0:
        raise ValueError(f"input_angles: give a 1-D array of input angles (rad), got shape {thetas.shape}")
    return _sweep_jit(drive, err, thetas, bool(normal))


@eqx.filter_jit
def _normal_jit(drive, err, theta_T, rotation):
    pins = _pins(drive, err, theta_T)
    return _normal(drive, err, pins, pins.phi, theta_T * (drive.z_pins / drive.z_lobes) + rotation)[0]


def normal_clearance(drive: CycloidPin, errors: CycloidErrors | None, input_angle: ArrayLike, *,
                     rotation: ArrayLike = 0.0) -> Float[Array, " zb"]:
    """Normal clearance (mm) of every pin with the disc at a given rotation, not at its contact.

    **Arguments:**

    - `drive`, `errors`: the stage and its errors.
    - `input_angle`: θ_T, rad.
    - `rotation`: the disc's rotation from its theoretical position (z_b/z_a) θ_T, rad
      (default 0: the theoretical position).

    **Returns:** min over each pin's flank half of |pin centre − flank point| − r′, mm (seed eq. 8).
    """
    require_x64()
    err = checked_errors(drive, errors)
    return _normal_jit(drive, err, jnp.asarray(input_angle, dtype=float), jnp.asarray(rotation, dtype=float))


def pitch_angles(drive: CycloidPin, points: int = 64, *, start: float = 0.0) -> np.ndarray:
    """`points` input angles evenly over one pin pitch [start, start + 2π/z_b), rad (the seed's figures 3–8)."""
    points = _whole("points", points, minimum=1)
    return start + np.arange(points) * (drive.pitch / points)


def revolution_angles(drive: CycloidPin, points_per_pitch: int = 16, *, revolutions: int = 1) -> np.ndarray:
    """Input angles over `revolutions` whole input revolutions, `points_per_pitch` per pin pitch, rad.

    The pairing of pins and tooth spaces repeats after z_a revolutions (one output revolution).
    """
    points_per_pitch = _whole("points_per_pitch", points_per_pitch, minimum=1)
    revolutions = _whole("revolutions", revolutions, minimum=1)
    n = points_per_pitch * drive.z_pins * revolutions
    return np.arange(n) * (TWO_PI * revolutions / n)


def loaded_pairs(result: Clearances, *, budget_mm: float) -> Int[Array, "*p"]:
    """Pairs that can carry load in the forward direction: pins on a driving flank whose tangential
    clearance on the pin circle is within the deformation budget (mm). The contacting pair counts."""
    ok = result.on_driving_flank & (result.tangential_arc <= budget_mm * (1.0 + 1e-12) + 1e-12)
    return jnp.sum(ok, axis=-1)


def smooth_loaded_pairs(result: Clearances, *, budget_mm: ArrayLike, width_mm: ArrayLike) -> Float[Array, "*p"]:
    """A smooth surrogate of `loaded_pairs`: Σ over driving pins of σ((budget − arc)/width), for gradients.

    `width_mm` (mm) sets the smoothing; the surrogate tends to the exact count as it → 0.
    """
    arc = jnp.where(result.on_driving_flank & jnp.isfinite(result.tangential_arc), result.tangential_arc, 1e6)
    z = (budget_mm - arc) / width_mm
    return jnp.sum(jnp.where(result.on_driving_flank, jax.nn.sigmoid(z), 0.0), axis=-1)


def theoretical_pairs(drive: CycloidPin) -> int:
    """Pins on driving flanks at a generic input position: z_b/2 (rounded down for odd z_b)."""
    return drive.z_pins // 2


def first_order_clearance(drive: CycloidPin, phi: ArrayLike, *, pin_circle_radius: float | None = None,
                          pin_radius: float | None = None) -> Float[Array, "..."]:
    """First-order rotation to contact (rad) of a pin at flank parameter φ for the shift/equidistant
    modification alone (no errors; optionally actual R′, r′ in mm):
    [Δr S − ΔR (1 − K_1 cos φ)] / (a z_a sin φ), with Δr = r_Z − r′, ΔR = R_Z − R′. For reports and checks."""
    phi = jnp.asarray(phi, dtype=float)
    R1 = drive.pin_circle_radius if pin_circle_radius is None else pin_circle_radius
    r1 = drive.pin_radius if pin_radius is None else pin_radius
    K = drive.eccentricity * drive.z_pins / R1
    S = jnp.sqrt(1 + K * K - 2 * K * jnp.cos(phi))
    dr = drive.wheel_pin_radius - r1
    dR = drive.wheel_pin_circle_radius - R1
    return (dr * S - dR * (1 - K * jnp.cos(phi))) / (drive.eccentricity * drive.z_lobes * jnp.sin(jnp.abs(phi)))


__all__: Sequence[str] = (
    "CycloidErrors", "CycloidPin", "Clearances", "CycloidModification", "check_modification", "checked_errors", "clearances",
    "disc_outline", "first_order_clearance", "loaded_pairs", "min_curvature_radius", "normal_clearance", "pitch_angles", "revolution_angles",
    "smooth_loaded_pairs", "sweep", "theoretical_pairs", "theoretical_profile", "tooth_profile",
)
