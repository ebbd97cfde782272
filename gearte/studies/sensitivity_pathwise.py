"""Pathwise sensitivities of Monte Carlo means to the parameters of the error laws, for any drive.

Every draw of an error model is a differentiable function of its laws' parameters
(reparametrisation: a tolerance band draws centre + half-width·u, a Rayleigh law
scale·√(−2 log(1 − u)), …), so the derivative of the mean of a metric over a batch with
respect to a law parameter (a half-width, a scale, a fixed value) is the mean over samples
of the per-sample gradient, with the samples' random numbers held (common random numbers).
Sample i uses the study's key ``fold_in(key, i)``, as `gearte.monte_carlo` does, so the mean
is that of the study's first `n_samples` samples.

The metric is taken by its smooth surrogate (`AbstractMetric.smooth`): a loaded-pair count,
piecewise constant, has no pathwise derivative of its own. A phase drawn uniformly on
[0, 2π) has no parameter; a law parameter that a metric does not depend on gets 0.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray, UInt

from ..core.metrics import AbstractMetric
from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.units import ARCSEC_PER_RAD, UNIT_SYMBOLS, angle_from_rad
from ..core.validate import as_int
from ..drives.protocol import AbstractDrive
from .errors import ErrorModel, check_drive_model
from .laws import Uniform
from .montecarlo import as_key


class PathwiseSensitivity(eqx.Module):
    """One metric's Monte Carlo mean and its gradient with respect to every law parameter.

    - `metric`: the metric's name; `mean`: the mean of its smooth value over the samples (rad, or a count).
    - `gradient`: an `ErrorModel` of the same structure as the study's, whose law parameters hold
      ∂mean/∂parameter (per µm for lengths, per rad for angles); read it with `gradient_rows`.
    - `n_samples`: how many samples the mean is over.
    """

    metric: str = eqx.field(static=True)
    mean: float
    gradient: ErrorModel
    n_samples: int = eqx.field(static=True)


@kept_jit
def _chunk_grad(
    drive: AbstractDrive,
    metrics: tuple[AbstractMetric, ...],
    static: ErrorModel,
    key: PRNGKeyArray,
    params: ErrorModel,
    idx: UInt[Array, " chunk"],
    weight: Float[Array, " chunk"],
) -> tuple[Float[Array, " metrics"], ErrorModel]:
    """Sums over a chunk of samples `idx` (sample i drawn with ``fold_in(key, i)``, weighted by `weight`) of the
    metrics' smooth values and of their gradients with respect to the law parameters `params` (the model's inexact
    arrays; `static`: the rest of it). Traced once per drive, metrics, model structure and chunk size."""

    def per(i, wt):
        def f(pp):
            errors = eqx.combine(pp, static).sample(jax.random.fold_in(key, i))
            r = drive.response(errors)
            return wt * jnp.stack([m.smooth(drive, r) for m in metrics])

        return f(params), jax.jacrev(f)(params)

    vals, grads = jax.vmap(per)(idx, weight)
    return jnp.sum(vals, axis=0), jax.tree.map(lambda g: jnp.sum(g, axis=0), grads)


def pathwise_sensitivities(
    drive: AbstractDrive,
    model: ErrorModel,
    metrics: AbstractMetric | Sequence[AbstractMetric],
    *,
    key: int | PRNGKeyArray,
    n_samples: int = 256,
    chunk: int = 64,
) -> dict[str, PathwiseSensitivity]:
    """∂ mean(metric)/∂(law parameter) over `n_samples` samples, pathwise, for every metric and every parameter.

    **Arguments:**

    - `drive`: any drive; `model`: its error model (an `ErrorModel` over ``drive.error_sources``).
    - `metrics`: one metric object of the drive, or several (computed together).
    - `key`: the study's seed or key; sample i uses ``fold_in(key, i)``.
    - `n_samples`: samples in the mean (their gradients are averaged).
    - `chunk`: samples computed together (vectorised; ≥ 1, at most `n_samples` used); every chunk has the same
      shape, so one compilation.

    **Returns:** a `PathwiseSensitivity` per metric, by metric name.
    """
    require_x64()
    metrics = (metrics,) if isinstance(metrics, AbstractMetric) else tuple(metrics)
    if not metrics or not all(isinstance(m, AbstractMetric) for m in metrics):
        raise ValueError(f"metrics: give one or more metric objects of the drive, e.g. {list(drive.metrics.values())[:2]}")
    offered = drive.metrics
    for m in metrics:
        if m.name not in offered or type(offered[m.name]) is not type(m):
            raise ValueError(f"metrics: {type(drive).__name__} offers {list(offered)}, not {m.name!r}")
    check_drive_model(drive, model)
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples: must be a whole number ≥ 1, got {n_samples!r}")
    chunk = min(as_int("chunk", chunk, minimum=1), int(n_samples))
    k0 = as_key(key)
    params, static = eqx.partition(model, eqx.is_inexact_array)

    total, gsum = None, None
    for start in range(0, int(n_samples), chunk):
        # Every chunk has the same shape (one compilation); samples past n_samples get weight 0.
        idx = jnp.arange(start, start + chunk, dtype=jnp.uint32)
        weight = (idx < n_samples).astype(float)
        v, g = _chunk_grad(drive, metrics, static, k0, params, idx, weight)
        total = v if total is None else total + v
        gsum = g if gsum is None else jax.tree.map(jnp.add, gsum, g)
    assert total is not None and gsum is not None
    out = {}
    for i, m in enumerate(metrics):
        grad = jax.tree.map(lambda g, i=i: g[i] / n_samples, gsum)
        out[m.name] = PathwiseSensitivity(m.name, float(total[i]) / n_samples, eqx.combine(grad, static), int(n_samples))
    return out


@dataclasses.dataclass(frozen=True)
class GradientRow:
    """∂mean/∂(one law parameter): `label` ("source.parameter", e.g. ``pin_radius.half_width``), the source's
    unit (`unit`: "µm" or "rad") and the derivative per that unit (`value`; summed over a source's instances)."""

    label: str
    source: str
    unit: str
    value: float


def _law_rows(prefix: str, law) -> Iterator[tuple[str, float]]:
    # A tolerance band is reported by its centre and half-width (draw = centre + half-width·u).
    if isinstance(law, Uniform) and law.symmetric:
        lo, hi = float(np.sum(np.asarray(law.low))), float(np.sum(np.asarray(law.high)))
        yield f"{prefix}.centre", lo + hi
        yield f"{prefix}.half_width", hi - lo
        return
    if not isinstance(law, eqx.Module):
        return
    for f in dataclasses.fields(law):
        v = getattr(law, f.name, None)
        if eqx.is_inexact_array(v):
            yield f"{prefix}.{f.name}", float(np.sum(np.asarray(v)))
        elif isinstance(v, eqx.Module):
            yield from _law_rows(f"{prefix}.{f.name}", v)


def _left_out(law) -> bool:
    """A law whose parameters are all 0 (a source left out of a study file: fixed at 0)."""
    leaves = [x for x in jax.tree.leaves(law) if eqx.is_array(x)]
    return bool(leaves) and all(bool(np.all(np.asarray(x) == 0)) for x in leaves)


def gradient_rows(sensitivity: PathwiseSensitivity, model: ErrorModel) -> list[GradientRow]:
    """The gradient of `sensitivity` as rows, source by source in the drive's order; sources fixed at 0 in
    `model` (left out of a study file) are skipped. An eccentricity's phase parameters are labelled
    ``source.phase.…``."""
    rows = []
    grad = sensitivity.gradient
    for name, spec in model.specs.items():
        if _left_out(model.sources[name].magnitude):
            continue
        src = grad.sources[name]
        for label, v in _law_rows(name, src.magnitude):
            rows.append(GradientRow(label, name, spec.unit, v))
        if src.phase is not None:
            for label, v in _law_rows(f"{name}.phase", src.phase):
                rows.append(GradientRow(label, name, "rad", v))
    return rows


def _metric_unit(metric: AbstractMetric, unit: str) -> tuple[str, float]:
    if metric.quantity != "angle":
        return "pairs", 1.0
    u = metric.report_unit or unit
    return u, float(angle_from_rad(1.0, u))


def pathwise_summary(
    result: Mapping[str, PathwiseSensitivity], model: ErrorModel, metrics: Mapping[str, AbstractMetric], *, unit: str = "arcsec"
) -> dict:
    """The summary entry of pathwise sensitivities: per metric its mean and the derivatives per µm (lengths) or per ″
    (angles). Angular metrics are in the metric's own report unit if it has one (``report_unit``), else in `unit`."""
    n = next(iter(result.values())).n_samples
    out: dict = {"samples": n, "what": "d(mean over reducers)/d(law parameter), pathwise (reparametrised draws)"}
    for name, s in result.items():
        u, k = _metric_unit(metrics[name], unit)
        rows = {}
        for r in gradient_rows(s, model):
            per, scale = ("µm", 1.0) if r.unit == "µm" else ("″", 1.0 / ARCSEC_PER_RAD)
            rows[r.label] = {"per": per, "value": r.value * k * scale}
        out[name] = {"unit": u, "mean": s.mean * k, "derivatives": rows}
    return out


def pathwise_report(entry: dict) -> list[str]:
    """The report section of a `pathwise_summary` entry (Markdown lines)."""
    names = [k for k in entry if k not in ("samples", "what")]
    if not names:
        return []
    head = " | ".join(f"d mean {n} ({UNIT_SYMBOLS.get(entry[n]['unit'], entry[n]['unit'])} per)" for n in names)
    L = [
        "",
        "## Sensitivity of the Monte Carlo means to the error laws",
        "",
        f"Pathwise derivatives over {entry['samples']:,} samples (samples 0 … {entry['samples'] - 1:,} of the study's seed, "
        "its `pathwise_samples` whatever the Monte Carlo's count; random numbers held): "
        "mean of the per-sample gradient of each metric's smooth value.",
        "",
        "| | " + " | ".join(f"{n}" for n in names) + " |",
        "|---" * (len(names) + 1) + "|",
        "| mean | " + " | ".join(f"{entry[n]['mean']:.4g} {entry[n]['unit']}" for n in names) + " |",
        "",
        f"| parameter | {head} |",
        "|---" * (len(names) + 1) + "|",
    ]
    for key in entry[names[0]]["derivatives"]:
        cells = [entry[n]["derivatives"][key] for n in names]
        L.append(f"| {key} (per {cells[0]['per']}) | " + " | ".join(f"{c['value']:.4g}" for c in cells) + " |")
    return [*L, ""]


__all__ = ("GradientRow", "PathwiseSensitivity", "gradient_rows", "pathwise_report", "pathwise_sensitivities", "pathwise_summary")
