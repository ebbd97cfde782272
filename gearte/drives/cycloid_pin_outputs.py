"""Cycloid-pin reducer: what a `gearte run` of a ``cycloid_pin`` study writes beyond the metric's statistics.

- The **reference reducer** (``[drive.reference]``, e.g. the reducer of Yao & Liang's (2001)
  figures 3–8): every pin's tangential and normal clearance at one input position, the
  contacting pairs, the loaded pairs, the clearance curves over one pin pitch, the rotation
  error and lost motion over whole input revolutions, and the gradients of its metrics with
  respect to every error and to the profile modification.
- The **Monte Carlo** over the study's error laws: lost motion (max and min over the grid),
  rotation error peak-to-peak, loaded pairs at the input position and their minimum over the
  grid, interference, and every pin's clearances at the input position.

Everything is returned as `StudyOutputs` (summary entries, report lines, figures drawn by
`gearte.cli.plots`, arrays); the report's text is `gearte.drives.cycloid_pin_report`. Nothing here imports
the studies or the command line.
"""

from __future__ import annotations

import math
import time
import warnings
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.solution import is_successful
from ..core.units import ARCMIN_PER_RAD, ARCSEC_PER_RAD
from .cycloid_pin_contact import _analyse, clearances, loaded_pairs, pitch_angles, revolution_angles, sweep, theoretical_pairs
from .cycloid_pin_floating import floating_equilibrium
from .cycloid_pin_geometry import YAO_LIANG_J, checked_errors, paper_pin, paper_position, paper_tooth
from .cycloid_pin_metrics import LoadedPairs, LostMotion, RotationErrorPeakToPeak, floating_disc, floating_loaded_pairs, sensitivities
from .cycloid_pin_report import report
from .cycloid_pin_table import TO_INTERNAL, unit_of
from .protocol import AbstractStudyContext, Figure, StudyOutputs

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin

#: Scalar outputs of one Monte Carlo sample (`SampleOutputs`), in order, before the per-pin blocks.
SAMPLE_SCALARS = (
    "lost_motion_max",
    "lost_motion_min",
    "lost_motion_mean",
    "rotation_error_p2p",
    "rotation_error_mean",
    "loaded_pairs_min",
    "loaded_pairs_mean",
    "lost_motion",
    "rotation_error",
    "loaded_pairs",
    "contact_pin",
    "not_converged",
)

ASSUMPTIONS = {
    "frame": "converted mechanism (arm fixed); pins numbered 1…z_b counter-clockwise from the crank direction at "
    "θ_T = 0; the input angle θ_T turns the pin wheel relative to the arm",
    "driving_flank": "the tooth-space half whose contacts push the disc clockwise; a forward load holds the disc "
    "against the driving flanks",
    "rotation_error": "Δθ = θ_a − (z_b/z_a) θ_T of the contacting pair = output rotation error",
    "lost_motion": "driving contact − reverse contact with the input held; the headline is its maximum over the revolution sweep",
    "tangential_clearance": "from the contact of the pin's own flank (forward load for driving pins, reverse "
    "for reverse pins), as an angle of the output and × R′ on the pin circle",
    "normal_clearance": "min over the pin's flank of |pin centre − flank point| − r′, at that contacting configuration",
    "loaded_pairs": "driving-flank pins whose tangential clearance on the pin circle ≤ the deformation budget",
    "paper_numbering": "K (Yao & Liang 2001, sec. 2): the position counted counter-clockwise from the static axis (the "
    "crank), K = n − J; their input angle turns the pin wheel clockwise, gearte's counter-clockwise, so gearte's θ_T is "
    "their −θ_T: over their sweep (gearte θ_T ∈ (−pitch, 0]) K is gearte's pin number, at gearte θ_T ∈ (0, pitch) it is "
    "the pin number + 1; n: their pin and tooth numbers with J = 6 (gearte pin j is their pin j + 1 + J, gearte tooth "
    "space s their tooth J + 1 − s, mod z)",
    "disc_centre": "the disc centre is held at the given offset from the eccentric (rigid, as in Yao & Liang 2001); "
    "`disc_centre` also reports the disc free to float within a circle of that radius, and `floating_equilibrium` that "
    "floating disc solved as the minimum of the contact potential (pins as unilateral springs, rigid limit; the pin "
    "wheel stays at its offset Δ_2)",
}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def input_angle(drive: CycloidPin) -> float:
    """θ_T of the per-pin analysis, rad (default half a pin pitch)."""
    a = drive.analysis.input_angle
    return drive.pitch / 2 if a is None else a


