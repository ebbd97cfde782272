"""Cycloid-pin reducer: the contact solve of every pin, vectorised over pins, input angles and reducers.

For pin j (centre C relative to the disc centre, ρ = |C|) facing half s = ±1 of tooth space n, the
disc rotation at which its own flank touches it (`gearte.drives.cycloid_pin`, module notes) needs the
flank parameter φ = s t, t ∈ [0, π], at which the pin-centre locus of the flank is at distance ρ from
the disc centre. The locus of the placed space is

    Q(φ) = e^{−iβ_n} e^{−ism} (X(φ) + W_{n,s}),    X = P_Z − d N_Z,    W_{n,s} = e^{ism} (D_n − e^{iβ_n} E)

(complex numbers for points: X the wheel's curve with d = r_Z − r′ (less the generating deviation e_n(φ)),
m the rotation modification, D_n the wheel offsets of the space, β_n its index angle, E the bore
eccentricity). The rotations drop out of |Q| = |X + W|, so the equation is

    f(t) = |X(s t) + W|² − ρ² = 0,

and the rotation to contact is arg C + β_n + s m − arg(X + W) − (z_b/z_a) θ_T, one argument of a product.

**The solve (fixed length, no data-dependent loop).**

1. The error-free reducer's contact t* of every pin at every input angle: |X|² = A² + B² − 2AB cos t
   (A = R_Z − d/S, B = a − dK/S, S = (1 + K² − 2K cos t)^{1/2}) depends on cos t alone, so a Newton
   iteration in c = cos t converges from the pin's nominal flank parameter in a few steps (exactly in one
   for an unmodified profile). It depends on the drive only, so under `jax.vmap` over reducers it is
   computed once for the whole batch.
2. One chord step in c from c* = cos t* with the reducer's errors: f at t* needs no new sine or cosine
   (those of t* are shared by the batch), and the slope is that of the even part A² + B² − 2ABc, which
   stays finite at the folds t = 0 (a pin at the bottom of a tooth space) and t = π (at a tooth tip),
   where a Newton step in t fails.
3. `T_STEPS` steps to the increasing root of the local quadratic model of f in t (f, f′, f″ written out as jets:
   the product and quotient rules applied by hand, `_locus`), kept within a bracket in [0, π].

The result is checked, as before: a radius residual ||X + W| − ρ| below `RESIDUAL_TOL_MM` counts as
converged (reported per pin). `tests/test_cycloid.py` holds the solve to 1e-10 rad against an independent
per-pin, per-angle root search, over Monte Carlo reducers of the examples.

**Sines and cosines** are float64 polynomials, which vectorise where XLA's float64 `sin`, `cos` and `atan2` on
CPU are scalar library calls. `sincos` and `atan2` below take any argument (Cody-Waite reduction to [−π/4, π/4],
Taylor series to the 17th/18th power; two argument halvings and an odd series for the arctangent); the flank
angles u = t/z_a and v = z_b t/z_a of the solve, with t in [0, π], need no reduction (`_trig`: the series of u,
and of r = (v − π/2)/2, |r| < 1 rad, from which sin v = cos 2r and cos v = −sin 2r). All are accurate to a few
units in the last place on the angles used here (tested against NumPy).

**Stored stages.** XLA on CPU fuses elementwise producers into every consumer, so a stage read by several later
ones would be recomputed in each; `materialise` stores the few arrays each stage hands on (through a loop of
zero trips, which XLA does not fuse into).

The gradient with respect to the errors and the modification is the implicit one: the iteration is not
differentiated, the final evaluation is, and dt = −(∂f/∂p)/(∂f/∂t) dp enters through a term that is zero
in value.

Units: geometry in mm, errors in µm, angles in rad.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ..core.units import TWO_PI
from .cycloid_pin_geometry import UM, CycloidErrors

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin
    from .cycloid_pin_contact import PinLayout

#: Newton steps in c of the error-free contact (once per batch), and in t per reducer.
NOMINAL_STEPS = 8
T_STEPS = 2
#: A pin-to-locus radius residual below this (mm) counts as converged.
RESIDUAL_TOL_MM = 1e-9

# ---------------------------------------------------------------- float64 polynomial kernels

# π/2 in three parts with trailing zero bits (Cephes' DP1…DP3 × 2): k·_PIO2_1 is exact for |k| < 2²⁴.
_PIO2_1 = 1.57079625129699707031e00
_PIO2_2 = 7.54978941586159635336e-08
_PIO2_3 = 5.39030285815811905290e-15
_SIN = tuple((-1) ** k / math.factorial(2 * k + 1) for k in range(1, 9))  # r³ … r¹⁷
_COS = tuple((-1) ** k / math.factorial(2 * k) for k in range(2, 10))  # r⁴ … r¹⁸
_ATAN = tuple((-1) ** k / (2 * k + 1) for k in range(12))  # a … a²³


def _horner(z, coefs):
    acc = coefs[-1]
    for c in coefs[-2::-1]:
        acc = acc * z + c
    return acc


@jax.custom_jvp
def sincos(x: Array) -> tuple[Array, Array]:
    """(sin x, cos x) of float64 `x` (rad), vectorised polynomials; a few ulp for |x| up to 10⁶."""
    k = jnp.round(x * (2.0 / math.pi))
    r = ((x - k * _PIO2_1) - k * _PIO2_2) - k * _PIO2_3  # |r| ≤ π/4
    z = r * r
    s = r + r * z * _horner(z, _SIN)
    c = 1.0 - 0.5 * z + z * z * _horner(z, _COS)
    q = k - 4.0 * jnp.floor(k * 0.25)  # quadrant 0 … 3
    swap = (q == 1.0) | (q == 3.0)
    sn = jnp.where(swap, c, s)
    cs = jnp.where(swap, s, c)
    return jnp.where(q >= 2.0, -sn, sn), jnp.where((q == 1.0) | (q == 2.0), -cs, cs)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * dx, -s * dx)


@jax.custom_jvp
def atan2(y: Array, x: Array) -> Array:
    """arctan2(y, x) (rad, in [−π, π]) of float64 arrays, vectorised; a few ulp."""
    ax, ay = jnp.abs(x), jnp.abs(y)
    hi, lo = jnp.maximum(ax, ay), jnp.minimum(ax, ay)
    a = lo / jnp.where(hi > 0, hi, 1.0)  # tan of the angle to the nearer axis, in [0, 1]
    # Two halvings, atan a = 2 atan(a / (1 + √(1 + a²))): the angle is then ≤ π/16, where the odd series converges.
    a = a / (1.0 + jnp.sqrt(1.0 + a * a))
    a = a / (1.0 + jnp.sqrt(1.0 + a * a))
    r = 4.0 * a * _horner(a * a, _ATAN)
    r = jnp.where(ay > ax, 0.5 * math.pi - r, r)
    r = jnp.where(x < 0, math.pi - r, r)
    return jnp.where(y < 0, -r, r)


@atan2.defjvp
def _atan2_jvp(primals, tangents):
    (y, x), (dy, dx) = primals, tangents
    r2 = x * x + y * y
    return atan2(y, x), (x * dy - y * dx) / jnp.where(r2 > 0, r2, 1.0)


@jax.custom_jvp
def _stored(arrays: tuple[Array, ...]) -> tuple[Array, ...]:
    v = arrays[0].reshape(-1)[0]
    trips = (v != v).astype(jnp.int32)  # 0 for every finite or infinite value; 1 for NaN (the body is the identity)
    # (The body adds 0 × i, not provably 0 for floats, so XLA keeps the loop rather than forwarding the operands.)
    return jax.lax.fori_loop(0, trips, lambda i, c: tuple(x + i.astype(x.dtype) * 0.0 for x in c), arrays)


@_stored.defjvp
def _stored_jvp(primals, tangents):
    # The identity: tangents pass unchanged (a loop of unknown trip count could not be transposed for gradients).
    return _stored(*primals), tangents[0]


def materialise(tree):
    """`tree` unchanged in value, computed once and stored before its uses.

    XLA on CPU fuses elementwise producers into every consumer and drops optimisation barriers before fusion, so
    a value computed per reducer (or per angle) and broadcast to every pin at every angle, or a stage of the solve
    read by several later ones, would be recomputed in each of them, per element. The operands of a loop are never
    fused into it: the floating-point arrays of `tree` pass through a `fori_loop` whose trip count is 0 (NaN ≠ NaN
    decides it, which XLA cannot know before the run), the identity at the cost of storing them once.
    """
    leaves, treedef = jax.tree.flatten(tree)
    idx = [i for i, x in enumerate(leaves) if eqx.is_array(x) and jnp.issubdtype(x.dtype, jnp.floating)]
    if not idx:
        return tree
    arrays = _stored(tuple(leaves[i] for i in idx))
    for i, x in zip(idx, arrays, strict=True):
        leaves[i] = x
    return jax.tree.unflatten(treedef, leaves)


# ---------------------------------------------------------------- the geometry of one pin's solve


class _Generating(eqx.Module):
    """The generating machine's errors, per pin (its tooth space) where they vary by space (mm, rad)."""

    slide: Array
    across: Array
    wheel: Array
    crank: Array
    chain_cos: Array
    chain_sin: Array
    pitch: Array
    pitch_sin: Array
    pitch_cos: Array


