"""Distributions of error magnitudes (µm) and rules for error phases (rad).

Magnitudes: `Fixed`, `Uniform`, `Normal`, `TruncatedNormal`, `Rayleigh` (optionally
truncated at the tolerance). Phases: `UniformPhase` on [0, 2π), `FixedPhase`, and
`RelativePhase` (a phase set by an assembly rule relative to another phase, e.g. the
planetary seed's Table 3: γ_s = β_r + 7π/9).

Every draw is a pure function of its `jax.random` key. Truncation is by
conditioning — the same law as resampling until the draw is within the tolerance —
and is drawn by the inverse CDF so that its cost is fixed and its result does not
depend on how many rejections a loop would have needed.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import ndtr, ndtri
from jaxtyping import Array, Float, PRNGKeyArray

from ._validate import as_float


def _check_finite(name: str, value: float, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a tolerance or magnitude cannot be negative")


class AbstractMagnitude(eqx.Module):
    """Law of an error magnitude, µm."""

    @abc.abstractmethod
    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...]) -> Float[Array, "..."]:
        """Draw magnitudes (µm) of the given shape."""

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports."""


class Fixed(AbstractMagnitude):
    """Always `value` µm."""

    value: Float[Array, ""]

    def __init__(self, value: float):
        self.value = jnp.asarray(_check_finite("Fixed.value", value, nonnegative=True))

    def sample(self, key, shape):
        del key
        return jnp.broadcast_to(self.value, shape)

    def describe(self) -> str:
        return f"fixed {float(self.value):g} µm"


class Uniform(AbstractMagnitude):
    """Uniform on [`low`, `high`] µm."""

    low: Float[Array, ""]
    high: Float[Array, ""]

    def __init__(self, low: float, high: float):
        lo = _check_finite("Uniform.low", low, nonnegative=True)
        hi = _check_finite("Uniform.high", high, nonnegative=True)
        if not hi >= lo:
            raise ValueError(f"Uniform: high ({hi}) must be ≥ low ({lo})")
        self.low, self.high = jnp.asarray(lo), jnp.asarray(hi)

    def sample(self, key, shape):
        return self.low + (self.high - self.low) * jax.random.uniform(key, shape, dtype=float)

    def describe(self) -> str:
        return f"uniform on [{float(self.low):g}, {float(self.high):g}] µm"


class Normal(AbstractMagnitude):
    """Normal with `mean` and `std` µm. A negative draw is a magnitude with its phase turned by π."""

    mean: Float[Array, ""]
    std: Float[Array, ""]

    def __init__(self, mean: float, std: float):
        self.mean = jnp.asarray(_check_finite("Normal.mean", mean))
        self.std = jnp.asarray(_check_finite("Normal.std", std, nonnegative=True))

    def sample(self, key, shape):
        return self.mean + self.std * jax.random.normal(key, shape, dtype=float)

    def describe(self) -> str:
        return f"normal, mean {float(self.mean):g} µm, std {float(self.std):g} µm"


class TruncatedNormal(AbstractMagnitude):
    """Normal (`mean`, `std` µm) conditioned on [`low`, `high`] µm (default [0, ∞))."""

    mean: Float[Array, ""]
    std: Float[Array, ""]
    low: Float[Array, ""]
    high: Float[Array, ""]

    def __init__(self, mean: float, std: float, low: float = 0.0, high: float = math.inf):
        self.mean = jnp.asarray(_check_finite("TruncatedNormal.mean", mean))
        self.std = jnp.asarray(_check_finite("TruncatedNormal.std", std, positive=True))
        lo = float(low)
        hi = float(high)
        if math.isnan(lo) or math.isnan(hi) or not hi > lo:
            raise ValueError(f"TruncatedNormal: need low < high, got low={low}, high={high}")
        self.low, self.high = jnp.asarray(lo), jnp.asarray(hi)

    def sample(self, key, shape):
        a = ndtr((self.low - self.mean) / self.std)
        b = ndtr((self.high - self.mean) / self.std)
        u = jax.random.uniform(key, shape, dtype=float)
        p = jnp.clip(a + u * (b - a), 1e-300, 1.0 - 1e-16)
        return jnp.clip(self.mean + self.std * ndtri(p), self.low, self.high)

    def describe(self) -> str:
        return (f"normal (mean {float(self.mean):g} µm, std {float(self.std):g} µm) truncated to "
                f"[{float(self.low):g}, {float(self.high):g}] µm")