# ---------------------------------------------------------------- one Monte Carlo sample


class SampleOutputs(eqx.Module):
    """One Monte Carlo sample of a cycloid-pin stage for the report: ``fn(key) → vector`` (use `unpack`).

    Draws the errors with the study's error model (``model.sample(key)``), sweeps the drive's
    grid and analyses the input position `analysis_angle` (with normal clearances if `normal`).
    Outputs: `SAMPLE_SCALARS` (lost motion max/min/mean over the grid, rotation-error
    peak-to-peak and mean, rad; loaded pairs min/mean over the grid; lost motion, rotation
    error, loaded pairs and contacting pin (0-based) at `analysis_angle`; non-converged solves),
    then ``tangential_arc`` (z_b, mm; NaN where the pin can never touch) and
    ``normal_clearance`` (z_b, mm) at `analysis_angle`.
    """

    drive: Any
    model: Any
    positions: Float[Array, " p"]
    analysis_angle: Float[Array, ""]
    normal: bool = eqx.field(static=True)

    def __call__(self, key: PRNGKeyArray) -> Float[Array, " m"]:
        d = self.drive
        err = checked_errors(d, self.model.sample(key))
        res = jax.vmap(lambda t: _analyse(d, err, t, False))(self.positions)
        return sample_vector(d, err, res, self.analysis_angle, self.normal)

    def unpack(self, values) -> dict[str, np.ndarray]:
        """Split per-sample vectors (n, m) into named arrays."""
        return unpack(self.drive, values)

    def bytes_per_sample(self) -> int:
        return 8 * (int(self.positions.size) + 1) * self.drive.z_pins * 64


def sample_vector(d: CycloidPin, err, res, analysis_angle, normal: bool) -> Float[Array, " m"]:
    """The report's per-sample vector of one reducer with errors `err`, from its sweep `res` over the grid and
    an analysis at `analysis_angle` (see `SampleOutputs`)."""
    budget = d.analysis.budget_mm
    at = _analyse(d, err, analysis_angle, normal)
    te, lm = res.rotation_error, res.lost_motion
    counts = loaded_pairs(res, budget_mm=budget).astype(float)
    scalars = jnp.stack(
        [
            jnp.max(lm),
            jnp.min(lm),
            jnp.mean(lm),
            jnp.max(te) - jnp.min(te),
            jnp.mean(te),
            jnp.min(counts),
            jnp.mean(counts),
            at.lost_motion,
            at.rotation_error,
            loaded_pairs(at, budget_mm=budget).astype(float),
            at.contact_pin.astype(float),
            (jnp.sum(~res.converged) + jnp.sum(~at.converged)).astype(float),
        ]
    )
    arc = jnp.where(jnp.isfinite(at.tangential_arc), at.tangential_arc, jnp.nan)
    return jnp.concatenate([scalars, arc, at.normal_clearance])


def unpack(drive: CycloidPin, values) -> dict[str, np.ndarray]:
    """Split per-sample vectors (n, m) of `sample_vector` into named arrays."""
    v = np.asarray(values)
    k = len(SAMPLE_SCALARS)
    zb = drive.z_pins
    out = {name: v[..., i] for i, name in enumerate(SAMPLE_SCALARS)}
    out["tangential_arc"] = v[..., k : k + zb]
    out["normal_clearance"] = v[..., k + zb : k + 2 * zb]
    return out


def sample_outputs(drive: CycloidPin, model) -> SampleOutputs:
    """The per-sample function of the Monte Carlo outputs for `drive` with errors drawn by `model`."""
    return SampleOutputs(drive, model, drive.input_angles(), jnp.asarray(input_angle(drive)), drive.analysis.normal)


# ---------------------------------------------------------------- the reference reducer


def _pair(drive: CycloidPin, pin: int, space: int, theta: float, flank: str) -> dict:
    """A contacting pair in gearte's numbering and in Yao & Liang's (K, and n with their J = 6)."""
    return {
        "pin": pin + 1,
        "tooth_space": space + 1,
        "flank": flank,
        "K": int(paper_position(drive, pin, theta)),
        "paper_pin": int(paper_pin(drive, pin)),
        "paper_tooth": int(paper_tooth(drive, space)),
    }


