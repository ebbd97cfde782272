"""The profile modification of a cycloid-pin disc, chosen by gradient (Yao & Liang 2001; `gearte.drives.cycloid_pin`).

Problem: choose the shift ΔR_Z and equidistant Δr_Z (and, optionally, the rotation δ) that
keep the lost motion within a spec, leave a radial clearance at root and tip (lubrication,
assembly), and maximise the number of pairs that can carry load under the drive's tangential
deformation budget — for one reducer's errors (or none).

The count of loaded pairs is piecewise constant, so the optimiser maximises a smooth
surrogate, the mean over input positions of Σ σ((budget − arc_j)/w) over the driving pins,
with quadratic penalties on the constraints (lost motion in units of 1′, radial clearance in
units of 10 µm) and a continuation in the penalty weight 10 → 10³ → 10⁵. Every start is solved
with optimistix's BFGS (``throw=False``; the result code of every solve is kept); the answer is
the start whose *exact* metrics are best among the feasible ones (most loaded pairs on average
over the positions — what the surrogate maximises —, then at their minimum, then the smallest
lost motion).

A study file asks for it with a ``[modification]`` table (`ModificationSpec`); the summary
entry and report section are `modification_summary` and `modification_report`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike

from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.schema import ConfigError, Table
from ..core.solution import RESULTS, check, result_name
from ..core.units import ARCMIN_PER_RAD, ARCSEC_PER_RAD
from ..drives.cycloid_pin import CycloidPin
from ..drives.cycloid_pin_contact import revolution_angles
from ..drives.cycloid_pin_geometry import CycloidErrors, CycloidModification, check_modification, checked_errors
from ..drives.cycloid_pin_metrics import grid_metrics, grid_metrics_jit

ARCMIN = math.pi / (180.0 * 60.0)  # rad per ′
PENALTY_WEIGHTS = (10.0, 1e3, 1e5)


class ModificationStart(eqx.Module):
    """One start of `optimise_modification`: where it began and ended (ΔR_Z, Δr_Z[, δ·R_z] in mm), how the
    solver finished at each penalty weight (`results`: names of `gearte.RESULTS` items; `steps`), and the
    exact metrics there (lost motion in rad, radial clearance in mm)."""

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


class ModificationSolution(eqx.Module):
    """The optimised modification and its exact metrics.

    - `modification`, `drive`: the best modification and the stage that carries it.
    - `loaded_pairs_min`, `loaded_pairs_mean`: exact loaded-pair counts over the positions.
    - `lost_motion_max`, `lost_motion_min`: rad; `radial_clearance`: mm (Δr_Z − ΔR_Z).
    - `feasible`: the constraints hold exactly.
    - `starts`: every start (`ModificationStart`), in the order tried.
    - `initial`: the same metrics for the drive's own modification (a `ModificationStart`).
    - `result`: `RESULTS.successful`, or `RESULTS.infeasible` when no start meets the constraints.
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
    result: RESULTS


def _with(drive: CycloidPin, x, rotation: bool) -> CycloidPin:
    """The drive with shift x[0] and equidistant x[1] (mm), and the rotation x[2]/R_z if it is optimised, else the
    drive's own."""
    R = drive.pin_circle_radius
    mod = CycloidModification(x[0], x[1], x[2] / R if rotation else drive.modification.rotation)
    return eqx.tree_at(lambda d: d.modification, drive, mod)


@kept_jit
def _solve_penalised(
    drive: CycloidPin,
    err: CycloidErrors,
    pos: Array,
    targets: Array,
    x0: Array,
    mu: Array,
    rotation: bool,
    max_steps: int,
) -> tuple[Array, Any, Array]:
    """BFGS on the penalised surrogate of `optimise_modification` from `x0` at penalty weight `mu`: the end, the
    result code and the steps. `targets`: the lost-motion bounds (rad) and the radial clearance (mm) it aims at.
    Module level, with the values as arguments: every start, weight and later call with the same drive structure
    and shapes reuses one compiled solve (`rotation` and `max_steps` are static)."""
    hi_t, lo_t, c_t = targets[0], targets[1], targets[2]

    def objective(x, mu):
        d = _with(drive, x, rotation)
        m = grid_metrics(d, err, pos)
        v1 = jax.nn.relu(m["lost_motion_max"] - hi_t) / ARCMIN
        v2 = jax.nn.relu(lo_t - m["lost_motion_min"]) / ARCMIN
        v3 = jax.nn.relu(c_t - (x[1] - x[0])) / 0.01
        return -m["loaded_pairs_smooth"] + mu * (v1**2 + v2**2 + v3**2)

    solver = optx.BFGS(rtol=1e-9, atol=1e-9)
    sol = optx.minimise(objective, solver, x0, mu, max_steps=max_steps, throw=False)
    return sol.value, sol.result, sol.stats["num_steps"]


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


