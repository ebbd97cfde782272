"""Cycloid-pin reducer: tolerances, Monte Carlo, sensitivities (spec cycloid_pin.md, "What gearte must offer").

- `CycloidTolerances`: how each error of `CycloidErrors` is drawn over a production batch
  (signed laws for scalar errors, the foundation's magnitude and phase laws for
  eccentricity-like ones, and sinusoidal patterns for per-space / per-pin errors such as
  the seed's Δβ(n) = 30″ sin(2πn/z_a)).
- `CycloidStudy`: one Monte Carlo sample, ``key → vector of metrics`` (lost motion, rotation
  error, loaded pairs, per-pin clearances), for `gearte.monte_carlo`.
- `unit_metrics`, `sensitivities`: the metrics of one reducer as differentiable functions of
  its errors and of the modification, and their gradients.
- `tolerance_sensitivities`: pathwise derivatives of Monte Carlo means with respect to every
  parameter of every law (a tolerance half-width, a Rayleigh scale, …).
"""

from __future__ import annotations

import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._distributions import AbstractMagnitude, AbstractPhase, FixedPhase, UniformPhase
from .._precision import require_x64
from .cycloid_pin import (ERROR_FIELDS, ERROR_UNITS, PER_PIN, PER_SPACE, CycloidErrors, CycloidPin, CycloidModification,
                          _analyse, checked_errors, loaded_pairs, revolution_angles, smooth_loaded_pairs)

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi


# ---------------------------------------------------------------- laws


class AbstractErrorLaw(eqx.Module):
    """Law of a signed error (µm, or rad for angles): ``sample(key, shape)``."""

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...]) -> Float[Array, "..."]:
        raise NotImplementedError

    def describe(self, unit: str = "µm") -> str:
        raise NotImplementedError


class Exactly(AbstractErrorLaw):
    """Always `value` (may be negative)."""

    value: Float[Array, ""]

    def __init__(self, value: ArrayLike):
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"Exactly.value: must be finite, got {value!r}")
        self.value = jnp.asarray(v)

    def sample(self, key, shape):
        del key
        return jnp.broadcast_to(self.value, shape)

    def describe(self, unit: str = "µm") -> str:
        return f"fixed {_fmt(float(self.value), unit)}"


class SignedUniform(AbstractErrorLaw):
    """Uniform on `centre` ± `half_width` (a tolerance band; half_width ≥ 0)."""

    centre: Float[Array, ""]
    half_width: Float[Array, ""]

    def __init__(self, half_width: ArrayLike, centre: ArrayLike = 0.0):
        h, c = float(half_width), float(centre)
        if not (math.isfinite(h) and math.isfinite(c)):
            raise ValueError("SignedUniform: centre and half_width must be finite")
        if h < 0:
            raise ValueError(f"SignedUniform.half_width: must be ≥ 0, got {h:g} (a tolerance cannot be negative)")
        self.centre, self.half_width = jnp.asarray(c), jnp.asarray(h)

    def sample(self, key, shape):
        return self.centre + self.half_width * jax.random.uniform(key, shape, dtype=float, minval=-1.0, maxval=1.0)

    def describe(self, unit: str = "µm") -> str:
        return f"uniform on {_fmt(float(self.centre), unit)} ± {_fmt(float(self.half_width), unit)}"


