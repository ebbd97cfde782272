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
  0) s = spec / statistic(e^y) exactly; otherwise s is found by a bracketed root search in log s
  (`gearte.optimise.root_search`), and its gradient by the implicit-function theorem (ds/dy = −∂g/∂y / ∂g/∂s). BFGS (optimistix)
  minimises the cost over y. A source's cost is flat beyond its maximum T_max (default 10 ×
  nominal): sources that barely matter are held there.
- **Checked, not assumed.** The found direction is scaled on a fresh Monte Carlo sample so
  that every exact yield clears its target by four binomial standard errors, then verified
  on another fresh seed. The baseline — the cheapest uniform scaling of the nominal
  tolerances — gets the same treatment.

The problem, its common draws and its metric samples are in `gearte.optimise.budget_model`; this module scales,
optimises, calibrates and verifies.
"""

from __future__ import annotations

import functools
import math
import sys
from collections.abc import Iterable, Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray
from tqdm import tqdm

from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.solution import RESULTS, check
from ..core.validate import as_int
from ..studies.montecarlo import as_key
from .budget_model import (
    BudgetProblem,
    Constraint,
    _Draws,
    _missed,
    _violation,
    check_tolerances,
    common_draws,
    metric_samples,
    statistic,
)
from .root_search import bracketed_root
from .statistics import Yield

_BRACKET = (1e-3, 1e2)  # scale of the direction e^y, which starts at the nominal tolerances


#: The violation a scale search counts where the model has no valid state (NaN): far beyond any metric's.
_NO_STATE = 1e3


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
    root = bracketed_root(lambda x: g(x, ds), lo, hi, bisect_above=_NO_STATE)
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
      statistic there, over the samples that solved (rad for angles); `verified_statistics`: every constraint's (in
      its metric's units: rad for angles, a count for pairs); `verified_values`: the first constraint's exact metric per
      sample (NaN where its solves failed).
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
    verified_statistics: tuple[float, ...] = ()


# Module-level compiled functions, keyed on the problem's structure and not on a fresh closure: a
# Pareto front, a second budget on the same drive or a random-assembly comparison reuses the code
# compiled for the first (every array in the problem, spec included, is a traced argument).
@kept_jit
def _exact_samples_jit(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Array:
    return metric_samples(p, tolerances, draws, exact=True)


@kept_jit
def _worst_violation_jit(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Array:
    return jnp.max(_violation(p, metric_samples(p, tolerances, draws)))


@kept_jit
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


#: The optimiser of the budget's smoothed cost: it is not smooth to machine precision, so 1e-6 relative.
_BFGS = optx.BFGS(rtol=1e-6, atol=1e-6)


@kept_jit
def _minimise_cost(p: BudgetProblem, y0: Array, draws: _Draws, max_steps: int) -> optx.Solution:
    """BFGS on `_cost_objective` from y0, compiled once per problem structure (a repeat run loads its program)."""
    return optx.minimise(_cost_objective, _BFGS, y0, (p, draws), max_steps=max_steps, throw=False)


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
        # (less a few rounding units: the statistic of the scaled tolerances is s times that of T only to rounding, and
        # the check below must not find the exact scale a hair over the spec)
        lo = min(float(c.spec) / _exact_stat(c, x[j], n_check) for j, c in enumerate(p.constraints)) * (1 - 1e-12)
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
        verified_statistics=tuple(_exact_stat(c, _solved(c, x[j])) for j, c in enumerate(p.constraints)),
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
    n_samples = as_int("optimise_budget: n_samples", n_samples, minimum=1)
    n_check = as_int("optimise_budget: n_check", n_check, minimum=1)
    max_steps = as_int("optimise_budget: max_steps", max_steps, minimum=1)
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
    show = sys.stderr.isatty() if progress is None else progress
    with tqdm(desc="budget: BFGS on the smoothed cost", unit=" evaluations", disable=not show, leave=False) as bar:
        _BAR.append(bar)
        try:
            if show:
                sol = optx.minimise(_cost_objective_shown, _BFGS, y0, (p, draws), max_steps=max_steps, throw=False)
            else:
                sol = _minimise_cost(p, y0, draws, max_steps)
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
    res = _calibrate_and_verify(
        p, direction, capped, key=k_check, n_check=n_check, label="optimised", result=result, converged=converged, progress=progress
    )
    if bool(res.result == RESULTS.infeasible):
        check(
            res.result,
            throw=throw,
            what=f"optimise_budget: on {n_check:,} fresh samples the optimiser's tolerances, scaled down to 1e-3 of them, "
            "still miss a constraint by more than four standard errors",
        )
    return res


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
    n_check = as_int("uniform_scaling: n_check", n_check, minimum=1)
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
    statistic itself by Euler's theorem: each is the share of the TE a source owns. `tolerances`: one value > 0 per
    budgeted source; `n_samples` ≥ 1.
    """
    tol = check_tolerances(p, tolerances)
    n_samples = as_int("n_samples", n_samples, minimum=1)
    draws = common_draws(p, as_key(key), n_samples)
    t = {n: jnp.asarray(tol[n]) for n in p.names}
    c0 = p.constraints[0]
    g = _statistic_grad_jit(p, t, draws, c0)
    return {n: float(g[n] * t[n]) for n in p.names}


def pareto_front(
    p: BudgetProblem,
    specs,
    *,
    key: int | PRNGKeyArray,
    n_samples: int = 4096,
    n_check: int = 50_000,
    throw: bool = False,
    progress: bool | None = None,
) -> list[BudgetResult]:
    """Optimised budgets for each spec of the first constraint in `specs` (rad for angles): the cost-vs-spec front
    (`progress` as for `optimise_budget`). Each spec is checked as `Constraint` checks it (> 0) before any is solved.
    `throw`: raise at the first spec that cannot be met or whose optimiser fails, as `optimise_budget(throw=True)`
    does (default False: such a point comes back with its `result` set, and the front goes on)."""
    c0 = p.constraints[0]
    if isinstance(specs, (str, bytes)) or not isinstance(specs, Iterable):
        raise ValueError(f"pareto_front: specs: a list of specs of the first constraint (rad for angles), got {specs!r}")
    problems = []
    for i, s in enumerate(specs):
        try:
            c = Constraint(c0.metric, s, c0.statistic)
        except (TypeError, ValueError) as e:
            raise ValueError(f"pareto_front: specs[{i}]: {e}") from None
        problems.append(eqx.tree_at(lambda b: b.constraints, p, (c, *p.constraints[1:])))
    return [optimise_budget(q, key=key, n_samples=n_samples, n_check=n_check, throw=throw, progress=progress) for q in problems]
