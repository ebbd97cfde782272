"""Tolerance budgets: the cheapest tolerances whose TE meets a specification.

Spec: tolerances.md ("The budget problem"). Decision variables: one tolerance T_i (µm)
per error source; objective: Σ cost_i(T_i); constraint on a TE statistic — the yield
P(TE ≤ spec) ≥ target (equivalently the target-quantile ≤ spec) or mean + kσ ≤ spec.

How it is solved:

- **Common random numbers.** Each sample's magnitude is written T_i · u_i with u_i a
  standard draw of the source's law at its nominal tolerance (u = magnitude / T_nominal),
  and its phases are drawn once; the same draws serve every iteration, so the statistic is
  a deterministic, differentiable function of the tolerances. (This assumes each law
  scales with its tolerance, as "Rayleigh with scale = fraction × tolerance, truncated at
  the tolerance" and "fixed at the tolerance" do.)
- **Smooth statistic.** The target-quantile is the root q of mean σ((q − TE_k)/w) = target,
  a kernel-smoothed quantile of stated width w; TE_k is the exact peak (its gradient is exact).
- **The constraint is always tight.** TE is positively homogeneous of degree 1 in the
  tolerances, so T = e^y · spec / statistic(e^y) meets the spec exactly for every
  direction y, and optimistix's BFGS minimises the cost over y. A source's cost is flat
  beyond its maximum T_max (default 10 × nominal), which bounds sources that barely matter
  (e.g. one an assembly rule cancels); they are held at T_max when the budget is scaled.
- **Checked, not assumed.** The found direction is scaled on a fresh Monte Carlo sample so
  that its exact yield clears the target by four binomial standard errors, then verified on
  another fresh seed (≥ 50,000 samples). The baseline — the cheapest uniform scaling of the
  nominal tolerances — gets the same treatment.
"""

from __future__ import annotations

import math
from typing import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray

from ._costs import AbstractCostModel
from ._errors import Eccentricity, ErrorModel
from ._metrics import te_metric
from ._montecarlo import as_key, sample_keys
from ._precision import require_x64
from .drives._base import AbstractDrive

CONSTRAINTS = ("yield", "mean_k_sigma")


def smooth_quantile(x: Float[Array, " n"], level: float, width, *, iterations: int = 64) -> Float[Array, ""]:
    """Kernel-smoothed `level`-quantile of samples `x`: the q with mean σ((q − x_k)/width) = level.

    Differentiable in `x` and in `width` (which may depend on `x`) by the implicit-function
    theorem: dq = Σ_k σ'_k [dx_k + (q − x_k) dw / w] / Σ_k σ'_k. As width → 0 it tends to the
    empirical quantile.
    """
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


class BudgetProblem(eqx.Module):
    """A tolerance-budget problem (build with `budget_problem`)."""

    drive: AbstractDrive
    model: ErrorModel
    costs: dict[str, AbstractCostModel]
    nominal: dict[str, Array]
    maximum: dict[str, Array]
    minimum: dict[str, Array]
    spec: Float[Array, ""]
    target: Float[Array, ""]
    width: Float[Array, ""]  # relative to the mean TE
    constraint: str = eqx.field(static=True)
    metric: str = eqx.field(static=True)

    @property
    def names(self) -> list[str]:
        return list(self.model.counts)


