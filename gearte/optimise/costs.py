"""Cost–tolerance models: the manufacturing cost of holding an error source to a tolerance T (µm).

Each model is an `eqx.Module` called as `model(T) -> cost`, on floats or JAX arrays,
differentiable in T (and in its coefficients, which are array leaves), so that a
tolerance budget can be optimised with `jax.grad`:

- `Reciprocal(a, b)`: c = a + b/T;
- `ReciprocalSquare(a, b)`: c = a + b/T² (the reciprocal-square model usually attributed
  to Spotts, 1973);
- `Exponential(a, b, k)`: c = a + b·e^(−kT);
- `Power(a, k)`: c = a·T^(−k) (the power law usually attributed to Sutherland and Roth, 1975);
- `GradeTable(costs_by_grade, ...)`: a cost per ISO 1328 grade, interpolated smoothly
  in the continuous grade of T.

gearte ships no cost coefficients: they depend on the shop, the machine and the batch
size, and should be fitted to the user's own cost data. Each analytic model has a
`normalised(T_ref)` constructor whose cost is 1 at the reference tolerance T_ref — a unit
cost that makes budgets comparable in shape, not in money.
"""

from __future__ import annotations

import abc
import math
import numbers
from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..core.validate import as_float, is_traced
from ..standards.iso1328 import GRADES, check_standard, grade_for_tolerance, iso1328_tolerance


