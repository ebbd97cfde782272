"""Cycloid-pin reducer: the disc geometry, its profile modification and the errors of one reducer.

The model and its conventions are set out in `gearte.drives.cycloid_pin` (Yao & Liang 2001).
This module holds what the clearance analysis (`cycloid_pin_contact`) builds on: the
modification of the dressed wheel (`CycloidModification`), the errors of one reducer
(`CycloidErrors`), and the tooth flanks they give (`tooth_profile`).

Units: geometry in mm, errors in µm, angles in rad.
"""

from __future__ import annotations

import abc
import dataclasses
import functools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..core.units import MM_PER_UM, TWO_PI
from ..core.validate import as_float, check_array_values
from .cycloid_pin_grinding import GeneratingDeviation, generating_deviation, normal_deviation, rigid_pitch_error
from .protocol import Eccentricity

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin

UM = MM_PER_UM  # mm per µm


def _number(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(
        name, value, positive=positive, nonnegative=nonnegative, hint="a radius or length cannot be zero or negative" if positive else ""
    )


def min_curvature_radius(pin_circle_radius: float, eccentricity: float, z_pins: int, *, points: int = 20001) -> float:
    """Smallest radius of curvature (mm) of the convex part of the theoretical (pin-centre) curve.

    The equidistant E = P − r N is free of loops (undercut) exactly when r is below this
    radius: E′ = |P′| (1 + r κ) T, with κ the signed curvature (negative where the curve
    is convex, towards the tooth tips).

    **Arguments:**

    - `pin_circle_radius`: R (mm); `eccentricity`: a (mm); `z_pins`: z_b.
    """
    return _min_curvature_radius(float(pin_circle_radius), float(eccentricity), int(z_pins), int(points))


@functools.lru_cache(maxsize=256)
def _min_curvature_radius(R: float, a: float, zb: int, points: int) -> float:
    """`min_curvature_radius` on plain numbers, remembered: every drive built with the same geometry (a study's checks,
    its Monte Carlo, a tolerance study's many drives) asks for the same value, a 20,001-point evaluation."""
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
      by δ (gearte's rotation modification; 0 for Yao & Liang's profiles).
    """

    shift: Float[Array, ""]
    equidistant: Float[Array, ""]
    rotation: Float[Array, ""]

    def __init__(self, shift: ArrayLike = 0.0, equidistant: ArrayLike = 0.0, rotation: ArrayLike = 0.0):
        self.shift = jnp.asarray(shift, dtype=float)
        self.equidistant = jnp.asarray(equidistant, dtype=float)
        self.rotation = jnp.asarray(rotation, dtype=float)


def check_modification(drive: CycloidPin) -> None:
    """Raise `ValueError` if the dressed wheel gives an impossible or undercut profile (Python floats; before jit)."""
    R, a, zb = float(drive.pin_circle_radius), float(drive.eccentricity), drive.z_pins
    RZ = float(drive.wheel_pin_circle_radius)
    rZ = float(drive.wheel_pin_radius)
    rot = float(drive.modification.rotation)
    for name, v in (
        ("modification.shift", RZ - R),
        ("modification.equidistant", rZ - float(drive.pin_radius)),
        ("modification.rotation", rot),
    ):
        if not math.isfinite(v):
            raise ValueError(f"{name}: must be finite, got {v}")
    if not RZ > 0:
        raise ValueError(f"modification.shift: the wheel's pin-circle radius R_Z = {RZ:g} mm must be > 0")
    if not rZ > 0:
        raise ValueError(f"modification.equidistant: the wheel's pin radius r_Z = {rZ:g} mm must be > 0")
    KZ = a * zb / RZ
    if not KZ < 1.0:
        raise ValueError(
            f"modification.shift: with R_Z = {RZ:g} mm the wheel's K = a z_b / R_Z = {KZ:.6g} is ≥ 1; use a smaller negative shift"
        )
    rho = min_curvature_radius(RZ, a, zb)
    if not rZ < rho:
        raise ValueError(
            f"modification.equidistant: the wheel's pin radius r_Z = {rZ:g} mm is not below the smallest "
            f"radius of curvature of its theoretical profile, {rho:.6g} mm: the ground profile would be "
            "undercut (looped); reduce the equidistant modification"
        )
    if abs(rot) >= math.pi / (2 * (zb - 1)):
        raise ValueError(
            f"modification.rotation: {rot:g} rad is not a small rotation; it must be below a quarter of a "
            f"tooth space, π/(2 z_a) = {math.pi / (2 * (zb - 1)):.6g} rad"
        )
    # A modification opens a clearance of at most |ΔR_Z| + |Δr_Z| along the normal; one as deep as the teeth (2a) leaves
    # the disc without a tooth that any pin could touch (modifications are tenths of a millimetre).
    for name, v in (("shift", RZ - R), ("equidistant", rZ - float(drive.pin_radius))):
        if not abs(v) < 2 * a:
            raise ValueError(
                f"modification.{name}: {v:+g} mm is not below the teeth's depth, twice the eccentricity (2a = {2 * a:g} mm): "
                "no pin would touch the disc; a profile modification is a fraction of a millimetre"
            )


def _not_eccentricity(name: str) -> str:
    return (
        f"errors.{name}: a cycloid-pin error is a signed deviation (µm or rad; a magnitude and its phase are two fields); "
        "give a number or an array, not an Eccentricity"
    )


class CycloidErrors(eqx.Module):
    """The errors of one reducer: its disc's form-grinding errors and its own (Yao & Liang 2001, eqs. 1–3).

    Lengths in µm, angles in rad. Per-space fields take a scalar (the same for every
    space) or z_a values (space n = 0 … z_a − 1, the paper's n + 1); per-pin fields a scalar
    or z_b values. Every field defaults to 0.

    **Form grinding (Yao & Liang 2001, eqs. 1–2):**

    - `dressing_x`, `dressing_y`: δX_4, δY_4, the dresser's errors, µm.
    - `infeed`: ΔY_4(n), infeed error of each tooth space, µm (positive: less cut).
    - `index_offset`: β_0, the initial index angle, rad.
    - `indexing`: Δβ(n), the grinder's indexing error of each space, rad.
    - `setup_eccentricity`, `setup_phase`: ΔA (µm) at φ (rad), blank set-up eccentricity.
    - `mandrel_runout`, `mandrel_phase`: ΔB (µm) at its angle (rad; 0 as in eq. 2).

    **Reducer (Yao & Liang 2001, sec. 2):**

    - `pin_circle_radius`: R′_z − R_z, µm.
    - `pin_radius`: r′_z − r_z, µm (sleeve contact surface from the pin centre, fits included).
    - `eccentricity`: A′ − a, µm.
    - `pin_tangential`: δ_j, tangential position error of each pin, µm (positive: CCW).
    - `pin_radial`: radial position error of each pin, µm (positive: outwards).
    - `disc_offset`, `disc_offset_phase`: Δ_1 (µm) at α_1 (rad), disc centre from the eccentric.
    - `pin_wheel_offset`, `pin_wheel_offset_phase`: Δ_2 (µm) at α_2 (rad), pin-wheel centre
      from the input axis, fixed in the converted mechanism (the paper's eq. 3).
    - `pin_circle_eccentricity`, `pin_circle_eccentricity_phase`: (µm) at α_e (rad), a
      pin-circle eccentricity fixed in the housing: at α_e + θ_T in the converted frame.

    **Generating grinding only** (`gearte.drives.cycloid_pin_grinding`; a form-ground disc ignores
    them, and refuses them by name in a mapping). With `GeneratingGrinding()` the wheel is one pin of radius r_Z, and
    `dressing_x`, `dressing_y` and `infeed` are the wheel's centre offsets in the wheel-head frame
    (across; along the wheel slide, per space), no longer rigid shifts of a form wheel's profile.

    - `wheel_radius`: δr_w, error of the wheel's working radius r_Z (dressing), µm (positive: more cut).
    - `generating_eccentricity`: δa_g, error of the generating crank radius a, µm.
    - `generating_chain`, `generating_chain_phase`: A_c (rad) at p_c (rad), the generating chain's
      once-per-crank-revolution angular error ε_c(φ) = A_c sin(φ + p_c) (one crank revolution per space).
    - `pitch_accumulated`, `pitch_accumulated_phase`: A_p (rad) at p_p (rad), the work drive's
      once-per-revolution angular error A_p sin((2πn + φ)/z_a + p_p): the accumulated pitch error
      (F_p = 2 A_p R_z on the pin circle), the per-space part also within each space.
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
    wheel_radius: Float[Array, ""]
    generating_eccentricity: Float[Array, ""]
    generating_chain: Float[Array, ""]
    generating_chain_phase: Float[Array, ""]
    pitch_accumulated: Float[Array, ""]
    pitch_accumulated_phase: Float[Array, ""]

    def __init__(
        self,
        *,
        dressing_x: ArrayLike = 0.0,
        dressing_y: ArrayLike = 0.0,
        infeed: ArrayLike = 0.0,
        index_offset: ArrayLike = 0.0,
        indexing: ArrayLike = 0.0,
        setup_eccentricity: ArrayLike = 0.0,
        setup_phase: ArrayLike = 0.0,
        mandrel_runout: ArrayLike = 0.0,
        mandrel_phase: ArrayLike = 0.0,
        pin_circle_radius: ArrayLike = 0.0,
        pin_radius: ArrayLike = 0.0,
        eccentricity: ArrayLike = 0.0,
        pin_tangential: ArrayLike = 0.0,
        pin_radial: ArrayLike = 0.0,
        disc_offset: ArrayLike = 0.0,
        disc_offset_phase: ArrayLike = 0.0,
        pin_wheel_offset: ArrayLike = 0.0,
        pin_wheel_offset_phase: ArrayLike = 0.0,
        pin_circle_eccentricity: ArrayLike = 0.0,
        pin_circle_eccentricity_phase: ArrayLike = 0.0,
        wheel_radius: ArrayLike = 0.0,
        generating_eccentricity: ArrayLike = 0.0,
        generating_chain: ArrayLike = 0.0,
        generating_chain_phase: ArrayLike = 0.0,
        pitch_accumulated: ArrayLike = 0.0,
        pitch_accumulated_phase: ArrayLike = 0.0,
    ):
        given = dict(locals())
        for name in (f.name for f in dataclasses.fields(self)):
            x = given[name]
            if isinstance(x, Eccentricity):
                raise ValueError(_not_eccentricity(name))
            check_array_values(f"errors.{name}", x)
            setattr(self, name, jnp.asarray(x, dtype=float))


#: Fields of `CycloidErrors` with one value per tooth space / per pin.
PER_SPACE = ("infeed", "indexing")
PER_PIN = ("pin_tangential", "pin_radial")
ALL_ERROR_FIELDS = tuple(f.name for f in dataclasses.fields(CycloidErrors))
#: The fields only a generating-ground disc has (the machine's generating kinematics).
GENERATING_ONLY = (
    "wheel_radius",
    "generating_eccentricity",
    "generating_chain",
    "generating_chain_phase",
    "pitch_accumulated",
    "pitch_accumulated_phase",
)
#: The error fields of a form-ground disc's reducer (the error sources of ``process = "form"``), in order.
ERROR_FIELDS = tuple(f for f in ALL_ERROR_FIELDS if f not in GENERATING_ONLY)
#: The error fields of a generating-ground disc's reducer: those of form grinding, then `GENERATING_ONLY`.
GENERATING_ERROR_FIELDS = ERROR_FIELDS + GENERATING_ONLY


class AbstractGrindingProcess(eqx.Module):
    """How the discs are ground: which error sources the disc has (`fields`) and how the grinding machine's errors
    place each tooth space (`index_error`, `wheel_offsets`) or deform its flank (`flank_errors`)."""

    #: The process's name in study files (``[drive] process = …``).
    name: ClassVar[str]
    #: What the report says.
    description: ClassVar[str]
    #: The error fields of a disc ground so, in order (the error sources of the drive).
    fields: ClassVar[tuple[str, ...]]
    #: Whether the machine's errors act along the flank (`gearte.drives.cycloid_pin_grinding.normal_deviation`).
    flank_errors: ClassVar[bool]

    @abc.abstractmethod
    def index_error(self, err: CycloidErrors, n) -> Array:
        """The machine's rotation of tooth space(s) n about the disc centre (rad), added to the index angle β_n."""

    @abc.abstractmethod
    def wheel_offsets(self, err: CycloidErrors, n) -> tuple[Array, Array]:
        """The wheel's offsets that move tooth space(s) n rigidly in its own frame, (δX, δY) in mm."""


class FormGrinding(AbstractGrindingProcess):
    """Form grinding (Yao & Liang 2001), the default: the dressed wheel's offsets δX_4, δY_4 + ΔY_4(n) move each
    tooth space rigidly. Study files: ``process = "form"``."""

    name: ClassVar[str] = "form"
    description: ClassVar[str] = "form grinding"
    fields: ClassVar[tuple[str, ...]] = ERROR_FIELDS
    flank_errors: ClassVar[bool] = False

    def index_error(self, err: CycloidErrors, n) -> Array:
        return jnp.zeros_like(err.indexing[n])

    def wheel_offsets(self, err: CycloidErrors, n) -> tuple[Array, Array]:
        return err.dressing_x * UM, (err.dressing_y + err.infeed[n]) * UM


class GeneratingGrinding(AbstractGrindingProcess):
    """Generating grinding (`gearte.drives.cycloid_pin_grinding`): the wheel's offsets and the machine's generating
    errors act along the flank; the work drive's accumulated pitch error turns each tooth space rigidly. Study
    files: ``process = "generating"``."""

    name: ClassVar[str] = "generating"
    description: ClassVar[str] = "generating grinding"
    fields: ClassVar[tuple[str, ...]] = GENERATING_ERROR_FIELDS
    flank_errors: ClassVar[bool] = True

    def index_error(self, err: CycloidErrors, n) -> Array:
        return rigid_pitch_error(err, n)

    def wheel_offsets(self, err: CycloidErrors, n) -> tuple[Array, Array]:
        zero = jnp.zeros_like(err.infeed[n])
        return zero, zero


#: The grinding processes by their names in study files.
PROCESSES: dict[str, type[AbstractGrindingProcess]] = {p.name: p for p in (FormGrinding, GeneratingGrinding)}
#: Fields that are angles (rad): the index and generating-chain angles and every phase.
ANGLE_FIELDS = ("index_offset", "indexing", "generating_chain", "pitch_accumulated")
#: Unit of each error field, for reports.
ERROR_UNITS = {name: ("rad" if name in ANGLE_FIELDS or name.endswith("_phase") else "µm") for name in ALL_ERROR_FIELDS}


def _given_errors(errors: CycloidErrors | Mapping[str, Any] | None) -> dict[str, Any]:
    """The error fields that `errors` gives, by name (None gives none); an unknown field name is refused."""
    if errors is None:
        return {}
    if isinstance(errors, CycloidErrors):
        return {name: getattr(errors, name) for name in ALL_ERROR_FIELDS}
    if isinstance(errors, Mapping):
        unknown = sorted(set(errors) - set(ALL_ERROR_FIELDS))
        if unknown:
            raise ValueError(f"errors: unknown error field(s) {unknown}; the fields are {list(ALL_ERROR_FIELDS)}")
        return dict(errors)
    raise ValueError(f"errors: expected a CycloidErrors or a mapping of error fields, got {type(errors).__name__}")


def as_cycloid_errors(errors: CycloidErrors | Mapping[str, Any] | None) -> CycloidErrors:
    """`errors` as a `CycloidErrors`: None is no error; a mapping names fields (µm or rad), the others are 0.

    A mapping is what the drive protocol passes (``CycloidPin.response``): source name → value.
    """
    if isinstance(errors, CycloidErrors):
        return errors
    return CycloidErrors(**_given_errors(errors))


def checked_errors(drive: CycloidPin, errors: CycloidErrors | Mapping[str, Any] | None) -> CycloidErrors:
    """`errors` with per-space and per-pin fields broadcast to z_a and z_b values; shapes checked (trace time).

    `errors`: a `CycloidErrors`, a mapping of field names to values (the others 0), or None (no error).
    Values that are not JAX arrays are checked and broadcast in NumPy: one conversion each, in `CycloidErrors`.
    """
    process = getattr(drive, "process", None)  # a drive built on the cycloid geometry (RV) has form-ground discs
    if isinstance(errors, Mapping):
        wrong = sorted(set(errors) & set(GENERATING_ONLY) - set(ERROR_FIELDS if process is None else process.fields))
        if wrong:
            raise ValueError(
                f"errors: {wrong} are errors of a generating-ground disc; this disc is form-ground "
                '(give the drive process = "generating" in a study file, GeneratingGrinding() in Python, or leave them out)'
            )
    given = _given_errors(errors)
    out = {}
    for name in ALL_ERROR_FIELDS:
        v = given.get(name, 0.0)
        if isinstance(v, Eccentricity):
            raise ValueError(_not_eccentricity(name))
        if any(isinstance(leaf, jax.Array) for leaf in jax.tree_util.tree_leaves(v)):
            v = jnp.asarray(v)  # JAX values (traced ones too), alone or in a list
        shape = np.shape(v)
        if name in PER_SPACE or name in PER_PIN:
            n = drive.z_lobes if name in PER_SPACE else drive.z_pins
            what = "tooth space (z_a)" if name in PER_SPACE else "pin (z_b)"
            if shape not in ((), (1,), (n,)):
                raise ValueError(f"errors.{name}: give a scalar or one value per {what} = {n} values, got shape {shape}")
            xp = jnp if isinstance(v, jax.Array) else np
            v = xp.broadcast_to(xp.reshape(v, -1) if shape else v, (n,))
        elif shape != ():
            raise ValueError(f"errors.{name}: must be a scalar, got shape {shape}")
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
    offsets (δX_4, δY_4 + ΔY_4(n)), the index rotation −β_n and the bore eccentricity (Yao & Liang 2001, eqs. 1–2);
    for a generating-ground disc also the machine's errors along the flank (`gearte.drives.cycloid_pin_grinding`)."""

    cos_mod: Array
    sin_mod: Array
    dx: Array
    dy: Array
    cos_beta: Array
    sin_beta: Array
    ex: Array
    ey: Array
    generating: GeneratingDeviation | None


def _placement(drive: CycloidPin, err: CycloidErrors, n, side) -> _Placement:
    m = drive.modification
    beta = jnp.asarray(n).astype(float) * (TWO_PI / drive.z_lobes) + err.index_offset + err.indexing[n]
    ex = err.setup_eccentricity * jnp.cos(err.setup_phase) + err.mandrel_runout * jnp.cos(err.mandrel_phase)
    ey = err.setup_eccentricity * jnp.sin(err.setup_phase) + err.mandrel_runout * jnp.sin(err.mandrel_phase)
    # A generating machine's offsets act along the flank (normal_deviation), its work drive's error rigidly.
    process = drive.process
    beta = beta + process.index_error(err, n)
    dx, dy = process.wheel_offsets(err, n)
    gen = generating_deviation(err, n) if process.flank_errors else None
    return _Placement(
        jnp.cos(side * m.rotation),
        -jnp.sin(side * m.rotation),
        dx,
        dy,
        jnp.cos(beta),
        -jnp.sin(beta),
        ex * UM,
        ey * UM,
        gen,
    )


def _placed_curve(drive: CycloidPin, pl: _Placement, phi, d):
    """Tooth-space half placed by `pl`: the wheel's P_Z − d N_Z in the disc frame centred on the bore, mm.
    d = r_Z: the flank; d = r_Z − r′: the pin-centre locus. A generating-ground flank has d − e_n(φ)."""
    if pl.generating is not None:
        d = d - normal_deviation(
            pl.generating, phi, wheel_pin_circle_radius=drive.wheel_pin_circle_radius, eccentricity=drive.eccentricity, z_pins=drive.z_pins
        )
    x, y = _wheel_curve(drive.wheel_pin_circle_radius, drive.eccentricity, drive.z_lobes, drive.z_pins, phi, d)
    x, y = pl.cos_mod * x - pl.sin_mod * y, pl.sin_mod * x + pl.cos_mod * y
    x, y = x + pl.dx, y + pl.dy
    x, y = pl.cos_beta * x - pl.sin_beta * y, pl.sin_beta * x + pl.cos_beta * y
    return x - pl.ex, y - pl.ey


def _space_curve(drive: CycloidPin, err: CycloidErrors, n, side, phi, d):
    """Tooth space n, half `side` (±1): see `_placed_curve`."""
    return _placed_curve(drive, _placement(drive, err, n, side), phi, d)


def tooth_profile(
    drive: CycloidPin, phi: ArrayLike, *, errors: CycloidErrors | Mapping[str, Any] | None = None, space: int = 0
) -> Float[Array, "... 2"]:
    """Points of the actual flank of tooth space `space` (mm, disc frame centred on the bore).

    `phi` ∈ [−π, π] is the flank parameter (φ > 0: driving half, φ < 0: reverse half).
    """
    err = checked_errors(drive, errors)
    phi = jnp.asarray(phi, dtype=float)
    side = jnp.where(phi >= 0, 1.0, -1.0)
    x, y = _space_curve(drive, err, jnp.asarray(space % drive.z_lobes), side, phi, drive.wheel_pin_radius)
    return jnp.stack([x, y], axis=-1)


def disc_outline(
    drive: CycloidPin, *, errors: CycloidErrors | Mapping[str, Any] | None = None, points_per_space: int = 200
) -> Float[Array, "m 2"]:
    """The whole actual disc outline (mm), all z_a tooth spaces in order, for plotting."""
    phi = jnp.linspace(-math.pi, math.pi, points_per_space)
    pts = [tooth_profile(drive, phi, errors=errors, space=n) for n in range(drive.z_lobes)]
    return jnp.concatenate(pts, axis=0)


# ---------------------------------------------------------------- Yao & Liang's numbering

#: Yao & Liang (2001) compute their figures 3–8 with J = 6 (tooth space 1 of the disc, and pin 1, six
#: teeth to the right of the static axis at θ_T = 0).
YAO_LIANG_J = 6


def paper_position(drive: CycloidPin, pin: ArrayLike, input_angle: ArrayLike) -> np.ndarray:
    """K: the paper's number of the position of gearte's pin `pin` (0-based) at gearte's input angle θ_T (rad).

    Yao & Liang (2001, sec. 2) count positions counter-clockwise from the static axis (gearte's +y, the
    crank): at their input angle θ_T′ ∈ [0, 2π/z_b) the pin of position K is at (K − 1) 2π/z_b − θ_T′
    from it. Their θ_T′ turns the pin wheel clockwise, gearte's θ_T counter-clockwise, so the two
    describe the same configuration when θ_T′ = −θ_T (mod a pitch); gearte's pin j is at
    ψ_j = θ_T + 2πj/z_b, so K = 1 + round((ψ_j + θ_T′)·z_b/2π) (mod z_b, in 1 … z_b). Over the paper's
    sweep θ_T′ ∈ [0, 2π/z_b), gearte's θ_T ∈ (−2π/z_b, 0], K is gearte's pin number j + 1; over
    gearte's default sweep θ_T ∈ (0, 2π/z_b), K = j + 2.
    """
    zb = drive.z_pins
    p = TWO_PI / zb
    th = np.asarray(input_angle, dtype=float)
    tp = np.mod(-th, p)
    tp = np.where(tp > p * (1 - 1e-9), 0.0, tp)
    psi = th + np.asarray(pin) * p
    return (np.rint((psi + tp) / p).astype(int) % zb) + 1


def paper_pin(drive: CycloidPin, pin: ArrayLike, *, J: int = YAO_LIANG_J) -> np.ndarray:
    """The paper's number n (1 … z_b) of gearte's pin `pin` (0-based): n = K + J at θ_T = 0, so n = j + 1 + J."""
    return (np.asarray(pin) + J) % drive.z_pins + 1


def paper_tooth(drive: CycloidPin, space: ArrayLike, *, J: int = YAO_LIANG_J) -> np.ndarray:
    """The paper's number n (1 … z_a) of gearte's tooth space `space` (0-based).

    The paper numbers the disc's tooth spaces counter-clockwise from its tooth 1 (its frame X′_2 O Y′_2,
    which is turned 2πJ/z_a clockwise from the static axis at θ_T = 0); gearte numbers them clockwise
    from space 0, which is on the static axis at θ_T = 0. So space s is the paper's tooth J + 1 − s (mod z_a).
    """
    return (J - np.asarray(space)) % drive.z_lobes + 1


def errors_from_paper(drive: CycloidPin, *, J: int = YAO_LIANG_J, **fields: Any) -> dict[str, Any]:
    """Error fields given in Yao & Liang's numbering and frames, in gearte's (µm, rad; a mapping for `CycloidErrors`).

    - per-space fields (`infeed`, `indexing`): value n − 1 is the paper's tooth n; gearte's space s gets tooth
      J + 1 − s; the paper turns tooth n counter-clockwise by β(n), gearte turns space s clockwise, so
      `indexing` and `index_offset` change sign;
    - per-pin fields: value n − 1 is the paper's pin n, gearte's pin j = n − 1 − J;
    - angles in the disc frame (`setup_phase`, `mandrel_phase`): the paper's frame X′_2 O Y′_2 is gearte's
      disc frame turned 2πJ/z_a clockwise, so its angle α is gearte's α − 2πJ/z_a;
    - everything else (lengths; the static-frame angles α_1, α_2) is the same. The generating machine's
      errors are gearte's own (the paper has none): give them in gearte's convention.
    """
    za, zb = drive.z_lobes, drive.z_pins
    out = {}
    for name, v in fields.items():
        if name not in ALL_ERROR_FIELDS:
            raise ValueError(f"{name}: not an error field; the fields are {list(ALL_ERROR_FIELDS)}")
        v = np.asarray(v, dtype=float)
        if name in PER_SPACE and v.ndim:
            v = v[(J - np.arange(za)) % za]  # gearte space s ← paper tooth J + 1 − s (index J − s)
        if name in PER_PIN and v.ndim:
            v = v[(np.arange(zb) + J) % zb]  # gearte pin j ← paper pin j + 1 + J (index j + J)
        if name in ("indexing", "index_offset"):
            v = -v
        if name in GENERATING_ONLY:
            raise ValueError(f"{name}: the paper has no generating-machine errors; give them in gearte's convention")
        if name in ("setup_phase", "mandrel_phase"):
            v = v - TWO_PI * J / za
        out[name] = v if v.ndim else float(v)
    return out
