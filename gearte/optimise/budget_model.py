"""A tolerance budget's problem and its Monte Carlo samples (`gearte.budget_problem`, solved by `gearte.optimise_budget`).

The budgeted sources, their nominal and extreme tolerances and costs, the constraints (a statistic of a metric
against its spec), the common random draws (each budgeted value written ``c + T_i · u_i``: its law's centre, the
tolerance and a standard draw) and each constraint's metric for every draw at given tolerances, smooth for the
optimiser or exact for the checks (module notes of `gearte.optimise.budget`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.metrics import AbstractMetric, Peak, check_offered
from ..core.programs import kept_jit
from ..core.validate import as_float, check_names
from ..drives.protocol import AbstractDrive, Eccentricity
from ..studies.errors import ErrorModel, check_drive_model
from ..studies.laws import AbstractValueLaw
from ..studies.montecarlo import sample_keys
from .costs import AbstractCostModel
from .statistics import AbstractStatistic, Yield


class Constraint(eqx.Module):
    """One constraint of a budget: `statistic` of `metric` against `spec` (rad for angles, pairs for counts)."""

    metric: AbstractMetric
    spec: Float[Array, ""]
    statistic: AbstractStatistic

    def __init__(self, metric: AbstractMetric, spec: float, statistic: AbstractStatistic = Yield()):
        if not isinstance(metric, AbstractMetric):
            raise ValueError(f"Constraint.metric: a metric object such as gearte.Peak(), got {metric!r}")
        if not isinstance(statistic, AbstractStatistic):
            raise ValueError(f"Constraint.statistic: gearte.Yield(target) or gearte.MeanKSigma(k), got {statistic!r}")
        s = float(spec)
        if not (math.isfinite(s) and s > 0):
            raise ValueError(f"Constraint.spec: the specification of {metric.name} must be > 0, got {spec!r}")
        self.metric, self.spec, self.statistic = metric, jnp.asarray(s), statistic


class BudgetProblem(eqx.Module):
    """A tolerance-budget problem (build with `budget_problem`)."""

    drive: AbstractDrive
    model: ErrorModel
    costs: dict[str, AbstractCostModel]
    nominal: dict[str, Array]
    maximum: dict[str, Array]
    minimum: dict[str, Array]
    constraints: tuple[Constraint, ...]
    width: Float[Array, ""]  # relative to the mean of each metric
    # The order of the budgeted sources, static: a dict field comes back from `jit` with its keys sorted, so an
    # order taken from `costs` would differ inside and outside a compiled function (and the components of the
    # optimiser's y, built outside, would be read as other sources inside).
    order: tuple[str, ...] = eqx.field(static=True)

    @property
    def names(self) -> list[str]:
        """The budgeted sources, in the order given (the components of the optimiser's y), inside `jit` as outside."""
        return list(self.order)

    @property
    def homogeneous(self) -> bool:
        """Whether every statistic is positively homogeneous of degree 1 in the tolerances."""
        return (
            self.drive.linear
            and all(c.metric.homogeneous and not c.metric.higher_is_better for c in self.constraints)
            and all(_centre(self.model, n) is None for n in self.names)
            and set(self.names) == set(self.model.specs)
        )


def _centre(model: ErrorModel, name: str):
    """The centre a deviation source is toleranced about, or None for 0 (magnitudes)."""
    if model.specs[name].kind == "eccentricity":
        return None
    law = model.sources[name].magnitude
    if isinstance(law, AbstractValueLaw) and law.banded:
        return law.centre()
    return None


def budget_problem(
    drive: AbstractDrive,
    model: ErrorModel,
    *,
    costs: Mapping[str, AbstractCostModel],
    nominal: Mapping[str, float],
    spec: float | None = None,
    statistic: AbstractStatistic = Yield(),
    metric: AbstractMetric = Peak(),
    constraints: Sequence[Constraint] | None = None,
    maximum: Mapping[str, float] | None = None,
    minimum: Mapping[str, float] | None = None,
    width: float | None = None,
) -> BudgetProblem:
    """Set up a budget problem.

    **Arguments:**

    - `drive`, `model`: the drive and how its errors are drawn at the nominal tolerances
      (phases: random or an assembly rule).
    - `costs`: a cost model per budgeted error source (sources not named keep their laws).
    - `nominal`: nominal tolerance per budgeted source (µm, or rad; the laws in `model` are for these).
    - `spec`, `statistic`, `metric`: one constraint, ``statistic(metric) ≤ spec`` (spec in rad
      for angles); or give `constraints`, a list of `Constraint`s, instead.
    - `maximum`: largest tolerance allowed per source (default 10 × nominal).
    - `minimum`: the finest tolerance the shop can hold per source (default 0): a spec that
      even these miss is infeasible, and `optimise_budget` says so.
    - `width`: width of the smoothed quantile relative to the mean of each metric (default
      0.005). Relative, so that a homogeneous statistic stays exactly homogeneous.
    """
    check_drive_model(drive, model)
    if not isinstance(costs, Mapping):
        raise ValueError(
            f"costs: a mapping of error source → cost model, e.g. {{'sun_manufacturing': gearte.Reciprocal(0.0, 40.0)}}; got {costs!r}"
        )
    if not isinstance(nominal, Mapping):
        raise ValueError(f"nominal: a mapping of budgeted source → nominal tolerance; got {nominal!r}")
    names = list(costs)
    unknown = [n for n in names if n not in model.specs]
    if unknown:
        raise ValueError(f"costs: {unknown} are not error sources of this drive; use some of {list(model.specs)}")
    if not names:
        raise ValueError("costs: give a cost model for at least one error source")
    check_names(nominal, names, what=f"nominal: give one entry per budgeted source {names}")
    for n in names:
        if not isinstance(costs[n], AbstractCostModel):
            raise ValueError(f"costs[{n!r}]: expected a cost model such as gearte.Reciprocal(a, b)")
        as_float(f"nominal[{n!r}]", nominal[n], positive=True, hint="a tolerance")
    for what, m in (("maximum", maximum), ("minimum", minimum)):
        if m is not None and not isinstance(m, Mapping):
            raise ValueError(f"{what}: a mapping of budgeted source → tolerance, got {m!r}")
        extra = [n for n in (m or {}) if n not in names]
        if extra:
            raise ValueError(f"{what}: {extra} are not budgeted sources; use some of {names}")
    maximum = dict(maximum or {})
    for n in names:
        tmax = as_float(f"maximum[{n!r}]", maximum.get(n, 10 * float(nominal[n])), positive=True)
        maximum[n] = tmax
    minimum = dict(minimum or {})
    for n in names:
        tmin = as_float(f"minimum[{n!r}]", minimum.get(n, 0.0))
        if not 0 <= tmin < maximum[n]:
            raise ValueError(f"minimum[{n!r}]: must be ≥ 0 and below the maximum {maximum[n]:g}, got {tmin!r}")
        minimum[n] = tmin
    if constraints is None:
        if spec is None:
            raise ValueError("spec: give the specification (rad for an angle), or a list of `constraints`")
        constraints = [Constraint(metric, spec, statistic)]
    elif spec is not None:
        raise ValueError("give either `spec` (one constraint) or `constraints`, not both")
    if isinstance(constraints, Constraint) or not isinstance(constraints, (list, tuple)):
        raise ValueError(f"constraints: a list of gearte.Constraint objects, got {constraints!r}")
    constraints = tuple(constraints)
    if not constraints:
        raise ValueError("constraints: give at least one")
    for c in constraints:
        if not isinstance(c, Constraint):
            raise ValueError(f"constraints: expected gearte.Constraint objects, got {c!r}")
        check_offered(c.metric, drive, what="constraint metric")
    w = float(width) if width is not None else 5e-3
    if not (math.isfinite(w) and 0 < w < 1):
        raise ValueError(f"width: a relative width in (0, 1), got {width!r}")
    return BudgetProblem(
        drive=drive,
        model=model,
        costs={n: costs[n] for n in names},
        nominal={n: jnp.asarray(float(nominal[n])) for n in names},
        maximum={n: jnp.asarray(maximum[n]) for n in names},
        minimum={n: jnp.asarray(minimum[n]) for n in names},
        constraints=constraints,
        width=jnp.asarray(w),
        order=tuple(names),
    )


def check_tolerances(p: BudgetProblem, tolerances) -> dict[str, float]:
    """`tolerances` (µm, or rad for angles; None: the nominal ones) as one finite float > 0 per budgeted source of `p`;
    raises ValueError naming the missing, unknown or invalid entry."""
    if tolerances is None:
        return {n: float(p.nominal[n]) for n in p.names}
    if not isinstance(tolerances, Mapping):
        raise ValueError(f"tolerances: a mapping source → tolerance (µm), got {type(tolerances).__name__}")
    check_names(tolerances, p.names, what=f"tolerances: give one tolerance (µm) per error source {p.names}")
    out = {}
    for n in p.names:
        try:
            t = float(tolerances[n])
        except (TypeError, ValueError):
            raise ValueError(f"tolerances[{n!r}]: expected a number (µm), got {tolerances[n]!r}") from None
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"tolerances[{n!r}]: a tolerance must be finite and > 0 µm, got {tolerances[n]!r}")
        out[n] = t
    return out