def optimise_modification(
    drive: CycloidPin,
    errors: CycloidErrors | Mapping[str, Any] | None = None,
    *,
    lost_motion_max: float,
    lost_motion_min: float = 0.0,
    radial_clearance_min: float = 0.0,
    positions: ArrayLike | None = None,
    rotation: bool = False,
    starts: Sequence[Sequence[float]] | None = None,
    max_steps: int = 200,
    throw: bool = True,
) -> ModificationSolution:
    """Choose the modification that maximises the loaded pairs with the lost motion within a spec.

    **Arguments:**

    - `drive`: the stage (its own modification is reported as `initial`; its deformation budget
      and smoothing width, `drive.analysis`, define the loaded pairs).
    - `errors`: the reducer's errors (None: an error-free reducer).
    - `lost_motion_max`: the lost-motion spec, rad (over all `positions`).
    - `lost_motion_min`: required lost motion (backlash), rad (default 0: no interference).
    - `radial_clearance_min`: required radial clearance at root and tip Δr_Z − ΔR_Z, mm.
    - `positions`: input angles, rad (default one input revolution, 2 per pin pitch).
    - `rotation`: also optimise a rotation modification δ (else the drive's own δ is kept).
    - `starts`: starting points (ΔR_Z, Δr_Z[, δ R_z]) in mm (default: spread over the split of
      the lost motion between the modifications).
    - `max_steps`: BFGS steps per penalty weight.
    - `throw`: raise if no start meets the constraints (else check `result`).

    **Returns:** a `ModificationSolution` with the exact count and constraints at the optimum.
    """
    require_x64()
    if not isinstance(drive, CycloidPin):
        raise ValueError(f"drive: expected a CycloidPin, got {type(drive).__name__}")
    for name, v in (
        ("lost_motion_max", lost_motion_max),
        ("lost_motion_min", lost_motion_min),
        ("radial_clearance_min", radial_clearance_min),
    ):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: must be a finite number ≥ 0, got {v!r}")
    if not lost_motion_max > lost_motion_min:
        raise ValueError(f"lost_motion_max ({lost_motion_max:g} rad) must exceed lost_motion_min ({lost_motion_min:g} rad)")
    err = checked_errors(drive, errors)
    pos = jnp.asarray(revolution_angles(drive, 2) if positions is None else positions, dtype=float)
    if pos.ndim != 1 or pos.size == 0:
        raise ValueError(f"positions: give a 1-D array of input angles (rad), got shape {pos.shape}")
    lm_hi, lm_lo, c_lo = float(lost_motion_max), float(lost_motion_min), float(radial_clearance_min)
    n = 3 if rotation else 2

    def exact(x) -> ModificationStart:
        d = _with(drive, jnp.asarray(x, dtype=float), rotation)
        m = grid_metrics_jit(d, err, pos)
        radial = float(x[1] - x[0])
        ok = float(m["lost_motion_max"]) <= lm_hi * (1 + 1e-9) and float(m["lost_motion_min"]) >= lm_lo - 1e-12 and radial >= c_lo - 1e-12
        try:
            check_modification(d)
        except ValueError:
            ok = False
        return ModificationStart(
            start=(),
            end=tuple(float(v) for v in x),
            results=(),
            steps=(),
            loaded_pairs_min=int(m["loaded_pairs_min"]),
            loaded_pairs_mean=float(m["loaded_pairs_mean"]),
            lost_motion_max=float(m["lost_motion_max"]),
            lost_motion_min=float(m["lost_motion_min"]),
            radial_clearance=radial,
            feasible=bool(ok),
        )

    # The quadratic penalty leaves violations of order 1/μ; aim inside the constraints by a margin
    # (10⁻³′ and 10⁻⁵ mm) so that the optimum holds them exactly. Arrays: another spec reuses the compiled solve.
    targets = jnp.asarray([lm_hi - 1e-3 * ARCMIN, lm_lo + 1e-3 * ARCMIN, c_lo + 1e-5])

    m0 = drive.modification
    x_init = np.array(
        [float(m0.shift), float(m0.equidistant)] + ([float(m0.rotation) * float(drive.pin_circle_radius)] if rotation else [])
    )
    if starts is None:
        target = lm_hi if lm_lo == 0 else 0.5 * (lm_lo + lm_hi)
        # A rotation held (not optimised) adds its 2δ to the lost motion the shift and equidistant must leave.
        held = 0.0 if rotation else 2.0 * float(drive.modification.rotation)
        aim = max((0.9 * target if lm_lo == 0 else target) - held, 0.0)
        start_list = [x_init, *_default_starts(drive, aim, c_lo, rotation)]
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
            x_new, res, k = _solve_penalised(drive, err, pos, targets, x, jnp.asarray(mu), rotation, max_steps)
            codes.append(result_name(res))
            steps.append(int(k))
            if bool(jnp.all(jnp.isfinite(x_new))):
                x = x_new
        e = exact(np.asarray(x))
        tried.append(
            ModificationStart(
                start=tuple(float(v) for v in x0),
                end=e.end,
                results=tuple(codes),
                steps=tuple(steps),
                loaded_pairs_min=e.loaded_pairs_min,
                loaded_pairs_mean=e.loaded_pairs_mean,
                lost_motion_max=e.lost_motion_max,
                lost_motion_min=e.lost_motion_min,
                radial_clearance=e.radial_clearance,
                feasible=e.feasible,
            )
        )

    def rank(s: ModificationStart):
        return (s.feasible, round(s.loaded_pairs_mean, 9), s.loaded_pairs_min, -s.lost_motion_max)

    best = max(tried, key=rank)
    init = exact(x_init)
    d_best = _with(drive, jnp.asarray(best.end, dtype=float), rotation)
    result: RESULTS = RESULTS.successful if best.feasible else RESULTS.infeasible  # pyright: ignore[reportAssignmentType]
    sol = ModificationSolution(
        modification=d_best.modification,
        drive=d_best,
        loaded_pairs_min=best.loaded_pairs_min,
        loaded_pairs_mean=best.loaded_pairs_mean,
        lost_motion_max=best.lost_motion_max,
        lost_motion_min=best.lost_motion_min,
        radial_clearance=best.radial_clearance,
        feasible=best.feasible,
        starts=tuple(tried),
        initial=init,
        result=result,
    )
    check(result, throw=throw, what="optimise_modification")
    return sol