class Sinusoid(AbstractErrorLaw):
    """A pattern over spaces or pins: e_k = A sin(2π·order·(k + 1)/N + φ), k = 0 … N − 1.

    (k + 1 is the seed's 1-based tooth number: Δβ(n) = 30″ sin(2πn/z_a) is
    ``Sinusoid(Exactly(30″), FixedPhase(0))``.) `amplitude` is any law of a scalar (a
    foundation magnitude law or a signed law); `phase` a foundation phase law.
    """

    amplitude: Any
    phase: Any
    order: int

    def __init__(self, amplitude, phase=None, *, order: int = 1):
        self.amplitude = amplitude if hasattr(amplitude, "sample") else Exactly(amplitude)
        self.phase = FixedPhase(0.0) if phase is None else phase if hasattr(phase, "sample") else FixedPhase(phase)
        if isinstance(order, bool) or not isinstance(order, int) or order < 1:
            raise ValueError(f"Sinusoid.order: must be a whole number ≥ 1, got {order!r}")
        self.order = order

    def sample(self, key, shape):
        if len(shape) != 1:
            raise ValueError("Sinusoid: only for per-space or per-pin errors (one value per tooth space or pin)")
        ka, kp = jax.random.split(key)
        n = shape[0]
        amp = self.amplitude.sample(ka, ())
        ph = self.phase.sample(kp, ())
        k = jnp.arange(1, n + 1, dtype=float)
        return amp * jnp.sin(TWO_PI * self.order * k / n + ph)

    def describe(self, unit: str = "µm") -> str:
        a = self.amplitude.describe(unit) if isinstance(self.amplitude, AbstractErrorLaw) else self.amplitude.describe()
        return f"A sin(2π·{self.order}·n/N + φ), A: {a}, φ: {self.phase.describe()}"


TWO_PI = 2.0 * math.pi


def _fmt(v: float, unit: str) -> str:
    if unit == "rad":
        return f"{v * ARCSEC_PER_RAD:.6g}″"
    return f"{v:.6g} {unit}"


def _describe(law, unit: str) -> str:
    if isinstance(law, AbstractErrorLaw):
        return law.describe(unit)
    d = law.describe()
    if unit == "rad" and isinstance(law, AbstractMagnitude):
        d = d.replace("µm", "rad")
    return d


def _is_law(x) -> bool:
    return isinstance(x, (AbstractErrorLaw, AbstractMagnitude, AbstractPhase))


class CycloidTolerances(eqx.Module):
    """How each error of `CycloidErrors` is drawn (fields of the same names; default: exactly 0).

    Each field is a law with ``sample(key, shape)``: `Exactly`, `SignedUniform`, `Sinusoid`
    (per-space / per-pin fields only), a foundation magnitude law (`Fixed`, `Uniform`,
    `Normal`, `TruncatedNormal`, `Rayleigh`) or, for `*_phase` fields, a phase law
    (`UniformPhase`, `FixedPhase`). Per-space and per-pin fields draw one value per space
    / pin (independently, unless the law is a `Sinusoid`). Units as in `CycloidErrors`:
    µm, and rad for angles.
    """

    laws: dict

    def __init__(self, **laws):
        unknown = sorted(set(laws) - set(ERROR_FIELDS))
        if unknown:
            raise ValueError(f"CycloidTolerances: unknown error field(s) {unknown}; the fields are {list(ERROR_FIELDS)}")
        full = {}
        for name in ERROR_FIELDS:
            law = laws.get(name, Exactly(0.0))
            if not _is_law(law):
                law = Exactly(law)
            if isinstance(law, Sinusoid) and name not in PER_SPACE + PER_PIN:
                raise ValueError(f"CycloidTolerances.{name}: a Sinusoid pattern needs a per-space or per-pin error "
                                 f"({', '.join(PER_SPACE + PER_PIN)})")
            full[name] = law
        self.laws = full

    def sample(self, key: PRNGKeyArray, drive: CycloidPin) -> CycloidErrors:
        """One reducer's errors; field i uses ``fold_in(key, i)`` in the order of `CycloidErrors`."""
        out = {}
        for i, name in enumerate(ERROR_FIELDS):
            k = jax.random.fold_in(key, i)
            shape = (drive.z_lobes,) if name in PER_SPACE else (drive.z_pins,) if name in PER_PIN else ()
            out[name] = jnp.asarray(self.laws[name].sample(k, shape), dtype=float)
        return CycloidErrors(**out)

    def describe(self) -> list[tuple[str, str]]:
        """(field, law) rows for reports; fields that are exactly 0 are left out."""
        rows = []
        for name in ERROR_FIELDS:
            law = self.laws[name]
            if isinstance(law, Exactly) and float(law.value) == 0.0:
                continue
            rows.append((name, _describe(law, ERROR_UNITS[name])))
        return rows