class _Geo(eqx.Module):
    """Per pin: its flank half, the offset W of its space's locus, the factor of its rotation to contact."""

    side: Array  # s = ±1
    d: Array  # r_Z − r′, mm
    wx: Array
    wy: Array
    rho2: Array  # |C|², mm²
    fx: Array  # C e^{iβ_n} e^{ism} e^{−i θ_T z_b/z_a}: the rotation is arg(F conj(X + W))
    fy: Array
    gen: _Generating | None


def _geometry(drive: CycloidPin, err: CycloidErrors, pins: PinLayout, theta_T) -> _Geo:
    za, zb = drive.z_lobes, drive.z_pins
    bar = materialise
    n = pins.space
    s = pins.side
    sm, cm = sincos(drive.modification.rotation)
    process = drive.process
    spaces = jnp.arange(za)
    beta = jnp.arange(za, dtype=float) * (TWO_PI / za) + err.index_offset + err.indexing + process.index_error(err, spaces)
    sb, cb = sincos(beta)
    ex = (err.setup_eccentricity * jnp.cos(err.setup_phase) + err.mandrel_runout * jnp.cos(err.mandrel_phase)) * UM
    ey = (err.setup_eccentricity * jnp.sin(err.setup_phase) + err.mandrel_runout * jnp.sin(err.mandrel_phase)) * UM
    dx, dy = process.wheel_offsets(err, spaces)
    gen = None
    if process.flank_errors:
        spa, cpa = sincos(jnp.arange(za, dtype=float) * (TWO_PI / za) + err.pitch_accumulated_phase)
        gen = bar(
            _Generating(
                slide=(err.dressing_y + err.infeed) * UM,
                across=err.dressing_x * UM,
                wheel=err.wheel_radius * UM,
                crank=err.generating_eccentricity * UM,
                chain_cos=err.generating_chain * jnp.cos(err.generating_chain_phase),
                chain_sin=err.generating_chain * jnp.sin(err.generating_chain_phase),
                pitch=err.pitch_accumulated,
                pitch_sin=spa,
                pitch_cos=cpa,
            )
        )
        gen = eqx.tree_at(lambda e: (e.slide, e.pitch_sin, e.pitch_cos), gen, (gen.slide[n], gen.pitch_sin[n], gen.pitch_cos[n]))
    # Per tooth space (both halves): D − e^{iβ} E, and e^{iβ}; then per pin.
    vx = dx - (cb * ex - sb * ey)
    vy = dy - (sb * ex + cb * ey)
    vx, vy, sb, cb, sm, cm = bar((vx, vy, sb, cb, sm, cm))
    vx, vy, sb, cb = vx[n], vy[n], sb[n], cb[n]
    sm = s * sm  # e^{ism}
    wx, wy = cm * vx - sm * vy, sm * vx + cm * vy  # W = e^{ism} (D − e^{iβ} E)
    c = pins.centre
    cx, cy = c[..., 0], c[..., 1]
    st, ct = bar(sincos(-theta_T * (zb / za)))
    # e^{iβ} e^{ism} e^{−iθ_T z_b/z_a}
    rx, ry = cb * cm - sb * sm, sb * cm + cb * sm
    rx, ry = rx * ct - ry * st, rx * st + ry * ct
    return _Geo(
        side=s,
        d=drive.wheel_pin_radius - pins.radius,
        wx=wx,
        wy=wy,
        rho2=cx * cx + cy * cy,
        fx=cx * rx - cy * ry,
        fy=cx * ry + cy * rx,
        gen=gen,
    )


