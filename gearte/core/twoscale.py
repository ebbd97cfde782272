"""Extrema of a slow TE plus one fast line (e.g. a tooth-mesh term), cheaply and with a certificate.

`extrema` samples the whole hyper-period at 16 points per period of the *fastest*
order. When one line is far faster than all the others — a harmonic drive's
tooth-mesh term at z₂ times the input speed (even z₂) next to eccentricity terms at 1,
2 and 2 z₂/z₁ — that grid is mostly spent on a term whose amplitude is known in
closed form. Here the signal is split as ``F = S + b sin(k τ + φ)`` with S the slow
part and b the amplitude of the fast order k, and:

1. the best few local maxima of S are located exactly, as `extrema` does (grid of
   16 points per period of S's highest order, then Newton's method);
2. from each, Newton's method on F starts at the point itself and at the crests
   of the fast line nearest to it; the best point visited is the maximum of F.

Bounds that hold whatever S is: ``max F ≤ max S + b`` (each part at its maximum),
and ``max F ≥ max S + b − ½ D₂ (π/k)²`` where D₂ = Σ k_j² |c_j| bounds |S''| (the
crest of the fast line nearest to the maximum of S is at most π/k away, where S
has dropped by at most ½ D₂ (π/k)²). The value found always lies between them, so
``(max S + b) − (value found)`` is a *certified* bound on its error, returned per
signal as `max_gap` (and `min_gap`); it is zero when there is no fast line. In
practice the value is the exact maximum (tested against `extrema` to ~1e-12), and
the gap is the small, harmless amount by which no crest of the fast line meets the
maximum of S exactly.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .extrema import extrema
from .grid import _basis, _candidates, _derivatives, _grid_values, grid_size
from .signal import TESignal, evaluate
from .units import TWO_PI as _TWO_PI
from .validate import as_int


class TwoScaleExtrema(eqx.Module):
    """Maximum and minimum of ``slow + fast line`` over the hyper-period, with certified error bounds.

    `max`, `min` in rad of output angle; `theta_max`, `theta_min` input angles (rad);
    `max_gap`, `min_gap` (rad, ≥ 0): the true maximum lies in ``[max, max + max_gap]``
    and the true minimum in ``[min − min_gap, min]``.
    """

    max: Float[Array, "*batch"]
    min: Float[Array, "*batch"]
    theta_max: Float[Array, "*batch"]
    theta_min: Float[Array, "*batch"]
    max_gap: Float[Array, "*batch"]
    min_gap: Float[Array, "*batch"]


def _split(signal: TESignal, j_fast: int) -> tuple[TESignal, Array, Array]:
    keep = [j for j in range(len(signal.orders)) if j != j_fast]
    slow = TESignal(
        offset=signal.offset,
        cos_coef=signal.cos_coef[..., keep],
        sin_coef=signal.sin_coef[..., keep],
        orders=tuple(signal.orders[j] for j in keep),
        fundamental=signal.fundamental,
    )
    return slow, signal.cos_coef[..., j_fast], signal.sin_coef[..., j_fast]


def _newton_best(signal: TESignal, tau: Array, sign: float, steps: int, max_step: float) -> tuple[Array, Array]:
    """Safeguarded Newton ascent of ``sign · f`` from every τ in the last axis; best point visited overall."""
    taus, vals = [], []
    for n in range(steps + 1):
        f, f1, f2 = _derivatives(signal, tau)
        taus.append(tau)
        vals.append(sign * f)
        if n == steps:
            break
        concave = sign * f2 < 0.0
        step = jnp.where(concave, -f1 / jnp.where(concave, f2, 1.0), sign * jnp.sign(f1) * max_step)
        tau = tau + jnp.clip(step, -max_step, max_step)
    t = jnp.concatenate(taus, axis=-1)
    v = jnp.concatenate(vals, axis=-1)
    i = jnp.argmax(v, axis=-1)[..., None]
    return jnp.take_along_axis(t, i, axis=-1)[..., 0], sign * jnp.take_along_axis(v, i, axis=-1)[..., 0]


def _one_side(
    signal: TESignal, slow: TESignal, bc: Array, bs: Array, k_fast: int, sign: float, candidates: int, newton_steps: int
) -> tuple[Array, Array, Array]:
    """τ and value of the maximum (sign = +1) or minimum (sign = −1) of F, and the slow part's extreme value."""
    if slow.orders:
        m = grid_size(slow.orders, 16)
        block = 8
        h = _TWO_PI / m
        cos_b, sin_b = _basis(slow.orders, m, wrap=True)
        g = _grid_values(slow, cos_b, sin_b)
        idx, delta = _candidates(g, sign, block, candidates)
        tau_s = (idx.astype(delta.dtype) + delta) * h
        # Exact local extrema of the slow part (its own Newton steps, one per candidate).
        ts, vs = [], []
        for _ in range(3):
            f, f1, f2 = _derivatives(slow, tau_s)
            ts.append(tau_s)
            vs.append(sign * f)
            concave = sign * f2 < 0.0
            tau_s = tau_s + jnp.clip(jnp.where(concave, -f1 / jnp.where(concave, f2, 1.0), 0.0), -h, h)
        f, _, _ = _derivatives(slow, tau_s)
        ts.append(tau_s)
        vs.append(sign * f)
        stack_t, stack_v = jnp.stack(ts, axis=-1), jnp.stack(vs, axis=-1)
        best = jnp.argmax(stack_v, axis=-1)[..., None]
        tau_s = jnp.take_along_axis(stack_t, best, axis=-1)[..., 0]  # (..., c) refined candidates
        slow_best = sign * jnp.max(jnp.take_along_axis(stack_v, best, axis=-1)[..., 0], axis=-1)
    else:
        tau_s = jnp.zeros(signal.offset.shape + (1,))
        slow_best = signal.offset
    # Crests (sign = +1) or troughs (−1) of b sin(k τ + φ), φ = atan2(bc, bs): k τ + φ = ±π/2 + 2πn.
    phi = jnp.arctan2(bc, bs)[..., None]
    target = 0.5 * math.pi * sign
    n0 = jnp.round((k_fast * tau_s + phi - target) / _TWO_PI)
    starts = [tau_s] + [(target - phi + _TWO_PI * (n0 + d)) / k_fast for d in (-1.0, 0.0, 1.0)]
    tau0 = jnp.concatenate(starts, axis=-1)
    tau, val = _newton_best(signal, tau0, sign, newton_steps, math.pi / (2 * k_fast))
    return tau, val, slow_best


