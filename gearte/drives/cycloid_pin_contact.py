"""Cycloid-pin reducer: the tooth-clearance analysis (Yao & Liang 2001; model in `gearte.drives.cycloid_pin`).

For every pin at an input position θ_T: the disc rotation at which its own flank touches it
(a bracketed Newton solve of fixed length, vmapped over pins, positions and samples, and
differentiated by the implicit function theorem), the contacting pairs under a forward and a
reverse load, the rotation error and lost motion, and each pin's tangential and normal
clearance (`Clearances`). `sweep` repeats it over input angles.

Units: geometry in mm, errors in µm, angles in rad.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.units import TWO_PI
from ..core.validate import as_int
from .cycloid_pin_geometry import UM, CycloidErrors, _placed_curve, _placement, _rot, checked_errors
from .cycloid_pin_solve import Contact, contacts, materialise, sincos

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin

ErrorsLike = CycloidErrors | Mapping[str, Any] | None


class PinLayout(eqx.Module):
    """Where every pin is at one input position (the converted mechanism; see `gearte.drives.cycloid_pin`).

    - `centre`: pin centres relative to the disc centre, mm (z_b × 2).
    - `space`: the tooth space each pin sits in (0 … z_a − 1); `side`: +1 driving flank, −1 reverse.
    - `phi`: nominal flank parameter (the pin's angle from the crank), rad.
    - `radius`: r′, mm; `pin_circle`: R′, mm.
    """

    centre: Float[Array, "zb 2"]  # pin centres relative to the disc centre, converted frame, mm
    space: Int[Array, " zb"]  # tooth space each pin sits in
    side: Float[Array, " zb"]  # +1 driving flank, −1 reverse flank
    phi: Float[Array, " zb"]  # nominal flank parameter (pin angle from the crank), rad
    radius: Float[Array, ""]  # r′, mm
    pin_circle: Float[Array, ""]  # R′, mm


@eqx.filter_jit
def _pins(drive: CycloidPin, err: CycloidErrors, theta_T) -> PinLayout:
    zb, za = drive.z_pins, drive.z_lobes
    j = jnp.arange(zb, dtype=float)
    R1 = drive.pin_circle_radius + err.pin_circle_radius * UM
    psi_nom = theta_T + j * (TWO_PI / zb)
    # sin/cos of ψ = ψ_nom + δ_j/R′ by angle addition: ψ_nom's are shared by a batch of reducers. What is
    # computed per angle, per reducer or per pin is stored before it is broadcast to every pin at every angle
    # of every reducer (`materialise`: XLA would otherwise recompute it there, per element).
    sn, cn = materialise(sincos(psi_nom))
    se, ce = sincos(err.pin_tangential * UM / R1)
    rad = R1 + err.pin_radial * UM
    A1 = drive.eccentricity + err.eccentricity * UM
    obx = (
        err.pin_wheel_offset * jnp.cos(err.pin_wheel_offset_phase)
        + err.pin_circle_eccentricity * jnp.cos(err.pin_circle_eccentricity_phase + theta_T)
        - err.disc_offset * jnp.cos(err.disc_offset_phase)
    ) * UM
    oby = (
        -A1
        + (
            err.pin_wheel_offset * jnp.sin(err.pin_wheel_offset_phase)
            + err.pin_circle_eccentricity * jnp.sin(err.pin_circle_eccentricity_phase + theta_T)
            - err.disc_offset * jnp.sin(err.disc_offset_phase)
        )
        * UM
    )
    se, ce, rad, obx, oby = materialise((se, ce, rad, obx, oby))
    cx = obx - rad * (sn * ce + cn * se)
    cy = oby + rad * (cn * ce - sn * se)
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
    return PinLayout(jnp.stack([cx, cy], axis=-1), space, side, phi, drive.pin_radius + err.pin_radius * UM, R1)


def pin_layout(drive: CycloidPin, errors: ErrorsLike, input_angle: ArrayLike) -> PinLayout:
    """Where every pin is, and which flank of which tooth space it faces, at input position θ_T (rad)."""
    require_x64()
    return _pins(drive, checked_errors(drive, errors), jnp.asarray(input_angle, dtype=float))


#: Fixed iteration count of the normal-clearance search (the contact solve's are in `gearte.drives.cycloid_pin_solve`).
DISTANCE_STEPS = 12


def _stop(tree):
    return jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, tree)


# The pin layout and the contact solve are jitted: a program that analyses several angles or both load
# directions (a sweep and the analysis angle, the RV reducer's discs) traces each of them once and calls it, where
# plain functions would be traced again at every call; the values are those of the inlined code.
@eqx.filter_jit
def _contacts(drive: CycloidPin, err: CycloidErrors, pins: PinLayout, theta_T) -> Contact:
    """Rotation to contact of every pin against its own flank (`gearte.drives.cycloid_pin_solve`)."""
    return contacts(drive, err, pins, theta_T)


def _normal(drive: CycloidPin, err: CycloidErrors, pins: PinLayout, phi0, turn):
    """min over the pin's flank half of |pin centre − flank point| − r′ (mm) with the disc turned by `turn`
    (rad, per pin) from its theoretical zero (Yao & Liang 2001, eq. 8), and whether the search converged."""
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
    fd = lambda s: jax.jvp(fs, (s,), (ones,))[1]

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
    - `space`: the tooth space (0 … z_a − 1, the paper's n − 1) each pin sits in.
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
    return _analyse_jit(drive, err, jnp.asarray(theta_T, dtype=float), normal)


@eqx.filter_jit
def _analyse_jit(drive: CycloidPin, err: CycloidErrors, theta_T, normal: bool) -> Clearances:
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
    # Own-flank tangential clearance (Yao & Liang 2001, eq. 7, signed form: no assumption on the sign of Δθ).
    tang = jnp.where(drive_side, fwd - te_f, te_r - rev)
    finite = jnp.isfinite(tang)
    # Double `where`: no inf × 0 = NaN in the gradient of the never-touching pins.
    arc = jnp.where(finite, jnp.where(finite, tang, 0.0) * pins.pin_circle, jnp.inf)
    if normal:
        turn = theta_T * (drive.z_pins / drive.z_lobes) + jnp.where(drive_side, te_f, te_r)
        nc, nc_ok = _normal(drive, err, pins, con.phi, turn)
    else:
        nc, nc_ok = jnp.full(pins.side.shape, jnp.nan), True
    return Clearances(
        input_angle=theta_T,
        space=pins.space,
        rotation_to_contact=jnp.where(con.reachable, con.rotation, jnp.where(drive_side, inf, -inf)),
        on_driving_flank=drive_side,
        reachable=con.reachable,
        interference=con.interference,
        converged=con.converged & nc_ok,
        contact_pin=i_f,
        reverse_contact_pin=i_r,
        rotation_error=te_f,
        reverse_rotation_error=te_r,
        lost_motion=te_f - te_r,
        tangential_clearance=tang,
        tangential_arc=arc,
        normal_clearance=nc,
        pin_circle_radius=pins.pin_circle,
    )


def contact_geometry(drive: CycloidPin, errors: ErrorsLike, input_angle: ArrayLike) -> tuple[PinLayout, Array, Array]:
    """At input position θ_T = `input_angle` (rad), from one pin layout: the layout (`pin_layout`), every pin's
    rotation to contact (`Clearances.rotation_to_contact`, rad) and its normal clearance with the disc at its
    theoretical position (`normal_clearance`, mm), the values those functions give. For a model built on this
    geometry (the RV reducer's discs): each of those functions lays the pins out again, and in one program XLA
    compiles every layout (a fifth of an RV program's compilation)."""
    require_x64()
    err = checked_errors(drive, errors)
    theta_T = jnp.asarray(input_angle, dtype=float)
    pins = _pins(drive, err, theta_T)
    con = _contacts(drive, err, pins, theta_T)
    rotation = jnp.where(con.reachable, con.rotation, jnp.where(pins.side > 0, jnp.inf, -jnp.inf))
    gap = _normal(drive, err, pins, pins.phi, theta_T * (drive.z_pins / drive.z_lobes) + 0.0)[0]
    return pins, rotation, gap


@kept_jit
def _clearances_jit(drive, err, theta_T, normal):
    return _analyse(drive, err, theta_T, normal)


@kept_jit
def _sweep_jit(drive, err, thetas, normal):
    return jax.vmap(lambda t: _analyse(drive, err, t, normal))(thetas)


def clearances(drive: CycloidPin, errors: ErrorsLike, input_angle: ArrayLike, *, normal: bool = True) -> Clearances:
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


def sweep(drive: CycloidPin, errors: ErrorsLike, input_angles: ArrayLike, *, normal: bool = True) -> Clearances:
    """`clearances` at every input angle of `input_angles` (rad); fields gain a leading axis."""
    require_x64()
    err = checked_errors(drive, errors)
    thetas = jnp.asarray(input_angles, dtype=float)
    if thetas.ndim != 1 or thetas.size == 0:
        raise ValueError(f"input_angles: give a 1-D array of input angles (rad), got shape {thetas.shape}")
    return _sweep_jit(drive, err, thetas, bool(normal))


@kept_jit
def _normal_jit(drive, err, theta_T, rotation):
    pins = _pins(drive, err, theta_T)
    return _normal(drive, err, pins, pins.phi, theta_T * (drive.z_pins / drive.z_lobes) + rotation)[0]


def normal_clearance(drive: CycloidPin, errors: ErrorsLike, input_angle: ArrayLike, *, rotation: ArrayLike = 0.0) -> Float[Array, " zb"]:
    """Normal clearance (mm) of every pin with the disc at a given rotation, not at its contact.

    **Arguments:**

    - `drive`, `errors`: the stage and its errors.
    - `input_angle`: θ_T, rad.
    - `rotation`: the disc's rotation from its theoretical position (z_b/z_a) θ_T, rad
      (default 0: the theoretical position).

    **Returns:** min over each pin's flank half of |pin centre − flank point| − r′, mm (Yao & Liang 2001, eq. 8).
    """
    require_x64()
    err = checked_errors(drive, errors)
    return _normal_jit(drive, err, jnp.asarray(input_angle, dtype=float), jnp.asarray(rotation, dtype=float))


def pitch_angles(drive: CycloidPin, points: int = 64, *, start: float = 0.0) -> np.ndarray:
    """`points` input angles evenly over one pin pitch [start, start + 2π/z_b), rad (the paper's figures 3–8)."""
    points = as_int("points", points, minimum=1)
    return start + np.arange(points) * (drive.pitch / points)


def revolution_angles(drive: CycloidPin, points_per_pitch: int = 16, *, revolutions: int = 1) -> np.ndarray:
    """Input angles over `revolutions` whole input revolutions, `points_per_pitch` per pin pitch, rad.

    The pairing of pins and tooth spaces repeats after z_a revolutions (one output revolution).
    """
    points_per_pitch = as_int("points_per_pitch", points_per_pitch, minimum=1)
    revolutions = as_int("revolutions", revolutions, minimum=1)
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


def first_order_clearance(
    drive: CycloidPin, phi: ArrayLike, *, pin_circle_radius: float | None = None, pin_radius: float | None = None
) -> Float[Array, ...]:
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


__all__ = (
    "Clearances",
    "PinLayout",
    "clearances",
    "first_order_clearance",
    "loaded_pairs",
    "normal_clearance",
    "pin_layout",
    "pitch_angles",
    "revolution_angles",
    "smooth_loaded_pairs",
    "sweep",
    "theoretical_pairs",
)