def _series_sincos(x, bound: float):
    """(sin x, cos x) by their Taylor series about 0, no argument reduction, for |x| ≤ `bound` ≤ 1 (rad): as many
    terms as keep the first one left out below 1e-18 there (decided when tracing)."""
    k = 1
    while k < len(_SIN) and bound ** (2 * k + 3) / math.factorial(2 * k + 3) > 1e-18 * bound:
        k += 1
    z = x * x
    return x + x * z * _horner(z, _SIN[:k]), 1.0 - 0.5 * z + z * z * _horner(z, _COS[:k])


#: The solve's flank parameters t lie in [0, π] (bracketed steps; a step below 1e-6 rad may leave the bracket by
#: that much): `_trig` is exact to rounding on this slightly wider interval.
_T_MARGIN = 0.01


def _trig(drive: CycloidPin, t):
    """sin and cos of u = t/z_a and v = z_b t/z_a (the wheel curve's two angles) for t in [0, π] ± `_T_MARGIN`.

    u is small (|u| ≤ (π + margin)/z_a): its series needs no argument reduction. v = π/2 + 2r with
    |r| ≤ ((π + margin) z_b/z_a − π/2)/2 (below 1 rad for z_a ≥ 9): sin v = cos 2r = (cos r − sin r)(cos r + sin r),
    cos v = −sin 2r, from the series of r. Where a range exceeds 1 rad (few lobes), `sincos` instead."""
    za, zb = float(drive.z_lobes), float(drive.z_pins)
    top = math.pi + _T_MARGIN
    bu, br = top / za, 0.5 * (top * zb / za - 0.5 * math.pi)
    su, cu = _series_sincos(t / za, bu) if bu <= 1.0 else sincos(t / za)
    if br > 1.0:
        sv, cv = sincos(t * (zb / za))
        return su, cu, sv, cv
    sr, cr = _series_sincos(0.5 * (t * (zb / za) - 0.5 * math.pi), br)
    return su, cu, (cr - sr) * (cr + sr), -2.0 * sr * cr


