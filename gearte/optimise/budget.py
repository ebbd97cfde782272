"""Tolerance budgets: the cheapest tolerances whose metrics meet their specifications, for any drive.

Decision variables: one tolerance T_i per budgeted error source (µm, or rad for angular
sources); objective: Σ cost_i(T_i); constraints on statistics of metrics of the drive's
response — the yield P(metric ≤ spec) ≥ target (equivalently the target-quantile ≤ spec;
for a metric where more is better, such as loaded pairs, P(metric ≥ spec) ≥ target) or
mean + kσ ≤ spec.

How it is solved:

- **Common random numbers.** Each sample's value of a budgeted source is written
  ``c + T_i · u_i``, with c the centre its law is toleranced about (0 for a magnitude) and
  u_i = (draw − c)/T_nominal a standard draw at the nominal tolerance; phases and the other
  sources are drawn once. The same draws serve every iteration, so each statistic is a
  deterministic, differentiable function of the tolerances.
- **Smooth statistics.** The target-quantile is the root q of mean σ((q − x_k)/w) = target, a
  kernel-smoothed quantile of stated width w relative to the mean; each sample's metric is
  the metric's `smooth` value (exact where the metric is already Lipschitz, such as a peak).
- **The constraints are always tight.** Along a direction e^y the tolerances are scaled by
  the largest s that meets every constraint. When the drive is linear and every metric is
  positively homogeneous of degree 1 (a peak of a sinusoidal drive, sources toleranced about
  0) s = spec / statistic(e^y) exactly; otherwise s is found by a bracketed root search in log s, and its
  gradient by the implicit-function theorem (ds/dy = −∂g/∂y / ∂g/∂s). BFGS (optimistix)
  minimises the cost over y. A source's cost is flat beyond its maximum T_max (default 10 ×
  nominal): sources that barely matter are held there.
- **Checked, not assumed.** The found direction is scaled on a fresh Monte Carlo sample so
  that every exact yield clears its target by four binomial standard errors, then verified
  on another fresh seed. The baseline — the cheapest uniform scaling of the nominal
  tolerances — gets the same treatment.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray
from tqdm import tqdm

from ..core.metrics import AbstractMetric, Peak
from ..core.precision import require_x64
from ..core.solution import RESULTS, check
from ..drives.protocol import AbstractDrive, Eccentricity
from ..studies.errors import ErrorModel
from ..studies.laws import AbstractValueLaw
from ..studies.montecarlo import as_key, sample_keys
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
    names = list(costs)
    unknown = [n for n in names if n not in model.specs]
    if unknown:
        raise ValueError(f"costs: {unknown} are not error sources of this drive; use some of {list(model.specs)}")
    if not names:
        raise ValueError("costs: give a cost model for at least one error source")
    for what, m in (("nominal", nominal),):
        missing = [n for n in names if n not in m]
        extra = [n for n in m if n not in names]
        if missing or extra:
            raise ValueError(
                f"{what}: give one entry per budgeted source {names}"
                + (f"; missing {missing}" if missing else "")
                + (f"; unknown {extra}" if extra else "")
            )
    for n in names:
        if not isinstance(costs[n], AbstractCostModel):
            raise ValueError(f"costs[{n!r}]: expected a cost model such as gearte.Reciprocal(a, b)")
        t = float(nominal[n])
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"nominal[{n!r}]: a tolerance must be > 0, got {nominal[n]!r}")
    maximum = dict(maximum or {})
    for n in names:
        tmax = float(maximum.get(n, 10 * float(nominal[n])))
        if not (math.isfinite(tmax) and tmax > 0):
            raise ValueError(f"maximum[{n!r}]: must be > 0, got {tmax!r}")
        maximum[n] = tmax
    minimum = dict(minimum or {})
    for n in names:
        tmin = float(minimum.get(n, 0.0))
        if not (math.isfinite(tmin) and 0 <= tmin < maximum[n]):
            raise ValueError(f"minimum[{n!r}]: must be ≥ 0 and below the maximum {maximum[n]:g}, got {tmin!r}")
        minimum[n] = tmin
    if constraints is None:
        if spec is None:
            raise ValueError("spec: give the specification (rad for an angle), or a list of `constraints`")
        constraints = [Constraint(metric, spec, statistic)]
    elif spec is not None:
        raise ValueError("give either `spec` (one constraint) or `constraints`, not both")
    constraints = tuple(constraints)
    if not constraints:
        raise ValueError("constraints: give at least one")
    offered = drive.metrics
    for c in constraints:
        if not isinstance(c, Constraint):
            raise ValueError(f"constraints: expected gearte.Constraint objects, got {c!r}")
        if c.metric.name not in offered:
            raise ValueError(f"constraint metric {c.metric.name!r}: {type(drive).__name__} offers {list(offered)}")
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


class _Draws(eqx.Module):
    """Common random numbers: the errors at the nominal tolerances, with the budgeted values as standard draws u."""

    u: dict[str, Array]
    errors: dict[str, Any]


def common_draws(p: BudgetProblem, key: PRNGKeyArray, n: int) -> _Draws:
    """`n` common random samples of the problem's errors from `key` (the study's per-sample keys)."""
    return _common_draws_jit(p, key, n)


@eqx.filter_jit
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


_BRACKET = (1e-3, 1e2)  # scale of the direction e^y, which starts at the nominal tolerances


#: Width in log s at which the root search stops (the constraint's root is then known to ~1e-12 relative in s).
_ROOT_TOL = 1e-12
#: Most evaluations of the root search after the bracket is found (Illinois converges superlinearly; ~6-10 are used).
_ROOT_STEPS = 60
#: The violation a scale search counts where the model has no valid state (NaN): far beyond any metric's.
_NO_STATE = 1e3


def _bracketed_root(g, lo: float, hi: float, *, bisect_above: float = math.inf) -> Array:
    """The root of g (increasing: ≤ 0 feasible, > 0 infeasible; finite: the caller maps a NaN to a violation) in
    [lo, hi] (log s, lo < 0 < hi), or the end of the bracket that is the answer: lo where even lo is infeasible, hi
    where even hi is feasible.

    The search brackets the root outwards from log s = 0 (the direction as given: the optimiser starts at the nominal
    tolerances and moves the direction by factors, not orders of magnitude), doubling the step from log 4, so it seldom
    visits the far ends of the bracket (near-perfect parts, where a contact drive's solves are slowest); then the
    Illinois variant of regula falsi (a bracket kept at every step, superlinear convergence) until the bracket is
    `_ROOT_TOL` wide, bisecting while the infeasible end's value is at least `bisect_above` (where the caller counts a
    model without a valid state). Each evaluation is one pass over the common samples: about 8-12 passes for a smooth
    constraint, where a fixed bisection of the whole bracket needed 26."""
    zero = jnp.zeros(())
    g0 = g(zero)
    up = g0 <= 0  # feasible at s = 1: the root lies above

    def widen_cond(state):
        x, gx, _, _, _, k = state
        outside = jnp.where(up, gx <= 0, gx > 0)
        at_end = jnp.where(up, x >= hi, x <= lo)
        return outside & ~at_end & (k < 8)

    def widen(state):
        x, gx, _, _, step, k = state
        nx = jnp.clip(jnp.where(up, x + step, x - step), lo, hi)
        return nx, g(nx), x, gx, 2.0 * step, k + 1

    start = (zero, g0, zero, g0, jnp.asarray(math.log(4.0)), jnp.asarray(0))
    x, gx, prev, g_prev, _, _ = jax.lax.while_loop(widen_cond, widen, start)
    # Feasible end a (g ≤ 0) and infeasible end b (g > 0): the last point and the one before it.
    a = jnp.where(up, prev, x)
    b = jnp.where(up, x, prev)
    ga = jnp.where(up, g_prev, gx)
    gb = jnp.where(up, gx, g_prev)
    bracketed = (ga <= 0) & (gb > 0)

    def cond(state):
        a, b, ga, _, _, _, k = state
        return bracketed & (b - a > _ROOT_TOL) & (ga < 0) & (k < _ROOT_STEPS)

    def body(state):
        a, b, ga, gb, no_state, side, k = state
        c = jnp.clip((a * gb - b * ga) / jnp.where(gb != ga, gb - ga, 1.0), a, b)
        # Bisect while the infeasible end is where the model has no valid state (its value, before any Illinois
        # halving, at least `bisect_above`): regula falsi would creep from the feasible end towards that jump.
        c = jnp.where((c <= a) | (c >= b) | no_state, 0.5 * (a + b), c)
        gc = g(c)
        feasible = gc <= 0
        # Halve the function value at the end that stays twice in a row (Illinois), to avoid one-sided stalls.
        ga_new = jnp.where(feasible, gc, jnp.where(side == -1, 0.5 * ga, ga))
        gb_new = jnp.where(feasible, jnp.where(side == 1, 0.5 * gb, gb), gc)
        no_state_new = jnp.where(feasible, no_state, gc >= bisect_above)
        return jnp.where(feasible, c, a), jnp.where(feasible, b, c), ga_new, gb_new, no_state_new, jnp.where(feasible, 1, -1), k + 1

    start = (a, b, ga, gb, gb >= bisect_above, jnp.asarray(0), jnp.asarray(0))
    a, *_ = jax.lax.while_loop(cond, body, start)
    # Not bracketed: the search stopped at an end of the bracket, which is the answer.
    return jnp.where(bracketed, a, jnp.where(up, hi, lo))


def _scale(p: BudgetProblem, d: Mapping[str, Array], draws: _Draws) -> Array:
    """The largest s (within the bracket) with every constraint met at s·d; differentiable in d."""
    if p.homogeneous:
        # Positive homogeneity: the statistic of s·d is s times that of d.
        x = metric_samples(p, d, draws)
        return jnp.min(jnp.stack([c.spec / statistic(p, x[j], c) for j, c in enumerate(p.constraints)]))

    def g(log_s, dd):
        s = jnp.exp(log_s)
        v = jnp.max(_violation(p, metric_samples(p, {n: s * dd[n] for n in p.names}, draws)))
        # Far outside its tolerances a model may have no valid state (NaN): that is infeasible.
        return jnp.nan_to_num(v, nan=_NO_STATE, posinf=_NO_STATE)

    ds = jax.lax.stop_gradient(d)
    lo, hi = math.log(_BRACKET[0]), math.log(_BRACKET[1])
    root = _bracketed_root(lambda x: g(x, ds), lo, hi, bisect_above=_NO_STATE)
    found = root
    log_s = jax.lax.stop_gradient(found)
    # Implicit-function theorem at the root: d(log s) = −∂g/∂d · dd / ∂g/∂(log s).
    g_s = jax.lax.stop_gradient(jax.grad(g)(log_s, ds))
    g_live = g(log_s, d) - jax.lax.stop_gradient(g(log_s, ds))
    safe = jnp.where(jnp.abs(g_s) > 0, g_s, 1.0)
    return jnp.exp(log_s - jnp.where(jnp.abs(g_s) > 0, g_live / safe, 0.0))


def tight_tolerances(p: BudgetProblem, y: Array, draws: _Draws) -> dict[str, Array]:
    """Tolerances in the direction e^y, scaled so that the binding constraint holds exactly."""
    d = {n: jnp.exp(y[i]) for i, n in enumerate(p.names)}
    s = _scale(p, d, draws)
    return {n: s * d[n] for n in p.names}


def _capped_cost(p: BudgetProblem, tolerances: Mapping[str, Array]) -> Float[Array, ""]:
    # Beyond its maximum a source costs no less: there is no reason to loosen it further.
    return sum(p.costs[n](jnp.minimum(tolerances[n], p.maximum[n]), throw=False) for n in p.names)  # pyright: ignore[reportReturnType]


def total_cost(p: BudgetProblem, tolerances: Mapping[str, Array], *, throw: bool = True) -> Float[Array, ""]:
    """Σ cost_i(T_i)."""
    return sum(p.costs[n](tolerances[n], throw=throw) for n in p.names)  # pyright: ignore[reportReturnType]


class BudgetResult(eqx.Module):
    """A checked budget.

    - `tolerances`: per budgeted source (µm, or rad); `cost`: Σ cost_i.
    - `verified_yield`: fraction of `verified_samples` fresh samples meeting every constraint;
      `verified_yields`: per constraint; `verified_statistic`: the first constraint's exact
      statistic there, over the samples that solved (rad for angles); `verified_values`: the first constraint's exact
      metric per sample (NaN where its solves failed).
    - `failed_solves`: verification samples whose solves failed (a drive that solves, such as the RV reducer; a
      yield counts them as missing its spec, a mean ± kσ is taken over the samples that solved).
    - `result`: the solve's `RESULTS` code; `converged`: whether the optimiser reported success.
    """

    tolerances: dict[str, float]
    cost: float
    verified_yield: float
    verified_yields: tuple[float, ...]
    verified_statistic: float
    verified_samples: int
    verified_values: np.ndarray
    result: RESULTS
    converged: bool
    label: str
    failed_solves: int = 0


# Module-level compiled functions, keyed on the problem's structure and not on a fresh closure: a
# Pareto front, a second budget on the same drive or a random-assembly comparison reuses the code
# compiled for the first (every array in the problem, spec included, is a traced argument).
@eqx.filter_jit
def _exact_samples_jit(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Array:
    return metric_samples(p, tolerances, draws, exact=True)


@eqx.filter_jit
def _worst_violation_jit(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Array:
    return jnp.max(_violation(p, metric_samples(p, tolerances, draws)))


@eqx.filter_jit
def _tight_tolerances_jit(p: BudgetProblem, y: Array, draws: _Draws) -> dict[str, Array]:
    return tight_tolerances(p, y, draws)


@eqx.filter_jit
@functools.partial(jax.grad, argnums=1)
def _statistic_grad_jit(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws, c: Constraint) -> Array:
    return statistic(p, metric_samples(p, tolerances, draws)[0], c)


#: The progress bar of the budget being optimised (None: none shown). The compiled objective reports every evaluation
#: to `_report_cost` through a host callback, which updates whatever bar is set here at that moment.
_BAR: list[Any] = []


def _report_cost(cost) -> None:
    if _BAR:
        _BAR[-1].set_postfix_str(f"cost {float(cost):.6g}", refresh=False)
        _BAR[-1].update(1)


def _cost_objective(y: Array, args: tuple[BudgetProblem, _Draws]) -> Array:
    """The budget's objective: the capped cost of the tight tolerances in the direction e^y."""
    p, draws = args
    return _capped_cost(p, tight_tolerances(p, y, draws))


