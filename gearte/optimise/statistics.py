"""The statistics a tolerance budget constrains, as objects: a yield (a quantile) or mean ± kσ.

Each knows its smooth form (for the optimiser: a kernel-smoothed quantile, differentiable in the
samples), its exact form (for calibration and verification), and how much margin a calibration
on a finite sample needs.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.validate import is_traced


def smooth_quantile(x: Float[Array, " n"], level: float, width, *, iterations: int = 64) -> Float[Array, ""]:
    """Kernel-smoothed `level`-quantile of samples `x`: the q with mean σ((q − x_k)/width) = level.

    Differentiable in `x` and in `width` (which may depend on `x`) by the implicit-function
    theorem: dq = Σ_k σ'_k [dx_k + (q − x_k) dw / w] / Σ_k σ'_k. As width → 0 it tends to the
    empirical quantile. `x` is 1-D, `level` in (0, 1), `width` > 0 (checked where they are not traced).
    """
    _check_quantile_args(x, level, width)
    xs = jax.lax.stop_gradient(x)
    width = jnp.asarray(width, dtype=float)
    ws = jax.lax.stop_gradient(width)

    def residual(q):
        return jnp.mean(jax.nn.sigmoid((q - xs) / ws)) - level

    def body(_, lh):  # bisection: monotone and safe for any data
        lo, hi = lh
        mid = 0.5 * (lo + hi)
        up = residual(mid) > 0
        return jnp.where(up, lo, mid), jnp.where(up, mid, hi)

    lo, hi = jax.lax.fori_loop(0, iterations, body, (jnp.min(xs) - 40 * ws, jnp.max(xs) + 40 * ws))
    q = 0.5 * (lo + hi)
    s = jax.nn.sigmoid((q - xs) / ws)
    wk = s * (1 - s)
    wk = wk / jnp.sum(wk)
    return q + jnp.sum(wk * (x - xs)) + jnp.sum(wk * (q - xs)) / ws * (width - ws)


def _check_quantile_args(x, level, width) -> None:
    """`smooth_quantile`'s arguments, where they are concrete (a traced value passes unchecked; a shape is always known)."""
    if np.ndim(x) != 1:
        raise ValueError(f"smooth_quantile: x must be 1-D (one value per sample), got shape {np.shape(x)}; flatten it or pass one row")
    if not is_traced(level):
        lv = float(level)
        if not 0 < lv < 1:
            raise ValueError(f"smooth_quantile: level must be in (0, 1) (e.g. 0.9973 for 99.73 %), got {level!r}")
    if not is_traced(width):
        w = np.asarray(width, dtype=float)
        if not (np.all(np.isfinite(w)) and np.all(w > 0)):
            raise ValueError(f"smooth_quantile: width must be finite and > 0 (the same unit as x, e.g. 0.005 × its mean), got {width!r}")


class AbstractStatistic(eqx.Module):
    """The statistic a budget constrains (an object, as optimistix passes a norm).

    `lower` says the metric's spec is a lower bound (more is better, e.g. loaded pairs).
    """

    @abc.abstractmethod
    def smooth(self, x: Float[Array, " n"], *, lower: bool, width: Float[Array, ""]) -> Float[Array, ""]:
        """A smooth statistic of samples `x` (`width`: relative smoothing width, for quantiles)."""

    @abc.abstractmethod
    def exact(self, x: np.ndarray, *, lower: bool, margin_samples: int | None = None) -> float:
        """The exact statistic of samples `x`; with `margin_samples`, the calibration target that clears the
        constraint with a safety margin for a fresh sample of that size."""

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports."""


def binomial_se(p: float, n: int) -> float:
    """The standard error of a yield p estimated from n samples, √(p (1 − p) / n)."""
    return math.sqrt(max(p * (1.0 - p), 0.0) / max(n, 1))


class Yield(AbstractStatistic):
    """P(metric meets its spec) ≥ `target`: the target-quantile of the metric against the spec."""

    target: float = eqx.field(static=True)

    def __init__(self, target: float = 0.9973):
        t = float(target)
        if not 0.5 <= t < 1:
            raise ValueError(f"Yield.target: a yield in [0.5, 1), got {target!r}")
        self.target = t

    def smooth(self, x, *, lower, width):
        level = (1.0 - self.target) if lower else self.target
        # Width ∝ the mean keeps the statistic positively homogeneous of degree 1, exactly.
        return smooth_quantile(x, level, width * jnp.mean(jnp.abs(x)) if lower else width * jnp.mean(x))

    def exact(self, x, *, lower, margin_samples=None):
        t = self.target
        if margin_samples is not None:
            # Four standard errors: the calibration and the verification samples each carry one
            # binomial error, so the verified yield clears the target with ~99.8 % probability.
            t = min(t + 4 * binomial_se(t, margin_samples), 1 - 1.0 / margin_samples)
        return float(np.quantile(x, 1.0 - t if lower else t))

    def describe(self) -> str:
        return f"yield ≥ {self.target:g}"


class MeanKSigma(AbstractStatistic):
    """mean + k·σ of the metric against the spec (mean − kσ for a metric where more is better)."""

    k: float = eqx.field(static=True)

    def __init__(self, k: float = 3.0):
        kk = float(k)
        if not (math.isfinite(kk) and kk >= 0):
            raise ValueError(f"MeanKSigma.k: k ≥ 0, got {k!r}")
        self.k = kk

    def smooth(self, x, *, lower, width):
        del width
        return jnp.mean(x) - self.k * jnp.std(x) if lower else jnp.mean(x) + self.k * jnp.std(x)

    def exact(self, x, *, lower, margin_samples=None):
        del margin_samples
        sd = np.std(x, ddof=1)
        return float(np.mean(x) - self.k * sd if lower else np.mean(x) + self.k * sd)

    def describe(self) -> str:
        return f"mean ± {self.k:g}σ"