def paper_pitch_contacts(drive: CycloidPin, errors, points: int) -> list[dict]:
    """The contacting pairs (forward load) over Yao & Liang's sweep of one pitch, θ_T′ ∈ [0, 2π/z_b) (gearte's
    θ_T = −θ_T′), with the share of the pitch each holds: K (= gearte pin number there), pin, tooth space."""
    th = -np.arange(points) * (drive.pitch / points)
    res = sweep(drive, errors, th)  # the shape of the report's pitch sweep: compiled once
    pins, spaces = np.asarray(res.contact_pin), np.asarray(res.space)
    out = []
    for j in sorted(set(pins.tolist())):
        where = np.flatnonzero(pins == j)
        pair = _pair(drive, j, int(spaces[where[0], j]), float(th[where[0]]), "driving")
        out.append(pair | {"share_of_pitch": float(where.size / points)})
    return out


def reference_summary(drive: CycloidPin) -> tuple[dict, dict]:
    """Summary entries of the reference reducer, and the arrays behind its plots."""
    d, err, a = drive, drive.reference, drive.analysis
    zb, budget, theta0 = d.z_pins, a.budget_mm, input_angle(drive)
    at = clearances(d, err, theta0)
    pitch = sweep(d, err, pitch_angles(d, a.pitch_points, start=0.0))
    rev_angles = revolution_angles(d, a.sweep_points_per_pitch, revolutions=a.sweep_revolutions)
    rev = sweep(d, err, rev_angles, normal=False)
    conv = bool(np.all(np.asarray(at.converged)) and np.all(np.asarray(pitch.converged)) and np.all(np.asarray(rev.converged)))
    centre = floating_disc(d, err, positions=rev_angles, rings=2, directions=12)

    arc = np.asarray(at.tangential_arc)
    tang = np.asarray(at.tangential_clearance)
    normal = np.asarray(at.normal_clearance)
    drv = np.asarray(at.on_driving_flank)
    space = np.asarray(at.space)
    rot = np.asarray(at.rotation_to_contact)
    loaded_mask = drv & (arc <= budget * (1 + 1e-12) + 1e-12)
    pairs = [
        {
            "pin": j + 1,
            "tooth_space": int(space[j]) + 1,
            "flank": "driving" if drv[j] else "reverse",
            "on_driving_flank": bool(drv[j]),
            "can_touch": bool(np.isfinite(arc[j])),
            "tangential_clearance_mm": _num(arc[j]),
            "tangential_clearance_arcsec": _num(tang[j] * ARCSEC_PER_RAD),
            "normal_clearance_mm": float(normal[j]),
            "rotation_to_contact_arcsec": _num(rot[j] * ARCSEC_PER_RAD),
            "loaded": bool(loaded_mask[j]),
        }
        for j in range(zb)
    ]
    n_loaded = int(loaded_pairs(at, budget_mm=budget))
    pitch_loaded = np.asarray(loaded_pairs(pitch, budget_mm=budget))
    rev_loaded = np.asarray(loaded_pairs(rev, budget_mm=budget))
    te_f = np.asarray(rev.rotation_error) * ARCSEC_PER_RAD
    te_r = np.asarray(rev.reverse_rotation_error) * ARCSEC_PER_RAD
    lm = np.asarray(rev.lost_motion) * ARCMIN_PER_RAD
    ci, ri = int(at.contact_pin), int(at.reverse_contact_pin)
    summary = {
        "reference_errors": drive.given_reference(),
        "input_angle_deg": math.degrees(theta0),
        "deformation_budget_mm": budget,
        "pairs": pairs,
        "process": d.process.name,
        "contact_pair": _pair(d, ci, int(space[ci]), theta0, "driving"),
        "reverse_contact_pair": _pair(d, ri, int(space[ri]), theta0, "reverse"),
        "paper_J": YAO_LIANG_J,
        "contact_pairs_over_paper_pitch": paper_pitch_contacts(d, err, a.pitch_points),
        "loaded_pairs": n_loaded,
        "loaded_pairs_out_of": theoretical_pairs(d),
        "loaded_pairs_over_pitch": {"min": int(pitch_loaded.min()), "max": int(pitch_loaded.max()), "mean": float(pitch_loaded.mean())},
        "loaded_pairs_over_revolution": {"min": int(rev_loaded.min()), "max": int(rev_loaded.max()), "mean": float(rev_loaded.mean())},
        "lost_motion_arcmin": float(lm.max()),
        "lost_motion_range_arcmin": [float(lm.min()), float(lm.max())],
        "lost_motion_at_input_angle_arcmin": float(at.lost_motion) * ARCMIN_PER_RAD,
        "interference": bool(lm.min() < 0),
        "disc_centre": _disc_centre(centre) | {"loaded_pairs_floating": floating_loaded_pairs(d, err, theta0)},
        "floating_equilibrium": floating_summary(d, err),
        "rotation_error_p2p_arcsec": float(te_f.max() - te_f.min()),
        "rotation_error_reverse_p2p_arcsec": float(te_r.max() - te_r.min()),
        "rotation_error_at_input_angle_arcsec": float(at.rotation_error) * ARCSEC_PER_RAD,
        "rotation_error_mean_arcsec": float(te_f.mean()),
        "sweep": {
            "pitch_points": a.pitch_points,
            "revolution_points_per_pitch": a.sweep_points_per_pitch,
            "revolutions": a.sweep_revolutions,
            "all_solves_converged": conv,
        },
        "clearance_assumptions": dict(ASSUMPTIONS),
    }
    curves = {
        "at": at,
        "pitch": pitch,
        "rev": rev,
        "rev_angles": rev_angles,
        "te_f": te_f,
        "te_r": te_r,
        "lm": lm,
        "arc": arc,
        "normal": normal,
        "drv": drv,
        "ci": ci,
        "ri": ri,
        "n_loaded": n_loaded,
    }
    return summary, curves