def _cost_objective_shown(y: Array, args: tuple[BudgetProblem, _Draws]) -> Array:
    """`_cost_objective`, reporting every evaluation to the progress bar. A program with a host callback is not kept in
    JAX's persistent compilation cache, so this one is used only where the bar is shown."""
    cost = _cost_objective(y, args)
    jax.debug.callback(_report_cost, cost)
    return cost


def _met(c: Constraint, x: np.ndarray) -> np.ndarray:
    return x >= float(c.spec) if c.metric.higher_is_better else x <= float(c.spec)


def _solved(c: Constraint, x: np.ndarray) -> np.ndarray:
    """The samples of `x` (exact values of `c`'s metric) whose solves succeeded: those not set to `_missed`."""
    return x[x != float(_missed(c))]


def _exact_stat(c: Constraint, x: np.ndarray, margin_samples: int | None = None) -> float:
    """`c`'s exact statistic of `x`. A yield counts a sample whose solves failed as missing its spec; a mean ± kσ has
    no value to average for it, and is taken over the samples that solved (their number is reported apart)."""
    if not isinstance(c.statistic, Yield):
        x = _solved(c, x)
    return c.statistic.exact(x, lower=c.metric.higher_is_better, margin_samples=margin_samples)


def _calibrate_and_verify(
    p: BudgetProblem,
    direction: dict[str, float],
    capped: set[str],
    *,
    key,
    n_check: int,
    label: str,
    result,
    converged: bool,
    progress: bool | None = None,
) -> BudgetResult:
    """Scale the uncapped tolerances so every exact statistic on a fresh sample meets its spec with
    a four-standard-error margin, then verify on another fresh sample. `progress`: a bar over the passes over the
    fresh samples (default: when stderr is a terminal)."""
    k_cal, k_ver = jax.random.split(key)
    cal = common_draws(p, k_cal, n_check)
    ver = common_draws(p, k_ver, n_check)
    show = sys.stderr.isatty() if progress is None else progress
    desc = f"budget: calibrating and verifying ({label}) on {n_check:,} fresh samples"
    with tqdm(desc=desc, unit=" passes", disable=not show, leave=False) as bar:
        return _calibrate_and_verify_with(
            p, direction, capped, cal, ver, bar, n_check=n_check, label=label, result=result, converged=converged
        )