# Jets: a value and its first `order` derivatives in t, (f, f′) or (f, f′, f″), as tuples of arrays; the derivatives
# of the locus are written out (product and quotient rules on these), not traced by nested `jax.jvp`, which would
# carry every zero and repeated term of the angle-addition form through every stage.


def _zero(x) -> bool:
    return isinstance(x, float) and x == 0.0


def _mul(x, y):
    return 0.0 if _zero(x) or _zero(y) else x * y


def _add(*xs):
    xs = [x for x in xs if not _zero(x)]
    return sum(xs[1:], xs[0]) if xs else 0.0


def _jmul(a, b):
    out = (a[0] * b[0],)
    if len(a) > 1:
        out += (_add(_mul(a[0], b[1]), _mul(a[1], b[0])),)
    if len(a) > 2:
        out += (_add(_mul(a[0], b[2]), _mul(2.0 * a[1], b[1]) if not _zero(a[1]) else 0.0, _mul(a[2], b[0])),)
    return out


def _jdiv(a, b):
    """a/b of jets whose divisor b has nonzero derivatives."""
    q0 = a[0] / b[0]
    if len(a) == 1:
        return (q0,)
    q1 = (a[1] - q0 * b[1]) / b[0]
    if len(a) == 2:
        return q0, q1
    return q0, q1, (a[2] - 2.0 * q1 * b[1] - q0 * b[2]) / b[0]