class Rayleigh(AbstractMagnitude):
    """Rayleigh law with `scale` σ µm (mode σ, mean σ√(π/2)); optionally conditioned on ≤ `truncate_at` µm.

    The magnitude of a 2-D offset whose x and y parts are independent N(0, σ²):
    the law of eccentricities over a batch (seed 000, sec. 3.2; seed 002, sec. 2.3).
    """

    scale: Float[Array, ""]
    truncate_at: Float[Array, ""] | None

    def __init__(self, scale: float, truncate_at: float | None = None):
        self.scale = jnp.asarray(_check_finite("Rayleigh.scale", scale, positive=True))
        if truncate_at is None:
            self.truncate_at = None
        else:
            self.truncate_at = jnp.asarray(_check_finite("Rayleigh.truncate_at", truncate_at, positive=True))

    def sample(self, key, shape):
        u = jax.random.uniform(key, shape, dtype=float)
        if self.truncate_at is None:
            p = jnp.ones(())
        else:
            p = -jnp.expm1(-0.5 * (self.truncate_at / self.scale) ** 2)  # P(X ≤ T)
        # Inverse CDF of the (conditioned) law: F(x) = 1 − exp(−x²/2σ²).
        return self.scale * jnp.sqrt(-2.0 * jnp.log1p(-u * p))

    def describe(self) -> str:
        s = f"Rayleigh, scale σ = {float(self.scale):g} µm"
        if self.truncate_at is not None:
            s += f", truncated at {float(self.truncate_at):g} µm (conditioned: same law as resampling)"
        return s


class AbstractPhase(eqx.Module):
    """Law or rule of an error phase, rad."""

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports."""


class UniformPhase(AbstractPhase):
    """Uniform on [0, 2π): random assembly."""

    def sample(self, key, shape):
        return 2.0 * jnp.pi * jax.random.uniform(key, shape, dtype=float)

    def describe(self) -> str:
        return "uniform on [0, 2π)"


class FixedPhase(AbstractPhase):
    """Always `value` rad."""

    value: Float[Array, ""]

    def __init__(self, value: float):
        self.value = jnp.asarray(_check_finite("FixedPhase.value", value))

    def sample(self, key, shape):
        del key
        return jnp.broadcast_to(self.value, shape)

    def describe(self) -> str:
        return f"fixed {float(self.value):.6g} rad ({math.degrees(float(self.value)):.6g}°)"


class RelativePhase(AbstractPhase):
    """Assembly rule: this phase = the phase of source `to` + `offset` rad.

    `to` names another error source of the same drive; a per-planet source may
    refer to a per-planet source (planet by planet) or to a single one.
    """

    offset: Float[Array, ""]
    to: str = eqx.field(static=True)

    def __init__(self, to: str, offset: float = 0.0):
        if not isinstance(to, str) or not to:
            raise ValueError("RelativePhase.to: name the error source whose phase this one follows")
        self.to = to
        self.offset = jnp.asarray(_check_finite("RelativePhase.offset", offset))

    def describe(self) -> str:
        return f"assembly rule: phase of {self.to} + {float(self.offset):.6g} rad ({math.degrees(float(self.offset)):.6g}°)"


class Optimised(AbstractPhase):
    """Placeholder phase for a study file: the phase is chosen by the allocation optimiser.

    With `relative_to` the rule is ``phase = phase(relative_to) + offset`` (offset chosen);
    without, the phase itself is chosen (an absolute assembly position).
    """

    relative_to: str | None = eqx.field(static=True)

    def __init__(self, relative_to: str | None = None):
        self.relative_to = relative_to

    def describe(self) -> str:
        return "chosen by the allocation optimiser" + (f" (offset from the phase of {self.relative_to})" if self.relative_to else " (absolute)")