def _calibrate_and_verify_with(
    p: BudgetProblem,
    direction: dict[str, float],
    capped: set[str],
    cal: _Draws,
    ver: _Draws,
    bar: Any,
    *,
    n_check: int,
    label: str,
    result,
    converged: bool,
) -> BudgetResult:
    """`_calibrate_and_verify` on drawn calibration and verification samples, counting its passes on `bar`."""

    def run(t, d):
        x = _exact_samples_jit(p, t, d)
        bar.update(1)
        return x

    def ok(x) -> bool:
        return all(
            (_exact_stat(c, np.asarray(x[j]), n_check) >= float(c.spec))
            if c.metric.higher_is_better
            else (_exact_stat(c, np.asarray(x[j]), n_check) <= float(c.spec))
            for j, c in enumerate(p.constraints)
        )

    def at(scale):
        return {n: jnp.asarray(direction[n] if n in capped else direction[n] * scale) for n in p.names}

    if not capped and p.homogeneous:
        # Homogeneity: the statistic of s·T is s times that of T (exact for the empirical quantile).
        x = np.asarray(run(at(1.0), cal))
        lo = min(float(c.spec) / _exact_stat(c, x[j], n_check) for j, c in enumerate(p.constraints))
    else:
        # Held sources or a non-linear drive break homogeneity: bisection in log scale. The direction is already tight
        # on the common samples (scale 1), so the bracket starts at [1/2, 2] and widens 4-fold at a time (within
        # [1e-3, 1e3]) until it holds the step of the exact statistics; then 1e-5 relative is enough.
        lo, hi = 0.5, 2.0
        widened_down = False
        while lo > 1e-3 and not ok(run(at(lo), cal)):
            lo, hi, widened_down = max(lo / 4, 1e-3), lo, True
        while not widened_down and hi < 1e3 and ok(run(at(hi), cal)):  # (hi is known to fail if the bracket went down)
            lo, hi = hi, min(hi * 4, 1e3)
        while math.log(hi / lo) > 1e-5:
            mid = math.sqrt(lo * hi)
            if ok(run(at(mid), cal)):
                lo = mid
            else:
                hi = mid
    tol = at(lo)
    if not ok(run(tol, cal)):
        # The finest scale searched still misses the target: the spec cannot be met this way.
        result = RESULTS.infeasible
    x = np.asarray(run(tol, ver))
    met = [_met(c, x[j]) for j, c in enumerate(p.constraints)]
    failed = int(np.sum(x[0] == float(_missed(p.constraints[0]))))
    return BudgetResult(
        tolerances={n: float(v) for n, v in tol.items()},
        cost=float(total_cost(p, tol)),
        verified_yield=float(np.mean(np.logical_and.reduce(met))),
        verified_yields=tuple(float(np.mean(m)) for m in met),
        verified_statistic=_exact_stat(p.constraints[0], _solved(p.constraints[0], x[0])),
        verified_samples=n_check,
        verified_values=np.where(x[0] == float(_missed(p.constraints[0])), np.nan, x[0]),
        result=result,
        converged=converged,
        label=label,
        failed_solves=failed,
    )


