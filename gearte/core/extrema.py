"""Exact extrema of a TE signal over its hyper-period, and the peak, peak-to-peak, RMS and spectrum functions.

Exact extrema (≤ 1e-6 relative, in practice ~1e-14): the signal is sampled in float32 on a
grid of ``oversample`` points per period of its highest order; the blocks (half the shortest
period) with the best grid maxima are re-evaluated in float64 and refined by safeguarded Newton
steps on the trigonometric polynomial itself, round after round until a rigorous bound (grid
spacing, curvature and float32 rounding) shows that no unrefined block can hold a better
extremum (see `_locate_extrema`); a refined block whose window shows a second hump that could hold more, or whose
best point a Newton step would still raise (a flat peak), is refined again from every point of its window.

A very flat top (f″ near zero), or two humps closer than a grid step (the grid's maximum between them, where
f″ > 0 and Newton's method takes no step), leaves a Newton step from the best point a gain to make: such a block is
refined again from every point of its window (`FLAT_GAIN`). On constructed families of such peaks (orders 1 and 3,
and 1, 64 and 192, with β near −1/9 in cos u + β cos 3u plus a small tilt) 41 of 400 and 16 of 240 had been off by
more than 1e-6 of the span (up to 5.8e-5), whatever `newton_steps`; none of 2,080 now (4e-7 at worst;
tests/test_extrema_humps.py). Random signals like the examples' are within 1e-6 in the tests
(tests/test_metrics.py) and 3e-11 at worst on 400 random signals of orders up to 40. The
search runs on stopped gradients; the value is then re-evaluated at the located
angle, so by the envelope theorem its gradient is exact and finite, also at
zero amplitude and at ties (where it is a valid subgradient).

For objectives that an optimiser should see as smooth, use `smooth_peak`.
"""

from __future__ import annotations

import functools
from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .grid import _argmax, _basis, _check_orders, _cis_powers, _cis_small, _grid_values, _top, grid_size
from .precision import require_x64
from .signal import TESignal, evaluate
from .units import TWO_PI as _TWO_PI
from .validate import as_float, as_int, is_traced


class Extrema(eqx.Module):
    """Maximum and minimum of a TE signal over its whole hyper-period.

    `max`, `min` in rad of output angle; `theta_max`, `theta_min` are the input
    angles (rad, within ``[0, 2π/f₀)``) where they occur.
    """

    max: Float[Array, "*batch"]
    min: Float[Array, "*batch"]
    theta_max: Float[Array, "*batch"]
    theta_min: Float[Array, "*batch"]


#: Newton steps (at least) of the later rounds of `_locate_extrema`, which refine a block from every point of its
#: window: a block the first round reopens holds a flat peak.
MULTI_START_NEWTON_STEPS = 4

#: A block refined in the first round is refined again from every point of its window where a Newton step from its
#: best point would still gain more than this, relative to the signal's scale Σ |a_k| + |b_k| (a flat top).
FLAT_GAIN = 1e-8

#: Blocks of a row refined in each later round of `_locate_extrema` (the first round refines `candidates`), or one in
#: 1,024 of its blocks where that is more (a round's selection costs all of a row's blocks).
LATER_CANDIDATES = 16


#: Signals of at most this many orders have their float32 grid's block maxima and minima kept point by point as the
#: grid is made (one elementwise pass; `_locate_extrema`), more orders have the grid stored and reduced over its blocks.
#: The stored grid and its reductions (XNNPACK's, over the 8 points of a block) took three passes over memory: the
#: example's 50,000 signals (3 orders) 1.8-2.1 µs per signal that way, 1.3-1.7 point by point; 8 orders, the same or
#: a little less. For 16 orders XLA computes the whole grid once for the maxima and once more for the minima: 4.4 µs
#: per signal stored against 6.0 (16 orders to 21), 2.2 ms against 5.2 (16 orders to 16,384).
POINTWISE_ORDERS = 8
#: ... and at most this many terms (orders × points per block) are unrolled that way: 8 orders at 64 points per period
#: (32 per block) took 7.6 s to compile instead of 1.4, at 128 points 53 s.
POINTWISE_TERMS = 64