# ---------------------------------------------------------------- metrics of one reducer

#: Scalar metrics of `unit_metrics` (angles rad, lengths mm, counts pairs).
UNIT_METRICS = ("lost_motion_max", "lost_motion_min", "lost_motion_mean", "rotation_error_p2p", "rotation_error_mean",
                "loaded_pairs_smooth", "loaded_pairs_min", "loaded_pairs_mean")


def _metrics(drive: CycloidPin, err: CycloidErrors, positions, budget_mm, width_mm) -> dict:
    res = jax.vmap(lambda t: _analyse(drive, err, t, False))(positions)
    te = res.rotation_error
    lm = res.lost_motion
    exact = loaded_pairs(res, budget_mm=budget_mm).astype(float)
    return {"lost_motion_max": jnp.max(lm), "lost_motion_min": jnp.min(lm), "lost_motion_mean": jnp.mean(lm),
            "rotation_error_p2p": jnp.max(te) - jnp.min(te), "rotation_error_mean": jnp.mean(te),
            "loaded_pairs_smooth": jnp.mean(smooth_loaded_pairs(res, budget_mm=budget_mm, width_mm=width_mm)),
            "loaded_pairs_min": jnp.min(exact), "loaded_pairs_mean": jnp.mean(exact),
            "not_converged": jnp.sum(~res.converged).astype(float)}


@eqx.filter_jit
def _metrics_jit(drive, err, positions, budget_mm, width_mm):
    return _metrics(drive, err, positions, budget_mm, width_mm)


def _positions(drive: CycloidPin, positions) -> Array:
    p = jnp.asarray(revolution_angles(drive, 4) if positions is None else positions, dtype=float)
    if p.ndim != 1 or p.size == 0:
        raise ValueError(f"positions: give a 1-D array of input angles (rad), got shape {p.shape}")
    return p


def _budget(budget_mm, width_mm) -> tuple[float, float]:
    b = float(budget_mm)
    if not (math.isfinite(b) and b >= 0):
        raise ValueError(f"budget_mm: the tangential deformation budget must be a length ≥ 0 mm, got {budget_mm!r}")
    w = b / 10.0 if width_mm is None else float(width_mm)
    if not (math.isfinite(w) and w > 0):
        raise ValueError(f"width_mm: the smoothing width of the loaded-pair count must be > 0 mm, got {width_mm!r} "
                         "(give one when the budget is 0)")
    return b, w


def unit_metrics(drive: CycloidPin, errors: CycloidErrors | None, *, budget_mm: float, positions: ArrayLike | None = None,
                 width_mm: float | None = None) -> dict[str, Array]:
    """Metrics of one reducer over a set of input positions (no normal clearances).

    **Arguments:**

    - `drive`, `errors`: the stage and its errors.
    - `budget_mm`: tangential elastic deformation budget on the pin circle, mm (seed: 0.2).
    - `positions`: input angles θ_T, rad (default: one input revolution, 4 per pin pitch).
    - `width_mm`: smoothing width of the loaded-pair surrogate, mm (default budget/10).

    **Returns:** a dict: ``lost_motion_max/min/mean`` (rad), ``rotation_error_p2p/mean`` (rad),
    ``loaded_pairs_smooth`` (mean over positions of the sigmoid surrogate),
    ``loaded_pairs_min/mean`` (exact counts), ``not_converged`` (pins whose solve did not converge).
    """
    require_x64()
    b, w = _budget(budget_mm, width_mm)
    return _metrics_jit(drive, checked_errors(drive, errors), _positions(drive, positions), b, w)


