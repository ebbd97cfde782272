"""Cycloid-pin reducer: choose the profile modification by gradient (spec cycloid_pin.md, last section).

Problem: choose the shift ΔR_Z and equidistant Δr_Z (and, optionally, the rotation δ) that
keep the lost motion within a spec, leave a radial clearance at root and tip (lubrication,
assembly), and maximise the number of pairs that can carry load under a tangential
deformation budget — for one reducer's errors (or none).

The count of loaded pairs is piecewise constant, so the optimiser maximises a smooth
surrogate, the mean over input positions of Σ σ((budget − arc_j)/w) over the driving pins,
with quadratic penalties on the constraints (lost motion in units of 1′, radial clearance in
units of 10 µm) and a continuation in the penalty weight 10 → 10³ → 10⁵. Every start is solved
with optimistix's BFGS (``throw=False``; the result code of every solve is reported); the
answer is the start whose *exact* metrics are best among the feasible ones (most loaded pairs
on average over the positions — what the surrogate maximises —, then at their minimum, then
the smallest lost motion).
"""

from __future__ import annotations

import math
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import ArrayLike

from .._precision import require_x64
from .cycloid_pin import CycloidErrors, CycloidPin, CycloidModification, check_modification, checked_errors, revolution_angles
from .cycloid_pin_studies import _metrics, _metrics_jit

ARCMIN = math.pi / (180.0 * 60.0)  # rad per ′
PENALTY_WEIGHTS = (10.0, 1e3, 1e5)


class ModificationStart(eqx.Module):
    """One start of `optimise_modification`: where it began and ended, and how the solver finished."""

    start: tuple[float, ...]
    end: tuple[float, ...]
    results: tuple[str, ...]
    steps: tuple[int, ...]
    loaded_pairs_min: int
    loaded_pairs_mean: float
    lost_motion_max: float
    lost_motion_min: float
    radial_clearance: float
    feasible: bool


class ModificationResult(eqx.Module):
    """The optimised modification and its exact metrics.

    - `modification`, `drive`: the best modification and the stage that carries it.
    - `loaded_pairs_min`, `loaded_pairs_mean`: exact loaded-pair counts over the positions.
    - `lost_motion_max`, `lost_motion_min`: rad; `radial_clearance`: mm (Δr_Z − ΔR_Z).
    - `feasible`: the constraints hold exactly.
    - `starts`: every start (`ModificationStart`), in the order tried.
    - `initial`: the same metrics for the drive's own modification (a `ModificationStart`).
    """

    modification: CycloidModification
    drive: CycloidPin
    loaded_pairs_min: int
    loaded_pairs_mean: float
    lost_motion_max: float
    lost_motion_min: float
    radial_clearance: float
    feasible: bool
    starts: tuple
    initial: ModificationStart


def _with(drive: CycloidPin, x, rotation: bool) -> CycloidPin:
    R = drive.pin_circle_radius
    mod = CycloidModification(x[0], x[1], x[2] / R if rotation else jnp.zeros(()))
    return eqx.tree_at(lambda d: d.modification, drive, mod)


def _default_starts(drive: CycloidPin, target_rad: float, radial_min: float, rotation: bool) -> list[np.ndarray]:
    """Starts spread over the split of the target lost motion between equidistant, shift (and rotation),
    from the first-order lost motion 2[Δr_Z − ΔR_Z √(1 − K_1²)] / (a z_a) + 2δ."""
    a, za, K = float(drive.eccentricity), drive.z_lobes, float(drive.K1)
    half = 0.5 * target_rad * a * za  # mm of "equidistant-equivalent"
    starts = []
    for f in (0.0, 0.25, 0.5, 0.75, 1.0):
        dr = (1 - f) * half
        dR = -f * half / math.sqrt(1 - K * K)
        if dr - dR < radial_min:  # widen radially without changing the first-order lost motion
            extra = radial_min - (dr - dR)
            dr += extra * math.sqrt(1 - K * K) / (1 + math.sqrt(1 - K * K))
            dR -= extra / (1 + math.sqrt(1 - K * K))
        starts.append(np.array([dR, dr] + ([0.0] if rotation else [])))
    if rotation:
        R = float(drive.pin_circle_radius)
        starts.append(np.array([-radial_min / 2, radial_min / 2, 0.5 * target_rad * R]))
    return starts


