"""RV (K-H-V) reducer: what a `gearte run` of an ``rv_khv`` study writes beyond the metric's statistics.

- The **reference unit**: the study's typical sample (the sample whose metric is closest to the
  median, the unit of ``trace.png``), solved on the drive's report grid (`RVKHV.trace_points`
  output angles over one output revolution) under both load directions: its TE curves, TE
  peak-to-peak per direction and lost motion (max, min, mean over the grid).
- The **spectrum** of its forward TE over the output revolution: the discrete Fourier transform of
  the grid, amplitudes per order of the output speed, with the drive's own orders and where they
  alias on the grid.
- The **contact map** of the reference unit under the forward load: which unilateral contacts
  (the pins of each disc, both flanks of each sun–planet mesh) carry load at each output angle,
  and the count of loaded pins per disc.
- The **Monte Carlo**: statistics of the per-sample outputs of `RVKHV.sample_outputs` (TE p-p per
  direction, lost motion max and min over the grid) and the share of the equilibrium solves that
  succeeded.

Everything is returned as `StudyOutputs` (summary entries, report lines, figures drawn by
`gearte.drives.rv_khv_plots`, arrays); the report's text is `gearte.drives.rv_khv_report`. Nothing here
imports the studies or the command line.
"""

from __future__ import annotations

import warnings
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.solution import RESULTS
from ..core.units import ARCMIN_PER_RAD, ARCSEC_PER_RAD, angle_from_rad
from .protocol import AbstractStudyContext, Figure, StudyOutputs
from .rv_khv_report import report

if TYPE_CHECKING:
    from .rv_khv import RVKHV

#: Percentiles of the Monte Carlo statistics (those of `gearte.statistics`).
PERCENTILES = (1.0, 5.0, 50.0, 95.0, 99.0, 99.73)
#: A contact carries load when its force exceeds this fraction of the load scale k_pin × deflection_mm (the force
#: of the small load on a single contact at the pin-circle radius). The solver leaves contacts that only graze at
#: rounding level (≤ 1e-6 of that scale); contacts sharing the load carry 1e-3 of it or more.
LOADED_FRACTION = 1e-4
#: Lost motion within this many × deflection_mm / R (rad) of 0 is taken as none: the rigid limit removes the small
#: load's elastic part exactly for the contacts closed under it, and a contact that changes state under the load
#: itself shifts the result by about deflection_mm / R.
RESOLUTION_LOADS = 10.0
#: Spectral lines listed in the summary and the report (the largest).
SPECTRUM_LINES = 12

CONVENTIONS = {
    "rigid_limit": "every TE is the rigid-limit TE: the elastic part of the small load removed exactly for the closed "
    "contacts, so it depends on neither the load nor a common scale of the stiffnesses",
    "te": "TE = θ_o − θ_in / i (Hidaka et al. 1994, sec. 2.2) with the input held: the carrier's small rotation",
    "load_direction": "forward = a torque turning the carrier counter-clockwise (+); reverse = clockwise (−)",
    "lost_motion": "TE(+) − TE(−) at each output angle: the output's rotation between the two load directions with the "
    "input held; it is ≥ 0 at equilibrium (the minimiser of a convex potential is monotone in the load), and within "
    f"{RESOLUTION_LOADS:g} × deflection_mm / R of 0 it is taken as 0: the parts are preloaded (errors forced into the "
    "hyperstatic assembly hold the output in both directions); a value below −that is not the rigid limit of an equilibrium (flagged in the report: the small load then "
    "deflects the unit far more than deflection_mm / R, and removing its elastic part extrapolates too far)",
    "reference_unit": "the study's typical sample (metric closest to the median), the unit of trace.png",
    "grid": "the report grid of the drive (trace_points output angles, evenly spaced over one output revolution, from "
    "θ_o = 0); values are taken at these angles, not between them",
    "spectrum": "discrete Fourier transform of the forward TE on the report grid: amplitude of order k (cycles per "
    "output revolution) = 2 |X_k| / p (|X_0| / p for the mean); orders above p/2 alias onto the grid",
    "contact_map": f"forward load; a contact is loaded when its force exceeds {LOADED_FRACTION:g} × k_pin × deflection_mm",
}