def _jlin(*terms):
    """Σ c_k a_k of jets a_k with coefficients c_k (arrays broadcast against the jets, or floats); terms that are
    a Python 0 are left out and coefficients ±1 not multiplied, so that no operation is traced for them."""

    def coef(i):
        acc = None
        for c, a in terms:
            x = a[i]
            if isinstance(x, float) and x == 0.0:
                continue
            neg = isinstance(c, float) and c == -1.0
            if not (isinstance(c, float) and abs(c) == 1.0):
                x = c * x
            acc = (-x if neg else x) if acc is None else (acc - x if neg else acc + x)
        return 0.0 if acc is None else acc

    return tuple(coef(i) for i in range(len(terms[0][1])))


def _locus(drive: CycloidPin, g: _Geo, trig, order: int = 0):
    """X(s t) + W (mm, in the wheel's frame) as jets in t of `order` 0, 1 or 2: the pin-centre locus of the placed
    flank half, before its rotations. `trig`: `_trig(drive, t)`."""
    zb, za = drive.z_pins, drive.z_lobes
    RZ, a = drive.wheel_pin_circle_radius, drive.eccentricity
    K = a * float(zb) / RZ
    s = g.side
    su, cu, sv, cv = trig
    su, sv = s * su, s * sv  # φ = s t
    cphi = cu * cv + su * sv  # cos(v − u) = cos φ = cos t
    sphi = sv * cu - cv * su  # sin φ = s sin t
    S = jnp.sqrt(1.0 + K * K - 2.0 * K * cphi)
    wu, wv = 1.0 / za, float(zb) / za
    n = order + 1
    Su = (su, s * wu * cu, -wu * wu * su)[:n]
    Cu = (cu, -s * wu * su, -wu * wu * cu)[:n]
    Sv = (sv, s * wv * cv, -wv * wv * sv)[:n]
    Cv = (cv, -s * wv * sv, -wv * wv * cv)[:n]
    Cp = (cphi, -s * sphi, -cphi)[:n]
    Sp = (sphi, s * cphi, -sphi)[:n]
    S1 = K * s * sphi / S  # S′ (traced only where used)
    Sj = (S, S1, (K * cphi - S1 * S1) / S)[:n]
    one = (1.0,) + (0.0,) * order
    d = (g.d,) + (0.0,) * order
    if g.gen is not None:  # the generated flank's normal deviation e_n(φ) (gearte.drives.cycloid_pin_grinding)
        e = g.gen
        eps_c = _jlin((e.chain_cos, Sp), (e.chain_sin, Cp))
        delta_p = _jlin((e.pitch * e.pitch_sin, Cu), (e.pitch * e.pitch_cos, Su), (-e.pitch * e.pitch_sin, one))
        inner = _jlin((a, eps_c), (a * za, delta_p))
        num = _jlin((e.slide - e.crank * (-K), one), (-(e.slide * K + e.crank), Cp), (-e.across * K, Sp))
        num = _jlin((1.0, num), (-1.0, _jmul(inner, Sp)))
        dn = _jdiv(num, Sj)
        d = (g.d - dn[0] + e.wheel,) + tuple(-x for x in dn[1:])
    x = _jlin((RZ, Su), (-a, Sv), (-1.0, _jmul(d, _jdiv(_jlin((1.0, Su), (-K, Sv)), Sj))))
    y = _jlin((RZ, Cu), (-a, Cv), (-1.0, _jmul(d, _jdiv(_jlin((1.0, Cu), (-K, Cv)), Sj))))
    return (x[0] + g.wx,) + x[1:], (y[0] + g.wy,) + y[1:]