class Sensitivity(eqx.Module):
    """Gradient of one metric of one reducer.

    - `metric`: its name (see `UNIT_METRICS`); `value`: its value (rad, or pairs).
    - `errors`: ∂metric/∂(each `CycloidErrors` field) (per µm, or per rad for angles).
    - `modification`: ∂metric/∂(shift, equidistant: per mm; rotation: per rad).
    """

    metric: str
    value: Array
    errors: CycloidErrors
    modification: CycloidModification


@eqx.filter_jit
def _grad_jit(drive, err, positions, budget_mm, width_mm, metrics: tuple):
    def f(diff):
        mod, e = diff
        d = eqx.tree_at(lambda x: x.modification, drive, mod)
        m = _metrics(d, e, positions, budget_mm, width_mm)
        return jnp.stack([m[k] for k in metrics])

    diff = (drive.modification, err)
    return f(diff), jax.jacrev(f)(diff)


def _check_metrics(metrics) -> tuple[str, ...]:
    metrics = tuple(metrics)
    smooth = [x for x in UNIT_METRICS if x not in ("loaded_pairs_min", "loaded_pairs_mean")]
    for m in metrics:
        if m not in smooth:
            raise ValueError(f"metrics: {m!r} has no gradient here; use some of {smooth}")
    if not metrics:
        raise ValueError(f"metrics: name at least one of {smooth}")
    return metrics


def sensitivities(drive: CycloidPin, errors: CycloidErrors | None, *, budget_mm: float, metrics=("lost_motion_max",),
                  positions: ArrayLike | None = None, width_mm: float | None = None) -> dict[str, Sensitivity]:
    """Gradients of `metrics` (names of `UNIT_METRICS` except the exact counts) with respect to every
    error and to the modification amounts, at the reducer `errors`.

    The lost motion and rotation error are max/min over positions: their gradient is that of the
    position and pair that attain it. The loaded-pair count is piecewise constant; its
    sensitivity is that of the smooth surrogate ``loaded_pairs_smooth``.
    """
    require_x64()
    b, w = _budget(budget_mm, width_mm)
    metrics = _check_metrics(metrics)
    err = checked_errors(drive, errors)
    pos = _positions(drive, positions)
    vals, (gmod, gerr) = _grad_jit(drive, err, pos, b, w, metrics)
    return {m: Sensitivity(m, vals[i], jax.tree.map(lambda g: g[i], gerr), jax.tree.map(lambda g: g[i], gmod))
            for i, m in enumerate(metrics)}


def sensitivity_rows(sens: Sensitivity, *, scale: float = 1.0) -> list[tuple[str, str, float]]:
    """(quantity, unit, ∂metric/∂quantity × scale) rows: every error field (per-space / per-pin fields
    summed: the effect of the same change on all of them) and the three modification amounts."""
    rows = []
    for name in ERROR_FIELDS:
        g = np.asarray(getattr(sens.errors, name))
        rows.append((name, ERROR_UNITS[name], float(np.sum(g)) * scale))
    m = sens.modification
    rows += [("modification.shift", "mm", float(m.shift) * scale), ("modification.equidistant", "mm", float(m.equidistant) * scale),
             ("modification.rotation", "rad", float(m.rotation) * scale)]
    return rows


# ---------------------------------------------------------------- Monte Carlo

#: Scalar outputs of `CycloidStudy`, in order, before the per-pin blocks.
STUDY_SCALARS = ("lost_motion_max", "lost_motion_min", "lost_motion_mean", "rotation_error_p2p", "rotation_error_mean",
                 "loaded_pairs_min", "loaded_pairs_mean", "lost_motion", "rotation_error", "loaded_pairs", "contact_pin",
                 "not_converged")