def _stats(v, unit: str) -> dict:
    """n, min, max, mean, std (n − 1) and percentiles of the finite values, with the count of non-finite ones."""
    v = np.asarray(v, dtype=np.float64).ravel()
    fin = v[np.isfinite(v)]
    out: dict[str, Any] = {"unit": unit, "n": int(fin.size), "non_finite": int(v.size - fin.size)}
    if not fin.size:
        return out | {"min": None, "max": None, "mean": None, "std": None, "percentiles": {}}
    pct = np.percentile(fin, PERCENTILES)
    return out | {
        "min": float(fin.min()),
        "max": float(fin.max()),
        "mean": float(fin.mean()),
        "std": float(fin.std(ddof=1)) if fin.size > 1 else 0.0,
        "percentiles": {f"{p:g}": float(x) for p, x in zip(PERCENTILES, pct, strict=True)},
    }


def resolution(drive: RVKHV) -> float:
    """The lost motion (rad) within which it is taken as 0 (`RESOLUTION_LOADS` × deflection_mm / R)."""
    return RESOLUTION_LOADS * float(drive.deflection_mm) / float(drive.stage.pin_circle_radius)


def _range(x) -> dict:
    x = np.asarray(x, dtype=np.float64)
    return {"mean": float(x.mean()), "min": float(x.min()), "max": float(x.max())}


# ---------------------------------------------------------------- spectrum


