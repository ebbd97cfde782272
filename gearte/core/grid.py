"""The hyper-period grid of a TE signal: its size, its tables of cos kτ and sin kτ, the signal's values and
derivatives from them, and the choice of a grid's best blocks. The exact extrema (`gearte.core.extrema`), the
two-scale search (`gearte.core.twoscale`) and the harmonic drive's assembly search stand on them.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from fractions import Fraction

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .signal import TESignal, gcd_fractions
from .units import TWO_PI as _TWO_PI


def grid_size(orders: tuple[int, ...], oversample: int) -> int:
    # A whole number of blocks of half a period of the highest order (see `_argmax_tau`).
    block = max(1, oversample // 2)
    m = max(64, oversample * max(orders))
    return block * -(-m // block)


#: Most entries of the exact extrema's tables for one signal: distinct orders × grid points (`grid_size`). The tables
#: of cos kτ and sin kτ are constants of the compiled search: 2²³ entries keep them within about 200 MB (at the bound,
#: 5-7 s to compile and 2 GB of peak memory with 16-32 orders), where a longer hyper-period or more orders would
#: exhaust the memory. At 16 points per period two orders reach 262,144 periods; the planetary and harmonic drives
#: have 3-4 orders.
MAX_GRID_ENTRIES = 2**23


def grid_entries(orders: tuple[int, ...], oversample: int = 16) -> int:
    """Entries of the exact extrema's tables for a signal of these orders (`MAX_GRID_ENTRIES`)."""
    return len(orders) * grid_size(orders, oversample) if orders else 0


def _check_orders(signal: TESignal, oversample: int, *, what: str) -> None:
    """Refuse a signal whose tables would exceed `MAX_GRID_ENTRIES`: they would not fit in memory."""
    entries = grid_entries(signal.orders, oversample)
    if entries > MAX_GRID_ENTRIES:
        raise ValueError(
            f"{what}: the signal's {len(signal.orders)} orders up to {max(signal.orders):,} (periods of its fastest term "
            f"over the hyper-period) need {entries:,} table entries at {oversample} points per period, more than "
            f"{MAX_GRID_ENTRIES:,}; they would not fit in memory. Frequencies with small denominators (or tooth counts with "
            "common factors) keep the hyper-period short"
        )


def _short(x) -> str:
    return str(x) if len(str(x)) <= 16 else f"{float(x):.6g}"


def check_frequencies(freqs: Sequence[Fraction], *, what: str) -> None:
    """Raise a ValueError naming `what` where the frequencies `freqs` (multiples of the input speed) make a signal
    whose exact extrema would need more than `MAX_GRID_ENTRIES` table entries (`grid_entries`), before any signal is
    built (for a drive given as explicit terms)."""
    nonzero = sorted({abs(f) for f in freqs if f != 0})
    if not nonzero:
        return
    f0 = gcd_fractions(nonzero)
    periods = nonzero[-1] / f0
    if grid_entries(tuple(int(f / f0) for f in nonzero)) > MAX_GRID_ENTRIES:
        raise ValueError(
            f"{what}: over the hyper-period of these frequencies ({', '.join(_short(f) for f in nonzero)}: {_short(1 / f0)} "
            f"input revolutions) the fastest term makes {_short(periods)} periods; with {len(nonzero)} distinct orders the "
            f"exact extrema's grid (16 points per period, one table row per order) would need "
            f"{_short(len(nonzero) * 16 * periods)} entries, more than {MAX_GRID_ENTRIES:,}. The count grows with the "
            "frequencies' ratio and their denominators (for a gear train, with large coprime tooth counts): give "
            "frequencies as fractions with small denominators, e.g. '7/24', or tooth counts with common factors"
        )