def floating_summary(drive: CycloidPin, err) -> dict:
    """The disc floating in its turning-arm bearing (clearance: the given Δ_1) on the drive's grid, at the minimum of
    the contact potential (`gearte.drives.cycloid_pin_floating`), beside the rigid disc held at the fixed offsets."""
    fe = floating_equilibrium(drive, err)
    rigid = np.asarray(drive.response(err).lost_motion)
    lm = np.asarray(fe.lost_motion) * ARCMIN_PER_RAD
    n, steps = np.asarray(fe.loaded_pairs), np.asarray(fe.steps)
    return {
        "clearance_um": float(fe.clearance),
        "positions": int(lm.size),
        "lost_motion_arcmin": {"min": float(lm.min()), "max": float(lm.max())},
        "loaded_pairs_forward": {"min": int(n[0].min()), "max": int(n[0].max())},
        "loaded_pairs_reverse": {"min": int(n[1].min()), "max": int(n[1].max())},
        "interfering_share_rigid": float(np.mean(rigid < 0)),
        "interfering_share_floating": float(np.mean(np.any(np.asarray(fe.preloaded), axis=0))),
        "all_solves_successful": is_successful(fe.result),
        "newton_steps": {"max": int(steps.max()), "mean": float(steps.mean())},
    }


def _disc_centre(c: dict) -> dict:
    """`floating_disc`'s result for the summary (µm, ′) with a sentence saying what happens."""
    am = ARCMIN_PER_RAD
    out = {
        "offset_along_crank_um": c["along_crank"],
        "offset_across_crank_um": c["across_crank"],
        "disc_offset_along_crank_um": c["disc_offset_along"],
        "pin_wheel_offset_along_crank_um": c["pin_wheel_offset_along"],
        "eccentricity_error_um": c["eccentricity_error"],
        "radial_clearance_um": c["radial_clearance"],
        "gap_at_space_bottom_um": c["root_gap"],
        "gap_at_tooth_tip_um": c["tip_gap"],
        "profile_eccentricity_um": c["profile_eccentricity"],
        "float_radius_um": c["float_radius"],
        "lost_motion_min_rigid_arcmin": c["lost_motion_min_rigid"] * am,
        "lost_motion_min_centred_arcmin": c["lost_motion_min_centred"] * am,
        "lost_motion_min_floating_arcmin": c["lost_motion_min_floating"] * am,
        "interfering_share_rigid": c["interfering_rigid"],
        "interfering_share_floating": c["interfering_floating"],
        "best_fixed_offset": {
            "offset_um": c["best_offset"]["offset"],
            "phase_deg": math.degrees(c["best_offset"]["phase"]),
            "lost_motion_min_arcmin": c["best_offset"]["lost_motion_min"] * am,
        },
    }
    g, cc, pe = c["radial_clearance"], c["along_crank"], c["profile_eccentricity"]
    head = (
        f"radial clearance g = (R′ − R_Z) + (r_Z − r′) = {g:.1f} µm; the fixed offsets move the disc {cc:+.1f} µm along the crank "
        f"(ΔA′ {c['eccentricity_error']:+.1f}, Δ_1 {c['disc_offset_along']:+.1f}, Δ_2 {c['pin_wheel_offset_along']:+.1f} µm), "
        f"leaving {g - cc:.1f} µm at the space bottoms next to the crank and {g + cc:.1f} µm at the tips opposite, "
        f"of which the disc's own profile eccentricity takes up to {pe:.1f} µm"
    )
    if c["interfering_rigid"] > 0 and c["interfering_floating"] == 0:
        tail = (
            f"; the rigid disc held there interferes over {100 * c['interfering_rigid']:.0f} % of the revolution "
            f"(lost motion down to {c['lost_motion_min_rigid'] * am:.2f}′): the fixed-offset idealisation interferes. "
            f"A disc free to float within {c['float_radius']:.1f} µm of the eccentric (its bearing clearance) finds a "
            f"position without interference at every input angle (lost motion ≥ {c['lost_motion_min_floating'] * am:.2f}′): "
            "it does not jam; it settles where the pins let it."
        )
    elif c["interfering_rigid"] > 0:
        tail = (
            f"; the rigid disc interferes over {100 * c['interfering_rigid']:.0f} % of the revolution, and floating within "
            f"{c['float_radius']:.1f} µm does not clear it everywhere ({100 * c['interfering_floating']:.0f} % of the "
            f"revolution; lost motion down to {c['lost_motion_min_floating'] * am:.2f}′): the pairs there must deform."
        )
    else:
        tail = f"; no interference (lost motion ≥ {c['lost_motion_min_rigid'] * am:.2f}′ with the offsets held)."
    out["explanation"] = head + tail
    return out


