"""Harmonic drive: Liu's estimate and the tooth-mesh line in a `gearte run`'s outputs (`gearte.drives.harmonic_outputs`).

Both readings of Liu's eq. (8) (with the 1/√N averaging as printed and without it) against the Monte Carlo and
Liu's measured units, every value behind the estimate with its source, and where the tooth-mesh lines lie and why
(the two mesh zones' relative phase; docs/harmonic.md derives it).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..core.units import angle_from_rad
from .harmonic_estimate import LIU_COMPUTED_ARCMIN, LIU_MEASURED_ARCMIN, delta_for_arcmin
from .harmonic_sources import CLASSES, LIU_ARCSEC_PER_UM_MM, tooth_zone_factor

if TYPE_CHECKING:
    from .harmonic import HarmonicDrive

METRIC_TEXT = {"peak_to_peak": "peak-to-peak over one output revolution", "peak": "peak |TE|", "rms": "RMS"}


def source_basis(drive: HarmonicDrive) -> list[dict]:
    """Every value behind the estimate with where it comes from (the study file's `basis`, or Liu's own values)."""
    z1, z2 = drive.z_flexspline, drive.z_circular_spline
    a_deg = math.degrees(float(drive.pressure_angle))
    n_default = abs(float(drive.teeth_in_mesh) - 0.1 * (z1 + z2)) < 1e-12
    liu_drive = (z1, z2) == (180, 182)
    return [
        {"name": "z₁, z₂", "value": f"{z1}, {z2}", "basis": "Liu, sec. 4 (i = 90)" if liu_drive else "the study file"},
        {"name": "α_n", "value": f"{a_deg:g}°", "basis": "Liu, sec. 2.3 (α_n = 20°)" if abs(a_deg - 20) < 1e-9 else "the study file"},
        {
            "name": "K_b",
            "value": f"{float(drive.k_b):g}",
            "basis": "Liu, sec. 2.3 (K_b = 1.0)" if float(drive.k_b) == 1.0 else "the study file",
        },
        {
            "name": "N",
            "value": f"{float(drive.teeth_in_mesh):.6g}",
            "basis": "Liu, sec. 2.3 (N = 0.1 (z₁ + z₂))" if n_default else "the study file",
        },
        {"name": "d", "value": f"{float(drive.pitch_diameter):g} mm", "basis": "the study file (Liu gives no pitch diameter)"},
    ] + [
        {
            "name": s.name,
            "value": f"{float(s.tolerance):g} µm",
            "class": s.source_class,
            "kind": s.kind,
            "basis": s.basis or "not stated in the study file",
        }
        for s in drive.sources
    ]


def estimate_readings(drive: HarmonicDrive, est, values: np.ndarray, unit: str, metric: str) -> tuple[dict, list[str]]:
    """Both readings of eq. (8) (with Liu's averaging 1/√N and without), the Δ behind Liu's 2.51′ in each, and both
    against the Monte Carlo and Liu's measured units (each a peak-to-peak of one unit).

    The drive's TE carries eq. (8)'s gain as printed, so the Monte Carlo is of that reading; without the averaging
    every TE is √N times larger, the Monte Carlo included: the ratios to the estimate are the same in both readings,
    what changes is where Liu's measured units fall in the batch.
    """
    per_arcmin = angle_from_rad(1.0, unit) / angle_from_rad(1.0, "arcmin")  # this unit per ′
    v_arcmin = values / per_arcmin
    n = float(drive.teeth_in_mesh)
    per_um = float(drive.k_b) * LIU_ARCSEC_PER_UM_MM / float(drive.pitch_diameter)  # ″ per µm of Δ, no averaging
    readings = {}
    for key, arcmin, formula, factor, scale in (
        ("as_printed", est.arcmin, "(K_b/√N)·Δ·412.8/d", f"1/√N = 1/√{n:.6g} = {est.averaging:.6f}", 1.0),
        ("no_averaging", est.arcmin_no_averaging, "K_b·Δ·412.8/d", "1", 1.0 / est.averaging),
    ):
        v = scale * v_arcmin
        median, p9973 = (float(x) for x in np.percentile(v, [50.0, 99.73]))
        readings[key] = {
            "formula": formula,
            "averaging_factor": factor,
            "arcmin": arcmin,
            "arcsec": 60.0 * arcmin,
            "liu_2_51_needs_delta_um": delta_for_arcmin(drive, LIU_COMPUTED_ARCMIN, averaging=key == "as_printed"),
            "monte_carlo_median_arcmin": median,
            "monte_carlo_p99_73_arcmin": p9973,
            "monte_carlo_median_over_estimate": median / arcmin if arcmin else None,
            "monte_carlo_p99_73_over_estimate": p9973 / arcmin if arcmin else None,
            "liu_measured_over_estimate": [m / arcmin if arcmin else None for m in LIU_MEASURED_ARCMIN],
            "monte_carlo_fraction_at_or_below_measured": {f"{m:g}": float(np.mean(v <= m)) for m in LIU_MEASURED_ARCMIN},
        }
    out = {
        "readings": readings,
        "liu": {
            "computed_arcmin": LIU_COMPUTED_ARCMIN,
            "measured_arcmin": list(LIU_MEASURED_ARCMIN),
            "measured_over_computed": [m / LIU_COMPUTED_ARCMIN for m in LIU_MEASURED_ARCMIN],
            "measured_is": "the peak-to-peak of one unit's record over more than one output revolution (Liu, sec. 4, Table 1)",
            "tolerances": "from the drive's drawings, not listed in the paper",
        },
        "monte_carlo_metric": metric,
        "values_and_sources": source_basis(drive),
    }
    a, b = readings["as_printed"], readings["no_averaging"]
    measured = ", ".join(f"{m:g}′" for m in LIU_MEASURED_ARCMIN)
    lines = [
        "### Liu's estimate: both readings of eq. (8)",
        "",
        f"Eq. (8) as printed, Δφ = (K_b/√N)·Δ·412.8/d, averages over the N tooth pairs in mesh and the two zones; read "
        f"without the factor 1/√N, Δφ = K_b·Δ·412.8/d. With K_b = {float(drive.k_b):g}, N = {n:.6g}, "
        f"d = {float(drive.pitch_diameter):g} mm: {per_um:.5f}″ per µm of Δ without the averaging, "
        f"{per_um * est.averaging:.5f}″ with it. gearte's TE model carries the printed gain; without the averaging every "
        f"TE, the Monte Carlo's included, is √N = {1 / est.averaging:.4f} times larger, so the Monte Carlo / estimate "
        "ratios are the same in both readings and what changes is where Liu's measured units fall.",
        "",
        f"| reading | Δφ (Δ = {est.delta_um:.3f} µm) | Δ for Liu's {LIU_COMPUTED_ARCMIN}′ | Monte Carlo median, P99.73 | "
        f"Liu's measured {measured} / Δφ | Monte Carlo units at or below {measured} |",
        "|---|---|---|---|---|---|",
    ]
    for name, r in (("as printed, with 1/√N", a), ("without 1/√N", b)):
        fr = r["monte_carlo_fraction_at_or_below_measured"]
        lines.append(
            f"| {name}: {r['formula']} | {r['arcsec']:.3f}″ = **{r['arcmin']:.4f}′** | {r['liu_2_51_needs_delta_um']:.1f} µm | "
            f"{r['monte_carlo_median_arcmin']:.4f}′, {r['monte_carlo_p99_73_arcmin']:.4f}′ "
            f"({r['monte_carlo_median_over_estimate']:.3f}, {r['monte_carlo_p99_73_over_estimate']:.3f} × Δφ) | "
            + ", ".join(f"{x:.3f}" for x in r["liu_measured_over_estimate"])
            + " | "
            + ", ".join(f"{100 * x:.1f} %" for x in fr.values())
            + " |"
        )
    lines += [
        "",
        f"Arithmetic: Liu's {LIU_COMPUTED_ARCMIN}′ = {60 * LIU_COMPUTED_ARCMIN:.1f}″; {60 * LIU_COMPUTED_ARCMIN:.1f} × "
        f"{float(drive.pitch_diameter):g} / (412.8 × {float(drive.k_b):g}) = {b['liu_2_51_needs_delta_um']:.2f} µm without "
        f"the averaging, × √{n:.6g} = {a['liu_2_51_needs_delta_um']:.1f} µm with it (d is this study's; Liu gives none). "
        f"Monte Carlo: {METRIC_TEXT.get(metric, metric)}, {len(values):,} units. Liu's measured {measured} are each the "
        "peak-to-peak of one unit's record (sec. 4), not a batch statistic; Liu's own ratio measured / computed is "
        + ", ".join(f"{m / LIU_COMPUTED_ARCMIN:.2f}" for m in LIU_MEASURED_ARCMIN)
        + ".",
        "",
        "Values behind the estimate and where each comes from:",
        "",
        "| value | class, kind | amount | from |",
        "|---|---|---|---|",
    ]
    for e in out["values_and_sources"]:
        ck = f"{CLASSES[e['class']]['short']}, {e['kind'].replace('_', ' ')}" if "class" in e else "drive"
        lines.append(f"| {e['name']} | {ck} | {e['value']} | {e['basis']} |")
    lines.append("")
    return out, lines


def tooth_line_note(drive: HarmonicDrive, n: float) -> str:
    """One sentence on where the tooth-mesh line lies and why (the two zones' relative phase)."""
    z2 = drive.z_circular_spline
    if not any(s.source_class == "tooth" for s in drive.sources):
        return ""
    fund = z2 * n
    if z2 % 2 == 0:
        why = (
            f"z₂ = {z2} is even: the two zones, z₂π apart in CS tooth phase, mesh in phase, so the tooth-mesh "
            f"fundamental z₂·n = {fund:,.0f} cpm is the line (2z₂·n = {2 * fund:,.0f} cpm its harmonic)"
        )
    else:
        why = (
            f"z₂ = {z2} is odd: the two zones are half a tooth pitch apart, so the fundamental z₂·n = {fund:,.0f} cpm "
            f"cancels and only even harmonics, 2z₂·n = {2 * fund:,.0f} cpm first, stay"
        )
    return f" Tooth mesh: {z2} CS teeth pass each zone per input turn; {why}. Liu's eq. (6) puts it at 2z₂·n for any z₂."


def tooth_mesh_summary(drive: HarmonicDrive, input_rpm: float | None) -> dict:
    """Where the tooth-mesh lines lie and why: per-zone frequency, the zones' relative phase, each harmonic's fate."""
    z2 = drive.z_circular_spline
    harmonics = sorted({s.harmonic for s in drive.sources if s.source_class == "tooth"})
    per_h = []
    for h in harmonics:
        zf = tooth_zone_factor(z2, h)
        entry = {"harmonic": h, "freq_x_input": str(h * z2), "zone_factor": abs(zf), "in_te": zf != 0}
        if input_rpm is not None:
            entry["freq_cpm"] = h * z2 * input_rpm
        per_h.append(entry)
    out = {
        "z_circular_spline": z2,
        "per_zone_x_input": str(z2),
        "zone_2_tooth_phase": f"z₂·π = {z2}π",
        "zones": "in phase (even z₂)" if z2 % 2 == 0 else "half a tooth pitch apart (odd z₂)",
        "harmonics": per_h,
        "liu_eq6_x_input": str(2 * z2),
    }
    if input_rpm is not None:
        out["liu_eq6_cpm"] = 2 * z2 * input_rpm
    return out