def budget_problem(
    drive: AbstractDrive,
    model: ErrorModel,
    *,
    costs: Mapping[str, AbstractCostModel],
    nominal: Mapping[str, float],
    spec: float,
    constraint: str = "yield",
    target: float = 0.9973,
    maximum: Mapping[str, float] | None = None,
    minimum: Mapping[str, float] | None = None,
    width: float | None = None,
    metric: str = "peak",
) -> BudgetProblem:
    """Set up a budget problem.

    **Arguments:**

    - `drive`, `model`: the drive and how its errors are drawn at the nominal tolerances
      (phases: random or an assembly rule).
    - `costs`: a cost model per error source.
    - `nominal`: nominal tolerance per source, µm (the laws in `model` are for these).
    - `spec`: the TE specification, rad.
    - `constraint`: "yield" (P(TE ≤ spec) ≥ `target`) or "mean_k_sigma" (mean + `target`·σ ≤ spec).
    - `maximum`: largest tolerance allowed per source, µm (default 10 × nominal).
    - `minimum`: the finest tolerance the shop can hold per source, µm (default 0): a spec that
      even these miss is infeasible, and `optimise_budget` says so.
    - `width`: width of the smoothed quantile relative to the mean TE of the samples (default
      0.005). Relative, so that the statistic stays exactly homogeneous in the tolerances.
    - `metric`: "peak" or "peak_to_peak".
    """
    names = list(model.counts)
    for what, m in (("costs", costs), ("nominal", nominal)):
        missing = [n for n in names if n not in m]
        extra = [n for n in m if n not in names]
        if missing or extra:
            raise ValueError(f"{what}: give one entry per error source {names}" + (f"; missing {missing}" if missing else "")
                             + (f"; unknown {extra}" if extra else ""))
    for n in names:
        if not isinstance(costs[n], AbstractCostModel):
            raise ValueError(f"costs[{n!r}]: expected a cost model such as gearte.Reciprocal(a, b)")
        t = float(nominal[n])
        if not (math.isfinite(t) and t > 0):
            raise ValueError(f"nominal[{n!r}]: a tolerance must be > 0 µm, got {nominal[n]!r}")
    maximum = dict(maximum or {})
    for n in names:
        tmax = float(maximum.get(n, 10 * float(nominal[n])))
        if not (math.isfinite(tmax) and tmax > 0):
            raise ValueError(f"maximum[{n!r}]: must be > 0 µm, got {tmax!r}")
        maximum[n] = tmax
    minimum = dict(minimum or {})
    for n in names:
        tmin = float(minimum.get(n, 0.0))
        if not (math.isfinite(tmin) and 0 <= tmin < maximum[n]):
            raise ValueError(f"minimum[{n!r}]: must be ≥ 0 and below the maximum {maximum[n]:g} µm, got {tmin!r}")
        minimum[n] = tmin
    if not (math.isfinite(spec) and spec > 0):
        raise ValueError(f"spec: the TE specification must be > 0 rad, got {spec!r}")
    if constraint not in CONSTRAINTS:
        raise ValueError(f"constraint: one of {CONSTRAINTS}, got {constraint!r}")
    if constraint == "yield" and not 0.5 <= target < 1:
        raise ValueError(f"target: a yield in [0.5, 1), got {target!r}")
    if constraint == "mean_k_sigma" and not (math.isfinite(target) and target >= 0):
        raise ValueError(f"target: k ≥ 0 for mean + kσ, got {target!r}")
    if metric not in ("peak", "peak_to_peak"):
        raise ValueError(f"metric: 'peak' or 'peak_to_peak', got {metric!r}")
    w = float(width) if width is not None else 5e-3
    if not (math.isfinite(w) and 0 < w < 1):
        raise ValueError(f"width: a relative width in (0, 1), got {width!r}")
    return BudgetProblem(drive=drive, model=model, costs={n: costs[n] for n in names},
                         nominal={n: jnp.asarray(float(nominal[n])) for n in names},
                         maximum={n: jnp.asarray(maximum[n]) for n in names}, minimum={n: jnp.asarray(minimum[n]) for n in names},
                         spec=jnp.asarray(float(spec)),
                         target=jnp.asarray(float(target)), width=jnp.asarray(w), constraint=constraint, metric=metric)


class _Draws(eqx.Module):
    """Standard draws for common random numbers: u = magnitude / nominal, and the phases."""

    u: dict[str, Array]
    phase: dict[str, Array]


def _draws(p: BudgetProblem, key: PRNGKeyArray, n: int) -> _Draws:
    errs = jax.vmap(p.model.sample)(sample_keys(key, 0, n))
    return _Draws(u={k: e.magnitude / p.nominal[k] for k, e in errs.items()}, phase={k: e.phase for k, e in errs.items()})


def te_samples(p: BudgetProblem, tolerances: Mapping[str, Array], draws: _Draws) -> Float[Array, " n"]:
    """Exact TE metric (rad) of every drawn sample at these tolerances (µm)."""
    def one(u, ph):
        errs = {k: Eccentricity(tolerances[k] * u[k], ph[k]) for k in p.names}
        return te_metric(p.drive.signal(errs), p.metric)

    return jax.vmap(one)(draws.u, draws.phase)