#: The reference reducer's sensitivities: summary key → (metric, unit, factor per rad or per pair).
SENSITIVITY_METRICS = {
    "lost_motion_max": (LostMotion(), "arcmin", ARCMIN_PER_RAD),
    "rotation_error_p2p": (RotationErrorPeakToPeak(), "arcsec", ARCSEC_PER_RAD),
    "loaded_pairs_smooth": (LoadedPairs(), "pairs", 1.0),
}


def reference_sensitivities(drive: CycloidPin) -> dict:
    """Gradients of the reference reducer's metrics (over the report's revolutions at 2 positions per pitch) with
    respect to every error field (summed over spaces or pins: the same change on all of them) and the modification."""
    positions = revolution_angles(drive, 2, revolutions=drive.analysis.sweep_revolutions)
    sens = sensitivities(drive, drive.reference, metrics=tuple(m for m, _, _ in SENSITIVITY_METRICS.values()), positions=positions)
    out = {}
    for key, (metric, unit, k) in SENSITIVITY_METRICS.items():
        s = sens[metric.name]
        rows = {}
        for field in drive.error_fields:
            g = float(np.sum(np.asarray(getattr(s.errors, field))))
            u = unit_of(field)
            rows[field] = {"per": {"um": "µm", "arcsec": "″", "deg": "°"}[u], "value": g * k * TO_INTERNAL[u]}
        m = s.modification
        rows["modification.shift"] = {"per": "mm", "value": float(m.shift) * k}
        rows["modification.equidistant"] = {"per": "mm", "value": float(m.equidistant) * k}
        rows["modification.rotation"] = {"per": "″", "value": float(m.rotation) * k / ARCSEC_PER_RAD}
        out[key] = {"unit": unit, "value": float(s.value) * k, "derivatives": rows}
    return out


# ---------------------------------------------------------------- the Monte Carlo