def _f(drive, g, trig, order: int = 0):
    """f = |X + W|² − ρ² as a jet of `order`."""
    x, y = _locus(drive, g, trig, order)
    f = _jlin((1.0, _jmul(x, x)), (1.0, _jmul(y, y)))
    return (f[0] - g.rho2,) + f[1:]


def _even(drive, d, c):
    """|X|² = A² + B² − 2ABc of the wheel's curve at cos t = c (no W, no generating deviation)."""
    RZ, a = drive.wheel_pin_circle_radius, drive.eccentricity
    K = a * float(drive.z_pins) / RZ
    S = jnp.sqrt(1.0 + K * K - 2.0 * K * c)
    A, B = RZ - d / S, a - d * K / S
    return A * A + B * B - 2.0 * A * B * c


class Contact(eqx.Module):
    rotation: Float[Array, "*p zb"]  # θ_j − θ_theory, rad (finite; see `reachable`)
    phi: Float[Array, "*p zb"]  # flank parameter of the contact point
    reachable: Bool[Array, "*p zb"]  # the pin is not beyond the tooth tip
    interference: Bool[Array, "*p zb"]  # the pin is deeper than the tooth-space bottom at every rotation
    converged: Bool[Array, "*p zb"]
    residual: Float[Array, "*p zb"]  # ||X + W| − ρ| at the solution, mm


def _stop(tree):
    return jax.tree.map(lambda x: jax.lax.stop_gradient(x) if eqx.is_array(x) else x, tree)


def nominal_cosine(drive: CycloidPin, pins: PinLayout) -> Array:
    """cos t* of the error-free reducer's contact of every pin (depends on the drive and the input angle only)."""
    drive = _stop(drive)
    R, a = drive.pin_circle_radius, drive.eccentricity
    rho2 = R * R + a * a - 2.0 * R * a * jnp.cos(pins.phi)
    d = drive.wheel_pin_radius - drive.pin_radius
    c = jnp.cos(pins.phi)
    for _ in range(NOMINAL_STEPS):
        val, der = jax.jvp(lambda c: _even(drive, d, c), (c,), (jnp.ones_like(c),))
        val = val - rho2
        c = jnp.clip(c - val / jnp.where(der < 0, der, -1.0), -1.0, 1.0)
    return c