def _basis(orders: tuple[int, ...], m: int, *, wrap: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """cos(kτ_i), sin(kτ_i) on τ_i = 2πi/m, i = 0…m−1 (or −1…m with `wrap`), shape (K, m) (or (K, m + 2)).

    The angle is reduced exactly, k i mod m, before it is scaled: the tables are correctly rounded whatever k i."""
    i = np.arange(-1, m + 1, dtype=np.int64) if wrap else np.arange(m, dtype=np.int64)
    phase = (np.asarray(orders, dtype=np.int64)[:, None] * i) % m
    kt = phase.astype(np.float64) * (_TWO_PI / m)
    return np.cos(kt), np.sin(kt)


def _grid_values(signal: TESignal, cos_b: np.ndarray, sin_b: np.ndarray) -> Array:
    # Unrolled over orders (few): an elementwise sum whose order never changes with batch size.
    f = signal.offset[..., None]
    for j in range(len(signal.orders)):
        f = f + signal.cos_coef[..., j, None] * cos_b[j] + signal.sin_coef[..., j, None] * sin_b[j]
    return f


def _cis_powers(c1: Array, s1: Array, orders: tuple[int, ...]) -> tuple[Array, Array]:
    """cos(kτ), sin(kτ) for each order k from cos τ, sin τ, by repeated squaring (log k products each).

    Cheaper than a sine and cosine per order on the CPU; the rounding error grows like k·ε. The squarings
    cos 2ʲτ, sin 2ʲτ are shared by the orders (each order multiplies those of its binary digits, lowest first).
    """
    pc, ps = [c1], [s1]
    for _ in range(max(orders).bit_length() - 1):
        bc, bs = pc[-1], ps[-1]
        pc.append(bc * bc - bs * bs)
        ps.append(2.0 * bc * bs)
    cos_k, sin_k = [], []
    for k in orders:
        rc, rs = None, None
        for j in range(k.bit_length()):
            if (k >> j) & 1:
                bc, bs = pc[j], ps[j]
                rc, rs = (bc, bs) if rc is None or rs is None else (rc * bc - rs * bs, rc * bs + rs * bc)
        cos_k.append(rc)
        sin_k.append(rs)
    return jnp.stack(cos_k, axis=-1), jnp.stack(sin_k, axis=-1)


def _derivatives(signal: TESignal, tau: Array) -> tuple[Array, Array, Array]:
    """f, df/dτ, d²f/dτ² at τ of shape ``(..., c)``."""
    k = jnp.asarray(signal.orders, dtype=float)
    c, s = _cis_powers(jnp.cos(tau)[..., None], jnp.sin(tau)[..., None], signal.orders)
    c, s = c[..., 0, :], s[..., 0, :]
    a = signal.cos_coef[..., None, :]
    b = signal.sin_coef[..., None, :]
    f = signal.offset[..., None] + jnp.sum(a * c + b * s, axis=-1)
    f1 = jnp.sum(k * (b * c - a * s), axis=-1)
    f2 = -jnp.sum(k * k * (a * c + b * s), axis=-1)
    return f, f1, f2


#: `_top` searches a last axis up to this long by a chain of comparisons, one column after another, in one pass
#: (the first round's blocks of a signal of small orders: 42 for the planetary example); along a longer one, by
#: repeated argmax. (XLA's CPU reductions over a short axis, XNNPACK's, took a pass over memory for each maximum and
#: each index, 45 of the 90 ms of the example's 50,000 samples; the chain takes 4. The chain is not used inside the
#: refinement: fused with the Newton steps whose values it compares, XLA computed them again for every comparison.)
CHAIN_AXIS = 64
#: ... and for at most this many entries: the chains are unrolled, c of them over the axis (16 candidates over 62
#: blocks made a program of 42,000 lines that took minutes to compile).
CHAIN_CANDIDATES = 4


def _argmax(x: Array) -> Array:
    """`jnp.argmax` over the last axis (first of ties) as a maximum and a minimum: two plain
    reductions, which the CPU vectorises, rather than one reduction over (value, index) pairs."""
    n = x.shape[-1]
    hit = x == jnp.max(x, axis=-1, keepdims=True)
    return jnp.min(jnp.where(hit, jnp.arange(n), n), axis=-1)


def _top(score: Array, c: int) -> tuple[Array, Array]:
    """The `c` largest entries of the last axis and their indices, largest first, the first of equals first: `c`
    argmaxes, each found entry set to −∞ before the next (`_repeated_argmax`). Along a short axis (`CHAIN_AXIS`) each
    argmax is one chain over the columns that keeps the best so far and its index, taking a column only where it
    is strictly larger (an equal one came later); found columns enter as −∞, and where every column left is −∞ the
    index is 0, as the repeated argmax finds it."""
    n = score.shape[-1]
    c = min(c, n)
    if n > CHAIN_AXIS or c > CHAIN_CANDIDATES:
        return _repeated_argmax(score, c)
    cols = [score[..., i] for i in range(n)]
    vals, idxs = [], []
    for _ in range(c):
        best, first = cols[0], jnp.zeros(cols[0].shape, dtype=int)
        if idxs:  # entries already found are −∞ (the repeated argmax sets them so)
            best = jnp.where(functools.reduce(jnp.logical_or, [j == 0 for j in idxs]), -jnp.inf, best)
        for i in range(1, n):
            x = cols[i]
            if idxs:
                x = jnp.where(functools.reduce(jnp.logical_or, [j == i for j in idxs]), -jnp.inf, x)
            better = x > best
            best, first = jnp.where(better, x, best), jnp.where(better, i, first)
        vals.append(best)
        idxs.append(first)
    return jnp.stack(vals, axis=-1), jnp.stack(idxs, axis=-1)


def _repeated_argmax(score: Array, c: int) -> tuple[Array, Array]:
    """The `c` largest entries of the last axis and their indices by repeated argmax (cheap on CPU, unlike sorting),
    each found entry set to −∞ before the next."""
    pos = jnp.arange(score.shape[-1])
    vals, idxs = [], []
    for _ in range(min(c, score.shape[-1])):
        i = _argmax(score)
        vals.append(jnp.take_along_axis(score, i[..., None], axis=-1)[..., 0])
        idxs.append(i)
        score = jnp.where(pos == i[..., None], -jnp.inf, score)
    return jnp.stack(vals, axis=-1), jnp.stack(idxs, axis=-1)


def _block_scores(g: Array, sign: float, block: int) -> tuple[Array, Array, Array, Array]:
    """Per block of the grid: its best point, the parabola-vertex offset there (grid steps),
    the vertex value (for ranking) and the block's grid maximum (for certification).

    `g` holds f on the grid with one wrap-around point at each end. Blocks are half the
    shortest period long: a trigonometric polynomial of order K has at most K maxima per
    period, so a block rarely holds two.
    """
    f = sign * g[..., 1:-1]
    m = f.shape[-1]
    nb = m // block
    blocks = f.reshape(f.shape[:-1] + (nb, block))
    idx = jnp.argmax(blocks, axis=-1) + block * jnp.arange(nb)  # grid index of each block's best point
    fc = jnp.take_along_axis(f, idx, axis=-1)
    fp = sign * jnp.take_along_axis(g, idx, axis=-1)  # g is shifted by one: g[idx] = f[idx − 1]
    fn = sign * jnp.take_along_axis(g, idx + 2, axis=-1)
    d1 = fp - fn
    denom = fp - 2.0 * fc + fn
    curved = denom < 0.0
    delta = jnp.where(curved, jnp.clip(0.5 * d1 / jnp.where(curved, denom, -1.0), -0.5, 0.5), 0.0)
    score = fc - 0.25 * d1 * delta
    return idx, delta, score, fc


def _candidates(g: Array, sign: float, block: int, candidates: int) -> tuple[Array, Array]:
    """Grid indices and parabola-vertex offsets of the `candidates` best-ranked blocks (no certification)."""
    idx, delta, score, _ = _block_scores(g, sign, block)
    best = _repeated_argmax(score, candidates)[1]
    return jnp.take_along_axis(idx, best, axis=-1), jnp.take_along_axis(delta, best, axis=-1)


def _cis_small(t: Array, terms: int = 10) -> tuple[Array, Array]:
    """cos t, sin t for small |t| (≤ 0.5 rad) by their Taylor series, Horner in t².

    Polynomials vectorise on the CPU, unlike float64 sine and cosine calls; with 10 terms the
    truncation error is below t²¹/21! ≈ 2e-26 at |t| = 0.5.
    """
    t2 = t * t
    c = jnp.ones_like(t)
    s = jnp.ones_like(t)
    for n in range(terms, 0, -1):
        c = 1.0 - t2 * c / ((2 * n - 1) * (2 * n))
        s = 1.0 - t2 * s / ((2 * n) * (2 * n + 1))
    return c, t * s