# ---------------------------------------------------------------- the study kind [modification]


class ModificationSpec(eqx.Module):
    """``[modification]`` of a cycloid-pin study: choose R_Z, r_Z (and δ) for the reference reducer.

    Keys: ``lost_motion_max_arcmin`` (required, > 0), ``lost_motion_min_arcmin`` (0),
    ``radial_clearance_min_mm`` (0), ``rotation`` (false), ``positions_per_pitch`` (2; over the
    drive's ``[drive.analysis] revolutions``).
    """

    lost_motion_max_arcmin: float = eqx.field(static=True)
    lost_motion_min_arcmin: float = eqx.field(static=True)
    radial_clearance_min_mm: float = eqx.field(static=True)
    rotation: bool = eqx.field(static=True)
    positions_per_pitch: int = eqx.field(static=True)

    @classmethod
    def from_table(cls, t: Table, drive: Any) -> ModificationSpec:
        """Read a ``[modification]`` table (the caller refuses unknown keys); `drive` must be a `CycloidPin`."""
        if not isinstance(drive, CycloidPin):
            raise ConfigError(
                f"{t.where}: the profile-modification optimiser is for a cycloid-pin reducer "
                f'([drive] type = "cycloid_pin"), not {getattr(drive, "type_name", type(drive).__name__)}'
            )
        hi = t.number("lost_motion_max_arcmin", positive=True)
        lo = t.number("lost_motion_min_arcmin", 0.0, minimum=0)
        if not hi > lo:
            raise ConfigError(f"{t.where} lost_motion_max_arcmin: must exceed lost_motion_min_arcmin ({lo:g}′), got {hi:g}′")
        return cls(
            lost_motion_max_arcmin=hi,
            lost_motion_min_arcmin=lo,
            radial_clearance_min_mm=t.number("radial_clearance_min_mm", 0.0, minimum=0),
            rotation=t.boolean("rotation", False),
            positions_per_pitch=t.integer("positions_per_pitch", 2, minimum=1, maximum=4096),
        )

    def constraints(self) -> dict:
        """The spec as the summary's ``constraints`` entry."""
        return {
            "lost_motion_max_arcmin": self.lost_motion_max_arcmin,
            "lost_motion_min_arcmin": self.lost_motion_min_arcmin,
            "radial_clearance_min_mm": self.radial_clearance_min_mm,
            "rotation": self.rotation,
            "positions_per_pitch": self.positions_per_pitch,
        }

    def solve(self, drive: CycloidPin, *, throw: bool = False) -> ModificationSolution:
        """Optimise the modification for the drive's reference reducer."""
        positions = revolution_angles(drive, self.positions_per_pitch, revolutions=drive.analysis.sweep_revolutions)
        return optimise_modification(
            drive,
            drive.reference,
            lost_motion_max=self.lost_motion_max_arcmin / ARCMIN_PER_RAD,
            lost_motion_min=self.lost_motion_min_arcmin / ARCMIN_PER_RAD,
            radial_clearance_min=self.radial_clearance_min_mm,
            positions=positions,
            rotation=self.rotation,
            throw=throw,
        )