def _stats(v, unit: str) -> dict:
    """n, min, max, mean, std (n − 1) and percentiles of the finite values (as `gearte.statistics`)."""
    v = np.asarray(v, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    pct = np.percentile(v, (1.0, 5.0, 50.0, 95.0, 99.0, 99.73))
    return {
        "unit": unit,
        "n": int(v.size),
        "min": float(v.min()),
        "max": float(v.max()),
        "mean": float(v.mean()),
        "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
        "percentiles": {f"{p:g}": float(x) for p, x in zip((1.0, 5.0, 50.0, 95.0, 99.0, 99.73), pct, strict=True)},
    }


def _zero_law(law) -> bool:
    """A law whose parameters are all 0 draws 0 (a source left out of the study file)."""
    leaves = [x for x in jax.tree.leaves(law) if eqx.is_array(x)]
    return bool(leaves) and all(bool(np.all(np.asarray(x) == 0)) for x in leaves)


def tolerance_rows(model) -> dict[str, str]:
    """How each error source is drawn (value law), for reports; sources fixed at 0 are left out."""
    return {name: src.magnitude.describe(model.specs[name].unit) for name, src in model.sources.items() if not _zero_law(src.magnitude)}


def monte_carlo_summary(drive: CycloidPin, context: AbstractStudyContext, u: dict) -> dict:
    """The ``monte_carlo`` summary entry from the unpacked per-sample values `u`."""
    zb = drive.z_pins
    a = drive.analysis
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        arc = u["tangential_arc"]
        nrm = u["normal_clearance"]
        per_pin = []
        for j in range(zb):
            aj = arc[:, j]
            fin = np.isfinite(aj)
            per_pin.append(
                {
                    "pin": j + 1,
                    "can_touch_fraction": float(np.mean(fin)),
                    "tangential_clearance_mm": {
                        "mean": _num(np.nanmean(aj)) if fin.any() else None,
                        "p5": _num(np.nanpercentile(aj, 5)) if fin.any() else None,
                        "p95": _num(np.nanpercentile(aj, 95)) if fin.any() else None,
                    },
                    "normal_clearance_mm": {
                        "mean": _num(np.nanmean(nrm[:, j])),
                        "p5": _num(np.nanpercentile(nrm[:, j], 5)),
                        "p95": _num(np.nanpercentile(nrm[:, j], 95)),
                    },
                }
            )
    counts = np.bincount(u["loaded_pairs"].astype(int), minlength=zb // 2 + 1)
    ok = u["lost_motion_min"] >= 0
    return {
        "samples": context.samples,
        "seed": context.seed,
        "z_lobes": drive.z_lobes,
        "positions": {"count": int(drive.input_angles().size), "per_pitch": a.positions_per_pitch, "revolutions": a.revolutions},
        "tolerances": tolerance_rows(context.model),
        "lost_motion_max_arcmin": _stats(u["lost_motion_max"] * ARCMIN_PER_RAD, "arcmin"),
        "lost_motion_min_arcmin": _stats(u["lost_motion_min"] * ARCMIN_PER_RAD, "arcmin"),
        "rotation_error_p2p_arcsec": _stats(u["rotation_error_p2p"] * ARCSEC_PER_RAD, "arcsec"),
        "loaded_pairs": _stats(u["loaded_pairs"], "pairs") | {"histogram": {str(i): int(c) for i, c in enumerate(counts) if c}},
        "loaded_pairs_min_over_cycle": _stats(u["loaded_pairs_min"], "pairs"),
        "interference_fraction": float(np.mean(u["lost_motion_min"] < 0)),
        # For a reducer that interferes somewhere the rigid contacts are not those of the deformed reducer.
        "loaded_pairs_without_interference": _stats(u["loaded_pairs"][ok], "pairs") if np.any(ok) else None,
        "not_converged_solves": int(np.sum(u["not_converged"])),
        "per_pin_at_input_angle": per_pin,
    }


# ---------------------------------------------------------------- everything together


def study_outputs(drive: CycloidPin, context: AbstractStudyContext) -> StudyOutputs:
    """`CycloidPin.study_outputs`: the reference reducer, the Monte Carlo of clearances, their plots and report."""
    timing = {}
    t0 = time.perf_counter()
    summary, c = reference_summary(drive)
    timing["reference"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    summary["sensitivities"] = reference_sensitivities(drive)
    timing["sensitivities"] = time.perf_counter() - t0
    # The per-sample clearances were computed in the study's own Monte Carlo pass (`CycloidPin.sample_outputs`).
    u = unpack(drive, context.outputs["clearances"])
    summary["monte_carlo"] = monte_carlo_summary(drive, context, u)
    share = summary["monte_carlo"]["interference_fraction"]
    if share > 0:  # beside the headline: the lost motion of such a reducer is no play (the rigid model fails there)
        summary["warnings"] = [
            f"{100 * share:.2f} % of the reducers interfere somewhere on the grid (lost motion < 0): the rigid disc, its "
            "centre held at the fixed offsets, cannot be assembled there, and their lost motion is not a play (the "
            "Monte Carlo section below)"
        ]
    summary["analysis_timing_s"] = timing

    budget, zb, theta0 = drive.analysis.budget_mm, drive.z_pins, input_angle(drive)
    n_out = theoretical_pairs(drive)
    pitch, lm = c["pitch"], c["lm"]
    figures = [
        Figure(
            "clearance_per_pin.png",
            "gearte.drives.cycloid_pin_plots:clearance_per_pin",
            dict(
                tangential_mm=c["arc"],
                normal_mm=c["normal"],
                on_driving=c["drv"],
                budget_mm=budget,
                contact_pin=c["ci"] + 1,
                reverse_contact_pin=c["ri"] + 1,
                title=f"reference reducer: clearances at θ_T = {math.degrees(theta0):.4g}°; "
                f"{c['n_loaded']} of {n_out} driving pairs within {budget:g} mm",
            ),
            "clearance of every pin at the input position",
        ),
        Figure(
            "clearance_vs_input.png",
            "gearte.drives.cycloid_pin_plots:clearance_vs_input",
            dict(
                input_deg=np.degrees(np.asarray(pitch.input_angle)),
                tangential_mm=np.asarray(pitch.tangential_arc),
                normal_mm=np.asarray(pitch.normal_clearance),
                pins=[j + 1 for j in range(zb) if bool(np.all(np.asarray(pitch.on_driving_flank)[:, j]))],
                budget_mm=budget,
                title="reference reducer: driving-flank pairs over one pin pitch (cf. Yao & Liang 2001, figures 3–8)",
            ),
            "clearance against the input angle",
        ),
        Figure(
            "rotation_error.png",
            "gearte.drives.cycloid_pin_plots:rotation_error",
            dict(
                input_rev=np.asarray(c["rev_angles"]) / (2 * math.pi),
                forward_arcsec=c["te_f"],
                reverse_arcsec=c["te_r"],
                title=f"reference reducer: rotation error over {drive.analysis.sweep_revolutions} input revolution(s), "
                f"lost motion {lm.min():.2f}′ … {lm.max():.2f}′",
            ),
            "rotation error",
        ),
        Figure(
            "monte_carlo.png",
            "gearte.drives.cycloid_pin_plots:distributions",
            dict(
                series=[
                    ("lost motion, max over the grid (′)", u["lost_motion_max"] * ARCMIN_PER_RAD, "′"),
                    ("rotation error p-p (″)", u["rotation_error_p2p"] * ARCSEC_PER_RAD, "″"),
                    (f"loaded pairs at θ_T (of {n_out})", u["loaded_pairs"], ""),
                ],
                title=f"Monte Carlo of the clearances over {context.samples:,} reducers",
            ),
            "Monte Carlo",
        ),
    ]
    arrays = {
        "lost_motion_max_arcmin": u["lost_motion_max"] * ARCMIN_PER_RAD,
        "lost_motion_min_arcmin": u["lost_motion_min"] * ARCMIN_PER_RAD,
        "rotation_error_p2p_arcsec": u["rotation_error_p2p"] * ARCSEC_PER_RAD,
        "loaded_pairs": u["loaded_pairs"],
        "loaded_pairs_min": u["loaded_pairs_min"],
        "contact_pin": u["contact_pin"] + 1,
        "tangential_clearance_mm": u["tangential_arc"],
        "normal_clearance_mm": u["normal_clearance"],
    }
    # The reference reducer's curves.
    curves = {
        "pitch_input_angle_rad": np.asarray(pitch.input_angle),
        "pitch_tangential_clearance_mm": np.asarray(pitch.tangential_arc),
        "pitch_normal_clearance_mm": np.asarray(pitch.normal_clearance),
        "pitch_on_driving_flank": np.asarray(pitch.on_driving_flank),
        "revolution_input_angle_rad": np.asarray(c["rev_angles"]),
        "rotation_error_arcsec": c["te_f"],
        "reverse_rotation_error_arcsec": c["te_r"],
        "lost_motion_arcmin": lm,
        "contact_pin": np.asarray(c["rev"].contact_pin) + 1,
    }
    return StudyOutputs(summary=summary, report=report(drive, summary), figures=figures, arrays=arrays, files={"curves.npz": curves})


__all__ = (
    "SAMPLE_SCALARS",
    "SampleOutputs",
    "monte_carlo_summary",
    "reference_sensitivities",
    "reference_summary",
    "sample_outputs",
    "study_outputs",
    "tolerance_rows",
)