def optimise_modification(drive: CycloidPin, errors: CycloidErrors | None = None, *, lost_motion_max: float,
                          budget_mm: float, lost_motion_min: float = 0.0, radial_clearance_min: float = 0.0,
                          positions: ArrayLike | None = None, width_mm: float | None = None, rotation: bool = False,
                          starts: Sequence[Sequence[float]] | None = None, max_steps: int = 200) -> ModificationResult:
    """Choose the modification that maximises the loaded pairs with the lost motion within a spec.

    **Arguments:**

    - `drive`: the stage (its own modification is reported as `initial`).
    - `errors`: the reducer's errors (None: an error-free reducer).
    - `lost_motion_max`: the lost-motion spec, rad (over all `positions`).
    - `budget_mm`: tangential deformation budget on the pin circle, mm.
    - `lost_motion_min`: required lost motion (backlash), rad (default 0: no interference).
    - `radial_clearance_min`: required radial clearance at root and tip Δr_Z − ΔR_Z, mm.
    - `positions`: input angles, rad (default one input revolution, 2 per pin pitch).
    - `width_mm`: smoothing width of the count surrogate, mm (default budget/10).
    - `rotation`: also optimise a rotation modification δ.
    - `starts`: starting points (ΔR_Z, Δr_Z[, δ R_z]) in mm (default: spread over the split of
      the lost motion between the modifications).
    - `max_steps`: BFGS steps per penalty weight.

    **Returns:** a `ModificationResult` with the exact count and constraints at the optimum.
    """
    require_x64()
    for name, v in (("lost_motion_max", lost_motion_max), ("lost_motion_min", lost_motion_min),
                    ("radial_clearance_min", radial_clearance_min), ("budget_mm", budget_mm)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: must be a finite number ≥ 0, got {v!r}")
    if not lost_motion_max > lost_motion_min:
        raise ValueError(f"lost_motion_max ({lost_motion_max:g} rad) must exceed lost_motion_min ({lost_motion_min:g} rad)")
    b = float(budget_mm)
    w = b / 10.0 if width_mm is None else float(width_mm)
    if not (math.isfinite(w) and w > 0):
        raise ValueError(f"width_mm: must be > 0 mm, got {width_mm!r}")
    err = checked_errors(drive, errors)
    pos = jnp.asarray(revolution_angles(drive, 2) if positions is None else positions, dtype=float)
    lm_hi, lm_lo, c_lo = float(lost_motion_max), float(lost_motion_min), float(radial_clearance_min)
    n = 3 if rotation else 2

    def exact(x) -> ModificationStart:
        d = _with(drive, jnp.asarray(x, dtype=float), rotation)
        m = _metrics_jit(d, err, pos, b, w)
        radial = float(x[1] - x[0])
        ok = (float(m["lost_motion_max"]) <= lm_hi * (1 + 1e-9) and float(m["lost_motion_min"]) >= lm_lo - 1e-12
              and radial >= c_lo - 1e-12)
        try:
            check_modification(d)
        except ValueError:
            ok = False
        return ModificationStart(start=(), end=tuple(float(v) for v in x), results=(), steps=(),
                                 loaded_pairs_min=int(m["loaded_pairs_min"]), loaded_pairs_mean=float(m["loaded_pairs_mean"]),
                                 lost_motion_max=float(m["lost_motion_max"]), lost_motion_min=float(m["lost_motion_min"]),
                                 radial_clearance=radial, feasible=bool(ok))

    # The quadratic penalty leaves violations of order 1/μ; aim inside the constraints by a margin
    # (10⁻³′ and 10⁻⁵ mm) so that the optimum holds them exactly.
    hi_t, lo_t, c_t = lm_hi - 1e-3 * ARCMIN, lm_lo + 1e-3 * ARCMIN, c_lo + 1e-5

    def objective(x, mu):
        d = _with(drive, x, rotation)
        m = _metrics(d, err, pos, b, w)
        v1 = jax.nn.relu(m["lost_motion_max"] - hi_t) / ARCMIN
        v2 = jax.nn.relu(lo_t - m["lost_motion_min"]) / ARCMIN
        v3 = jax.nn.relu(c_t - (x[1] - x[0])) / 0.01
        return -m["loaded_pairs_smooth"] + mu * (v1 ** 2 + v2 ** 2 + v3 ** 2)

    solver = optx.BFGS(rtol=1e-9, atol=1e-9)

    @eqx.filter_jit
    def solve(x0, mu):
        sol = optx.minimise(objective, solver, x0, mu, max_steps=max_steps, throw=False)
        return sol.value, sol.result, sol.stats["num_steps"]

    m0 = drive.modification
    x_init = np.array([float(m0.shift), float(m0.equidistant)] + ([float(m0.rotation) * float(drive.pin_circle_radius)] if rotation else []))
    if starts is None:
        target = lm_hi if lm_lo == 0 else 0.5 * (lm_lo + lm_hi)
        start_list = [x_init] + _default_starts(drive, 0.9 * target if lm_lo == 0 else target, c_lo, rotation)
    else:
        start_list = [np.asarray(s, dtype=float) for s in starts]
        for s in start_list:
            if s.shape != (n,):
                raise ValueError(f"starts: each start is (ΔR_Z, Δr_Z{', δ·R_z' if rotation else ''}) in mm, got {s.tolist()}")
    tried = []
    for x0 in start_list:
        x = jnp.asarray(x0, dtype=float)
        codes, steps = [], []
        for mu in PENALTY_WEIGHTS:
            x_new, res, k = solve(x, jnp.asarray(mu))
            codes.append(_result_name(res))
            steps.append(int(k))
            if bool(jnp.all(jnp.isfinite(x_new))):
                x = x_new
        e = exact(np.asarray(x))
        tried.append(ModificationStart(start=tuple(float(v) for v in x0), end=e.end, results=tuple(codes), steps=tuple(steps),
                                       loaded_pairs_min=e.loaded_pairs_min, loaded_pairs_mean=e.loaded_pairs_mean,
                                       lost_motion_max=e.lost_motion_max, lost_motion_min=e.lost_motion_min,
                                       radial_clearance=e.radial_clearance, feasible=e.feasible))

    def rank(s: ModificationStart):
        return (s.feasible, round(s.loaded_pairs_mean, 9), s.loaded_pairs_min, -s.lost_motion_max)

    best = max(tried, key=rank)
    init = exact(x_init)
    d_best = _with(drive, jnp.asarray(best.end, dtype=float), rotation)
    return ModificationResult(modification=d_best.modification, drive=d_best, loaded_pairs_min=best.loaded_pairs_min,
                              loaded_pairs_mean=best.loaded_pairs_mean, lost_motion_max=best.lost_motion_max,
                              lost_motion_min=best.lost_motion_min, radial_clearance=best.radial_clearance,
                              feasible=best.feasible, starts=tuple(tried), initial=init)


def _result_name(res) -> str:
    for name in ("successful", "max_steps_reached", "nonlinear_max_steps_reached", "nonlinear_divergence"):
        if hasattr(optx.RESULTS, name) and res == getattr(optx.RESULTS, name):
            return name
    return str(optx.RESULTS[res]) if hasattr(optx.RESULTS, "__getitem__") else "failed"


__all__ = ("ModificationResult", "ModificationStart", "optimise_modification")