def contacts(drive: CycloidPin, err: CycloidErrors, pins: PinLayout, theta_T) -> Contact:
    """Rotation to contact of every pin against its own flank (module notes); any leading axes of `pins`."""
    # `materialise` stores the few arrays each stage hands on: without it XLA fuses every stage into its
    # consumers and recomputes the sines, cosines and square roots of the earlier stages many times.
    g = materialise(_geometry(drive, err, pins, theta_T))
    ds, gs = _stop((drive, g))
    ones = jnp.ones(g.side.shape)
    bar = materialise
    # Angles shared by a batch of reducers (0, π, the error-free contact): their sines and cosines once.
    zero, pi = jnp.zeros_like(ones), jnp.full_like(ones, math.pi)
    interference = _f(ds, gs, bar(_trig(ds, zero)))[0] > 0.0
    reachable = _f(ds, gs, bar(_trig(ds, pi)))[0] >= 0.0

    # 1. The error-free contact (shared by a batch of reducers), 2. one chord step in c with this reducer's errors.
    c0 = nominal_cosine(drive, pins)
    s0 = jnp.sqrt(jnp.maximum(1.0 - c0 * c0, 0.0))
    t0 = atan2(s0, c0)
    c0, t0, trig0 = bar((c0, t0, _trig(ds, t0)))
    f0 = _f(ds, gs, trig0)[0]
    slope = jax.jvp(lambda c: _even(ds, gs.d, c), (c0,), (ones,))[1]
    c1 = jnp.clip(c0 - f0 / jnp.where(slope < 0, slope, -1.0), -1.0, 1.0)
    t = atan2(jnp.sqrt(jnp.maximum(1.0 - c1 * c1, 0.0)), c1)
    lo = jnp.where(f0 <= 0, t0, 0.0)  # f(lo) ≤ 0 ≤ f(hi)
    hi = jnp.where(f0 > 0, t0, math.pi)
    t, lo, hi = materialise((t, lo, hi))
    # 3. Steps to the increasing root of the local quadratic model of f (Newton's step with the curvature: it
    #    stays well defined at a fold, where f′ → 0), within the bracket; bisection when it leaves it.
    for _ in range(T_STEPS):
        # f, f′, f″ at t: the sines once (stored), the derivatives written out.
        trig = bar(_trig(ds, t))
        val, d1, d2 = bar(_f(ds, gs, trig, 2))
        lo = jnp.where(val <= 0, jnp.maximum(lo, t), lo)
        hi = jnp.where(val > 0, jnp.minimum(hi, t), hi)
        disc = d1 * d1 - 2.0 * val * d2
        sq = jnp.sqrt(jnp.maximum(disc, 0.0))
        # Δ = (−f′ + √disc)/f″ = −2f/(f′ + √disc), whichever form does not cancel; no real root: Newton's step.
        den = jnp.where(d1 >= 0, d1 + sq, d2)
        num = jnp.where(d1 >= 0, -2.0 * val, sq - d1)
        step = jnp.where(disc >= 0, num / jnp.where(den != 0, den, 1.0), -val / jnp.where(d1 != 0, d1, 1.0))
        tn = t + step
        # (A step below 1e-6 rad is taken as it is: near a root the bracket's ends carry rounding noise.)
        inside = ((tn >= lo) & (tn <= hi)) | (jnp.abs(step) <= 1e-6)
        tn = jnp.where(inside & jnp.isfinite(tn), tn, 0.5 * (lo + hi))
        t, lo, hi = materialise((jnp.where(val == 0, t, tn), lo, hi))
    t = jax.lax.stop_gradient(jnp.where(interference, 0.0, jnp.where(reachable, t, math.pi)))

    # The final evaluation is differentiated; t enters with its implicit derivative (zero in value).
    trig = bar(_trig(ds, t))
    (x, xt), (y, yt) = _locus(drive, g, trig, 1)
    x, y, xt, yt = bar((x, y, xt, yt))
    r2 = x * x + y * y
    f = r2 - g.rho2
    der = jax.lax.stop_gradient(2.0 * (x * xt + y * yt))
    ok = (jnp.abs(der) > 1e-12) & reachable & ~interference & jnp.isfinite(f)
    dt = jnp.where(ok, -(f - jax.lax.stop_gradient(f)) / jnp.where(ok, der, 1.0), 0.0)
    drot = jax.lax.stop_gradient(-(x * yt - y * xt) / r2)  # d rotation / dt = −d arg(X + W)/dt
    rotation = atan2(g.fy * x - g.fx * y, g.fx * x + g.fy * y) + drot * dt
    resid = jax.lax.stop_gradient(jnp.abs(jnp.sqrt(r2) - jnp.sqrt(g.rho2)))
    converged = (resid < RESIDUAL_TOL_MM) | ~reachable | interference
    return Contact(rotation, g.side * (t + dt), reachable, interference, converged, resid)


__all__ = ("NOMINAL_STEPS", "RESIDUAL_TOL_MM", "T_STEPS", "Contact", "atan2", "contacts", "nominal_cosine", "sincos")