def _locate_extrema(signal: TESignal, oversample: int, candidates: int, newton_steps: int) -> tuple[Array, Array]:
    """τ of the maximum and of the minimum of the signal over [0, 2π), certified.

    1. **Grid, float32.** The signal less its offset c₀ on ``m`` grid points (`grid_size`), evaluated in
       float32 from float64 coefficients; its maximum and minimum per block of half the shortest period. The
       float32 rounding error is bounded by ``(2K + 4) u (Σ|a_k| + |b_k|)`` (K orders, u = 2⁻²⁴) and added to
       the certification margin below, so float32 ranks blocks but never decides; c₀ is added in float64.
    2. **Refinement, float64.** The maximum and the minimum are searched as one problem over 2B
       rows (row r + B is −row r). Each round takes the `candidates` best-ranked unrefined blocks
       of a row, re-evaluates those blocks (and one neighbour each side) in float64, starts from
       the parabola vertex at each block's best point and takes safeguarded Newton steps on the
       trigonometric polynomial written about that grid point (local coefficients from the
       tabulated cos kτᵢ, sin kτᵢ; cos kt, sin kt of the small offset t from a Taylor series and
       repeated squaring). Every point visited is an exact evaluation and the best one wins.
    3. **Certificate.** The true maximum lies within h/2 of a grid point and has f′ = 0, so it
       exceeds that block's grid maximum by at most h²/8 · max|f″| ≤ h²/8 · Σ k²|c_k| (+ the
       float32 bound). Rounds continue until no unrefined block can hold a better extremum; one
       round settles almost every signal, near-ties take more. The later rounds take only the rows still
       uncertified, 32 at a time, and `LATER_CANDIDATES` blocks of each: a signal with a fast order of large
       amplitude (large coprime tooth counts) has tens of humps within the margin of its maximum. A block
       refined in the first round from its best point whose float64 window has another local maximum, at least
       two points away, that could hold more (a flat peak with two humps), or whose best point a Newton step would
       still raise by more than `FLAT_GAIN` of the signal's scale (a flat top, two humps closer than a grid step),
       is refined again in a later round from every point of its window, with at least
       `MULTI_START_NEWTON_STEPS` Newton steps.
    """
    orders = signal.orders
    n_orders = len(orders)
    m = grid_size(orders, oversample)
    block = max(1, oversample // 2)
    nb = m // block
    h = _TWO_PI / m
    k = np.asarray(orders, dtype=np.float64)
    # (K, m), constants of the compiled search (computed in it, XLA would fuse the sines into the grid's sum, once per
    # sample: four times slower).
    cos_np, sin_np = _basis(orders, m)
    cos_tab, sin_tab = jnp.asarray(cos_np), jnp.asarray(sin_np)
    batch = signal.offset.shape
    a = signal.cos_coef.reshape(-1, n_orders)
    b = signal.sin_coef.reshape(-1, n_orders)
    off = signal.offset.reshape(-1)
    n = a.shape[0]
    rows = 2 * n

    # 1. float32 grid (unrolled over orders: an elementwise sum whose order never changes with batch size), without the
    # offset, which ranks no block: its rounding would swamp the oscillation of a signal far from zero. For a few
    # orders (`POINTWISE_ORDERS`) each block's maximum and minimum are kept point by point as the grid is made (the
    # grid never stored); for more, the grid is stored and reduced over its blocks. The float32 values of either way lie
    # within the rounding bound below (XLA may contract the sums' products differently).
    f32 = jnp.float32
    if n_orders <= POINTWISE_ORDERS and n_orders * block <= POINTWISE_TERMS:
        a32, b32 = a.astype(f32), b.astype(f32)
        # The float32 tables by point of the block, (K, block, nb): each point's values of every block contiguous.
        c32, s32 = (jnp.asarray(x.astype(np.float32).reshape(n_orders, nb, block).transpose(0, 2, 1).copy()) for x in (cos_np, sin_np))
        points = []  # the grid's i-th point of every block (n × nb)
        for i in range(block):
            gi = jnp.zeros((n, nb), dtype=f32)
            for j in range(n_orders):
                gi = gi + a32[:, j, None] * c32[j, i] + b32[:, j, None] * s32[j, i]
            points.append(gi)
        hi, lo = functools.reduce(jnp.maximum, points), functools.reduce(jnp.minimum, points)
    else:
        g = jnp.zeros((n, m), dtype=f32)
        for j in range(n_orders):
            g = g + a[:, j, None].astype(f32) * cos_tab[j].astype(f32) + b[:, j, None].astype(f32) * sin_tab[j].astype(f32)
        g = g.reshape(n, nb, block)
        hi, lo = jnp.max(g, axis=-1), jnp.min(g, axis=-1)
    top = jnp.concatenate([hi, -lo])  # (2B, nb), float32, less the offset

    sgn = jnp.concatenate([jnp.ones(n, dtype=a.dtype), -jnp.ones(n, dtype=a.dtype)])
    a2 = sgn[:, None] * jnp.concatenate([a, a])
    b2 = sgn[:, None] * jnp.concatenate([b, b])
    off2 = sgn * jnp.concatenate([off, off])
    u32 = float(np.finfo(np.float32).eps) / 2.0
    rounding = (2 * n_orders + 4) * 1.01 * u32 * jnp.sum(jnp.abs(a2) + jnp.abs(b2), axis=-1)
    margin = h * h / 8.0 * jnp.sum(k * k * jnp.sqrt(a2**2 + b2**2), axis=-1) + rounding
    c = min(candidates, nb)
    cos_pt, sin_pt = cos_tab.T, sin_tab.T  # (m, K): cos kτᵢ, sin kτᵢ
    # cos kτ_s, sin kτ_s at the offsets s h, s = 0 … block + 1, of a block's window from its first point.
    ks = np.outer(np.arange(block + 2) * h, k)
    cos_w, sin_w = jnp.asarray(np.cos(ks)), jnp.asarray(np.sin(ks))  # (block + 2, K)

    def refine(sel, a_r, b_r, off_r, multi: bool):
        """Refine the blocks `sel` (r, c) of the rows given: (blocks taken, τ, value, and each block's best value away
        from the hump refined, or its own where a Newton step would still raise it) per row. `multi`: Newton's method
        from every point of the block (a block may hold two humps of a flat peak), else from the block's best point
        alone."""
        p0 = (sel * block - 1) % m  # the window starts one point before the block
        cp, sp = cos_pt[p0], sin_pt[p0]  # (r, c, K)
        # f(τ_{p0} + t) = c₀ + Σ A_k cos kt + B_k sin kt  (coefficients about the window's first point).
        # Sums over the few orders are unrolled: elementwise fusions, far cheaper on the CPU than reductions.
        big_a = [a_r[:, None, q] * cp[..., q] + b_r[:, None, q] * sp[..., q] for q in range(n_orders)]
        big_b = [b_r[:, None, q] * cp[..., q] - a_r[:, None, q] * sp[..., q] for q in range(n_orders)]
        w = off_r[:, None, None]
        for q in range(n_orders):
            w = w + big_a[q][..., None] * cos_w[:, q] + big_b[q][..., None] * sin_w[:, q]  # float64 window
        inner = w[..., 1:-1]
        points = jnp.arange(block)
        rest = None
        if multi:
            # Every point of the block a start: two humps closer than a grid step show one grid maximum between them,
            # and the points beyond them lead to each.
            fm, fc, fp = w[..., :-2], inner, w[..., 2:]  # (r, c, block)
            expand = lambda x: x[..., None]  # (r, c) → (r, c, 1)
            first = points
        else:
            j = _argmax(inner)  # the block's best point, float64
            # The block's best local maximum of the window at least two points from its best one: a second hump (a
            # dip between) that the refinement from one start below does not reach; such a block is refined again,
            # from every start, where that hump could hold more.
            hump = (inner >= w[..., :-2]) & (inner >= w[..., 2:]) & (jnp.abs(points - j[..., None]) >= 2)
            rest = jnp.max(jnp.where(hump, inner, -jnp.inf), axis=-1)
            fm = jnp.take_along_axis(w, j[..., None], axis=-1)[..., 0]
            fc = jnp.take_along_axis(w, j[..., None] + 1, axis=-1)[..., 0]
            fp = jnp.take_along_axis(w, j[..., None] + 2, axis=-1)[..., 0]
            expand = lambda x: x
            first = j
        d1 = fm - fp
        denom = fm - 2.0 * fc + fp
        curved = denom < 0.0
        t = h * (1.0 + first.astype(w.dtype) + jnp.where(curved, jnp.clip(0.5 * d1 / jnp.where(curved, denom, -1.0), -0.5, 0.5), 0.0))
        # A block refined again holds a flat peak (two humps), where Newton's method converges slowly: more steps
        # (these rounds are rare: a few rows in ten thousand).
        steps = max(newton_steps, MULTI_START_NEWTON_STEPS) if multi else newton_steps

        def newton(t, best_t, best_v, best_g, last: bool):
            """Evaluate at t, keep the best point visited (the first of equals) and, in the first round, the gain a
            Newton step from it would predict (infinite where the signal is not concave there), and take a Newton
            step."""
            c1, s1 = _cis_small(t)
            ck, sk = _cis_powers(c1, s1, orders)  # (r, c, K), or (r, c, block, K) from every start
            fv, f1, f2 = expand(off_r[:, None]), 0.0, 0.0
            for q, kq in enumerate(orders):
                even = expand(big_a[q]) * ck[..., q] + expand(big_b[q]) * sk[..., q]
                fv = fv + even
                f1 = f1 + kq * (expand(big_b[q]) * ck[..., q] - expand(big_a[q]) * sk[..., q])
                f2 = f2 - kq * kq * even
            concave = f2 < 0.0
            step = jnp.clip(jnp.where(concave, -f1 / jnp.where(concave, f2, 1.0), 0.0), -h, h)
            gain = None
            if not multi:
                # The gain of the (safeguarded) step by the quadratic model, counted where its end lies in the block
                # (to half a grid step beyond its end points): a hump beyond it is another block's, which the
                # certificate bounds.
                inside = (t + step >= 0.5 * h) & (t + step <= (block + 0.5) * h)
                gain = jnp.where(concave, f1 * step + 0.5 * f2 * step * step, jnp.where(f1 == 0.0, 0.0, jnp.inf))
                gain = jnp.where(inside, gain, 0.0)
            if best_v is None:
                best_v, best_g = fv, gain
            else:
                better = fv > best_v
                best_t, best_v = jnp.where(better, t, best_t), jnp.where(better, fv, best_v)
                best_g = None if gain is None else jnp.where(better, gain, best_g)
            if not last:
                t = t + step
            return t, best_t, best_v, best_g

        if multi:
            # A loop, not unrolled: XLA would fuse every step into one kernel of thousands of operations, which LLVM
            # took minutes to compile for many orders (16 orders of up to 16,384 periods: over ten minutes; 2 s now).
            best_v, best_g = jnp.full(t.shape, -jnp.inf, dtype=t.dtype), None
            t, best_t, best_v, _ = jax.lax.fori_loop(0, steps, lambda _, tv: newton(*tv, last=False), (t, t, best_v, None))
            _, best_t, best_v, _ = newton(t, best_t, best_v, None, last=True)
        else:
            # Unrolled (one or two steps): the steps fuse into one kernel, and no stacking of the steps, which XLA
            # would fuse by recomputing every step once per output.
            best_t, best_v, best_g = t, None, None
            for step_no in range(steps + 1):
                t, best_t, best_v, best_g = newton(t, best_t, best_v, best_g, last=step_no == steps)
        assert best_v is not None
        at = expand(p0.astype(w.dtype)) * h
        flat_v, flat_t = best_v.reshape(best_v.shape[0], -1), (best_t + at).reshape(best_v.shape[0], -1)
        best = _argmax(flat_v)[:, None]  # the best candidate (the first of equals)
        tau_new = jnp.take_along_axis(flat_t, best, axis=-1)[:, 0]
        v_new = jnp.take_along_axis(flat_v, best, axis=-1)[:, 0]
        if multi:  # a scatter: the comparison below would hold (rows, c, blocks) booleans, gigabytes for large c
            taken = jnp.zeros((sel.shape[0], nb), dtype=bool).at[jnp.arange(sel.shape[0])[:, None], sel].set(True)
        else:
            assert best_g is not None and rest is not None
            taken = jnp.any(jnp.arange(nb) == sel[..., None], axis=-2)
            # A block whose best point a Newton step would still raise (a flat top: f″ near zero, or two humps closer
            # than a grid step with the best point in the dip between them) is reopened like a second hump, ranked
            # by its own value.
            scale = jnp.sum(jnp.abs(a_r) + jnp.abs(b_r), axis=-1)  # the offset changes no shape
            unsettled = best_g > FLAT_GAIN * scale[:, None]
            # Reopened where the gain a step predicts (twice it: a quartic top's true gain is 1.5 times the
            # prediction; at most the margin) could take the block past the row's best value.
            could = best_v + jnp.minimum(2.0 * best_g, margin[:, None]) > v_new[:, None]
            rest = jnp.where(unsettled & could, jnp.maximum(rest, best_v), rest)
        return taken, tau_new, v_new, rest

    # Round one: every row, each block from its best point; the row's best block after them bounds the others.
    best_top, picks = _top(top, c + 1)  # (one fewer where every block is a candidate)
    sel = picks[:, :c]
    next_top = best_top[:, c] if c < nb else jnp.full((rows,), -jnp.inf, dtype=top.dtype)
    taken, tau, val, rest = refine(sel, a2, b2, off2, multi=False)
    assert rest is not None
    # A refined block whose second hump could still hold more (a flat peak) stays open, ranked by that hump, for the
    # later rounds, which refine from every point of a block with more Newton steps. Kept per row and
    # candidate, not scattered into the (rows × blocks) arrays: the blocks reopened are merged into them only for
    # the rows a later round takes.
    reopen = rest + margin[:, None] > val[:, None]

    def bound_of(remaining, top_r, off_r):
        return jnp.max(jnp.where(remaining, top_r, -jnp.inf), axis=-1).astype(val.dtype) + off_r

    # Each row's bound (the best an unrefined block or a reopened hump could hold, less the margin), computed once
    # for every row and then only for the rows a later round takes: a round costs those rows, not the batch.
    bound = jnp.maximum(next_top.astype(val.dtype) + off2, jnp.max(jnp.where(reopen, rest, -jnp.inf), axis=-1))
    state = (~taken, tau, val, reopen, bound)

    # Later rounds (near-ties and flat peaks): only the rows still uncertified, `few` at a time, gathered, refined
    # and scattered back, so a rare row does not cost a round of the batch; each takes `LATER_CANDIDATES` blocks of a
    # row (a signal with a fast order of large amplitude has many near-tied humps: tens of blocks to refine).
    few = min(rows, 32)
    c_later = min(max(LATER_CANDIDATES, nb // 1024), nb)

    def uncertified(st):
        return st[4] + margin > st[2]

    def later_round(st):
        remaining, best_tau, best_val, reopen, bound = st
        pick = jnp.nonzero(uncertified(st), size=few, fill_value=rows)[0]  # rows (index `rows` = none)
        safe = jnp.minimum(pick, rows - 1)
        # The picked rows' reopened blocks join their unrefined ones, ranked by their second hump (or their value).
        sub = jnp.arange(few)[:, None]
        rem_p = remaining[safe].at[sub, sel[safe]].max(reopen[safe])
        reopened = (rest[safe] - off2[safe][:, None]).astype(top.dtype)
        top_p = top[safe].at[sub, sel[safe]].set(jnp.where(reopen[safe], reopened, top[safe][sub, sel[safe]]))
        sel_p = jax.lax.top_k(jnp.where(rem_p, top_p, -jnp.inf), c_later)[1].astype(int)
        taken, t_new, v_new, _ = refine(sel_p, a2[safe], b2[safe], off2[safe], multi=True)
        better = v_new > best_val[safe]
        rem_p = rem_p & ~taken
        remaining = remaining.at[pick].set(rem_p, mode="drop")
        reopen = reopen.at[pick].set(False, mode="drop")
        bound = bound.at[pick].set(bound_of(rem_p, top_p, off2[safe]), mode="drop")
        best_tau = best_tau.at[pick].set(jnp.where(better, t_new, best_tau[safe]), mode="drop")
        best_val = best_val.at[pick].set(jnp.where(better, v_new, best_val[safe]), mode="drop")
        return remaining, best_tau, best_val, reopen, bound

    state = jax.lax.while_loop(lambda st: jnp.any(uncertified(st)), later_round, state)
    tau = state[1]
    return tau[:n].reshape(batch), tau[n:].reshape(batch)


# Compiled once per signal structure (orders) and options, also when called eagerly: the
# certification loop would otherwise be compiled afresh at every eager call.
_locate_extrema_jit = eqx.filter_jit(_locate_extrema)


def extrema(signal: TESignal, *, oversample: int = 16, candidates: int = 2, newton_steps: int = 1) -> Extrema:
    """Exact maximum and minimum of the TE over the whole hyper-period.

    **Arguments:**

    - `signal`: the TE (rad); any batch shape.
    - `oversample`: grid points per period of the highest order (≥ 8).
    - `candidates`: grid maxima refined by Newton's method.
    - `newton_steps`: Newton iterations per candidate (≥ 0; 0 keeps the grid's parabolic estimate).

    **Returns:** an `Extrema` (rad; input angles in rad).
    """
    require_x64()
    oversample = as_int("extrema: oversample", oversample, minimum=8)  # the candidate ranking needs 8 points per period
    candidates = as_int("extrema: candidates", candidates, minimum=1)
    newton_steps = as_int("extrema: newton_steps", newton_steps, minimum=0)
    _check_orders(signal, oversample, what="extrema")
    f0 = float(signal.fundamental)
    if not signal.orders:
        zero = jnp.zeros_like(signal.offset)
        return Extrema(max=signal.offset, min=signal.offset, theta_max=zero, theta_min=zero)
    frozen = jax.lax.stop_gradient(signal)
    tau_max, tau_min = _locate_extrema_jit(frozen, oversample, candidates, newton_steps)
    tau_max, tau_min = jnp.mod(tau_max, _TWO_PI), jnp.mod(tau_min, _TWO_PI)
    theta_max = jax.lax.stop_gradient(tau_max / f0)
    theta_min = jax.lax.stop_gradient(tau_min / f0)
    # Re-evaluate with live coefficients: envelope theorem → exact, finite gradients.
    return Extrema(max=evaluate(signal, theta_max), min=evaluate(signal, theta_min), theta_max=theta_max, theta_min=theta_min)


def peak(signal: TESignal, **kwargs) -> Float[Array, "*batch"]:
    """Peak ``max_θ |TE(θ)|`` over the hyper-period (rad); includes constant offsets."""
    e = extrema(signal, **kwargs)
    return jnp.maximum(e.max, -e.min)


def peak_to_peak(signal: TESignal, **kwargs) -> Float[Array, "*batch"]:
    """Peak-to-peak ``max TE − min TE`` over the hyper-period (rad), the ISO / catalogue sense."""
    e = extrema(signal, **kwargs)
    return e.max - e.min


def _safe_sqrt(x: Array) -> Array:
    # sqrt with a finite (zero) gradient at 0, e.g. for all-zero amplitudes.
    pos = x > 0.0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, x, 1.0)), 0.0)