class CycloidStudy(eqx.Module):
    """One Monte Carlo sample of a cycloid-pin stage: ``study(key) → vector`` (use `unpack`).

    **Arguments:**

    - `drive`: the stage (with its modification).
    - `tolerances`: how its errors are drawn.
    - `budget_mm`: tangential deformation budget, mm.
    - `positions`: input angles for the lost motion, rotation error and loaded pairs over the
      cycle (default: one input revolution, 4 per pin pitch), rad.
    - `analysis_angle`: the input position of the per-pin clearances (default half a pitch), rad.
    - `normal`: also the per-pin normal clearances at `analysis_angle`.

    Outputs (`unpack`): the `STUDY_SCALARS` (lost motion max/min/mean over the positions,
    rotation-error peak-to-peak and mean, rad; loaded pairs min/mean over the positions; lost
    motion, rotation error, loaded pairs and contacting pin (0-based) at `analysis_angle`; the
    number of non-converged solves) and, at `analysis_angle`, ``tangential_arc`` (z_b, mm; NaN
    where the pin can never touch) and ``normal_clearance`` (z_b, mm).
    """

    drive: CycloidPin
    tolerances: CycloidTolerances
    budget_mm: Float[Array, ""]
    positions: Float[Array, " p"]
    analysis_angle: Float[Array, ""]
    normal: bool

    def __init__(self, drive: CycloidPin, tolerances: CycloidTolerances, *, budget_mm: float,
                 positions: ArrayLike | None = None, analysis_angle: float | None = None, normal: bool = True):
        if not isinstance(drive, CycloidPin):
            raise ValueError(f"drive: expected a CycloidPin, got {type(drive).__name__}")
        if not isinstance(tolerances, CycloidTolerances):
            raise ValueError(f"tolerances: expected a CycloidTolerances, got {type(tolerances).__name__}")
        self.drive, self.tolerances = drive, tolerances
        b = float(budget_mm)
        if not (math.isfinite(b) and b >= 0):
            raise ValueError(f"budget_mm: the tangential deformation budget must be a length ≥ 0 mm, got {budget_mm!r}")
        self.budget_mm = jnp.asarray(b)
        self.positions = _positions(drive, positions)
        self.analysis_angle = jnp.asarray(drive.pitch / 2 if analysis_angle is None else float(analysis_angle))
        self.normal = bool(normal)

    @property
    def size(self) -> int:
        return len(STUDY_SCALARS) + 2 * self.drive.z_pins

    def __call__(self, key: PRNGKeyArray) -> Float[Array, " m"]:
        err = self.tolerances.sample(key, self.drive)
        res = jax.vmap(lambda t: _analyse(self.drive, err, t, False))(self.positions)
        at = _analyse(self.drive, err, self.analysis_angle, self.normal)
        te, lm = res.rotation_error, res.lost_motion
        counts = loaded_pairs(res, budget_mm=self.budget_mm).astype(float)
        scalars = jnp.stack([jnp.max(lm), jnp.min(lm), jnp.mean(lm), jnp.max(te) - jnp.min(te), jnp.mean(te),
                             jnp.min(counts), jnp.mean(counts), at.lost_motion, at.rotation_error,
                             loaded_pairs(at, budget_mm=self.budget_mm).astype(float), at.contact_pin.astype(float),
                             (jnp.sum(~res.converged) + jnp.sum(~at.converged)).astype(float)])
        arc = jnp.where(jnp.isfinite(at.tangential_arc), at.tangential_arc, jnp.nan)
        return jnp.concatenate([scalars, arc, at.normal_clearance])

    def unpack(self, values) -> dict[str, np.ndarray]:
        """Split per-sample vectors (n, m) into named arrays."""
        v = np.asarray(values)
        k = len(STUDY_SCALARS)
        zb = self.drive.z_pins
        out = {name: v[..., i] for i, name in enumerate(STUDY_SCALARS)}
        out["tangential_arc"] = v[..., k:k + zb]
        out["normal_clearance"] = v[..., k + zb:k + 2 * zb]
        return out

    def bytes_per_sample(self) -> int:
        """Rough peak working memory per sample (bytes), to size Monte Carlo blocks."""
        return 8 * (int(self.positions.size) + 1) * self.drive.z_pins * 64