def optimise_budget(
    p: BudgetProblem,
    *,
    key: int | PRNGKeyArray,
    n_samples: int = 4096,
    n_check: int = 50_000,
    max_steps: int = 300,
    throw: bool = True,
    progress: bool | None = None,
) -> BudgetResult:
    """The cheapest tolerances meeting the constraints, checked on a fresh Monte Carlo sample.

    **Arguments:**

    - `p`: the problem (`budget_problem`).
    - `key`: seed or key (common random numbers; the calibration and verification samples
      use independent streams).
    - `n_samples`: common random samples in the optimised statistics.
    - `n_check`: fresh samples for calibration and for verification (each).
    - `throw`: raise if the spec is infeasible within the minimum tolerances or the optimiser
      fails (else check the result's `result`).
    - `progress`: show the optimiser's evaluations of the cost on stderr (default: when stderr is a terminal);
      each evaluation scales the tolerances by a root search over the common samples. (The optimiser's program is
      then not kept in JAX's persistent compilation cache, which does not store host callbacks.)

    **Returns:** a `BudgetResult`.
    """
    require_x64()
    k_crn, k_check = jax.random.split(as_key(key))
    draws = common_draws(p, k_crn, n_samples)
    # Feasible at all? At the minimum tolerances, or (none given) at the finest the scale search reaches.
    finest = {n: (p.minimum[n] if float(p.minimum[n]) > 0 else _BRACKET[0] * p.nominal[n]) for n in p.names}
    worst = float(_worst_violation_jit(p, finest, draws))
    if worst > 0:
        check(
            RESULTS.infeasible,
            throw=throw,
            what=f"optimise_budget: even at the tolerances "
            f"{ ({n: float(v) for n, v in finest.items()}) } a constraint is missed by {worst:.4g} (the other sources' "
            "laws alone break it)",
        )
        return _failed(p, RESULTS.infeasible)

    # Start from the nominal tolerances' proportions.
    y0 = jnp.log(jnp.asarray([float(p.nominal[n]) for n in p.names]))
    # The smoothed statistic is not smooth to machine precision: ask for 1e-6 relative cost.
    show = sys.stderr.isatty() if progress is None else progress
    with tqdm(desc="budget: BFGS on the smoothed cost", unit=" evaluations", disable=not show, leave=False) as bar:
        _BAR.append(bar)
        try:
            fn = _cost_objective_shown if show else _cost_objective
            sol = optx.minimise(fn, optx.BFGS(rtol=1e-6, atol=1e-6), y0, (p, draws), max_steps=max_steps, throw=False)
            jax.effects_barrier()
        finally:
            _BAR.pop()
    tol = _tight_tolerances_jit(p, sol.value, draws)
    capped = {n for n in p.names if float(tol[n]) >= float(p.maximum[n])}
    finer = [n for n in p.names if float(tol[n]) < float(p.minimum[n])]
    if finer:
        check(
            RESULTS.infeasible, throw=throw, what=f"optimise_budget: the cheapest budget needs {finer} finer than their minimum tolerances"
        )
        return _failed(p, RESULTS.infeasible)
    direction = {n: min(float(tol[n]), float(p.maximum[n])) for n in p.names}
    result = RESULTS.promote(sol.result)
    converged = bool(sol.result == optx.RESULTS.successful)
    check(result, throw=throw, what="optimise_budget (BFGS on the smoothed cost)")
    return _calibrate_and_verify(
        p, direction, capped, key=k_check, n_check=n_check, label="optimised", result=result, converged=converged, progress=progress
    )


