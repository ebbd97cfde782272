"""Sinusoidal error components and the TE signal they make.

A component is ``A sin(r θ + φ)``: amplitude A (µm along a line of action),
frequency r (an exact rational multiple of the input speed), phase φ (rad), and
a gain (rad of output angle per µm) that the drive model supplies. θ is the
input angle in rad. The TE at the output is the sum of ``gain · A sin(r θ + φ)``.

Because every r is rational, the TE is a trigonometric polynomial in
``τ = f₀ θ`` with f₀ the greatest common divisor of the frequencies: it repeats
after the *hyper-period* of ``1/f₀`` input revolutions. `TESignal` stores it in
that canonical form (one cosine and one sine coefficient per distinct order),
which is what the exact metrics work on.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from fractions import Fraction

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .precision import require_x64

FrequencyLike = int | Fraction | str | float


def as_frequency(value: FrequencyLike, *, name: str = "frequency") -> Fraction:
    """Parse a frequency (a multiple of the input speed) as an exact fraction.

    Accepts an int, a `Fraction`, a string such as ``"11/24"`` or ``"7/8"``, or a
    float that is within 1e-12 of a fraction with a denominator ≤ 10⁶.
    """
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected a number or a fraction string like '7/24', got {value!r}")
    if isinstance(value, Fraction):
        return value
    if isinstance(value, int):
        return Fraction(value)
    if isinstance(value, str):
        try:
            return Fraction(value.replace(" ", ""))
        except (ValueError, ZeroDivisionError):
            raise ValueError(f"{name}: cannot read {value!r} as a fraction; write it like '7/24' or '2'") from None
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{name}: must be finite, got {value!r}")
        frac = Fraction(value).limit_denominator(10**6)
        if abs(float(frac) - value) > 1e-12 * max(1.0, abs(value)):
            raise ValueError(
                f"{name}: {value!r} is not a rational multiple of the input speed with a small "
                "denominator; give it exactly as a fraction string such as '91/45'"
            )
        return frac
    raise ValueError(f"{name}: expected a number or a fraction string like '7/24', got {type(value).__name__}")


def gcd_fractions(values: Sequence[Fraction]) -> Fraction:
    num = 0
    den = 1
    for v in values:
        # gcd(a/b, c/d) = gcd(a d, c b) / (b d), reduced by Fraction.
        num, den = math.gcd(num * v.denominator, v.numerator * den), den * v.denominator
        g = math.gcd(num, den)
        num, den = num // g, den // g
    return Fraction(num, den)


class Components(eqx.Module):
    """Sinusoidal error components ``gain · amplitude · sin(freq · θ + phase)``.

    **Arguments:**

    - `amplitude`: amplitudes A, µm along the line of action (shape ``(..., n)``).
    - `phase`: phases φ, rad (shape ``(..., n)``).
    - `gain`: output angle per µm of mesh error, rad/µm (shape ``(n,)`` or ``(..., n)``).
    - `freq`: n exact frequencies, multiples of the input speed (may be negative or 0).
    - `labels`: n names, for reports.
    """

    amplitude: Float[Array, "*batch n"]
    phase: Float[Array, "*batch n"]
    gain: Float[Array, "*batch n"]
    freq: tuple[Fraction, ...] = eqx.field(static=True)
    labels: tuple[str, ...] = eqx.field(static=True)

    def __init__(
        self,
        amplitude: ArrayLike,
        phase: ArrayLike,
        freq: Sequence[FrequencyLike],
        gain: ArrayLike = 1.0,
        labels: Sequence[str] | None = None,
    ):
        self.freq = tuple(as_frequency(f, name=f"freq[{i}]") for i, f in enumerate(freq))
        n = len(self.freq)
        self.amplitude = jnp.asarray(amplitude, dtype=float)
        self.phase = jnp.asarray(phase, dtype=float)
        self.gain = (
            jnp.broadcast_to(jnp.asarray(gain, dtype=float), self.amplitude.shape[:-1] + (n,))
            if jnp.ndim(gain) == 0
            else jnp.asarray(gain, dtype=float)
        )
        for nm, arr in (("amplitude", self.amplitude), ("phase", self.phase), ("gain", self.gain)):
            if arr.ndim == 0 or arr.shape[-1] != n:
                raise ValueError(f"Components: `{nm}` must have a last axis of length {n} (one per frequency), got shape {arr.shape}")
        self.labels = tuple(labels) if labels is not None else tuple(f"c{i}" for i in range(n))
        if len(self.labels) != n:
            raise ValueError(f"Components: {len(self.labels)} labels for {n} components")


class TESignal(eqx.Module):
    """A TE signal as a trigonometric polynomial over its hyper-period.

    ``TE(θ) = offset + Σ_j [cos_coef_j cos(k_j f₀ θ) + sin_coef_j sin(k_j f₀ θ)]``
    in rad of output angle, for the input angle θ in rad.

    **Arguments:**

    - `offset`: constant part, rad (shape ``(...)``).
    - `cos_coef`, `sin_coef`: coefficients per order, rad (shape ``(..., K)``).
    - `orders`: the K distinct positive integer orders k_j.
    - `fundamental`: f₀, a multiple of the input speed; the hyper-period is
      ``1/f₀`` input revolutions.
    """

    offset: Float[Array, "*batch"]
    cos_coef: Float[Array, "*batch K"]
    sin_coef: Float[Array, "*batch K"]
    orders: tuple[int, ...] = eqx.field(static=True)
    fundamental: Fraction = eqx.field(static=True)

    @property
    def hyper_period_revs(self) -> Fraction:
        """Hyper-period in input revolutions (exact)."""
        return 1 / self.fundamental

    @property
    def frequencies(self) -> tuple[Fraction, ...]:
        """Distinct frequencies (multiples of the input speed), one per order."""
        return tuple(k * self.fundamental for k in self.orders)


def to_signal(components: Components) -> TESignal:
    """Sum components into the canonical `TESignal` (rad at the output).

    Components of equal |frequency| are added as phasors; negative frequencies are
    folded onto positive ones; frequency 0 gives a constant ``A sin φ``.
    """
    require_x64()
    freqs = components.freq
    nonzero = sorted({abs(f) for f in freqs if f != 0})
    f0 = gcd_fractions(nonzero) if nonzero else Fraction(1)
    orders = tuple(int(f / f0) for f in nonzero)
    index = {f: j for j, f in enumerate(nonzero)}
    amp = components.amplitude * components.gain
    s_phi = amp * jnp.sin(components.phase)
    c_phi = amp * jnp.cos(components.phase)
    batch = amp.shape[:-1]
    offset = jnp.zeros(batch)
    cos_terms: list = [jnp.zeros(batch) for _ in nonzero]
    sin_terms: list = [jnp.zeros(batch) for _ in nonzero]
    # A sin(rθ+φ) = A sin φ · cos(|r|θ) + sign(r) A cos φ · sin(|r|θ). A Python loop over
    # components keeps the summation order fixed, so results do not depend on batch size.
    for i, f in enumerate(freqs):
        if f == 0:
            offset = offset + s_phi[..., i]
            continue
        j = index[abs(f)]
        cos_terms[j] = cos_terms[j] + s_phi[..., i]
        sin_terms[j] = sin_terms[j] + (c_phi[..., i] if f > 0 else -c_phi[..., i])
    stack = (lambda xs: jnp.stack(xs, axis=-1)) if nonzero else (lambda xs: jnp.zeros(batch + (0,)))
    return TESignal(offset=offset, cos_coef=stack(cos_terms), sin_coef=stack(sin_terms), orders=orders, fundamental=f0)


def evaluate(signal: TESignal, theta: ArrayLike) -> Float[Array, ...]:
    """TE (rad) at input angles `theta` (rad). Broadcasts ``signal`` batch dims against ``theta``.

    For a batched signal of shape ``(B,)`` and theta of shape ``(T,)`` pass
    ``theta[None, :]`` against a signal whose leaves are ``(B, 1, ...)``, or use `jax.vmap`.
    """
    require_x64()
    theta = jnp.asarray(theta, dtype=float)
    tau = theta * float(signal.fundamental)
    out = signal.offset + jnp.zeros_like(tau)
    for j, k in enumerate(signal.orders):
        out = out + signal.cos_coef[..., j] * jnp.cos(k * tau) + signal.sin_coef[..., j] * jnp.sin(k * tau)
    return out


def hyper_period_grid(signal: TESignal, points_per_rev: int) -> np.ndarray:
    """Input angles (rad) covering one hyper-period with `points_per_rev` per input revolution."""
    revs = signal.hyper_period_revs
    n = int(math.ceil(float(revs) * points_per_rev))
    return np.linspace(0.0, 2 * math.pi * float(revs), n, endpoint=False)