def tolerance_sensitivities(drive: CycloidPin, tolerances: CycloidTolerances, *, key: int | PRNGKeyArray, n_samples: int = 256,
                            budget_mm: float, metrics=("lost_motion_max",), positions: ArrayLike | None = None,
                            width_mm: float | None = None, chunk: int = 64) -> dict[str, tuple[Array, CycloidTolerances]]:
    """Pathwise derivatives of Monte Carlo means with respect to the law parameters.

    Every draw is a differentiable function of its law's parameters (reparametrisation:
    e.g. centre + half_width·u), so ∂ mean(metric)/∂ parameter is the mean over samples of
    the per-sample gradient. Sample i uses ``fold_in(key, i)`` as `CycloidStudy` does.

    **Returns:** for each metric, (mean value, gradient) where the gradient has the structure of
    `tolerances` (use `tolerance_gradient_rows` for a table).
    """
    from .._montecarlo import as_key  # here: gearte._montecarlo imports the drives package

    require_x64()
    b, w = _budget(budget_mm, width_mm)
    pos = _positions(drive, positions)
    k0 = as_key(key)
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples: must be a whole number ≥ 1, got {n_samples!r}")
    metrics = _check_metrics(metrics)
    params, static = eqx.partition(tolerances, eqx.is_inexact_array)

    chunk = max(1, min(int(chunk), int(n_samples)))

    @eqx.filter_jit
    def chunk_grad(p, idx, weight):
        def per(i, wt):
            def f(pp):
                tol = eqx.combine(pp, static)
                err = tol.sample(jax.random.fold_in(k0, i), drive)
                m = _metrics(drive, err, pos, b, w)
                return wt * jnp.stack([m[k] for k in metrics])
            return f(p), jax.jacrev(f)(p)
        vals, grads = jax.vmap(per)(idx, weight)
        return jnp.sum(vals, axis=0), jax.tree.map(lambda g: jnp.sum(g, axis=0), grads)

    total, gsum = None, None
    for start in range(0, n_samples, chunk):
        # Every chunk has the same shape (one compilation); samples past n_samples get weight 0.
        idx = jnp.arange(start, start + chunk, dtype=jnp.uint32)
        weight = (idx < n_samples).astype(float)
        v, g = chunk_grad(params, idx, weight)
        total = v if total is None else total + v
        gsum = g if gsum is None else jax.tree.map(jnp.add, gsum, g)
    out = {}
    for i, m in enumerate(metrics):
        grad = jax.tree.map(lambda g: g[i] / n_samples, gsum)
        out[m] = (total[i] / n_samples, eqx.combine(grad, static))
    return out


def tolerance_gradient_rows(grad: CycloidTolerances) -> list[tuple[str, float]]:
    """("field.parameter", value) rows of a `tolerance_sensitivities` gradient (non-zero law parameters)."""
    rows = []
    for name in ERROR_FIELDS:
        law = grad.laws[name]
        leaves = jax.tree_util.tree_flatten_with_path(law)[0]
        for path, leaf in leaves:
            if not eqx.is_inexact_array(leaf):
                continue
            label = name + "".join(f".{getattr(p, 'name', getattr(p, 'key', p))}" for p in path)
            rows.append((label, float(np.sum(np.asarray(leaf)))))
    return rows


__all__ = ("AbstractErrorLaw", "CycloidStudy", "CycloidTolerances", "Exactly", "Sensitivity", "SignedUniform", "Sinusoid",
           "STUDY_SCALARS", "UNIT_METRICS", "UniformPhase", "sensitivities", "sensitivity_rows", "tolerance_gradient_rows",
           "tolerance_sensitivities", "unit_metrics")
