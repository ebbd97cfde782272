"""RV (K-H-V) reducer: the planets' assembly phases that minimise a unit's TE or lost motion.

Each planet sits on its crankshaft's spline in one of z_g positions, whole teeth apart; the
position sets where the planet's run-out (`planet_eccentricity`) points when the crank's eccentrics
point along their reference direction. The error source `planet_assembly` of `RVKHV` is that angle,
2π k / z_g, added to the run-out's phase. For one measured unit (its errors known), the choice is a
discrete search over z_g^N combinations (91,125 for three planets of 45 teeth); `best_planet_assembly`
does a coordinate search: every position of one planet at a time (all z_g at once, one batched
response), the best kept, planet after planet, until a whole round changes nothing. The result is a
coordinate-wise optimum (no single planet's change improves it), not certified global; it is never
worse than the start.

The solves themselves must all succeed: a candidate with a failed solve is not chosen, and the
result code says so if the start or the optimum has one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..core.metrics import AbstractMetric, check_offered
from ..core.precision import require_x64
from ..core.solution import RESULTS, check
from ..core.validate import as_int
from ..drives.rv_khv import RVKHV, RVPeakToPeak, _response_jit


class AssemblyPhases(eqx.Module):
    """The planets' assembly positions found by `best_planet_assembly`.

    - `teeth`: k of each planet (its position on the crank's spline, whole teeth from the reference).
    - `phase`: 2π k / z_g, rad (the value of the error source `planet_assembly`).
    - `start`, `value`: the metric (rad) at the starting positions and at the chosen ones.
    - `metric`: the metric minimised; `rounds`: coordinate rounds taken; `evaluations`: units solved.
    - `result`: `RESULTS.successful`, or `RESULTS.contact_not_converged` if a solve of the chosen
      or the starting positions failed.
    """

    teeth: Int[Array, " N"]
    phase: Float[Array, " N"]
    start: Float[Array, ""]
    value: Float[Array, ""]
    metric: AbstractMetric
    rounds: int = eqx.field(static=True)
    evaluations: int = eqx.field(static=True)
    result: RESULTS


@eqx.filter_jit
def _candidates(drive: RVKHV, err: dict, planet: int, teeth: Array, metric: AbstractMetric):
    """The metric and whether every solve succeeded, for planet `planet` at each of its z_g positions (the others as
    in `teeth`)."""
    zg = drive.z_planet
    base = 2 * math.pi * teeth.astype(float) / zg
    thetas = drive.output_angles()

    def one(k):
        e = dict(err, planet_assembly=base.at[planet].set(2 * math.pi * k / zg))
        r = _response_jit(drive, e, thetas)
        return metric(drive, r), jnp.all(r.result == RESULTS.successful)

    return jax.vmap(one)(jnp.arange(zg, dtype=float))


@eqx.filter_jit
def _evaluate(drive: RVKHV, err: dict, teeth: Array, metric: AbstractMetric):
    e = dict(err, planet_assembly=2 * math.pi * teeth.astype(float) / drive.z_planet)
    r = _response_jit(drive, e, drive.output_angles())
    return metric(drive, r), jnp.all(r.result == RESULTS.successful)


def best_planet_assembly(
    drive: RVKHV,
    errors: Mapping[str, Any],
    *,
    metric: AbstractMetric = RVPeakToPeak(),
    start: Any = None,
    max_rounds: int = 4,
    throw: bool = True,
) -> AssemblyPhases:
    """The planets' positions on their cranks that minimise `metric` for one unit (see the module notes).

    **Arguments:**

    - `drive`: an `RVKHV`; its grid (`points`) is the one searched.
    - `errors`: the unit's errors (source name → value, as `RVKHV.response` takes them); `planet_assembly`, if
      given, is replaced by the search.
    - `metric`: one of the drive's metrics (`gearte.RVPeakToPeak()`, `gearte.RVPeakToPeakReverse()`,
      `gearte.RVLostMotion()`).
    - `start`: the starting positions k (whole teeth, one per planet; default all 0).
    - `max_rounds`: the most coordinate rounds (each tries every position of every planet).
    - `throw`: raise if a solve at the start or the optimum failed (else see `result`).

    **Returns:** `AssemblyPhases`.
    """
    require_x64()
    if not isinstance(drive, RVKHV):
        raise ValueError(f"drive: expected an RVKHV, got {type(drive).__name__}")
    check_offered(metric, drive)
    rounds_max = as_int("max_rounds", max_rounds, minimum=1)
    n, zg = drive.cranks, drive.z_planet
    given = np.zeros(n) if start is None else np.asarray(start, dtype=float).reshape(-1)
    teeth = given.astype(int)
    if given.shape != (n,) or np.any(given != teeth) or np.any(teeth < 0) or np.any(teeth >= zg):
        raise ValueError(f"start: give one whole-tooth position 0 … {zg - 1} per planet ({n}), got {start!r}")
    err = drive.errors(errors)
    v0, ok0 = _evaluate(drive, err, jnp.asarray(teeth), metric)
    best, evaluations, rounds = float(v0), 1, 0
    while rounds < rounds_max:
        rounds += 1
        changed = False
        for i in range(n):
            values, ok = _candidates(drive, err, i, jnp.asarray(teeth), metric)
            values = np.where(np.asarray(ok), np.asarray(values), np.inf)
            evaluations += zg
            k = int(np.argmin(values))
            if values[k] < best:
                best, teeth[i], changed = float(values[k]), k, True
        if not changed:
            break
    value, ok = _evaluate(drive, err, jnp.asarray(teeth), metric)
    result = RESULTS.where(ok0 & ok, RESULTS.successful, RESULTS.contact_not_converged)  # pyright: ignore[reportArgumentType]
    out = AssemblyPhases(
        teeth=jnp.asarray(teeth),
        phase=2 * math.pi * jnp.asarray(teeth, dtype=float) / zg,
        start=v0,
        value=value,
        metric=metric,
        rounds=rounds,
        evaluations=evaluations + 1,
        result=result,
    )
    check(out.result, throw=throw, what="best_planet_assembly")
    return out


__all__ = ("AssemblyPhases", "best_planet_assembly")