class _Draws(eqx.Module):
    """Common random numbers: the errors at the nominal tolerances, with the budgeted values as standard draws u."""

    u: dict[str, Array]
    errors: dict[str, Any]


def common_draws(p: BudgetProblem, key: PRNGKeyArray, n: int) -> _Draws:
    """`n` common random samples of the problem's errors from `key` (the study's per-sample keys)."""
    return _common_draws_jit(p, key, n)


@kept_jit
def _common_draws_jit(p: BudgetProblem, key: PRNGKeyArray, n: int) -> _Draws:
    errs = jax.vmap(p.model.sample)(sample_keys(key, 0, n))
    u = {}
    for k in p.names:
        e = errs[k]
        c = _centre(p.model, k)
        value = e.magnitude if isinstance(e, Eccentricity) else e
        u[k] = (value if c is None else value - c) / p.nominal[k]
    return _Draws(u=u, errors=errs)


def _errors_at(p: BudgetProblem, tolerances: Mapping[str, Array], u: Mapping[str, Array], errors: Mapping[str, Any]) -> dict:
    out = dict(errors)
    for k in p.names:
        c = _centre(p.model, k)
        value = tolerances[k] * u[k] if c is None else c + tolerances[k] * u[k]
        e = errors[k]
        out[k] = Eccentricity(value, e.phase) if isinstance(e, Eccentricity) else value
    return out


