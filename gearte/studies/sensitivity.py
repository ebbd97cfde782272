"""Variance-based (Sobol') sensitivity of a per-sample metric to the error sources, for any drive.

Every random part of an error model is one independent scalar *input*: the magnitude of
each instance of a source whose magnitude law is not a constant, and the phase of each
instance whose phase is uniform on [0, 2π) (random assembly). Phases set by a rule —
`FixedPhase`, or `RelativePhase` (an assembly rule such as Wang et al.'s (2013)
γ_s = β_r + 7π/9) — are not inputs: a rule-bound phase moves with the phase it follows,
so its effect is attributed to that source's phase input. A per-planet source (N
instances) gives N magnitude and N phase inputs.

Each input is a standard uniform U on [0, 1) mapped through its law's inverse CDF in JAX
(magnitude = F⁻¹(U) µm; phase = 2πU rad); the output Y is the exact TE metric of the
sample (the study's metric object, rad for angles), evaluated under `jax.vmap`. A deviation
source (a signed value) gives one value input per instance, mapped the same way.

**Design and estimator.** The two base matrices A and B (n × d each) are the two halves of
one scrambled Sobol' sequence in 2d dimensions (Saltelli et al. 2010, Comput. Phys.
Commun. 181:259, sec. 5 — the design `scipy.stats.sobol_indices` uses itself). From them
gearte evaluates Y at A, at B, at the d matrices A_B^(i) (column i from B) and at one
matrix per error source with *all* of that source's columns from B. The indices are then
computed by `scipy.stats.sobol_indices` from those evaluations (its Saltelli 2010
first-order and Jansen total estimators; the indices are not re-implemented here):

- per input i: first-order S_i = V[E(Y | X_i)] / V[Y] and total S_Ti = 1 − V[E(Y | X_~i)] / V[Y];
- per source u (all its inputs together): the closed first-order index
  S^clo_u = V[E(Y | X_u)] / V[Y] (its inputs' own effects and their interactions with one
  another) and the total index S^T_u = 1 − V[E(Y | X_~u)] / V[Y] (everything the source
  takes part in);
- per source, also Σ_{i∈u} S_i, the sum of its inputs' first-order indices: for independent
  inputs a lower bound of S^clo_u (it leaves out the interactions among the source's own
  inputs, e.g. between a magnitude and its phase).

Estimates carry Monte Carlo error of order 1/√n (an estimate may fall slightly below 0 or
above 1); `confidence_level` adds scipy's bootstrap intervals for the per-input indices.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.metrics import AbstractMetric
from ..core.precision import require_x64
from ..core.units import TWO_PI as _TWO_PI
from ..drives.protocol import AbstractDrive, Eccentricity
from .errors import ErrorModel
from .laws import AbstractValueLaw, FixedPhase, Optimised, RelativePhase, UniformPhase
from .montecarlo import TEStudy, as_key

# Keep U inside (0, 1): a law's inverse CDF may be infinite at the ends (Normal, untruncated Rayleigh).
_U_MIN, _U_MAX = 2.0**-53, 1.0 - 2.0**-53


# ------------------------------------------------------------------ the inputs of a model


class _Plan(eqx.Module):
    """How a row of d uniforms becomes one set of errors, and its metric (rad for angles)."""

    drive: AbstractDrive
    model: ErrorModel
    scale: dict[str, Array]  # value factor per source (tolerance / nominal for a budget), about the law's centre
    metric: AbstractMetric
    columns: tuple[tuple[str, tuple[int, ...], tuple[int, ...]], ...] = eqx.field(static=True)  # (source, value, phase columns)

    def errors(self, u: Float[Array, " d"]) -> dict:
        out: dict = {}
        cols = {name: (m, p) for name, m, p in self.columns}
        for name in self.model.order:
            src, spec = self.model.sources[name], self.model.specs[name]
            law = src.magnitude
            assert isinstance(law, AbstractValueLaw)
            val_cols, ph_cols = cols[name]
            uv = u[jnp.asarray(val_cols)].reshape(spec.shape) if val_cols else jnp.full(spec.shape, 0.5)
            # Scaled as a tolerance budget scales it: a band about its centre, anything else about 0.
            if spec.kind == "deviation" and law.banded:
                c = law.centre()
                value = c + self.scale[name] * (law.ppf(uv) - c)
            else:
                value = self.scale[name] * law.ppf(uv)
            if spec.kind == "deviation":
                out[name] = value
                continue
            rule = src.phase
            if isinstance(rule, UniformPhase):
                phase = _TWO_PI * u[jnp.asarray(ph_cols)].reshape(spec.shape)
            elif isinstance(rule, RelativePhase):
                phase = jnp.broadcast_to(out[rule.to].phase, spec.shape) + rule.offset
            else:  # FixedPhase (checked in _plan)
                assert isinstance(rule, FixedPhase)
                phase = jnp.broadcast_to(rule.value, spec.shape)
            out[name] = Eccentricity(value, phase)
        return {n: out[n] for n in self.model.specs}

    def __call__(self, u: Float[Array, " d"]) -> Float[Array, ""]:
        return self.metric(self.drive, self.drive.response(self.errors(jnp.clip(u, _U_MIN, _U_MAX))))


def _label(name: str, kind: str, i: int, count: int) -> str:
    return f"{name}.{kind}" if count == 1 else f"{name}.{kind}[{i}]"


def _plan(drive: AbstractDrive, model: ErrorModel, scale: Mapping[str, float], metric: AbstractMetric):
    """The inputs (labels, source, kind) and the `_Plan` that evaluates a row of uniforms."""
    labels, owners, kinds = [], [], []
    columns = []
    for name, spec in model.specs.items():
        src, c = model.sources[name], spec.count
        rule = src.phase
        kind = "magnitude" if spec.kind == "eccentricity" else "value"
        if isinstance(rule, Optimised):
            raise ValueError(
                f"error source {name!r}: its phase is to be chosen by the allocation optimiser; resolve the "
                "rule first (gearte.allocate_rule, then a RelativePhase or FixedPhase)"
            )
        if rule is not None and not isinstance(rule, (UniformPhase, RelativePhase, FixedPhase)):
            raise ValueError(
                f"error source {name!r}: phase law {type(rule).__name__} is not supported for Sobol' indices; "
                "use UniformPhase (an input), FixedPhase or RelativePhase (rules, not inputs)"
            )
        if not isinstance(src.magnitude, AbstractValueLaw):
            raise ValueError(
                f"error source {name!r}: its law ({type(src.magnitude).__name__}) has no inverse CDF for Sobol' "
                "indices; use Fixed, Uniform, Normal, TruncatedNormal or Rayleigh"
            )
        if src.magnitude.is_random():
            val_cols = tuple(range(len(labels), len(labels) + c))
            for i in range(c):
                labels.append(_label(name, kind, i, c))
                owners.append(name)
                kinds.append(kind)
        else:
            val_cols = ()
        if isinstance(rule, UniformPhase):
            ph_cols = tuple(range(len(labels), len(labels) + c))
            for i in range(c):
                labels.append(_label(name, "phase", i, c))
                owners.append(name)
                kinds.append("phase")
        else:
            ph_cols = ()
        columns.append((name, val_cols, ph_cols))
    plan = _Plan(
        drive=drive, model=model, scale={n: jnp.asarray(float(scale[n])) for n in model.specs}, metric=metric, columns=tuple(columns)
    )
    return tuple(labels), tuple(owners), tuple(kinds), plan


# ------------------------------------------------------------------ result


class SobolIndices(eqx.Module):
    """Sobol' indices of the per-sample TE metric (dimensionless fractions of its variance).

    Per input (`inputs`, labelled ``source.magnitude`` / ``source.phase``, with ``[i]`` the
    0-based instance for per-planet sources; `input_source` and `input_kind` say whose and
    which): `first_order` S_i and `total_order` S_Ti, arrays of shape (d,), with
    `first_order_ci`, `total_order_ci` (d, 2) bootstrap intervals when asked for.

    Per error source (dicts by source name; every source of the model is listed, a source
    with no random input has 0):

    - `source_first_order_sum`: Σ S_i over the source's inputs — a lower bound of its closed
      first-order index (it omits interactions among the source's own inputs);
    - `source_closed_first_order`: S^clo_u = V[E(Y | X_u)] / V[Y], estimated directly;
    - `source_total_order`: S^T_u = 1 − V[E(Y | X_~u)] / V[Y], estimated directly.

    `mean` (rad) and `variance` (rad²) of the metric over the A and B samples; `n` base
    samples; `evaluations` TE evaluations in all; `metric` the TE metric.
    """

    inputs: tuple[str, ...]
    input_source: tuple[str, ...]
    input_kind: tuple[str, ...]
    first_order: np.ndarray
    total_order: np.ndarray
    first_order_ci: np.ndarray | None
    total_order_ci: np.ndarray | None
    source_first_order_sum: dict[str, float]
    source_closed_first_order: dict[str, float]
    source_total_order: dict[str, float]
    mean: float
    variance: float
    n: int
    evaluations: int
    metric: str
    confidence_level: float | None

    @property
    def sources(self) -> list[str]:
        return list(self.source_total_order)

    def to_dict(self) -> dict:
        """Plain Python (JSON-ready) form: per-input and per-source indices, mean (rad), variance (rad²)."""
        per_input = {}
        for j, label in enumerate(self.inputs):
            row = {
                "source": self.input_source[j],
                "kind": self.input_kind[j],
                "first_order": float(self.first_order[j]),
                "total_order": float(self.total_order[j]),
            }
            if self.first_order_ci is not None and self.total_order_ci is not None:
                row["first_order_ci"] = [float(x) for x in self.first_order_ci[j]]
                row["total_order_ci"] = [float(x) for x in self.total_order_ci[j]]
            per_input[label] = row
        per_source = {
            n: {
                "first_order_sum": self.source_first_order_sum[n],
                "closed_first_order": self.source_closed_first_order[n],
                "total_order": self.source_total_order[n],
                "inputs": [lab for lab, s in zip(self.inputs, self.input_source) if s == n],
            }
            for n in self.sources
        }
        return {
            "metric": self.metric,
            "mean_rad": self.mean,
            "variance_rad2": self.variance,
            "n": self.n,
            "evaluations": self.evaluations,
            "confidence_level": self.confidence_level,
            "inputs": per_input,
            "sources": per_source,
            "definitions": {
                "first_order": "S_i = V[E(Y|X_i)]/V[Y]",
                "total_order": "S_Ti = 1 − V[E(Y|X_~i)]/V[Y]",
                "first_order_sum": "Σ of the source's inputs' S_i: a lower bound of its closed first-order index",
                "closed_first_order": "S^clo_u = V[E(Y|X_u)]/V[Y], all the source's inputs together",
                "total_order (source)": "S^T_u = 1 − V[E(Y|X_~u)]/V[Y]",
                "estimator": "scipy.stats.sobol_indices (Saltelli 2010 first order, Jansen total) on a scrambled Sobol' design",
            },
        }


# ------------------------------------------------------------------ main entry


def _numpy_rng(key: PRNGKeyArray) -> np.random.Generator:
    # The Sobol' scrambling is drawn by NumPy: seed it from the JAX key, so one key fixes everything.
    words = np.asarray(jax.random.bits(key, (4,), dtype=jnp.uint32))
    return np.random.default_rng([int(w) for w in words])


def _sobol_design(stats, n: int, d: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A and B (n × d each): the two halves of one scrambled Sobol' sequence in 2d dimensions."""
    try:
        engine = stats.qmc.Sobol(d=2 * d, scramble=True, bits=64, rng=rng)
    except TypeError:  # scipy < 1.15 names the generator `seed`
        engine = stats.qmc.Sobol(d=2 * d, scramble=True, bits=64, seed=rng)
    ab = engine.random(n)
    return ab[:, :d], ab[:, d:]


@eqx.filter_jit
def _metric_of_rows(plan: _Plan, u: Float[Array, "m d"]) -> Float[Array, " m"]:
    return jax.vmap(plan)(u)


def _evaluate(plan: _Plan, rows: np.ndarray, block: int) -> np.ndarray:
    """The metric (rad) of every row, in blocks of one fixed shape (one compilation)."""
    f = _metric_of_rows
    m = rows.shape[0]
    block = min(block, m)
    out = []
    for s in range(0, m, block):
        part = rows[s : s + block]
        k = part.shape[0]
        if k < block:
            part = np.concatenate([part, np.full((block - k, rows.shape[1]), 0.5)])
        out.append(np.asarray(f(plan, jnp.asarray(part)))[:k])
    return np.concatenate(out)


def sobol_indices(
    study: TEStudy,
    *,
    key: int | PRNGKeyArray,
    n: int = 1024,
    scale: Mapping[str, float] | None = None,
    confidence_level: float | None = None,
    n_resamples: int = 999,
    block_size: int = 2048,
) -> SobolIndices:
    """Sobol' indices of the per-sample TE metric with respect to the error sources' random inputs.

    **Arguments:**

    - `study`: a `gearte.TEStudy` (drive, error model, one metric).
    - `key`: integer seed or `jax.random` key; it fixes the scrambled Sobol' design, so the
      result is reproducible.
    - `n`: base samples, a power of 2 (≥ 16). Y is evaluated n · (2 + d + g) times, with d
      inputs and g sources that have inputs.
    - `scale`: a factor per source applied to its law about the law's centre, value =
      c + f · (F⁻¹(U) − c), as a tolerance budget scales tolerances (default 1 for every source).
    - `confidence_level`: e.g. 0.95 for bootstrap (BCa) intervals of the per-input indices
      from `scipy.stats`; None (default) for none.
    - `n_resamples`: bootstrap resamples.
    - `block_size`: samples evaluated together in one vectorised call (bounds memory).

    **Returns:** a `SobolIndices`.
    """
    require_x64()
    if not isinstance(study, TEStudy) or isinstance(study.metric, tuple):
        raise ValueError(f"study: expected a gearte.TEStudy(drive, errors, metric=...) with one metric, got {study!r:.80}")
    drive, model, metric = study.drive, study.errors, study.metric
    factors = {k: 1.0 for k in model.specs}
    for k, f in (scale or {}).items():
        if k not in factors:
            raise ValueError(f"scale: {k!r} is not an error source; use some of {list(factors)}")
        if not (math.isfinite(float(f)) and float(f) > 0):
            raise ValueError(f"scale[{k!r}]: a factor > 0, got {f!r}")
        factors[k] = float(f)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 16 or (int(n) & (int(n) - 1)):
        raise ValueError(f"n: the number of base samples must be a power of 2 ≥ 16 (a Sobol' sequence's balance needs it), got {n!r}")
    n = int(n)
    if isinstance(block_size, bool) or not isinstance(block_size, (int, np.integer)) or block_size < 1:
        raise ValueError(f"block_size: must be a whole number ≥ 1, got {block_size!r}")
    if confidence_level is not None and not (isinstance(confidence_level, (int, float)) and 0 < confidence_level < 1):
        raise ValueError(f"confidence_level: a probability in (0, 1) such as 0.95, or None, got {confidence_level!r}")
    if isinstance(n_resamples, bool) or not isinstance(n_resamples, (int, np.integer)) or n_resamples < 10:
        raise ValueError(f"n_resamples: must be a whole number ≥ 10, got {n_resamples!r}")
    key = as_key(key)

    labels, owners, kinds, plan = _plan(drive, model, factors, metric)
    d = len(labels)
    if d == 0:
        raise ValueError(
            "the error model has no random input: every magnitude is constant and every phase is fixed "
            "or set by a rule, so the TE does not vary"
        )
    groups = [s for s in model.specs if s in owners]
    from scipy import stats  # scipy.stats takes a second to import: only when Sobol' indices are asked for

    A, B = _sobol_design(stats, n, d, _numpy_rng(key))
    pages = []
    for j in range(d):
        page = A.copy()
        page[:, j] = B[:, j]
        pages.append(page)
    for s in groups:
        cols = [j for j, o in enumerate(owners) if o == s]
        page = A.copy()
        page[:, cols] = B[:, cols]
        pages.append(page)
    rows = np.concatenate([A, B] + pages)
    y = _evaluate(plan, rows, int(block_size))
    if not np.all(np.isfinite(y)):
        raise ValueError(
            f"the TE metric is not finite for {int(np.count_nonzero(~np.isfinite(y)))} of {y.size} samples; check the magnitude laws"
        )
    f_A, f_B = y[:n][None, :], y[n : 2 * n][None, :]
    f_pages = y[2 * n :].reshape(d + len(groups), 1, n)
    per_input, s1, st = _scipy_indices(stats, f_A, f_B, f_pages[:d], n)
    _, g1, gt = _scipy_indices(stats, f_A, f_B, f_pages[d:], n)
    ci1 = cit = None
    if confidence_level is not None:
        ci1, cit = _bootstrap(per_input, s1, st, float(confidence_level), int(n_resamples), key)
    names = list(model.specs)
    first_sum = {s: float(sum(s1[j] for j in range(d) if owners[j] == s)) for s in names}
    closed = {s: float(g1[groups.index(s)]) if s in groups else 0.0 for s in names}
    total = {s: float(gt[groups.index(s)]) if s in groups else 0.0 for s in names}
    both = np.concatenate([f_A[0], f_B[0]])
    return SobolIndices(
        inputs=labels,
        input_source=owners,
        input_kind=kinds,
        first_order=s1,
        total_order=st,
        first_order_ci=ci1,
        total_order_ci=cit,
        source_first_order_sum=first_sum,
        source_closed_first_order=closed,
        source_total_order=total,
        mean=float(np.mean(both)),
        variance=float(np.var(both)),
        n=n,
        evaluations=int(y.size),
        metric=metric.name,
        confidence_level=None if confidence_level is None else float(confidence_level),
    )


def _scipy_indices(stats, f_A, f_B, f_AB, n: int):
    """First-order and total indices (k,) of the k pages of `f_AB` (k, 1, n), by scipy.stats.sobol_indices."""
    k = f_AB.shape[0]
    # scipy squeezes its result, which fails for a single page: give it the page twice.
    pages = np.concatenate([f_AB, f_AB]) if k == 1 else f_AB
    res = stats.sobol_indices(func={"f_A": f_A, "f_B": f_B, "f_AB": pages}, n=n)
    first = np.asarray(res.first_order, dtype=float).reshape(-1)[:k]
    total = np.asarray(res.total_order, dtype=float).reshape(-1)[:k]
    return res, first, total


def _bootstrap(res, s1, st, level: float, n_resamples: int, key) -> tuple[np.ndarray, np.ndarray]:
    """Bootstrap intervals (d, 2) from scipy; an input whose index is the same in every resample (an
    input that never changes Y) gets the degenerate interval [S, S]."""
    # SobolResult.bootstrap passes no generator on, so scipy resamples with NumPy's legacy global
    # RandomState: seed it from the key for the call (and put it back) so the intervals are reproducible.
    state = np.random.get_state()
    np.random.seed(int(np.asarray(jax.random.bits(jax.random.fold_in(key, 1), (), dtype=jnp.uint32))))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with np.errstate(all="ignore"):
                b = res.bootstrap(confidence_level=level, n_resamples=n_resamples)
    finally:
        np.random.set_state(state)

    def interval(r, est):
        k = est.shape[0]
        lo = np.asarray(r.confidence_interval.low, dtype=float).reshape(-1)[:k]
        hi = np.asarray(r.confidence_interval.high, dtype=float).reshape(-1)[:k]
        bad = ~(np.isfinite(lo) & np.isfinite(hi))
        lo, hi = np.where(bad, est, lo), np.where(bad, est, hi)
        return np.stack([lo, hi], axis=-1)

    return interval(b.first_order, s1), interval(b.total_order, st)
