"""Assembly-phase allocation: choose how parts are turned at assembly to cut the TE (rules here; measured parts
in `allocation_measured`).

Two situations (Wang et al. 2013, sections 1 and 3):

- **Measured parts** (`allocate_measured`): every magnitude and manufacturing phase is
  known; choose the adjustable phases that minimise the exact peak (or peak-to-peak).
- **Unmeasured parts** (`allocate_rule`): only the tolerances are known; choose an
  assembly *rule* — adjustable phases as offsets from a datum phase (Wang et al.'s β_r) or
  as absolute values — that minimises the worst case over the unknown manufacturing
  phases, the expected TE over them, or the expected TE when the magnitudes are random
  too. Wang et al.'s collinear compensation (λ_i = ±1) is one candidate, not a limit: the
  optimiser works on the true objective, where phasors may close a polygon.

Optimisation runs on smooth surrogates with optimistix (BFGS, multi-start under
`vmap`); every reported figure is the exact metric.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.extrema import smooth_peak
from ..core.metrics import AbstractMetric, Peak, PeakToPeak
from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.signal import Components, to_signal
from ..core.solution import RESULTS, check
from ..core.units import TWO_PI as _TWO_PI
from ..core.validate import as_float, as_int, check_array_values, check_names
from ..drives.protocol import AbstractSinusoidalDrive, Eccentricity
from ..studies.errors import ErrorModel, check_drive_model
from ..studies.laws import FixedPhase, RelativePhase, UniformPhase
from ..studies.montecarlo import as_key, monte_carlo
from .rule_objectives import RULE_OBJECTIVES, AbstractRuleObjective, WorstCase


def starts_result(results, best) -> tuple[int, Any]:
    """How many starts succeeded, and the result code of the solve: that of the best start, or
    `some_starts_failed` when it succeeded but others did not (reported, not hidden)."""
    ok = np.asarray(results == optx.RESULTS.successful)
    best_ok = bool(ok[int(best)])
    if not best_ok:
        return int(ok.sum()), RESULTS.promote(jax.tree.map(lambda v: v[int(best)], results))
    return int(ok.sum()), RESULTS.successful if ok.all() else RESULTS.some_starts_failed


def best_start(values, results, *, rtol: float = 1e-9) -> int:
    """The start with the lowest exact value; among starts that tie it (within `rtol` relative: the same
    optimum, reached to rounding), one whose solve converged, so a tie is not reported as a failure."""
    v = np.asarray(values, dtype=np.float64)
    ok = np.asarray(results == optx.RESULTS.successful)
    tied = v <= v.min() + rtol * max(abs(float(v.min())), 1e-300)
    pool = np.nonzero(tied & ok)[0]
    return int(pool[np.argmin(v[pool])]) if pool.size else int(np.argmin(v))


def partial_success(result) -> bool:
    """Whether the best start succeeded but some others did not (reported, not raised)."""
    return bool(result == RESULTS.some_starts_failed)


def check_phase_drive(drive) -> None:
    if not isinstance(drive, AbstractSinusoidalDrive):
        raise ValueError(
            f"assembly-phase allocation needs a drive whose TE is a sum of sinusoids with phases "
            f"(planetary, harmonic, explicit); {type(drive).__name__} is not one"
        )


def check_extremum_metric(metric) -> None:
    if not isinstance(metric, (Peak, PeakToPeak)):
        raise ValueError(f"metric: gearte.Peak() or gearte.PeakToPeak(), got {metric!r}")


# ------------------------------------------------------------------ unmeasured parts: assembly rules


class RuleProblem(eqx.Module):
    """An assembly-rule problem: which phases are unknown, which are chosen, and how.

    Built by `rule_problem`. Free phases (the sources whose phase law is uniform) are the
    unknown manufacturing phases; each adjusted source's phase is ``datum + offset``
    ("relative") or ``offset`` ("absolute"); every other phase follows its own rule.
    """

    drive: AbstractSinusoidalDrive
    model: ErrorModel
    tolerances: dict[str, Array]
    adjust: dict[str, str] = eqx.field(static=True)
    datum: str = eqx.field(static=True)
    free: tuple[tuple[str, int], ...] = eqx.field(static=True)

    def phases(self, beta: Array, offsets: Array) -> dict[str, Array]:
        """All phases for free phases `beta` (one per free instance) and rule `offsets`."""
        counts = self.model.counts
        out: dict[str, Array] = {}
        free_index = {nm: i for i, nm in enumerate(self.free)}
        adj = list(self.adjust)
        for name in _rule_order(self):
            c = counts[name]
            if name in self.adjust:
                k = adj.index(name)
                off = offsets[k]
                out[name] = jnp.broadcast_to(out[self.datum] + off if self.adjust[name] == "relative" else off, (c,))
                continue
            rule = self.model.sources[name].phase
            if isinstance(rule, UniformPhase):
                out[name] = jnp.stack([beta[free_index[(name, i)]] for i in range(c)])
            elif isinstance(rule, RelativePhase):
                out[name] = jnp.broadcast_to(out[rule.to], (c,)) + rule.offset
            elif isinstance(rule, FixedPhase):
                out[name] = jnp.broadcast_to(rule.value, (c,))
            else:
                raise ValueError(f"error source {name!r}: phase law {type(rule).__name__} cannot be used in an assembly-rule problem")
        return out

    def errors(self, magnitudes: Mapping[str, Array], beta: Array, offsets: Array) -> dict[str, Eccentricity]:
        ph = self.phases(beta, offsets)
        return {n: Eccentricity(jnp.broadcast_to(magnitudes[n], (self.model.counts[n],)), ph[n]) for n in self.model.counts}

    def components_at_tolerance(self, beta: Array, offsets: Array) -> Components:
        return self.drive.components(self.errors(self.tolerances, beta, offsets))


def _rule_order(p: RuleProblem) -> list[str]:
    deps = {}
    for n in p.model.counts:
        if n in p.adjust:
            deps[n] = p.datum if p.adjust[n] == "relative" else None
        else:
            rule = p.model.sources[n].phase
            deps[n] = rule.to if isinstance(rule, RelativePhase) else None
    order: list[str] = []

    def visit(n, seen=()):
        if n in order:
            return
        if n in seen:
            raise ValueError("phase rules form a cycle: " + " → ".join(seen + (n,)))
        if deps[n] is not None:
            visit(deps[n], seen + (n,))
        order.append(n)

    for n in p.model.counts:
        visit(n)
    return order


def rule_problem(
    drive: AbstractSinusoidalDrive, model: ErrorModel, *, adjust: Mapping[str, str], datum: str, tolerances: Mapping[str, float]
) -> RuleProblem:
    """Set up an assembly-rule problem.

    **Arguments:**

    - `drive`, `model`: the drive and how its errors are drawn (uniform phases are the unknown
      manufacturing phases).
    - `adjust`: source → "relative" (phase = datum phase + offset) or "absolute" (phase = offset).
    - `datum`: the source whose (unknown) phase is the assembly datum, e.g. "ring_manufacturing" (β_r).
    - `tolerances`: µm per source: the magnitudes for the worst-case and expected objectives.
    """
    check_phase_drive(drive)
    check_drive_model(drive, model)
    if not isinstance(adjust, Mapping):
        raise ValueError(f"adjust: a mapping of source → 'relative' or 'absolute', e.g. {{'carrier_assembly': 'relative'}}; got {adjust!r}")
    counts = model.counts
    for n, mode in adjust.items():
        if n not in counts:
            raise ValueError(f"adjust: {n!r} is not an error source; use one of {sorted(counts)}")
        if mode not in ("relative", "absolute"):
            raise ValueError(f"adjust[{n!r}]: 'relative' (to the datum) or 'absolute', got {mode!r}")
    if not adjust:
        raise ValueError("adjust: name at least one error source whose assembly phase is chosen")
    if datum not in counts or datum in adjust:
        raise ValueError(f"datum: {datum!r} must be an error source that is not adjusted")
    if not isinstance(model.sources[datum].phase, UniformPhase):
        raise ValueError(f"datum: the phase of {datum!r} must be uniform (an unknown manufacturing phase)")
    missing = [n for n in counts if n not in tolerances or tolerances[n] is None]
    if missing:
        raise ValueError(f"tolerances: give a tolerance (µm) for {missing}")
    for n, t in tolerances.items():
        if not (math.isfinite(float(t)) and float(t) >= 0):
            raise ValueError(f"tolerances[{n!r}]: must be a finite number ≥ 0 µm, got {t!r}")
    free = tuple((n, i) for n in counts if n not in adjust and isinstance(model.sources[n].phase, UniformPhase) for i in range(counts[n]))
    return RuleProblem(
        drive=drive,
        model=model,
        tolerances={n: jnp.asarray(float(tolerances[n])) for n in counts},
        adjust=dict(adjust),
        datum=datum,
        free=free,
    )


def _groups(p: RuleProblem) -> tuple[np.ndarray, bool]:
    """Which free phase each component follows (−1: none), and whether each group is one frequency."""
    k = len(p.free)
    beta0, off0 = jnp.zeros(k), jnp.zeros(len(p.adjust))
    jac = np.asarray(jax.jacfwd(lambda b: p.components_at_tolerance(b, off0).phase)(beta0))
    if jac.ndim == 1:
        jac = jac[:, None]
    nz = np.abs(jac) > 0.5
    if np.any(nz.sum(axis=1) > 1):
        raise ValueError("a TE component depends on more than one unknown phase; the worst case needs a numerical search")
    group = np.where(nz.any(axis=1), np.argmax(nz, axis=1), -1)
    freqs = p.components_at_tolerance(beta0, off0).freq
    single = all(len({abs(freqs[j]) for j in np.nonzero(group == g)[0]}) <= 1 for g in range(k))
    return group, single


def _group_parts(p: RuleProblem, offsets: Array, group: np.ndarray) -> list:
    comps = p.components_at_tolerance(jnp.zeros(len(p.free)), offsets)
    parts = []
    for g in range(-1, len(p.free)):
        mask = jnp.asarray((group == g).astype(np.float64))
        if not np.any(group == g):
            continue
        parts.append((g, to_signal(Components(comps.amplitude * mask, comps.phase, comps.freq, gain=comps.gain))))
    return parts


def rule_offsets(p: RuleProblem, offsets: Mapping[str, Any] | Array, *, where: str) -> Array:
    """A rule's offsets (rad) as an array in the order of `p.adjust`: a mapping naming every adjusted source once,
    or one value per adjusted source (finite where given as numbers); else a ValueError naming `where`."""
    names = list(p.adjust)
    if isinstance(offsets, Mapping):
        check_names(offsets, names, what=f"{where}: offsets: name every adjusted source {names} once")
        for n in names:
            check_array_values(f"{where}: offsets[{n!r}]", offsets[n], unit="rad")
        return jnp.stack([jnp.asarray(offsets[n], dtype=float) for n in names])
    check_array_values(f"{where}: offsets", offsets, unit="rad")
    off = jnp.asarray(offsets, dtype=float)
    if off.shape != (len(names),):
        raise ValueError(f"{where}: offsets: give one value per adjusted source {names} (shape ({len(names)},)), got shape {off.shape}")
    return off


def worst_case(p: RuleProblem, offsets: Array, *, metric: AbstractMetric = Peak()) -> Float[Array, ""]:
    """Worst case of the exact peak over every unknown phase, magnitudes at the tolerances (rad).

    Each unknown phase turns its own group of components; when every group is one frequency
    (or a constant) each group can reach ± its amplitude at any instant, so the worst case is
    exactly the fixed part's peak plus the sum of the groups' amplitudes (Wang et al.'s
    sum-of-amplitudes, with each group's amplitude computed by phasor sum, exact).
    """
    if not isinstance(metric, Peak):
        raise ValueError("worst_case: only the peak metric (gearte.Peak()) is supported")
    off = rule_offsets(p, offsets, where="worst_case")
    group, single = _groups(p)
    if not single:
        raise ValueError("worst_case: an unknown phase drives components of several frequencies; use the expected objective")
    return jnp.asarray(sum(metric(p.drive, sig) for _, sig in _group_parts(p, off, group)))


def _smooth_worst_case(p: RuleProblem, offsets: Array, group: np.ndarray, width: float | Array) -> Array:
    total = 0.0
    for g, sig in _group_parts(p, offsets, group):
        if g < 0:
            total = total + smooth_peak(sig, width=width)
        else:
            # One frequency: amplitude = |phasor sum|, smoothed at 0.
            total = total + jnp.sum(jnp.sqrt(sig.cos_coef**2 + sig.sin_coef**2 + width**2)) + jnp.sqrt(sig.offset**2 + width**2)
    return jnp.asarray(total)


def _samples(p: RuleProblem, key: PRNGKeyArray, n: int, robust: bool):
    """Common random numbers: unknown phases (and, if `robust`, magnitudes) for n samples."""
    k_b, k_m = jax.random.split(key)
    beta = _TWO_PI * jax.random.uniform(k_b, (n, len(p.free)), dtype=float)
    if robust:
        mags = {}
        for j, name in enumerate(p.model.counts):
            mags[name] = p.model.sources[name].magnitude.sample(jax.random.fold_in(k_m, j), (n, p.model.counts[name]))
    else:
        mags = {name: jnp.broadcast_to(p.tolerances[name], (n, p.model.counts[name])) for name in p.model.counts}
    return beta, mags


class _RuleSample(eqx.Module):
    """One Monte Carlo sample of a rule: unknown phases uniform, magnitudes at tolerance or drawn."""

    problem: RuleProblem
    offsets: Array
    robust: bool = eqx.field(static=True)
    metric: AbstractMetric

    def __call__(self, key):
        p = self.problem
        k_b, k_m = jax.random.split(key)
        beta = _TWO_PI * jax.random.uniform(k_b, (len(p.free),), dtype=float)
        if self.robust:
            mags = {
                n: p.model.sources[n].magnitude.sample(jax.random.fold_in(k_m, j), (p.model.counts[n],))
                for j, n in enumerate(p.model.counts)
            }
        else:
            mags = p.tolerances
        return self.metric(p.drive, p.drive.signal(p.errors(mags, beta, self.offsets)))


def expected(
    p: RuleProblem,
    offsets: Array,
    *,
    key: int | PRNGKeyArray,
    n_samples: int = 50_000,
    robust: bool = False,
    metric: AbstractMetric = Peak(),
) -> Float[Array, ""]:
    """Mean exact metric (rad) over uniform unknown phases, magnitudes at the tolerances
    (or drawn by their laws if `robust`), by Monte Carlo with `n_samples` samples."""
    n_samples = as_int("expected: n_samples", n_samples, minimum=1)
    fn = _RuleSample(p, rule_offsets(p, offsets, where="expected"), robust, metric)
    return jnp.mean(jnp.asarray(monte_carlo(fn, key=key, n_samples=n_samples, block_size=1024, progress=False).values))


def _rule_objective(objective: Any) -> str:
    """The name of a rule objective given as an object (or, deprecated, as its name)."""
    if isinstance(objective, AbstractRuleObjective):
        return objective.name
    if isinstance(objective, str) and objective in RULE_OBJECTIVES:
        warnings.warn(
            f"allocate_rule(objective={objective!r}): give an objective object, "
            f"gearte.{RULE_OBJECTIVES[objective].__name__}(); names are deprecated",
            DeprecationWarning,
            stacklevel=3,
        )
        return objective
    raise ValueError(f"objective: gearte.WorstCase(), gearte.Expected() or gearte.Robust(), got {objective!r}")


class RuleAllocation(eqx.Module):
    """Result of `allocate_rule`: the chosen rule and its exact figures (rad).

    `offsets`: source → offset (rad) from the datum ("relative") or absolute phase.
    `worst_case`, `expected`, `robust`: the three objectives evaluated exactly (the last two
    by Monte Carlo with `n_check` fresh samples); `objective`: the name of the one minimised;
    `result`: the solve's `RESULTS` code; `starts`/`converged`: starts run and succeeded.
    """

    offsets: dict[str, Array]
    worst_case: Float[Array, ""]
    expected: Float[Array, ""]
    robust: Float[Array, ""]
    result: RESULTS
    objective: str = eqx.field(static=True)
    starts: int = eqx.field(static=True)
    converged: int = eqx.field(static=True)


def evaluate_rule(
    p: RuleProblem, offsets: Mapping[str, float] | Array, *, key: int | PRNGKeyArray, n_check: int = 50_000
) -> dict[str, Array]:
    """Exact worst case, expected and robust TE (rad) of a rule (e.g. Wang et al.'s Table 3 rule)."""
    off = rule_offsets(p, offsets, where="evaluate_rule")
    n_check = as_int("evaluate_rule: n_check", n_check, minimum=1)
    k1, k2 = jax.random.split(as_key(key))
    return {
        "worst_case": worst_case(p, off),
        "expected": expected(p, off, key=k1, n_samples=n_check),
        "robust": expected(p, off, key=k2, n_samples=n_check, robust=True),
    }


@kept_jit
def _optimise_rule(
    p: RuleProblem,
    objective: str,
    group: tuple[int, ...],
    beta: Array,
    mags: dict[str, Array],
    y0: Array,
    width: Array,
    max_steps: int,
) -> tuple[Array, optx.RESULTS, Array]:
    """BFGS on the smooth surrogate of the objective named `objective` (width `width`, rad; common random phases
    `beta` and magnitudes `mags`) from every row of `y0`: the ends, their result codes and the surrogate at each end
    (the worst case is scored exactly by the caller). Module level, with the values as arguments: another call of the
    same problem structure and shapes (another key, width or tolerances) traces and compiles nothing."""
    groups = np.asarray(group)

    def surrogate(y, args):
        del args
        if objective == "worst_case":
            return _smooth_worst_case(p, y, groups, width) / width
        vals = jax.vmap(lambda b, mg: smooth_peak(p.drive.signal(p.errors(mg, b, y)), width=width))(beta, mags)
        return jnp.mean(vals) / width

    solver = optx.BFGS(rtol=1e-9, atol=1e-9)
    sol = jax.vmap(lambda s: optx.minimise(surrogate, solver, s, None, max_steps=max_steps, throw=False))(y0)
    scores = jnp.zeros(y0.shape[0]) if objective == "worst_case" else jax.vmap(lambda y: surrogate(y, None))(sol.value)
    return sol.value, sol.result, scores


def allocate_rule(
    p: RuleProblem,
    *,
    objective: AbstractRuleObjective | str = WorstCase(),
    key: int | PRNGKeyArray,
    starts: int = 16,
    n_samples: int = 512,
    n_check: int = 50_000,
    width: float | None = None,
    max_steps: int = 300,
    throw: bool = True,
) -> RuleAllocation:
    """Find the assembly rule that minimises `objective` over the unknown phases.

    **Arguments:**

    - `p`: the problem (`rule_problem`).
    - `objective`: `gearte.WorstCase()` (magnitudes at the tolerances, worst unknown phases),
      `gearte.Expected()` (magnitudes at the tolerances, mean over uniform unknown phases) or
      `gearte.Robust()` (magnitudes drawn by their laws too, e.g. Rayleigh within the tolerance). Their
      names (``"worst_case"``, …) are still taken, with a `DeprecationWarning`.
    - `key`: seed or key (starts, common random numbers, the final check).
    - `starts`: optimiser starts under `vmap`.
    - `n_samples`: common random samples in the expected/robust surrogates.
    - `n_check`: fresh Monte Carlo samples for the exact expected/robust figures.
    - `width`: surrogate smoothing width, rad (default 0.2 % of the worst case at zero offsets).
    - `throw`: raise if the best start did not converge (else check `result`).

    **Returns:** a `RuleAllocation`.
    """
    require_x64()
    objective = _rule_objective(objective)
    starts = as_int("allocate_rule: starts", starts, minimum=1)
    n_samples = as_int("allocate_rule: n_samples", n_samples, minimum=1)
    n_check = as_int("allocate_rule: n_check", n_check, minimum=1)
    max_steps = as_int("allocate_rule: max_steps", max_steps, minimum=1)
    if width is not None:
        width = as_float("allocate_rule: width", width, positive=True, hint="rad")
    k_start, k_crn, k_check = jax.random.split(as_key(key), 3)
    m = len(p.adjust)
    group, single = _groups(p)
    if objective == "worst_case" and not single:
        raise ValueError("objective 'worst_case' needs every unknown phase to drive one frequency; use 'expected'")
    scale = float(worst_case(p, jnp.zeros(m))) if single else 1e-4
    w = float(width) if width is not None else 2e-3 * max(scale, 1e-12)
    beta, mags = _samples(p, k_crn, n_samples, robust=(objective == "robust"))

    y0 = _TWO_PI * jax.random.uniform(k_start, (starts, m), dtype=float)
    ends, results, scores = _optimise_rule(p, objective, tuple(int(g) for g in group), beta, mags, y0, jnp.asarray(w), max_steps)
    if objective == "worst_case":
        scores = jnp.stack([worst_case(p, y) for y in ends])
    best = best_start(scores, results)
    y_best = jnp.mod(ends[best], _TWO_PI)
    figures = evaluate_rule(p, y_best, key=k_check, n_check=n_check)
    converged, result = starts_result(results, best)
    # The surrogate is smooth but flat along valleys: a start that stops there is still scored exactly.
    check(result, throw=throw and not partial_success(result), what="allocate_rule")
    return RuleAllocation(
        offsets={n: y_best[i] for i, n in enumerate(p.adjust)},
        worst_case=figures["worst_case"],
        expected=figures["expected"],
        robust=figures["robust"],
        result=result,
        objective=objective,
        starts=starts,
        converged=converged,
    )