def metric_samples(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws, *, exact: bool = False) -> Float[Array, "c n"]:
    """Each constraint's metric (rad for angles) for every drawn sample at these tolerances: smooth, or `exact`."""

    def one(u, errs):
        r = p.drive.response(_errors_at(p, tolerances, u, errs))
        if not exact:
            return jnp.stack([c.metric.smooth(p.drive, r) for c in p.constraints])
        # The exact checks (calibration, verification) mark a sample whose solves failed (its metric would be that of
        # a wrong state) with a value far beyond every spec: a yield counts it as missing, a mean ± kσ leaves it out.
        ok = p.drive.solved(r)
        return jnp.stack([jnp.where(ok, c.metric(p.drive, r), _missed(c)) for c in p.constraints])

    return jax.vmap(one)(draws.u, draws.errors).T


def _missed(c: Constraint) -> Array:
    """A finite value of `c`'s metric that misses its spec by far (a sample whose solves failed)."""
    far = 1e3 * jnp.maximum(jnp.abs(c.spec), 1.0)
    return -far if c.metric.higher_is_better else far


def te_samples(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Float[Array, " n"]:
    """The first constraint's exact metric for every drawn sample (rad)."""
    return metric_samples(p, tolerances, draws, exact=True)[0]


def statistic(p: BudgetProblem, x: Float[Array, " n"], c: Constraint | None = None) -> Float[Array, ""]:
    """The constrained statistic of metric samples `x`, smooth (rad for angles)."""
    c = p.constraints[0] if c is None else c
    return c.statistic.smooth(x, lower=c.metric.higher_is_better, width=p.width)


def _violation(p: BudgetProblem, x: Array) -> Array:
    """Per constraint, statistic − spec (≤ 0 where met), signed so that it grows with the tolerances."""
    out = []
    for j, c in enumerate(p.constraints):
        s = statistic(p, x[j], c)
        out.append(c.spec - s if c.metric.higher_is_better else s - c.spec)
    return jnp.stack(out)