def _coef(name: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    return as_float(name, value, positive=positive, nonnegative=nonnegative, hint="a cost cannot be negative")


def _tolerance(T: ArrayLike, throw: bool) -> Float[Array, ...]:
    """T as a float array; a non-positive or non-finite tolerance is an error."""
    if is_traced(T):
        traced = jnp.asarray(T, dtype=float)
        if throw:
            traced = eqx.error_if(traced, ~(jnp.isfinite(traced) & (traced > 0)), "cost model: tolerance T must be finite and > 0 µm")
        return traced
    t = np.asarray(T, dtype=float)
    if not np.all(np.isfinite(t) & (t > 0)):
        raise ValueError(f"cost model: tolerance T must be finite and > 0 µm, got {T!r}")
    return jnp.asarray(t)


class AbstractCostModel(eqx.Module):
    """Cost of holding an error source to tolerance T, µm; decreasing in T."""

    @abc.abstractmethod
    def __call__(self, T: ArrayLike, *, throw: bool = True) -> Float[Array, ...]:
        """Cost at tolerance `T` µm (> 0), elementwise.

        A non-positive or non-finite concrete `T` raises `ValueError`; under `jit`,
        `grad` or `vmap` it raises through `eqx.error_if` when `throw=True` and gives an
        unspecified (possibly NaN) cost when `throw=False`.
        """

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports."""


class Reciprocal(AbstractCostModel):
    """c = a + b/T: a fixed cost `a` and a cost `b`/T that grows as the tolerance T (µm) tightens.

    Coefficients should come from the user's shop data; `Reciprocal.normalised(T_ref)` is
    the unit-cost model a = 0, b = T_ref.
    """

    a: Float[Array, ""]
    b: Float[Array, ""]

    def __init__(self, a: float, b: float):
        self.a = jnp.asarray(_coef("Reciprocal.a", a, nonnegative=True), dtype=float)
        self.b = jnp.asarray(_coef("Reciprocal.b", b, positive=True), dtype=float)

    @classmethod
    def normalised(cls, T_ref: float) -> Reciprocal:
        """c = T_ref / T: cost 1 at `T_ref` µm, doubling when the tolerance halves."""
        return cls(0.0, _coef("T_ref", T_ref, positive=True))

    def __call__(self, T, *, throw=True):
        return self.a + self.b / _tolerance(T, throw)

    def describe(self) -> str:
        return f"reciprocal, c = {float(self.a):g} + {float(self.b):g}/T (T in µm)"


class ReciprocalSquare(AbstractCostModel):
    """c = a + b/T² (the reciprocal-square model usually attributed to Spotts, 1973), T in µm.

    Coefficients should come from the user's shop data; `ReciprocalSquare.normalised(T_ref)`
    is the unit-cost model a = 0, b = T_ref².
    """

    a: Float[Array, ""]
    b: Float[Array, ""]

    def __init__(self, a: float, b: float):
        self.a = jnp.asarray(_coef("ReciprocalSquare.a", a, nonnegative=True), dtype=float)
        self.b = jnp.asarray(_coef("ReciprocalSquare.b", b, positive=True), dtype=float)

    @classmethod
    def normalised(cls, T_ref: float) -> ReciprocalSquare:
        """c = (T_ref / T)²: cost 1 at `T_ref` µm, four times as much when the tolerance halves."""
        t = _coef("T_ref", T_ref, positive=True)
        return cls(0.0, t * t)

    def __call__(self, T, *, throw=True):
        t = _tolerance(T, throw)
        return self.a + self.b / (t * t)

    def describe(self) -> str:
        return f"reciprocal-square (Spotts), c = {float(self.a):g} + {float(self.b):g}/T² (T in µm)"


class Exponential(AbstractCostModel):
    """c = a + b·e^(−kT), T in µm, k in 1/µm.

    Coefficients should come from the user's shop data; `Exponential.normalised(T_ref)` is
    the unit-cost model a = 0, k = 1/T_ref, b = e^(k·T_ref) = e.
    """

    a: Float[Array, ""]
    b: Float[Array, ""]
    k: Float[Array, ""]

    def __init__(self, a: float, b: float, k: float):
        self.a = jnp.asarray(_coef("Exponential.a", a, nonnegative=True), dtype=float)
        self.b = jnp.asarray(_coef("Exponential.b", b, positive=True), dtype=float)
        self.k = jnp.asarray(_coef("Exponential.k", k, positive=True), dtype=float)

    @classmethod
    def normalised(cls, T_ref: float, *, k: float | None = None) -> Exponential:
        """c = e^(−k(T − T_ref)): cost 1 at `T_ref` µm; `k` (1/µm) defaults to 1/T_ref."""
        t = _coef("T_ref", T_ref, positive=True)
        kk = 1.0 / t if k is None else _coef("Exponential.k", k, positive=True)
        return cls(0.0, math.exp(kk * t), kk)

    def __call__(self, T, *, throw=True):
        return self.a + self.b * jnp.exp(-self.k * _tolerance(T, throw))

    def describe(self) -> str:
        return f"exponential, c = {float(self.a):g} + {float(self.b):g}·exp(−{float(self.k):g}·T) (T in µm)"


class Power(AbstractCostModel):
    """c = a·T^(−k) (the power law usually attributed to Sutherland and Roth, 1975), T in µm.

    Coefficients should come from the user's shop data; `Power.normalised(T_ref, k=...)` is
    the unit-cost model a = T_ref^k.
    """

    a: Float[Array, ""]
    k: Float[Array, ""]

    def __init__(self, a: float, k: float):
        self.a = jnp.asarray(_coef("Power.a", a, positive=True), dtype=float)
        self.k = jnp.asarray(_coef("Power.k", k, positive=True), dtype=float)

    @classmethod
    def normalised(cls, T_ref: float, *, k: float = 1.0) -> Power:
        """c = (T_ref / T)^k: cost 1 at `T_ref` µm."""
        t = _coef("T_ref", T_ref, positive=True)
        kk = _coef("Power.k", k, positive=True)
        try:
            a = t**kk
        except OverflowError:
            raise ValueError(f"Power.normalised: T_ref^k = {t:g}^{kk:g} overflows; shop data give exponents of about 0.5-3") from None
        return cls(a, kk)

    def __call__(self, T, *, throw=True):
        return self.a * _tolerance(T, throw) ** (-self.k)

    def describe(self) -> str:
        return f"power (Sutherland), c = {float(self.a):g}·T^(−{float(self.k):g}) (T in µm)"


class GradeTable(AbstractCostModel):
    """Cost per ISO 1328 grade, interpolated smoothly in the continuous grade of T.

    A tolerance T (µm) is mapped to its continuous grade Q(T) = 5 + 2 log₂(T/T₅) by
    `grade_for_tolerance` (the unrounded √2-per-grade law of the quantity for this gear),
    and log-cost is interpolated over Q by a monotone cubic Hermite spline (C¹; node
    slopes: the weighted harmonic mean of Fritsch and Butland, 1984, inside, the end
    interval's secant at the two ends). At a tabulated grade the cost is the table's;
    between grades it is monotone, with no overshoot.

    Beyond the table ends the log-cost continues along a straight line in Q with the end
    interval's slope s (C¹ at the end). Since Q is linear in ln T, that is a power law
    c ∝ T^(−k) with k = −2s/ln 2 (`Power`), fitted to the last two tabulated grades: finer
    than the finest tabulated grade the cost keeps rising, coarser than the coarsest it
    keeps falling, at the rate of the nearest table interval.

    **Arguments:**

    - `costs_by_grade`: `{grade: cost}`, at least two whole grades of `standard`, costs
      finite and > 0 (the user's own cost data, in any unit), not increasing from a finer
      to a coarser grade.
    - `quantity`, `standard`, `module`, `diameter`, `face_width`, `teeth`: the tolerance
      and gear, as in `iso1328_tolerance`.
    """

    grades: Float[Array, " n"]
    log_costs: Float[Array, " n"]
    slopes: Float[Array, " n"]
    quantity: str = eqx.field(static=True)
    standard: str = eqx.field(static=True)
    module: float = eqx.field(static=True)
    diameter: float = eqx.field(static=True)
    face_width: float | None = eqx.field(static=True)
    teeth: int | None = eqx.field(static=True)

    def __init__(
        self,
        costs_by_grade: Mapping[int, float],
        quantity: str,
        standard: str,
        module: float,
        diameter: float,
        face_width: float | None = None,
        teeth: int | None = None,
    ):
        standard = check_standard(standard)
        # Validates the quantity and the gear once, here.
        iso1328_tolerance(quantity, standard=standard, module=module, diameter=diameter, face_width=face_width, grade=5.0, teeth=teeth)
        if not isinstance(costs_by_grade, Mapping) or len(costs_by_grade) < 2:
            raise ValueError(
                f"GradeTable.costs_by_grade: expected a mapping {{grade: cost}} with at least two grades, got {costs_by_grade!r}"
            )
        lo, hi = GRADES[standard]
        items = []
        for g, c in costs_by_grade.items():
            if isinstance(g, bool) or not (isinstance(g, numbers.Integral) or (isinstance(g, float) and g.is_integer())):
                raise ValueError(f"GradeTable.costs_by_grade: grades must be whole numbers, got {g!r}")
            if not lo <= g <= hi:
                raise ValueError(f"GradeTable.costs_by_grade: grade {g} is outside ISO {standard}'s grades {lo} to {hi}")
            items.append((int(g), _coef(f"GradeTable.costs_by_grade[{g}]", c, positive=True)))
        items.sort()
        for (g0, c0), (g1, c1) in zip(items[:-1], items[1:]):
            if c1 > c0:
                raise ValueError(
                    f"GradeTable.costs_by_grade: grade {g1} costs more ({c1:g}) than the finer grade {g0} "
                    f"({c0:g}); a coarser grade should not cost more"
                )
        x = np.array([g for g, _ in items], dtype=float)
        y = np.log(np.array([c for _, c in items], dtype=float))
        h = np.diff(x)
        delta = np.diff(y) / h
        d = np.empty_like(x)
        d[0], d[-1] = delta[0], delta[-1]
        # Fritsch & Butland (1984) weighted harmonic mean: |d| ≤ 3 min(|δ₋|, |δ₊|), which with
        # the secant end slopes keeps every Hermite piece monotone (Fritsch & Carlson, 1980).
        for i in range(1, len(x) - 1):
            a, b = delta[i - 1], delta[i]
            if a * b <= 0:
                d[i] = 0.0
            else:
                w1, w2 = 2 * h[i] + h[i - 1], h[i] + 2 * h[i - 1]
                d[i] = (w1 + w2) / (w1 / a + w2 / b)
        self.grades, self.log_costs, self.slopes = jnp.asarray(x), jnp.asarray(y), jnp.asarray(d)
        self.quantity, self.standard = quantity, standard
        self.module, self.diameter = float(module), float(diameter)
        self.face_width = None if face_width is None else float(face_width)
        self.teeth = None if teeth is None else int(teeth)

    def grade(self, T: ArrayLike, *, throw: bool = True) -> Float[Array, ...]:
        """Continuous grade of the tolerance `T` µm for this gear and quantity."""
        return grade_for_tolerance(
            _tolerance(T, throw),
            quantity=self.quantity,
            standard=self.standard,
            module=self.module,
            diameter=self.diameter,
            face_width=self.face_width,
            teeth=self.teeth,
        )

    def __call__(self, T, *, throw=True):
        q = self.grade(T, throw=throw)
        x, y, d = self.grades, self.log_costs, self.slopes
        n = x.shape[0]
        i = jnp.clip(jnp.searchsorted(x, q, side="right") - 1, 0, n - 2)
        x0, x1, y0, y1, d0, d1 = x[i], x[i + 1], y[i], y[i + 1], d[i], d[i + 1]
        h = x1 - x0
        t = (q - x0) / h
        t2, t3 = t * t, t * t * t
        inside = (2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + t) * h * d0 + (-2 * t3 + 3 * t2) * y1 + (t3 - t2) * h * d1
        below = y[0] + d[0] * (q - x[0])
        above = y[-1] + d[-1] * (q - x[-1])
        log_c = jnp.where(q < x[0], below, jnp.where(q > x[-1], above, inside))
        return jnp.exp(log_c)

    def describe(self) -> str:
        table = ", ".join(f"{int(g)}: {math.exp(float(c)):g}" for g, c in zip(self.grades, self.log_costs))
        return (
            f"grade table for {self.quantity} (ISO {self.standard}, m {self.module:g} mm, d {self.diameter:g} mm), "
            f"cost by grade {{{table}}}, monotone cubic in log-cost, power law beyond the ends"
        )
