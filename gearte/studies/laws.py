"""Laws of error values over a production batch: one family for every drive.

A law draws values of a given shape from a `jax.random` key, as a pure function of that
key. *Value laws* (`Fixed`, `Uniform`, `Normal`, `TruncatedNormal`, `Rayleigh`, and the
per-instance pattern `Sinusoid`) give lengths (µm) or angles (rad), signed where the error
is signed: a magnitude of an eccentricity must not be negative, a deviation such as a pin
radius error may be. *Phase laws* (`UniformPhase`, `FixedPhase`, and the assembly rules
`RelativePhase`, `Optimised`) give the angle of an eccentricity.

Every value law also has its inverse CDF (`ppf`), so that quasi-random designs (Sobol')
can drive it, and a `centre`, the value a tolerance band is centred on (0 for magnitudes):
a tolerance budget scales draws about it.

Truncation is by conditioning — the same law as resampling until the draw is within
bounds — and is drawn by the inverse CDF, so its cost is fixed and its result does not
depend on how many rejections a loop would have needed.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import ndtr, ndtri
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ..core.units import ARCSEC_PER_RAD, TWO_PI
from ..core.validate import as_float


def _finite(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a tolerance or magnitude cannot be negative")


def format_value(value: float, unit: str) -> str:
    """A law parameter for reports: µm as is, rad also in ″."""
    if unit == "rad":
        return f"{value * ARCSEC_PER_RAD:.6g}″"
    return f"{value:g} {unit}"


def _angle_text(x: float) -> str:
    """A phase for reports, rad and degrees; within 1e-9 rad (0.0002″) of a whole turn it reads 0, as an optimiser's
    rounding there means."""
    near = abs(math.remainder(x, TWO_PI)) <= 1e-9
    return "0 rad (0°)" if near else f"{x:.6g} rad ({math.degrees(x):.6g}°)"


class AbstractLaw(eqx.Module):
    """Law of an error value (µm, or rad for angles): ``sample(key, shape)``."""

    @abc.abstractmethod
    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...]) -> Float[Array, ...]:
        """Draw values of the given shape."""

    @abc.abstractmethod
    def describe(self, unit: str = "µm") -> str:
        """One line for reports."""

    def scaled(self, factor: float, *, about_centre: bool = False) -> AbstractLaw:
        """The law of the draws scaled by `factor` (a tolerance T/T_nominal): about 0, or about its centre.

        About 0 every parameter is multiplied (a magnitude law: x → f·x); about the centre c every
        value moves as c + f·(x − c), so a band keeps its middle (a signed deviation's tolerance).
        """
        c = self.centre() if about_centre and isinstance(self, AbstractValueLaw) else None

        def scale(x):
            if not eqx.is_inexact_array(x):
                return x
            return x * factor if c is None else c + (x - c) * factor

        return jax.tree.map(scale, self)


class AbstractValueLaw(AbstractLaw):
    """A law of a scalar value, with its inverse CDF and the value its spread is centred on."""

    @abc.abstractmethod
    def ppf(self, u: Array) -> Float[Array, ...]:
        """Inverse CDF at probabilities `u` (the map `sample` applies to a uniform draw)."""

    @abc.abstractmethod
    def lower(self) -> float:
        """The smallest value the law can draw (−∞ if unbounded), to check magnitudes."""

    @abc.abstractmethod
    def centre(self) -> Float[Array, ""]:
        """The value a tolerance budget scales draws about (0 for laws of a magnitude)."""

    def is_random(self) -> bool:
        """Whether the law has any spread (a constant is not an input of a sensitivity study)."""
        return True

    @property
    def banded(self) -> bool:
        """Whether the law is a band about a centre other than 0 by construction (decided statically, not from values)."""
        return False


class Fixed(AbstractValueLaw):
    """Always `value` (µm or rad; may be negative for a signed deviation)."""

    value: Float[Array, ""]

    def __init__(self, value: ArrayLike):
        self.value = jnp.asarray(_finite("Fixed.value", value))

    def sample(self, key, shape):
        del key
        return jnp.broadcast_to(self.value, shape)

    def ppf(self, u):
        return jnp.broadcast_to(self.value, jnp.shape(u))

    def lower(self) -> float:
        return float(self.value)

    def centre(self):
        return jnp.zeros(())

    def is_random(self) -> bool:
        return False

    def describe(self, unit: str = "µm") -> str:
        return f"fixed {format_value(float(self.value), unit)}"


class Uniform(AbstractValueLaw):
    """Uniform on [`low`, `high`] (µm or rad); `Uniform.centred(h, c)` is c ± h, a tolerance band."""

    low: Float[Array, ""]
    high: Float[Array, ""]
    symmetric: bool = eqx.field(static=True)

    def __init__(self, low: ArrayLike, high: ArrayLike, *, symmetric: bool = False):
        lo = _finite("Uniform.low", low)
        hi = _finite("Uniform.high", high)
        if not hi >= lo:
            raise ValueError(f"Uniform: high ({hi:g}) must be ≥ low ({lo:g})")
        self.low, self.high, self.symmetric = jnp.asarray(lo), jnp.asarray(hi), bool(symmetric)

    @classmethod
    def centred(cls, half_width: ArrayLike, centre: ArrayLike = 0.0) -> Uniform:
        """Uniform on `centre` ± `half_width` (half_width ≥ 0): a tolerance band."""
        h = _finite("Uniform.half_width", half_width, nonnegative=True)
        c = _finite("Uniform.centre", centre)
        return cls(c - h, c + h, symmetric=True)

    def _mid(self):
        return 0.5 * (self.low + self.high), 0.5 * (self.high - self.low)

    def sample(self, key, shape):
        if self.symmetric:
            c, h = self._mid()
            return c + h * jax.random.uniform(key, shape, dtype=float, minval=-1.0, maxval=1.0)
        return self.low + (self.high - self.low) * jax.random.uniform(key, shape, dtype=float)

    def ppf(self, u):
        if self.symmetric:
            c, h = self._mid()
            return c + h * (2.0 * u - 1.0)
        return self.low + (self.high - self.low) * u

    def lower(self) -> float:
        return float(self.low)

    @property
    def banded(self) -> bool:
        return self.symmetric

    def centre(self):
        # A band about its middle for a signed deviation; a magnitude law is scaled about 0.
        return self._mid()[0] if self.symmetric else jnp.zeros(())

    def is_random(self) -> bool:
        return float(self.high) > float(self.low)

    def describe(self, unit: str = "µm") -> str:
        if self.symmetric:
            c, h = (float(x) for x in self._mid())
            return f"uniform on {format_value(c, unit)} ± {format_value(h, unit)}"
        return f"uniform on [{format_value(float(self.low), unit)}, {format_value(float(self.high), unit)}]"


class Normal(AbstractValueLaw):
    """Normal with `mean` and `std`. As a magnitude, a negative draw is a magnitude with its phase turned by π."""

    mean: Float[Array, ""]
    std: Float[Array, ""]

    def __init__(self, mean: ArrayLike, std: ArrayLike):
        self.mean = jnp.asarray(_finite("Normal.mean", mean))
        self.std = jnp.asarray(_finite("Normal.std", std, nonnegative=True))

    def sample(self, key, shape):
        return self.mean + self.std * jax.random.normal(key, shape, dtype=float)

    def ppf(self, u):
        return self.mean + self.std * ndtri(u)

    def lower(self) -> float:
        return -math.inf

    def centre(self):
        return self.mean

    @property
    def banded(self) -> bool:
        return True

    def scaled(self, factor: float, *, about_centre: bool = False) -> Normal:
        if about_centre:
            return Normal(self.mean, self.std * factor)
        return Normal(self.mean * factor, self.std * factor)

    def is_random(self) -> bool:
        return float(self.std) > 0

    def describe(self, unit: str = "µm") -> str:
        return f"normal, mean {format_value(float(self.mean), unit)}, std {format_value(float(self.std), unit)}"


class TruncatedNormal(AbstractValueLaw):
    """Normal (`mean`, `std`) conditioned on [`low`, `high`] (default [0, ∞))."""

    mean: Float[Array, ""]
    std: Float[Array, ""]
    low: Float[Array, ""]
    high: Float[Array, ""]

    def __init__(self, mean: ArrayLike, std: ArrayLike, low: ArrayLike = 0.0, high: ArrayLike = math.inf):
        self.mean = jnp.asarray(_finite("TruncatedNormal.mean", mean))
        self.std = jnp.asarray(_finite("TruncatedNormal.std", std, positive=True))
        lo, hi = float(low), float(high)  # pyright: ignore[reportArgumentType]
        if math.isnan(lo) or math.isnan(hi) or not hi > lo:
            raise ValueError(f"TruncatedNormal: need low < high, got low={low}, high={high}")
        self.low, self.high = jnp.asarray(lo), jnp.asarray(hi)

    def sample(self, key, shape):
        return self.ppf(jax.random.uniform(key, shape, dtype=float))

    def ppf(self, u):
        a = ndtr((self.low - self.mean) / self.std)
        b = ndtr((self.high - self.mean) / self.std)
        p = jnp.clip(a + u * (b - a), 1e-300, 1.0 - 1e-16)
        return jnp.clip(self.mean + self.std * ndtri(p), self.low, self.high)

    def lower(self) -> float:
        return float(self.low)

    def centre(self):
        return jnp.zeros(())

    def describe(self, unit: str = "µm") -> str:
        return (
            f"normal (mean {format_value(float(self.mean), unit)}, std {format_value(float(self.std), unit)}) truncated to "
            f"[{format_value(float(self.low), unit)}, {format_value(float(self.high), unit)}]"
        )


class Rayleigh(AbstractValueLaw):
    """Rayleigh law with `scale` σ (mode σ, mean σ√(π/2)); optionally conditioned on ≤ `truncate_at`.

    The magnitude of a 2-D offset whose x and y parts are independent N(0, σ²): the law of
    eccentricities over a batch (Wang et al. 2013, sec. 3.2; Liu, sec. 2.3).
    """

    scale: Float[Array, ""]
    truncate_at: Float[Array, ""] | None

    def __init__(self, scale: ArrayLike, truncate_at: ArrayLike | None = None):
        self.scale = jnp.asarray(_finite("Rayleigh.scale", scale, positive=True))
        if truncate_at is None:
            self.truncate_at = None
        else:
            self.truncate_at = jnp.asarray(_finite("Rayleigh.truncate_at", truncate_at, positive=True))

    def sample(self, key, shape):
        return self.ppf(jax.random.uniform(key, shape, dtype=float))

    def ppf(self, u):
        p = jnp.ones(()) if self.truncate_at is None else -jnp.expm1(-0.5 * (self.truncate_at / self.scale) ** 2)  # P(X ≤ T)
        # Inverse CDF of the (conditioned) law: F(x) = 1 − exp(−x²/2σ²).
        return self.scale * jnp.sqrt(-2.0 * jnp.log1p(-u * p))

    def lower(self) -> float:
        return 0.0

    def centre(self):
        return jnp.zeros(())

    def describe(self, unit: str = "µm") -> str:
        s = f"Rayleigh, scale σ = {format_value(float(self.scale), unit)}"
        if self.truncate_at is not None:
            s += f", truncated at {format_value(float(self.truncate_at), unit)} (conditioned: same law as resampling)"
        return s


class AbstractPhase(AbstractLaw):
    """Law or assembly rule of the phase of an eccentricity, rad."""


class UniformPhase(AbstractPhase):
    """Uniform on [0, 2π): random assembly."""

    def sample(self, key, shape):
        return 2.0 * jnp.pi * jax.random.uniform(key, shape, dtype=float)

    def describe(self, unit: str = "rad") -> str:
        return "uniform on [0, 2π)"


class FixedPhase(AbstractPhase):
    """Always `value` rad."""

    value: Float[Array, ""]

    def __init__(self, value: ArrayLike):
        self.value = jnp.asarray(_finite("FixedPhase.value", value))

    def sample(self, key, shape):
        del key
        return jnp.broadcast_to(self.value, shape)

    def describe(self, unit: str = "rad") -> str:
        return f"fixed {_angle_text(float(self.value))}"


class AbstractRule(AbstractPhase):
    """An assembly rule: the phase follows the phase of another error source (`reference`), or is chosen."""

    @property
    @abc.abstractmethod
    def reference(self) -> str | None:
        """The error source whose phase this one is set from (None: an absolute phase)."""


class RelativePhase(AbstractRule):
    """Assembly rule: this phase = the phase of source `to` + `offset` rad.

    `to` names another error source of the same drive; a per-planet source may refer to a
    per-planet source (planet by planet) or to a single one (e.g. Wang et al. 2013, Table 3:
    γ_s = β_r + 7π/9).
    """

    offset: Float[Array, ""]
    to: str = eqx.field(static=True)

    def __init__(self, to: str, offset: ArrayLike = 0.0):
        if not isinstance(to, str) or not to:
            raise ValueError("RelativePhase.to: name the error source whose phase this one follows")
        self.to = to
        self.offset = jnp.asarray(_finite("RelativePhase.offset", offset))

    @property
    def reference(self) -> str:
        return self.to

    def sample(self, key, shape):
        raise ValueError(f"RelativePhase: a rule relative to {self.to!r} is drawn by the error model, not on its own")

    def describe(self, unit: str = "rad") -> str:
        return f"assembly rule: phase of {self.to} + {_angle_text(float(self.offset))}"


class Optimised(AbstractRule):
    """A phase the assembly optimiser chooses (in a study file: ``rule = "optimise"``).

    With `to` the rule is ``phase = phase(to) + offset`` (offset chosen); without, the phase
    itself is chosen (an absolute assembly position). Resolve it (`gearte.allocate_rule`)
    before drawing samples.
    """

    to: str | None = eqx.field(static=True)

    def __init__(self, to: str | None = None):
        if to is not None and (not isinstance(to, str) or not to):
            raise ValueError(
                f"Optimised.to: name the error source whose phase this one follows, or leave it out (None) for an "
                f"absolute phase; got {to!r}"
            )
        self.to = to

    @property
    def reference(self) -> str | None:
        return self.to

    def sample(self, key, shape):
        raise ValueError(
            "Optimised: this phase is to be chosen by the allocation optimiser; resolve the rule first "
            "(gearte.allocate_rule, or a study file's [allocation])"
        )

    def describe(self, unit: str = "rad") -> str:
        return "chosen by the allocation optimiser" + (f" (offset from the phase of {self.to})" if self.to else " (absolute)")


class Sinusoid(AbstractLaw):
    """A pattern over tooth spaces or pins: e_k = A sin(2π·order·(k + 1)/N + φ), k = 0 … N − 1.

    (k + 1 is the 1-based tooth number: Yao & Liang's (2001) Δβ(n) = 30″ sin(2πn/z_a) is
    ``Sinusoid(Fixed(30″ in rad), FixedPhase(0))``.) `amplitude` is a value law, `phase` a
    phase law; one amplitude and one phase are drawn per unit.
    """

    amplitude: AbstractValueLaw
    phase: AbstractPhase
    order: int = eqx.field(static=True)

    def __init__(self, amplitude: AbstractValueLaw | float, phase: AbstractPhase | float | None = None, *, order: int = 1):
        self.amplitude = amplitude if isinstance(amplitude, AbstractValueLaw) else Fixed(amplitude)
        self.phase = FixedPhase(0.0) if phase is None else phase if isinstance(phase, AbstractPhase) else FixedPhase(phase)
        if isinstance(order, bool) or not isinstance(order, int) or order < 1:
            raise ValueError(f"Sinusoid.order: must be a whole number ≥ 1, got {order!r}")
        self.order = order

    def sample(self, key, shape):
        if len(shape) != 1:
            raise ValueError("Sinusoid: only for per-space or per-pin errors (one value per tooth space or pin)")
        ka, kp = jax.random.split(key)
        n = shape[0]
        amp = self.amplitude.sample(ka, ())
        ph = self.phase.sample(kp, ())
        k = jnp.arange(1, n + 1, dtype=float)
        return amp * jnp.sin(TWO_PI * self.order * k / n + ph)

    def scaled(self, factor: float, *, about_centre: bool = False) -> Sinusoid:
        # The pattern A sin(…) is centred on 0 whatever the law of A: scaling it scales A about 0 (as a tolerance
        # budget scales the drawn values), never about the amplitude law's own centre.
        del about_centre
        return Sinusoid(self.amplitude.scaled(factor, about_centre=False), self.phase, order=self.order)  # pyright: ignore[reportArgumentType]

    def describe(self, unit: str = "µm") -> str:
        return f"A sin(2π·{self.order}·n/N + φ), A: {self.amplitude.describe(unit)}, φ: {self.phase.describe()}"