def _failed(p: BudgetProblem, result) -> BudgetResult:
    nan = float("nan")
    return BudgetResult(
        tolerances={n: nan for n in p.names},
        cost=nan,
        verified_yield=nan,
        verified_yields=(),
        verified_statistic=nan,
        verified_samples=0,
        verified_values=np.zeros(0),
        result=result,
        converged=False,
        label="infeasible",
    )


def uniform_scaling(p: BudgetProblem, *, key: int | PRNGKeyArray, n_check: int = 50_000, progress: bool | None = None) -> BudgetResult:
    """Baseline: the nominal tolerances scaled by one common factor to meet the same constraints (`progress`: a bar
    over the passes over the fresh samples, by default when stderr is a terminal)."""
    _, k_check = jax.random.split(as_key(key))
    return _calibrate_and_verify(
        p,
        {n: float(v) for n, v in p.nominal.items()},
        set(),
        key=k_check,
        n_check=n_check,
        label="uniform scaling of the nominal tolerances",
        result=RESULTS.successful,
        converged=True,
        progress=progress,
    )


def contributions(p: BudgetProblem, tolerances: Mapping[str, float], *, key: int | PRNGKeyArray, n_samples: int = 8192) -> dict[str, float]:
    """Gradient contributions ∂statistic/∂T_i · T_i of the first constraint at these tolerances (rad for angles).

    For a homogeneous problem (a linear drive's peak) the contributions add up to the
    statistic itself by Euler's theorem: each is the share of the TE a source owns.
    """
    draws = common_draws(p, as_key(key), n_samples)
    t = {n: jnp.asarray(float(tolerances[n])) for n in p.names}
    c0 = p.constraints[0]
    g = _statistic_grad_jit(p, t, draws, c0)
    return {n: float(g[n] * t[n]) for n in p.names}


def pareto_front(
    p: BudgetProblem, specs, *, key: int | PRNGKeyArray, n_samples: int = 4096, n_check: int = 50_000, progress: bool | None = None
) -> list[BudgetResult]:
    """Optimised budgets for each spec of the first constraint in `specs` (rad for angles): the cost-vs-spec front
    (`progress` as for `optimise_budget`)."""
    out = []
    for s in specs:
        q = eqx.tree_at(lambda b: b.constraints[0].spec, p, jnp.asarray(float(s)))
        out.append(optimise_budget(q, key=key, n_samples=n_samples, n_check=n_check, throw=False, progress=progress))
    return out
