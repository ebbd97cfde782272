"""Cycloid-pin reducer: the metrics of one reducer's clearance analysis over the input-angle grid.

A `CycloidPin`'s response (`CycloidPin.response`) is its `Clearances` at every angle of
its grid (`CycloidPin.input_angles`). The metrics below read it:

- `LostMotion` (``"lost_motion"``, the default): the largest lost motion over the grid, rad;
- `LostMotionMin` (``"lost_motion_min"``): the smallest (negative: the disc interferes somewhere);
- `RotationErrorPeakToPeak` (``"peak_to_peak"``): peak-to-peak of the rotation error (TE) of
  the stage under a forward load, rad;
- `LoadedPairs` (``"loaded_pairs"``): pairs that can carry load within the drive's tangential
  deformation budget, averaged over the grid (a count; higher is better);
- `LoadedPairsMin` (``"loaded_pairs_min"``): the fewest over the grid.

The counts are piecewise constant; their `smooth` surrogate is the sigmoid count
Σ σ((budget − arc_j)/w) over the driving pins (`smooth_loaded_pairs`), averaged (or
minimised) over the grid in the same way. The lost motion and rotation error are extrema
over the grid; their gradient is that of the position and pair that attain them.

`unit_metrics` and `sensitivities` give the metrics of one reducer and their gradients with
respect to its errors and to the profile modification.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..core.metrics import AbstractMetric, Quantity
from ..core.precision import require_x64
from ..core.programs import kept_jit
from .cycloid_pin_contact import Clearances, _analyse, _clearances_jit, _sweep_jit, loaded_pairs, smooth_loaded_pairs
from .cycloid_pin_geometry import CycloidErrors, CycloidModification, checked_errors

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin


def _counts(drive: CycloidPin, response: Clearances) -> Float[Array, " p"]:
    return loaded_pairs(response, budget_mm=drive.analysis.budget_mm).astype(float)


def _smooth_counts(drive: CycloidPin, response: Clearances) -> Float[Array, " p"]:
    a = drive.analysis
    return smooth_loaded_pairs(response, budget_mm=a.budget_mm, width_mm=a.width_mm)


class LostMotion(AbstractMetric):
    """Lost motion: the rotation of the output between its driving and reverse contacts with the input held,
    at most over the drive's input-angle grid (rad)."""

    name: ClassVar[str] = "lost_motion"
    label: ClassVar[str] = "lost motion, max over the grid"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcmin"

    def __call__(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        del drive
        return jnp.max(response.lost_motion)

    def describe(self) -> str:
        return "lost motion = driving contact − reverse contact with the input held, its maximum over the input-angle grid"


class LostMotionMin(AbstractMetric):
    """The smallest lost motion over the grid (rad); negative where the rigid disc interferes."""

    name: ClassVar[str] = "lost_motion_min"
    label: ClassVar[str] = "lost motion, min over the grid"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcmin"

    def __call__(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        del drive
        return jnp.min(response.lost_motion)

    def describe(self) -> str:
        return "lost motion, its minimum over the input-angle grid (negative: the rigid disc interferes there)"


class RotationErrorPeakToPeak(AbstractMetric):
    """Peak-to-peak of the rotation error (TE) of the stage under a forward load over the grid (rad)."""

    name: ClassVar[str] = "peak_to_peak"
    label: ClassVar[str] = "rotation error p-p"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcsec"

    def __call__(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        del drive
        te = response.rotation_error
        return jnp.max(te) - jnp.min(te)

    def describe(self) -> str:
        return "peak-to-peak of the rotation error Δθ = θ_a − (z_b/z_a) θ_T of the contacting pair (forward load) over the input-angle grid"


class LoadedPairs(AbstractMetric):
    """Loaded pairs: driving-flank pins whose tangential clearance on the pin circle is within the deformation
    budget, averaged over the grid. Smooth surrogate: the sigmoid count, averaged likewise."""

    name: ClassVar[str] = "loaded_pairs"
    label: ClassVar[str] = "loaded pairs, mean over the grid"
    quantity: ClassVar[Quantity] = "count"
    higher_is_better: ClassVar[bool] = True
    report_unit: ClassVar[str | None] = "pairs"

    def __call__(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        return jnp.mean(_counts(drive, response))

    def smooth(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        return jnp.mean(_smooth_counts(drive, response))

    def describe(self) -> str:
        return (
            "loaded pairs = driving-flank pins whose tangential clearance on the pin circle is within the deformation "
            "budget, the mean over the input-angle grid (smooth surrogate: Σ σ((budget − arc)/w))"
        )


class LoadedPairsMin(AbstractMetric):
    """The fewest loaded pairs over the grid. Smooth surrogate: the smallest sigmoid count over the grid."""

    name: ClassVar[str] = "loaded_pairs_min"
    label: ClassVar[str] = "loaded pairs, min over the grid"
    quantity: ClassVar[Quantity] = "count"
    higher_is_better: ClassVar[bool] = True
    report_unit: ClassVar[str | None] = "pairs"

    def __call__(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        return jnp.min(_counts(drive, response))

    def smooth(self, drive: CycloidPin, response: Clearances) -> Float[Array, ""]:
        return jnp.min(_smooth_counts(drive, response))

    def describe(self) -> str:
        return "loaded pairs (see loaded_pairs), the fewest over the input-angle grid"


#: The metrics a `CycloidPin` offers, by study-file name (the first is the default).
METRICS: tuple[type[AbstractMetric], ...] = (LostMotion, LostMotionMin, RotationErrorPeakToPeak, LoadedPairs, LoadedPairsMin)


# ---------------------------------------------------------------- one reducer

#: Scalar metrics of `unit_metrics` (angles rad, counts pairs).
UNIT_METRICS = (
    "lost_motion_max",
    "lost_motion_min",
    "lost_motion_mean",
    "rotation_error_p2p",
    "rotation_error_mean",
    "loaded_pairs_smooth",
    "loaded_pairs_min",
    "loaded_pairs_mean",
    "not_converged",
)


def _positions(drive: CycloidPin, positions: ArrayLike | None) -> Array:
    p = drive.input_angles() if positions is None else jnp.asarray(positions, dtype=float)
    if p.ndim != 1 or p.size == 0:
        raise ValueError(f"positions: give a 1-D array of input angles (rad), got shape {p.shape}")
    return p


def _sweep(drive: CycloidPin, err: CycloidErrors, positions) -> Clearances:
    return jax.vmap(lambda t: _analyse(drive, err, t, False))(positions)


def grid_metrics(drive: CycloidPin, err: CycloidErrors, positions) -> dict[str, Array]:
    """`unit_metrics` without checks, to call inside `jax.jit` (`err` as from `checked_errors`; `positions` an array)."""
    res = _sweep(drive, err, positions)
    te, lm = res.rotation_error, res.lost_motion
    exact = _counts(drive, res)
    return {
        "lost_motion_max": jnp.max(lm),
        "lost_motion_min": jnp.min(lm),
        "lost_motion_mean": jnp.mean(lm),
        "rotation_error_p2p": jnp.max(te) - jnp.min(te),
        "rotation_error_mean": jnp.mean(te),
        "loaded_pairs_smooth": jnp.mean(_smooth_counts(drive, res)),
        "loaded_pairs_min": jnp.min(exact),
        "loaded_pairs_mean": jnp.mean(exact),
        "not_converged": jnp.sum(~res.converged).astype(float),
    }


@kept_jit
def grid_metrics_jit(drive: CycloidPin, err: CycloidErrors, positions) -> dict[str, Array]:
    """`grid_metrics`, compiled."""
    return grid_metrics(drive, err, positions)


def unit_metrics(
    drive: CycloidPin, errors: CycloidErrors | Mapping[str, Any] | None = None, *, positions: ArrayLike | None = None
) -> dict[str, Array]:
    """Metrics of one reducer over a set of input positions (no normal clearances).

    **Arguments:**

    - `drive`: the stage (its deformation budget and smoothing width are those of `drive.analysis`).
    - `errors`: its errors (a `CycloidErrors`, a mapping of error fields, or None: none).
    - `positions`: input angles θ_T, rad (default: the drive's grid, `drive.input_angles()`).

    **Returns:** a dict: ``lost_motion_max/min/mean`` (rad), ``rotation_error_p2p/mean`` (rad),
    ``loaded_pairs_smooth`` (mean over positions of the sigmoid surrogate),
    ``loaded_pairs_min/mean`` (exact counts), ``not_converged`` (pins whose solve did not converge).
    """
    require_x64()
    return grid_metrics_jit(drive, checked_errors(drive, errors), _positions(drive, positions))


class Sensitivity(eqx.Module):
    """Gradient of one metric of one reducer.

    - `metric`: its name; `value`: its smooth value (rad, or pairs).
    - `errors`: ∂metric/∂(each `CycloidErrors` field) (per µm, or per rad for angles).
    - `modification`: ∂metric/∂(shift, equidistant: per mm; rotation: per rad).
    """

    metric: str = eqx.field(static=True)
    value: Array
    errors: CycloidErrors
    modification: CycloidModification


@kept_jit
def _grad_jit(drive, err, positions, metrics: tuple[AbstractMetric, ...]):
    def f(diff):
        mod, e = diff
        d = eqx.tree_at(lambda x: x.modification, drive, mod)
        res = _sweep(d, e, positions)
        return jnp.stack([m.smooth(d, res) for m in metrics])

    diff = (drive.modification, err)
    return f(diff), jax.jacrev(f)(diff)


def sensitivities(
    drive: CycloidPin,
    errors: CycloidErrors | Mapping[str, Any] | None = None,
    *,
    metrics: Sequence[AbstractMetric | str] = ("lost_motion",),
    positions: ArrayLike | None = None,
) -> dict[str, Sensitivity]:
    """Gradients of `metrics` (their smooth surrogates) with respect to every error and to the modification
    amounts, at the reducer `errors`.

    **Arguments:**

    - `drive`, `errors`: the stage and the reducer's errors.
    - `metrics`: metric objects of the drive (`LostMotion()`, …) or their names (``drive.metrics``).
    - `positions`: input angles, rad (default the drive's grid).

    The lost motion and rotation error are max/min over positions: their gradient is that of the
    position and pair that attain it. A loaded-pair count is piecewise constant; its
    sensitivity is that of its sigmoid surrogate.

    **Returns:** a `Sensitivity` per metric, by metric name.
    """
    require_x64()
    offered = drive.metrics
    objs = []
    for m in metrics:
        if isinstance(m, str):
            if m not in offered:
                raise ValueError(f"metrics: {m!r} is not a metric of this drive; use some of {list(offered)}")
            m = offered[m]
        if not isinstance(m, AbstractMetric):
            raise ValueError(f"metrics: expected metric objects or names, got {m!r}")
        objs.append(m)
    if not objs:
        raise ValueError(f"metrics: name at least one of {list(offered)}")
    err = checked_errors(drive, errors)
    vals, (gmod, gerr) = _grad_jit(drive, err, _positions(drive, positions), tuple(objs))
    out = {}
    for i, m in enumerate(objs):
        pick = lambda g, i=i: g[i]
        out[m.name] = Sensitivity(m.name, vals[i], jax.tree.map(pick, gerr), jax.tree.map(pick, gmod))
    return out


__all__ = (
    "METRICS",
    "UNIT_METRICS",
    "LoadedPairs",
    "LoadedPairsMin",
    "LostMotion",
    "LostMotionMin",
    "RotationErrorPeakToPeak",
    "Sensitivity",
    "floating_disc",
    "floating_loaded_pairs",
    "grid_metrics",
    "grid_metrics_jit",
    "sensitivities",
    "unit_metrics",
)


# ---------------------------------------------------------------- the disc centre: fixed or floating


def _offset(x: float, y: float) -> tuple[Array, Array]:
    return jnp.asarray(math.hypot(x, y), dtype=float), jnp.asarray(math.atan2(y, x), dtype=float)


def floating_disc(
    drive: CycloidPin,
    errors: CycloidErrors | Mapping[str, Any] | None = None,
    *,
    radius_um: float | None = None,
    positions: ArrayLike | None = None,
    rings: int = 4,
    directions: int = 16,
) -> dict[str, Any]:
    """Does the disc interfere because its centre is held at a fixed offset, or would it also interfere if it floated?

    Yao & Liang (2001) hold the disc centre at a fixed offset Δ_1 at α_1 from the eccentric (the turning-arm
    bearing's clearance) and the pin-wheel centre at Δ_2 at α_2 (the input-shaft bearings, the spigot fits).
    The radial clearance of the disc, g = (R′ − R_Z) + (r_Z − r′) (µm; the gap at a tooth-space bottom and at a
    tooth tip with the nominal centre distance), is shared between the two ends of the crank: a centre
    distance grown by c leaves g − c at the bottom of the spaces next to the crank and g + c at the tips
    opposite; the disc's own profile eccentricity (ΔA at φ plus ΔB, turning with the disc) takes up to its
    length from either. A rigid disc whose offset along the crank exceeds what is left interferes; a real
    disc floats within its bearing clearance and settles where the pins let it.

    **Arguments:**

    - `drive`, `errors`: the stage and the reducer's errors.
    - `radius_um`: how far the disc centre can float from the eccentric, µm (default: the given Δ_1).
    - `positions`: input angles, rad (default the drive's grid).
    - `rings`, `directions`: the search over centre offsets within `radius_um` (rings × directions + the centre).

    **Returns:** a dict (µm, rad): ``along_crank`` (c: ΔA′ + Δ_1 sin α_1 − Δ_2 sin α_2), ``across_crank``,
    ``disc_offset_along``, ``pin_wheel_offset_along``, ``eccentricity_error``, ``radial_clearance`` (g),
    ``root_gap`` (g − c), ``tip_gap`` (g + c), ``profile_eccentricity`` (|ΔA e^{iφ} + ΔB e^{iφ_B}|),
    ``lost_motion_min_rigid`` (min over the positions, the given offsets), ``lost_motion_min_centred`` (Δ_1 = 0),
    ``lost_motion_min_floating`` (min over positions of the max over centre offsets within `radius_um`),
    ``best_offset`` (the single fixed offset (µm, rad) with the largest minimum, and that minimum),
    ``interfering_rigid`` / ``interfering_floating`` (fractions of the positions), ``float_radius``.
    """
    require_x64()
    err = checked_errors(drive, errors)
    p = _positions(drive, positions)
    f = lambda x: float(jnp.asarray(x))
    rho = f(err.disc_offset) if radius_um is None else float(radius_um)
    d1, a1, d2, a2 = f(err.disc_offset), f(err.disc_offset_phase), f(err.pin_wheel_offset), f(err.pin_wheel_offset_phase)
    along = f(err.eccentricity) + d1 * math.sin(a1) - d2 * math.sin(a2)
    across = d1 * math.cos(a1) - d2 * math.cos(a2)
    g = (f(err.pin_circle_radius) - f(drive.modification.shift) * 1e3) + (f(drive.modification.equidistant) * 1e3 - f(err.pin_radius))
    pe = abs(
        f(err.setup_eccentricity) * complex(math.cos(f(err.setup_phase)), math.sin(f(err.setup_phase)))
        + f(err.mandrel_runout) * complex(math.cos(f(err.mandrel_phase)), math.sin(f(err.mandrel_phase)))
    )
    r = np.concatenate([[0.0], np.repeat(np.arange(1, rings + 1) / rings * rho, directions)])
    t = np.concatenate([[0.0], np.tile(np.arange(directions) * (2 * math.pi / directions), rings)])
    dx, dy = r * np.cos(t), r * np.sin(t)
    # One compiled sweep (the drive's response), called per offset: new error values do not recompile.
    lm = np.stack(
        [
            np.asarray(
                _sweep_jit(drive, eqx.tree_at(lambda e: (e.disc_offset, e.disc_offset_phase), err, _offset(x, y)), p, False).lost_motion
            )
            for x, y in zip(dx, dy, strict=True)
        ]
    )
    rigid = np.asarray(_sweep_jit(drive, err, p, False).lost_motion)
    floating = lm.max(axis=0)
    worst = lm.min(axis=1)
    k = int(np.argmax(worst))
    return {
        "along_crank": along,
        "across_crank": across,
        "disc_offset_along": d1 * math.sin(a1),
        "pin_wheel_offset_along": -d2 * math.sin(a2),
        "eccentricity_error": f(err.eccentricity),
        "radial_clearance": g,
        "root_gap": g - along,
        "tip_gap": g + along,
        "profile_eccentricity": pe,
        "lost_motion_min_rigid": float(rigid.min()),
        "lost_motion_min_centred": float(lm[0].min()),
        "lost_motion_min_floating": float(floating.min()),
        "best_offset": {"offset": float(r[k]), "phase": float(t[k]), "lost_motion_min": float(worst[k])},
        "interfering_rigid": float(np.mean(rigid < 0)),
        "interfering_floating": float(np.mean(floating < 0)),
        "float_radius": rho,
    }


def floating_loaded_pairs(
    drive: CycloidPin,
    errors: CycloidErrors | Mapping[str, Any] | None,
    input_angle: float,
    *,
    radius_um: float | None = None,
    rings: int = 2,
    directions: int = 12,
) -> dict[str, Any]:
    """Loaded pairs at one input angle for the disc centre anywhere within `radius_um` of the eccentric where the disc
    does not interfere (lost motion ≥ 0): where a floating disc can settle (see `floating_disc`).

    **Returns:** ``{"min", "max"}`` of the loaded-pair count over those centre positions (None if there is none),
    ``"positions"`` (how many of the `rings` × `directions` + 1 searched), ``"float_radius"`` (µm).
    """
    require_x64()
    err = checked_errors(drive, errors)
    rho = float(err.disc_offset) if radius_um is None else float(radius_um)
    th = jnp.asarray(input_angle, dtype=float)
    counts = []
    for k in range(rings * directions + 1):
        r = 0.0 if k == 0 else rho * ((k - 1) // directions + 1) / rings
        t = 0.0 if k == 0 else ((k - 1) % directions) * 2 * math.pi / directions
        e = eqx.tree_at(lambda e: (e.disc_offset, e.disc_offset_phase), err, _offset(r * math.cos(t), r * math.sin(t)))
        c = _clearances_jit(drive, e, th, True)  # the report's analysis at its input angle: compiled once
        if float(c.lost_motion) >= 0:
            counts.append(int(loaded_pairs(c, budget_mm=drive.analysis.budget_mm)))
    return {
        "min": min(counts) if counts else None,
        "max": max(counts) if counts else None,
        "positions": len(counts),
        "float_radius": rho,
    }