def statistic(p: BudgetProblem, x: Float[Array, " n"]) -> Float[Array, ""]:
    """The constrained statistic of TE samples `x` (rad), smooth."""
    if p.constraint == "yield":
        # Width ∝ mean TE keeps the statistic positively homogeneous of degree 1, exactly.
        return smooth_quantile(x, float(p.target), p.width * jnp.mean(x))
    return jnp.mean(x) + p.target * jnp.std(x)


def _tight(p: BudgetProblem, y: Array, draws: _Draws) -> dict[str, Array]:
    """Tolerances in the direction e^y, scaled so that the statistic equals the spec exactly.

    TE is positively homogeneous of degree 1 in the tolerances (magnitudes T_i·u_i, fixed
    phases), so the statistic of s·e^y is s times that of e^y: the scale is spec / statistic(e^y).
    """
    d = {n: jnp.exp(y[i]) for i, n in enumerate(p.names)}
    scale = p.spec / statistic(p, te_samples(p, d, draws))
    return {n: scale * d[n] for n in p.names}


def _capped_cost(p: BudgetProblem, tolerances: Mapping[str, Array]) -> Float[Array, ""]:
    # Beyond its maximum a source costs no less: there is no reason to loosen it further.
    return sum(p.costs[n](jnp.minimum(tolerances[n], p.maximum[n]), throw=False) for n in p.names)


def total_cost(p: BudgetProblem, tolerances: Mapping[str, Array], *, throw: bool = True) -> Float[Array, ""]:
    """Σ cost_i(T_i)."""
    return sum(p.costs[n](tolerances[n], throw=throw) for n in p.names)


class BudgetResult(eqx.Module):
    """A checked budget: tolerances (µm), cost, and the exact statistic on a fresh sample.

    `verified_yield` is P(TE ≤ spec) on `verified_samples` fresh samples; `verified_statistic`
    the constrained statistic there (rad); `converged` whether the solver reported success.
    """

    tolerances: dict[str, float]
    cost: float
    verified_yield: float
    verified_statistic: float
    verified_samples: int
    verified_values: np.ndarray
    converged: bool
    label: str


def _exact_stat(p: BudgetProblem, x: np.ndarray) -> float:
    if p.constraint == "yield":
        return float(np.quantile(x, float(p.target)))
    return float(np.mean(x) + float(p.target) * np.std(x, ddof=1))


def _calibrate_and_verify(p: BudgetProblem, direction: dict[str, float], capped: set[str], *, key, n_check: int, label: str,
                          converged: bool) -> BudgetResult:
    """Scale the uncapped tolerances so the exact statistic on a fresh sample meets the spec with a
    four-standard-error margin, then verify on another fresh sample."""
    k_cal, k_ver = jax.random.split(key)
    cal = _draws(p, k_cal, n_check)
    ver = _draws(p, k_ver, n_check)
    run = jax.jit(lambda t, d: te_samples(p, t, d))
    spec = float(p.spec)
    if p.constraint == "yield":
        t = float(p.target)
        # Four standard errors: the calibration and the verification samples each carry one
        # binomial error, so the verified yield clears the target with ~99.8 % probability.
        level = min(t + 4 * math.sqrt(t * (1 - t) / n_check), 1 - 1.0 / n_check)
        stat = lambda x: float(np.quantile(x, level))
    else:
        stat = lambda x: _exact_stat(p, x)

    def at(scale):
        return {n: jnp.asarray(direction[n] if n in capped else direction[n] * scale) for n in p.names}

    if not capped:
        # Homogeneity: the statistic of s·T is s times that of T (exact for the empirical quantile).
        lo = spec / stat(np.asarray(run(at(1.0), cal)))
    else:
        lo, hi = 1e-3, 1e3
        for _ in range(36):  # bisection in log scale (held sources break homogeneity)
            mid = math.sqrt(lo * hi)
            if stat(np.asarray(run(at(mid), cal))) <= spec:
                lo = mid
            else:
                hi = mid
    tol = at(lo)
    x = np.asarray(run(tol, ver))
    return BudgetResult(tolerances={n: float(v) for n, v in tol.items()}, cost=float(total_cost(p, tol)),
                        verified_yield=float(np.mean(x <= spec)), verified_statistic=_exact_stat(p, x), verified_samples=n_check,
                        verified_values=x, converged=converged, label=label)