def extrema_two_scale(signal: TESignal, *, fast_order: int | None = None, candidates: int = 8, newton_steps: int = 4) -> TwoScaleExtrema:
    """Exact extrema of a TE whose highest order is one fast line, without a grid at that line's rate.

    **Arguments:**

    - `signal`: the TE (rad); any batch shape.
    - `fast_order`: the order (an entry of ``signal.orders``) of the fast line; default the
      highest order. It must be the highest order.
    - `candidates`: local extrema of the slow part from which the search starts.
    - `newton_steps`: Newton iterations on the full signal from each start.

    **Returns:** a `TwoScaleExtrema` (rad; input angles in rad) with certified error bounds.
    """
    candidates = as_int("extrema_two_scale: candidates", candidates, minimum=1)
    newton_steps = as_int("extrema_two_scale: newton_steps", newton_steps, minimum=0)
    if not signal.orders:
        zero = jnp.zeros_like(signal.offset)
        return TwoScaleExtrema(signal.offset, signal.offset, zero, zero, zero, zero)
    if fast_order is None:
        fast_order = max(signal.orders)
    if fast_order not in signal.orders:
        raise ValueError(f"extrema_two_scale: fast_order {fast_order} is not one of the signal's orders {signal.orders}")
    if fast_order != max(signal.orders):
        raise ValueError(f"extrema_two_scale: fast_order {fast_order} must be the highest order ({max(signal.orders)})")
    f0 = float(signal.fundamental)
    frozen = jax.lax.stop_gradient(signal)
    slow, bc, bs = _split(frozen, signal.orders.index(fast_order))
    b = jnp.hypot(bc, bs)
    out = {}
    for name, sign in (("max", 1.0), ("min", -1.0)):
        tau, val, slow_best = _one_side(frozen, slow, bc, bs, fast_order, sign, candidates, newton_steps)
        theta = jax.lax.stop_gradient(jnp.mod(tau, _TWO_PI) / f0)
        # Re-evaluate with live coefficients (envelope theorem: exact gradients, as in `extrema`).
        out[name] = evaluate(signal, theta)
        out["theta_" + name] = theta
        out[name + "_gap"] = jax.lax.stop_gradient(jnp.maximum(sign * (slow_best + sign * b - val), 0.0))
    return TwoScaleExtrema(
        max=out["max"],
        min=out["min"],
        theta_max=out["theta_max"],
        theta_min=out["theta_min"],
        max_gap=out["max_gap"],
        min_gap=out["min_gap"],
    )


def fast_line_order(signal: TESignal, *, separation: int = 8) -> int | None:
    """The highest order if it is at least `separation` times the next one (a fast line), else None."""
    if len(signal.orders) < 2:
        return None
    top, nxt = signal.orders[-1], signal.orders[-2]
    return top if top >= separation * nxt else None


def extrema_auto(signal: TESignal) -> TwoScaleExtrema:
    """`extrema_two_scale` when the signal has a fast line (see `fast_line_order`), else `extrema` (gaps 0)."""
    k = fast_line_order(signal)
    if k is not None:
        return extrema_two_scale(signal, fast_order=k)
    e = extrema(signal)
    zero = jnp.zeros_like(e.max)
    return TwoScaleExtrema(e.max, e.min, e.theta_max, e.theta_min, zero, zero)