def modification_summary(drive: CycloidPin, spec: ModificationSpec, sol: ModificationSolution) -> dict:
    """The summary entry ``optimised_modification``: constraints, best, initial and every start."""
    R = float(drive.pin_circle_radius)

    def row(end, s, results=(), steps=()):
        r = {
            "shift_mm": end[0],
            "equidistant_mm": end[1],
            "wheel_pin_circle_radius_mm": R + end[0],
            "wheel_pin_radius_mm": float(drive.pin_radius) + end[1],
            "loaded_pairs_min": s.loaded_pairs_min,
            "loaded_pairs_mean": s.loaded_pairs_mean,
            "lost_motion_max_arcmin": s.lost_motion_max * ARCMIN_PER_RAD,
            "lost_motion_min_arcmin": s.lost_motion_min * ARCMIN_PER_RAD,
            "radial_clearance_mm": s.radial_clearance,
            "feasible": s.feasible,
        }
        if len(end) > 2:
            r["rotation_arcsec"] = end[2] / R * ARCSEC_PER_RAD
        if results:
            r["solver_results"] = list(results)
            r["solver_steps"] = list(steps)
        return r

    m = sol.modification
    best_end = [float(m.shift), float(m.equidistant)] + ([float(m.rotation) * R] if spec.rotation else [])
    held = {} if spec.rotation else {"rotation_held_arcsec": float(drive.modification.rotation) * ARCSEC_PER_RAD}
    return held | {
        "constraints": spec.constraints(),
        "best": row(best_end, sol),
        "initial": row(list(sol.initial.end), sol.initial),
        "starts": [row(list(s.end), s, s.results, s.steps) | {"start": list(s.start)} for s in sol.starts],
        "result": result_name(sol.result),
    }


def modification_report(drive: CycloidPin, entry: dict) -> list[str]:
    """The report section of ``optimised_modification`` (Markdown lines)."""
    c = entry["constraints"]
    L = [
        "",
        "## Optimised modification",
        "",
        f"Maximise the loaded pairs (budget {drive.analysis.budget_mm:g} mm) with the lost motion in "
        f"[{c['lost_motion_min_arcmin']:g}′, {c['lost_motion_max_arcmin']:g}′] and a radial clearance ≥ {c['radial_clearance_min_mm']:g} mm, "
        f"for the reducer analysed; exact counts over the revolution ({c['positions_per_pitch']} positions per pitch)"
        + (
            f"; the rotation modification held at the design's {entry['rotation_held_arcsec']:.4g}″."
            if entry.get("rotation_held_arcsec")
            else "."
        ),
        "",
        "| | R_Z (mm) | r_Z (mm) | loaded pairs mean (min) | lost motion (′) | radial clearance (mm) | feasible |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, r in (("as designed", entry["initial"]), ("optimised", entry["best"])):
        L.append(
            f"| {label} | {r['wheel_pin_circle_radius_mm']:.4f} | {r['wheel_pin_radius_mm']:.4f} | {r['loaded_pairs_mean']:.2f} "
            f"({r['loaded_pairs_min']}) | {r['lost_motion_min_arcmin']:.2f} … {r['lost_motion_max_arcmin']:.2f} | "
            f"{r['radial_clearance_mm']:.4f} | {'yes' if r['feasible'] else 'no'} |"
        )
    if entry["result"] != "successful":
        L += ["", "No start met the constraints: the best infeasible one is shown (loosen the spec)."]
    return [*L, ""]


__all__ = (
    "ModificationSolution",
    "ModificationSpec",
    "ModificationStart",
    "modification_report",
    "modification_summary",
    "optimise_modification",
)