def optimise_budget(p: BudgetProblem, *, key: int | PRNGKeyArray, n_samples: int = 4096, n_check: int = 50_000,
                    max_steps: int = 300) -> BudgetResult:
    """The cheapest tolerances meeting the constraint, checked on a fresh Monte Carlo sample.

    **Arguments:**

    - `p`: the problem (`budget_problem`).
    - `key`: seed or key (common random numbers; the calibration and verification samples
      use independent streams).
    - `n_samples`: common random samples in the optimised statistic.
    - `n_check`: fresh samples for calibration and for verification (each).
    """
    require_x64()
    k_crn, k_check = jax.random.split(as_key(key))
    draws = _draws(p, k_crn, n_samples)
    if any(float(v) > 0 for v in p.minimum.values()):
        floor = float(statistic(p, te_samples(p, p.minimum, draws)))
        if floor > float(p.spec):
            raise ValueError(f"infeasible spec: even at the minimum tolerances {({n: float(v) for n, v in p.minimum.items()})} µm "
                             f"the constrained statistic is {floor:.4g} rad > spec {float(p.spec):.4g} rad; loosen the spec, "
                             "lower the yield target, or allow finer tolerances")

    def objective(y, args):
        return _capped_cost(p, _tight(p, y, draws))

    # Start from the nominal tolerances' proportions.
    y0 = jnp.log(jnp.asarray([float(p.nominal[n]) for n in p.names]))
    # The smoothed statistic is not smooth to machine precision: ask for 1e-6 relative cost.
    sol = optx.minimise(objective, optx.BFGS(rtol=1e-6, atol=1e-6), y0, None, max_steps=max_steps, throw=False)
    tol = _tight(p, sol.value, draws)
    capped = {n for n in p.names if float(tol[n]) >= float(p.maximum[n])}
    finer = [n for n in p.names if float(tol[n]) < float(p.minimum[n])]
    if finer:
        raise ValueError(f"the cheapest budget needs {finer} finer than their minimum tolerances; the spec cannot be met "
                         "within them by this budget — loosen the spec or the minimums")
    direction = {n: min(float(tol[n]), float(p.maximum[n])) for n in p.names}
    return _calibrate_and_verify(p, direction, capped, key=k_check, n_check=n_check, label="optimised",
                                 converged=bool(sol.result == optx.RESULTS.successful))


def uniform_scaling(p: BudgetProblem, *, key: int | PRNGKeyArray, n_check: int = 50_000) -> BudgetResult:
    """Baseline: the nominal tolerances scaled by one common factor to meet the same constraint."""
    _, k_check = jax.random.split(as_key(key))
    return _calibrate_and_verify(p, {n: float(v) for n, v in p.nominal.items()}, set(), key=k_check, n_check=n_check,
                                 label="uniform scaling of the nominal tolerances", converged=True)


def contributions(p: BudgetProblem, tolerances: Mapping[str, float], *, key: int | PRNGKeyArray, n_samples: int = 8192) -> dict[str, float]:
    """Gradient contributions ∂statistic/∂T_i · T_i (rad) at these tolerances.

    TE is positively homogeneous of degree 1 in the tolerances, so by Euler's theorem the
    contributions add up to the statistic itself: each is the share of the TE a source owns.
    """
    draws = _draws(p, as_key(key), n_samples)
    t = {n: jnp.asarray(float(tolerances[n])) for n in p.names}
    g = eqx.filter_jit(jax.grad(lambda tt, dr: statistic(p, te_samples(p, tt, dr))))(t, draws)
    return {n: float(g[n] * t[n]) for n in p.names}


def pareto_front(p: BudgetProblem, specs, *, key: int | PRNGKeyArray, n_samples: int = 4096, n_check: int = 50_000) -> list[BudgetResult]:
    """Optimised budgets for each TE spec in `specs` (rad): the cost-vs-spec front."""
    out = []
    for s in specs:
        q = eqx.tree_at(lambda b: b.spec, p, jnp.asarray(float(s)))
        out.append(optimise_budget(q, key=key, n_samples=n_samples, n_check=n_check))
    return out