def order_spectrum(te) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-sided amplitude spectrum of a periodic sequence `te` (p values evenly spaced over one period).

    **Returns:** (orders 0 … ⌊p/2⌋ (cycles per period), amplitudes (te's unit), phases (rad)): ``te[n] = Σ_k A_k
    cos(2π k n / p + φ_k)`` with A_0 the mean, A_k = 2 |X_k| / p for 0 < k < p/2, and |X_{p/2}| / p for an even p.
    """
    x = np.asarray(te, dtype=np.float64).ravel()
    p = x.size
    X = np.fft.rfft(x)
    amp = 2.0 * np.abs(X) / p
    amp[0] /= 2.0
    if p % 2 == 0:
        amp[-1] /= 2.0
    return np.arange(X.size), amp, np.angle(X)


def alias_order(order: int, points: int) -> int:
    """The order (0 … ⌊p/2⌋) at which a sinusoid of `order` cycles per period appears when sampled at `points`
    evenly spaced angles: |order − points × round(order / points)|."""
    return int(abs(order - points * round(order / points)))


def drive_orders(drive: RVKHV) -> list[tuple[str, int]]:
    """The drive's own orders per output revolution (name, order): the carrier and discs (1), the eccentrics and
    planets turning in the fixed frame (z_c), the cranks in the carrier (z_p), the sun (i, where it is an integer),
    the pin mesh (z_c z_p) and the sun–planet mesh (z_p z_g)."""
    zp, zc = drive.z_pins, drive.z_pins - 1
    ratio = Fraction(drive.z_sun + drive.z_pins * drive.z_planet, drive.z_sun)
    out = [
        ("carrier and discs (once per output revolution)", 1),
        ("eccentrics and planets in the fixed frame: each pin's error, pin-circle and planet run-outs (z_c)", zc),
        ("cranks relative to the carrier (z_p)", zp),
    ]
    if ratio.denominator == 1:
        out.append(("sun: input run-out (i)", int(ratio)))
    out += [("pin mesh (z_c z_p)", zc * zp), ("sun–planet mesh (z_p z_g)", zp * drive.z_planet)]
    return out


def spectrum_lines(drive: RVKHV, te, *, count: int = SPECTRUM_LINES) -> list[tuple[str, float]]:
    """The largest lines of `te` (rad, one output revolution on an even grid) as `Trace.lines`: (frequency as an
    exact multiple of the input speed, k / i, amplitude in rad), the mean first."""
    orders, amp, _ = order_spectrum(te)
    ratio = Fraction(drive.z_sun + drive.z_pins * drive.z_planet, drive.z_sun)
    top = [int(k) for k in np.argsort(-amp[1:], kind="stable")[:count] + 1]
    return [("0 (constant)", float(amp[0]))] + [(str(Fraction(int(orders[k])) / ratio), float(amp[k])) for k in sorted(top)]


def spectrum_summary(drive: RVKHV, te_rad) -> tuple[dict, dict]:
    """The ``spectrum`` summary entry of a forward TE (rad) on the report grid, and its arrays (orders, amplitudes ″)."""
    te = np.asarray(te_rad, dtype=np.float64)
    p = te.size
    orders, amp, phase = order_spectrum(te)
    amp_s = amp * ARCSEC_PER_RAD
    top = np.argsort(-amp_s[1:], kind="stable")[:SPECTRUM_LINES] + 1
    named = drive_orders(drive)
    lines = []
    for k in top:
        k = int(k)
        lines.append(
            {
                "order": k,
                "amplitude_arcsec": float(amp_s[k]),
                "phase_rad": float(phase[k]),
                "drive_orders_here": [o for _, o in named if alias_order(o, p) == k],
            }
        )
    summary = {
        "of": "forward TE of the reference unit over one output revolution",
        "grid_points": p,
        "highest_resolved_order": p // 2,
        "mean_arcsec": float(amp_s[0]),
        "lines": lines,
        "drive_orders": [{"name": n, "order": o, "appears_at_order": alias_order(o, p), "aliased": o > p // 2} for n, o in named],
    }
    return summary, {"spectrum_order": orders, "spectrum_amplitude_arcsec": amp_s, "spectrum_phase_rad": phase}


# ---------------------------------------------------------------- contact map


def contact_groups(drive: RVKHV) -> list[tuple[str, int, int]]:
    """The unilateral contacts of `RVResponse.force`, in order, as (label, first, stop) column ranges: the pins of
    each disc (z_p each), then the two flanks of each sun–planet mesh (crank 1 +, −, crank 2 +, −, …; + is the flank
    whose line of action points counter-clockwise about the reducer's axis at the crank)."""
    zp, D, N = drive.z_pins, drive.discs, drive.cranks
    out = [(f"pins of disc {d + 1}", d * zp, (d + 1) * zp) for d in range(D)]
    out.append(("mesh flanks", D * zp, D * zp + 2 * N))
    return out


def loaded_contacts(drive: RVKHV, force) -> np.ndarray:
    """Which contacts carry load (boolean, the shape of `force`): force > `LOADED_FRACTION` × k_pin × deflection_mm."""
    f = np.asarray(force, dtype=np.float64)
    m = drive.discs * drive.z_pins + 2 * drive.cranks
    if f.shape[-1] != m:
        raise ValueError(
            f"force: expected {m} contacts (pins of {drive.discs} disc(s), 2 flanks of {drive.cranks} meshes), got {f.shape[-1]}"
        )
    return f > LOADED_FRACTION * float(drive.pin_stiffness) * float(drive.deflection_mm)


def contact_summary(drive: RVKHV, force) -> tuple[dict, dict]:
    """The ``contact_map`` summary entry of a response's force (2, p, m), and the arrays behind its plot."""
    loaded = loaded_contacts(drive, force)
    zp = drive.z_pins
    out: dict[str, Any] = {
        "load": "forward (the map and the counts); reverse counts beside them",
        "loaded_when_force_above": f"{LOADED_FRACTION:g} × k_pin × deflection_mm",
        "contacts": [{"group": g, "first": a + 1, "last": b} for g, a, b in contact_groups(drive)],
    }
    arrays: dict[str, np.ndarray] = {"contact_loaded_forward": loaded[0], "contact_loaded_reverse": loaded[1]}
    for d in range(drive.discs):
        for k, direction in enumerate(("forward", "reverse")):
            n = loaded[k, :, d * zp : (d + 1) * zp].sum(axis=1)
            arrays[f"loaded_pins_disc_{d + 1}_{direction}"] = n
            key = f"loaded_pins_disc_{d + 1}" + ("" if direction == "forward" else "_reverse")
            out[key] = _range(n) | {"of": zp}
    for k, direction in enumerate(("forward", "reverse")):
        n = loaded[k, :, drive.discs * zp :].sum(axis=1)
        out["loaded_mesh_flanks" + ("" if direction == "forward" else "_reverse")] = _range(n) | {"of": 2 * drive.cranks}
    return out, arrays


# ---------------------------------------------------------------- the reference unit


def reference_unit(drive: RVKHV, errors, *, index: int | None = None) -> tuple[dict, dict]:
    """The reference unit with `errors` on the report grid (`trace_points` output angles), both load directions.

    **Returns:** (summary entries ``reference_unit``, ``spectrum``, ``contact_map``; the arrays behind the plots).
    """
    th = drive.output_angles(drive.trace_points)
    r = drive.solve_at(errors, th)
    te = np.asarray(r.te, dtype=np.float64)
    f_s, r_s = te[0] * ARCSEC_PER_RAD, te[1] * ARCSEC_PER_RAD
    lm = te[0] - te[1]
    ok = np.asarray(r.result == RESULTS.successful)
    p = int(th.size)
    ref = {
        "index": index,
        "selection": CONVENTIONS["reference_unit"] if index is not None else "the errors given",
        "grid": {"points": p, "spacing_deg": 360.0 / p, "over": "one output revolution, from θ_o = 0"},
        "te_forward_arcsec": _range(f_s) | {"p2p": float(f_s.max() - f_s.min())},
        "te_reverse_arcsec": _range(r_s) | {"p2p": float(r_s.max() - r_s.min())},
        "te_p2p_forward_arcsec": float(f_s.max() - f_s.min()),
        "te_p2p_reverse_arcsec": float(r_s.max() - r_s.min()),
        "lost_motion_arcsec": _range(lm * ARCSEC_PER_RAD),
        "lost_motion_arcmin": _range(lm * ARCMIN_PER_RAD),
        "lost_motion_max_at_output_deg": float(np.degrees(np.asarray(th)[int(np.argmax(lm))])),
        "zero_lost_motion_share": float(np.mean(lm <= resolution(drive))),
        "negative_lost_motion": bool(lm.min() < -resolution(drive)),
        "solves": {"count": int(ok.size), "successful": int(ok.sum())},
    }
    spec, spec_arrays = spectrum_summary(drive, te[0])
    contacts, contact_arrays = contact_summary(drive, r.force)
    curves = {
        "output_angle_rad": np.asarray(th),
        "te_forward_arcsec": f_s,
        "te_reverse_arcsec": r_s,
        "lost_motion_arcmin": lm * ARCMIN_PER_RAD,
        "force_forward": np.asarray(r.force[0]),
        "result_ok": ok,
    }
    return {"reference_unit": ref, "spectrum": spec, "contact_map": contacts}, curves | spec_arrays | contact_arrays


# ---------------------------------------------------------------- the Monte Carlo


#: Per-sample outputs of `RVKHV.sample_outputs`: key → (summary and samples.npz name, unit, factor per rad).
SAMPLE_QUANTITIES = {
    "lost_motion": ("lost_motion_max_arcmin", "arcmin", ARCMIN_PER_RAD, "lost motion, max over the grid (′)"),
    "lost_motion_min": ("lost_motion_min_arcmin", "arcmin", ARCMIN_PER_RAD, "lost motion, min over the grid (′)"),
    "te_pp": ("te_p2p_forward_arcsec", "arcsec", ARCSEC_PER_RAD, "TE p-p, forward load (″)"),
    "te_pp_reverse": ("te_p2p_reverse_arcsec", "arcsec", ARCSEC_PER_RAD, "TE p-p, reverse load (″)"),
}


def monte_carlo_summary(outputs: dict, *, points: int, solves_per_sample: int, resolution_rad: float) -> tuple[dict, dict]:
    """The ``monte_carlo`` summary entry from the per-sample outputs (`RVKHV.sample_outputs`, rad), and the arrays
    in report units for samples.npz."""
    solved = np.asarray(outputs["solved"], dtype=np.float64).ravel()
    out: dict[str, Any] = {"samples": int(solved.size), "grid_points": points}
    arrays: dict[str, np.ndarray] = {}
    for key, (name, unit, k, _) in SAMPLE_QUANTITIES.items():
        v = np.asarray(outputs[key], dtype=np.float64) * k
        out[name] = _stats(v, unit)
        arrays[name] = v
    lm_min = np.asarray(outputs["lost_motion_min"], dtype=np.float64)
    out["lost_motion_resolution_arcsec"] = resolution_rad * ARCSEC_PER_RAD
    out["zero_lost_motion_somewhere_fraction"] = float(np.mean(lm_min <= resolution_rad))
    out["negative_lost_motion_fraction"] = float(np.mean(lm_min < -resolution_rad))
    failed = np.flatnonzero(solved < 1.0)
    out["solves"] = {
        "per_sample": solves_per_sample,
        "successful_share": float(solved.mean()) if solved.size else None,
        "samples_with_failed_solves": int(failed.size),
        "failed_samples": [{"index": int(i), "solved_share": float(solved[i])} for i in failed[:20]],
    }
    arrays["solved"] = solved
    return out, arrays


# ---------------------------------------------------------------- everything together


def typical_index(context: AbstractStudyContext) -> int:
    """The typical sample of the run (metric closest to the median, in the study's unit), as `gearte run` picks it."""
    values = np.asarray(angle_from_rad(np.asarray(context.values_rad), context.unit), dtype=np.float64).ravel()
    median = float(np.percentile(values, PERCENTILES)[2])
    return int(np.argmin(np.abs(values - median)))


def study_outputs(drive: RVKHV, context: AbstractStudyContext) -> StudyOutputs:
    """`RVKHV.study_outputs`: the reference unit (TE both ways, spectrum, contact map), the Monte Carlo, plots, report."""
    typical = typical_index(context)
    summary, c = reference_unit(drive, context.sample_errors(typical), index=typical)
    mc, mc_arrays = monte_carlo_summary(
        context.outputs, points=drive.points, solves_per_sample=2 * drive.points, resolution_rad=resolution(drive)
    )
    summary["monte_carlo"] = mc
    # The same unit on the study's grid (its Monte Carlo values) and on the reference grid above: how much the study
    # grid's maxima and minima miss between its angles (a lower bound of the p-p and of the lost motion's max).
    ref = summary["reference_unit"]
    on_grid = {
        "grid_points": drive.points,
        "te_p2p_forward_arcsec": float(np.ravel(context.outputs["te_pp"])[typical]) * ARCSEC_PER_RAD,
        "te_p2p_reverse_arcsec": float(np.ravel(context.outputs["te_pp_reverse"])[typical]) * ARCSEC_PER_RAD,
        "lost_motion_max_arcmin": float(np.ravel(context.outputs["lost_motion"])[typical]) * ARCMIN_PER_RAD,
    }
    fine = (ref["te_forward_arcsec"]["p2p"], ref["te_reverse_arcsec"]["p2p"], ref["lost_motion_arcmin"]["max"])
    coarse = (on_grid["te_p2p_forward_arcsec"], on_grid["te_p2p_reverse_arcsec"], on_grid["lost_motion_max_arcmin"])
    on_grid["understated_by"] = max(0.0, *(1.0 - c / f for c, f in zip(coarse, fine) if f > 0))
    ref["on_study_grid"] = on_grid
    summary["output_conventions"] = dict(CONVENTIONS)
    n_bad = mc["solves"]["samples_with_failed_solves"]
    if n_bad:
        warnings.warn(
            f"rv_khv: {n_bad} of {mc['samples']} samples have equilibrium solves that did not succeed "
            f"(successful share {mc['solves']['successful_share']:.6f}); see report.md",
            RuntimeWarning,
            stacklevel=2,
        )
    th_deg = np.degrees(c["output_angle_rad"])
    lm = ref["lost_motion_arcmin"]
    spec = summary["spectrum"]
    figures = [
        Figure(
            "te_both_directions.png",
            "gearte.drives.rv_khv_plots:te_both_directions",
            dict(
                output_deg=th_deg,
                forward_arcsec=c["te_forward_arcsec"],
                reverse_arcsec=c["te_reverse_arcsec"],
                resolution_arcsec=resolution(drive) * ARCSEC_PER_RAD,
                title=f"unit #{typical}: TE under both load directions (rigid limit, {th_deg.size} output angles); "
                f"lost motion {lm['min']:.3f}′ … {lm['max']:.3f}′, mean {lm['mean']:.3f}′",
            ),
            "TE for both load directions",
        ),
        Figure(
            "spectrum.png",
            "gearte.drives.rv_khv_plots:spectrum",
            dict(
                orders=c["spectrum_order"],
                amplitude_arcsec=c["spectrum_amplitude_arcsec"],
                marks=[(d["appears_at_order"], d["order"]) for d in spec["drive_orders"]],
                title=f"unit #{typical}: spectrum of the forward TE over one output revolution "
                f"({spec['grid_points']} points; orders above {spec['highest_resolved_order']} alias)",
            ),
            "spectrum of the forward TE",
        ),
        Figure(
            "contact_map.png",
            "gearte.drives.rv_khv_plots:contact_map",
            dict(
                output_deg=th_deg,
                loaded=c["contact_loaded_forward"],
                groups=contact_groups(drive),
                counts=[(f"disc {d + 1}", c[f"loaded_pins_disc_{d + 1}_forward"]) for d in range(drive.discs)],
                title=f"unit #{typical}: contacts carrying the forward load",
            ),
            "contact map",
        ),
    ]
    series = [(label, mc_arrays[name], "′" if unit == "arcmin" else "″") for name, unit, _, label in SAMPLE_QUANTITIES.values()]
    if context.metric.name == "lost_motion":  # histogram.png is already the lost motion's (the study's metric)
        series = series[1:]
    figures.append(
        Figure(
            "monte_carlo.png",
            "gearte.drives.cycloid_pin_plots:distributions",
            dict(series=series, title=f"Monte Carlo over {mc['samples']:,} reducers"),
            "Monte Carlo",
        )
    )
    files = {"reference_unit.npz": c}
    text = report(drive, summary, metric=context.metric.name)
    return StudyOutputs(summary=summary, report=text, figures=figures, arrays=mc_arrays, files=files)


__all__ = (
    "CONVENTIONS",
    "LOADED_FRACTION",
    "SAMPLE_QUANTITIES",
    "alias_order",
    "contact_groups",
    "contact_summary",
    "drive_orders",
    "loaded_contacts",
    "monte_carlo_summary",
    "order_spectrum",
    "reference_unit",
    "resolution",
    "spectrum_lines",
    "spectrum_summary",
    "study_outputs",
    "typical_index",
)