def rms(signal: TESignal) -> Float[Array, "*batch"]:
    """Root mean square of the TE over the hyper-period (rad), exact by Parseval."""
    power = signal.offset**2 + 0.5 * jnp.sum(signal.cos_coef**2 + signal.sin_coef**2, axis=-1)
    return _safe_sqrt(power)


class Spectrum(eqx.Module):
    """Amplitude spectrum of a TE signal: one line per distinct frequency.

    Line j is ``amplitude_j · sin(freq_j θ + phase_j)``; `offset` is the constant part (rad).
    """

    amplitude: Float[Array, "*batch K"]
    phase: Float[Array, "*batch K"]
    offset: Float[Array, "*batch"]
    freq: tuple[Fraction, ...] = eqx.field(static=True)


def spectrum(signal: TESignal) -> Spectrum:
    """Line spectrum (rad amplitudes; frequencies as multiples of the input speed)."""
    amp = _safe_sqrt(signal.cos_coef**2 + signal.sin_coef**2)
    phase = jnp.arctan2(signal.cos_coef, signal.sin_coef)
    return Spectrum(amplitude=amp, phase=phase, offset=signal.offset, freq=signal.frequencies)


def smooth_peak(signal: TESignal, *, width: float | Float[Array, ""], oversample: int = 16) -> Float[Array, "*batch"]:
    """Smooth approximation of the peak |TE| for optimisers (rad).

    ``width · log Σ_grid (e^{TE/width} + e^{−TE/width})`` over the hyper-period grid:
    it lies between the grid peak and the grid peak + ``width · log(2M)`` (an upper bound of the grid peak, not of
    the exact peak, which can lie above the grid's by its sampling error), and is infinitely differentiable in the
    coefficients. Report the exact `peak`.

    **Arguments:**

    - `width`: smoothing width, rad (e.g. 1 % of the expected peak); a number, or a traced value (checked > 0 only
      where it is a number).
    - `oversample`: grid points per period of the highest order.
    """
    if not is_traced(width):  # a traced width: the caller's to check
        as_float("smooth_peak: width", width, positive=True, hint="rad")
    oversample = as_int("smooth_peak: oversample", oversample, minimum=2)
    require_x64()
    _check_orders(signal, oversample, what="smooth_peak")
    if not signal.orders:
        return width * jnp.logaddexp(signal.offset / width, -signal.offset / width)
    m = grid_size(signal.orders, oversample)
    cos_b, sin_b = _basis(signal.orders, m)
    f = _grid_values(signal, cos_b, sin_b)
    both = jnp.concatenate([f, -f], axis=-1) / width
    return width * jax.nn.logsumexp(both, axis=-1)
