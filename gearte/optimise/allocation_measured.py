"""Assembly-phase allocation for measured parts: every magnitude and manufacturing phase known, choose the
turns (any angle, or whole teeth / bolt positions, certified by enumeration) that minimise the exact TE metric
(Wang et al. 2013, section 1). Optimised on smooth surrogates with optimistix (BFGS, multi-start under `vmap`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.extrema import smooth_peak
from ..core.metrics import AbstractMetric, Peak
from ..core.precision import require_x64
from ..core.solution import RESULTS, check
from ..core.units import TWO_PI as _TWO_PI
from ..core.validate import as_float, as_int
from ..drives.protocol import AbstractSinusoidalDrive, Eccentricity
from ..studies.montecarlo import as_key
from .allocation import best_start, check_extremum_metric, check_phase_drive, partial_success, starts_result


class MeasuredAllocation(eqx.Module):
    """Result of `allocate_measured`.

    `phases`: the chosen phase (rad) of every adjusted source; `te` and `te_before`: the
    exact metric (rad) with the chosen and with the given phases; `result`: the solve's
    `RESULTS` code; `starts`/`converged`: how many optimiser starts ran and how many reported
    success; `enumerated`: whether the discrete optimum was verified by enumerating every
    allowed combination.
    """

    phases: dict[str, Array]
    te: Float[Array, ""]
    te_before: Float[Array, ""]
    result: RESULTS
    metric: AbstractMetric
    starts: int = eqx.field(static=True)
    converged: int = eqx.field(static=True)
    enumerated: bool = eqx.field(static=True)


def _with_phases(errors: Mapping[str, Eccentricity], names: list[str], counts: list[int], y: Array) -> dict[str, Eccentricity]:
    out = dict(errors)
    i = 0
    for n, c in zip(names, counts):
        out[n] = Eccentricity(
            jnp.broadcast_to(errors[n].magnitude, (c,)) if errors[n].magnitude.ndim else errors[n].magnitude,
            y[i : i + c] if c > 1 else y[i],
        )
        i += c
    return out


@eqx.filter_jit
def _metric_at(
    drive: AbstractSinusoidalDrive,
    metric: AbstractMetric,
    errors: tuple[tuple[str, Eccentricity], ...],
    names: tuple[str, ...],
    counts: tuple[int, ...],
    ys: Float[Array, "n dim"],
) -> Float[Array, " n"]:
    """The exact metric (rad) with the `names` sources' phases at each row of `ys` (`counts` entries each), the other
    errors as in `errors` (name, value pairs in the drive's order); traced once per drive structure and shapes."""
    errs = dict(errors)
    # The signals under `vmap`, the metric on the whole batch at once (metrics take any batch shape), as the Monte
    # Carlo does: the exact extrema search works on dense arrays instead of through `vmap`'s batching of its loops.
    signals = jax.vmap(lambda y: drive.signal(_with_phases(errs, list(names), list(counts), y)))(ys)
    return metric(drive, signals)


@eqx.filter_jit
def _optimise(
    drive: AbstractSinusoidalDrive,
    metric: AbstractMetric,
    errors: tuple[tuple[str, Eccentricity], ...],
    names: tuple[str, ...],
    counts: tuple[int, ...],
    y0: Float[Array, "starts dim"],
    width: Float[Array, ""],
    max_steps: int,
) -> tuple[Float[Array, "starts dim"], optx.RESULTS, Float[Array, " starts"], Float[Array, ""]]:
    """BFGS on the smooth surrogate of `metric` (width `width`, rad; 0: 0.2 % of the exact metric at ``y0[0]``) from
    every row of `y0`: the ends, their result codes, the exact metric at each end and at ``y0[0]``. Module level, with
    the unit's values (errors, starts, width) as arguments: another unit of the same drive structure and shapes traces
    and compiles nothing."""
    errs = dict(errors)
    first = _metric_at(drive, metric, errors, names, counts, y0[:1])[0]
    width = jnp.where(width > 0, width, 2e-3 * jnp.maximum(first, 1e-12))

    def signal(y):
        return drive.signal(_with_phases(errs, list(names), list(counts), y))

    def surrogate(y, args):
        del args
        sig = signal(y)
        if isinstance(metric, Peak):
            return smooth_peak(sig, width=width) / width
        # Peak-to-peak: smooth max of f plus smooth max of −f.
        pos = smooth_peak(eqx.tree_at(lambda s: s.offset, sig, sig.offset + 1e3 * width), width=width)
        return (pos - 1e3 * width + smooth_peak(sig, width=width)) / width

    solver = optx.BFGS(rtol=1e-8, atol=1e-8)
    sol = jax.vmap(lambda s: optx.minimise(surrogate, solver, s, None, max_steps=max_steps, throw=False))(y0)
    return sol.value, sol.result, _metric_at(drive, metric, errors, names, counts, sol.value), first


def allocate_measured(
    drive: AbstractSinusoidalDrive,
    errors: Mapping[str, Eccentricity],
    *,
    adjust: Mapping[str, float | None],
    key: int | PRNGKeyArray,
    metric: AbstractMetric = Peak(),
    starts: int = 16,
    width: float | None = None,
    max_steps: int = 200,
    enumerate_limit: int = 20_000,
    throw: bool = True,
) -> MeasuredAllocation:
    """Choose the phases of the `adjust` sources that minimise the exact TE metric.

    **Arguments:**

    - `drive`, `errors`: the drive and its measured errors (magnitudes µm, phases rad).
    - `adjust`: source name → step (rad) between allowed assembly positions (e.g. 2π/z
      for a gear turned by whole teeth, 2π/n for an n-bolt pattern), or None for any angle.
      Allowed positions are the given (as-delivered) phase turned by whole steps.
    - `key`: seed or key for the random starts.
    - `metric`: `gearte.Peak()` or `gearte.PeakToPeak()`.
    - `starts`: optimiser starts, run together under `vmap`.
    - `width`: smoothing width of the surrogate, rad (default 0.2 % of the starting metric).
    - `enumerate_limit`: with discrete positions, enumerate every combination when there are
      at most this many, which certifies the discrete optimum.
    - `throw`: raise if the best start did not converge (else check `result`).

    **Returns:** a `MeasuredAllocation`.
    """
    require_x64()
    check_phase_drive(drive)
    check_extremum_metric(metric)
    counts_all = {n: s.count for n, s in drive.error_sources.items()}
    for n, step in adjust.items():
        if n not in counts_all:
            raise ValueError(f"adjust: {n!r} is not an error source of this drive; use one of {sorted(counts_all)}")
        if step is not None and not (math.isfinite(step) and step > 0):
            raise ValueError(f"adjust[{n!r}]: the step between positions must be > 0 rad, or None for any angle")
    if not adjust:
        raise ValueError("adjust: name at least one error source whose phase may be chosen")
    starts = as_int("starts", starts, minimum=1)
    max_steps = as_int("max_steps", max_steps, minimum=1)
    if width is not None:
        width = as_float("width", width, positive=True, hint="the smoothing width, rad; None for the default")
    errors = drive.checked(errors)
    names = list(adjust)
    counts = [counts_all[n] for n in names]
    dim = sum(counts)
    y_given = jnp.concatenate([errors[n].phase.reshape(-1) for n in names])

    def exact(y):
        return metric(drive, drive.signal(_with_phases(errors, names, counts, y)))

    y0 = _TWO_PI * jax.random.uniform(as_key(key), (starts, dim), dtype=float)
    y0 = y0.at[0].set(y_given)
    # The metric as delivered (the first start) and the default width come out of the same compiled program.
    w = jnp.asarray(0.0 if width is None else width)
    ends, results, values, te_before = _optimise(drive, metric, tuple(errors.items()), tuple(names), tuple(counts), y0, w, max_steps)
    best = best_start(values, results)
    y_best, te_best = ends[best], values[best]

    steps = [adjust[n] for n in names for _ in range(counts_all[n])]
    enumerated = False
    if any(s is not None for s in steps):
        many = functools.partial(_metric_at, drive, metric, tuple(errors.items()), tuple(names), tuple(counts))
        y_best, te_best, enumerated = _discrete(exact, many, y_best, y_given, steps, enumerate_limit)
    phases, i = {}, 0
    for n, c in zip(names, counts):
        phases[n] = jnp.mod(y_best[i : i + c], _TWO_PI) if c > 1 else jnp.mod(y_best[i], _TWO_PI)
        i += c
    converged, result = starts_result(results, best)
    check(result, throw=throw and not partial_success(result), what="allocate_measured")
    return MeasuredAllocation(
        phases=phases,
        te=te_best,
        te_before=te_before,
        result=result,
        metric=metric,
        starts=starts,
        converged=converged,
        enumerated=enumerated,
    )


def _discrete(exact, many, y_cont, y_given, steps, limit):
    """Snap to allowed positions (the given phase turned by whole steps); enumerate all of them
    when few enough (`many`: the metric at each row of phases), else search neighbours (`exact`: at one)."""
    grids = []
    for y, y0, s in zip(np.asarray(y_cont), np.asarray(y_given), steps):
        if s is None:
            grids.append(np.array([y]))
        else:
            n = max(1, int(round(_TWO_PI / s)))
            grids.append(y0 + np.arange(n) * (_TWO_PI / n))
    total = int(np.prod([len(g) for g in grids]))
    if total <= limit:
        mesh = np.stack(np.meshgrid(*grids, indexing="ij"), axis=-1).reshape(-1, len(grids))
        vals = np.concatenate([np.asarray(many(jnp.asarray(mesh[i : i + 4096]))) for i in range(0, total, 4096)])
        i = int(np.argmin(vals))
        return jnp.asarray(mesh[i]), jnp.asarray(vals[i]), True
    # Too many combinations: round, then coordinate descent over neighbouring positions.
    y = np.array([g[np.argmin(np.abs(np.angle(np.exp(1j * (g - v)))))] for g, v in zip(grids, np.asarray(y_cont))])
    best = float(exact(jnp.asarray(y)))
    improved = True
    while improved:
        improved = False
        for j, s in enumerate(steps):
            if s is None:
                continue
            for d in (-1, 1):
                cand = y.copy()
                cand[j] = (cand[j] + d * s) % _TWO_PI
                v = float(exact(jnp.asarray(cand)))
                if v < best - 1e-15:
                    y, best, improved = cand, v, True
    return jnp.asarray(y), jnp.asarray(best), False
