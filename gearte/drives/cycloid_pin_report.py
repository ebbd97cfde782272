"""Cycloid-pin reducer: the Markdown report of a ``cycloid_pin`` study (`gearte.drives.cycloid_pin_outputs`).

The summary entries computed there (the reference reducer, its disc centre, the Monte Carlo) written out as
the report's sections, every number with its unit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..core.units import number_text

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin


def _fmt(x, spec=".3f") -> str:
    return number_text(x, spec)


def _floating_line(f: dict) -> str:
    """The floating disc's bullet: what it does where the rigid, fixed-offset disc interferes."""
    lm, nf, nr = f["lost_motion_arcmin"], f["loaded_pairs_forward"], f["loaded_pairs_reverse"]
    numbers = (
        f"lost motion {lm['min']:.2f}′ … {lm['max']:.2f}′ and {nf['min']}–{nf['max']} loaded pairs forward, "
        f"{nr['min']}–{nr['max']} reverse (pins carrying force at vanishing load)"
    )
    head = (
        f"- the disc floating in its bearing clearance ({f['clearance_um']:.1f} µm; the contact potential's minimum, "
        f"pins as unilateral springs, rigid limit, on the grid of {f['positions']} input angles): "
    )
    if f["interfering_share_rigid"] > 0 and f["interfering_share_floating"] == 0:
        return (
            head + f"the rigid fixed-offset idealisation interferes over {100 * f['interfering_share_rigid']:.0f} % of "
            f"the grid, the floating disc nowhere: {numbers};"
        )
    if f["interfering_share_floating"] > 0:
        return head + f"it jams (contacts preloaded) at {100 * f['interfering_share_floating']:.0f} % of the grid; {numbers};"
    return head + numbers + ";"


def report(drive: CycloidPin, s: dict) -> list[str]:
    """The report sections of the reference reducer and of the Monte Carlo (Markdown lines)."""
    L = [
        "",
        "## Result for the reducer analysed",
        "",
        f"At the input position θ_T = {s['input_angle_deg']:.4f}° (pin wheel relative to the arm):",
        "",
        f"- contacting pair (forward load): pin {s['contact_pair']['pin']} with tooth space {s['contact_pair']['tooth_space']} "
        f"(Yao & Liang's numbering: position K = {s['contact_pair']['K']}, pair n = {s['contact_pair']['paper_pin']} with J = {s['paper_J']}); "
        f"reverse load: pin {s['reverse_contact_pair']['pin']} with tooth space {s['reverse_contact_pair']['tooth_space']} "
        f"(K = {s['reverse_contact_pair']['K']});",
        "- over Yao & Liang's sweep of one pitch (their θ_T from 0 to 2π/z_b, gearte's θ_T from 0 to −2π/z_b): contacting pair "
        + ", ".join(f"K = {p['K']} ({100 * p['share_of_pitch']:.0f} %)" for p in s["contact_pairs_over_paper_pitch"])
        + ";",
        f"- loaded pairs (tangential clearance ≤ {s['deformation_budget_mm']:g} mm on the pin circle): "
        f"**{s['loaded_pairs']} of the {s['loaded_pairs_out_of']}** theoretical pairs "
        f"(over one pitch {s['loaded_pairs_over_pitch']['min']}–{s['loaded_pairs_over_pitch']['max']}, over the revolution "
        f"{s['loaded_pairs_over_revolution']['min']}–{s['loaded_pairs_over_revolution']['max']});",
        f"- lost motion: **{s['lost_motion_arcmin']:.3f}′** at most over the revolution "
        f"(range {s['lost_motion_range_arcmin'][0]:.3f}′ … {s['lost_motion_range_arcmin'][1]:.3f}′; "
        f"{s['lost_motion_at_input_angle_arcmin']:.3f}′ at θ_T)"
        + ("; **negative somewhere: the rigid disc, its centre held at the fixed offsets, interferes there**" if s["interference"] else "")
        + ";",
        f"- the disc centre: {s['disc_centre']['explanation']}"
        + (
            f" Floating without interference at θ_T, it has {s['disc_centre']['loaded_pairs_floating']['min']}–"
            f"{s['disc_centre']['loaded_pairs_floating']['max']} loaded pairs (the rigid count above is that of an interfering disc)."
            if s["interference"] and s["disc_centre"]["loaded_pairs_floating"]["min"] is not None
            else ""
        ),
        _floating_line(s["floating_equilibrium"]),
        f"- rotation error (TE) of the stage, forward load: peak-to-peak **{s['rotation_error_p2p_arcsec']:.2f}″** over "
        f"{drive.analysis.sweep_revolutions} input revolution(s) (reverse load {s['rotation_error_reverse_p2p_arcsec']:.2f}″).",
        "",
        "![clearance per pin](clearance_per_pin.png)",
        "",
        "| pin | tooth space | flank | tangential clearance (mm) | tangential clearance (″) | normal clearance (mm) | within budget |",
        "|---|---|---|---|---|---|---|",
    ]
    for p in s["pairs"]:
        L.append(
            f"| {p['pin']} | {p['tooth_space']} | {p['flank']} | "
            f"{_fmt(p['tangential_clearance_mm'], '.4f') if p['can_touch'] else 'never touches'} | "
            f"{_fmt(p['tangential_clearance_arcsec'], '.1f')} | {_fmt(p['normal_clearance_mm'], '.4f')} | {'yes' if p['loaded'] else ''} |"
        )
    L += [
        "",
        "![clearance against the input angle](clearance_vs_input.png)",
        "",
        "![rotation error](rotation_error.png)",
        "",
        "## Errors of the reducer analysed",
        "",
        "| field | value |",
        "|---|---|",
    ]
    L += [f"| {k} | {v} |" for k, v in s["reference_errors"].items()] or ["| (none) | |"]
    L += [
        "",
        "## Sensitivities of the reducer analysed",
        "",
        "Derivatives at the errors above (per-space and per-pin errors: the same change on all of them); "
        "lost motion = its maximum over the revolution, loaded pairs = the smooth surrogate (mean over positions).",
        "",
        "| quantity | d lost motion (′ per) | d TE p-p (″ per) | d loaded pairs (per) |",
        "|---|---|---|---|",
    ]
    sens = s["sensitivities"]
    for key in sens["lost_motion_max"]["derivatives"]:
        a, b, c = (sens[m]["derivatives"][key] for m in ("lost_motion_max", "rotation_error_p2p", "loaded_pairs_smooth"))
        L.append(f"| {key} (per {a['per']}) | {a['value']:.4g} | {b['value']:.4g} | {c['value']:.4g} |")
    mc = s["monte_carlo"]
    L += [
        "",
        "## Monte Carlo of the clearances over the error laws",
        "",
        f"{mc['samples']:,} reducers, seed {mc['seed']}; the grid: {mc['positions']['count']} input positions "
        f"({mc['positions']['per_pitch']} per pin pitch over {mc['positions']['revolutions']} input revolution(s)). "
        + _cycle_note(mc["positions"]["revolutions"], mc.get("z_lobes")),
        "",
        "| error | law |",
        "|---|---|",
    ]
    L += [f"| {k} | {v} |" for k, v in mc["tolerances"].items()]
    L += ["", "| quantity | mean | std | P5 | P50 | P95 | max |", "|---|---|---|---|---|---|---|"]
    for label, key in (
        ("lost motion, max over the grid (′)", "lost_motion_max_arcmin"),
        ("lost motion, min over the grid (′)", "lost_motion_min_arcmin"),
        ("rotation error p-p (″)", "rotation_error_p2p_arcsec"),
        (f"loaded pairs at θ_T (of {s['loaded_pairs_out_of']})", "loaded_pairs"),
        ("loaded pairs, min over the grid", "loaded_pairs_min_over_cycle"),
    ):
        q = mc[key]
        L.append(
            f"| {label} | {q['mean']:.3f} | {q['std']:.3f} | {q['percentiles']['5']:.3f} | {q['percentiles']['50']:.3f} | "
            f"{q['percentiles']['95']:.3f} | {q['max']:.3f} |"
        )
    L += [
        "",
        f"Reducers that interfere somewhere on the grid (lost motion < 0): {100 * mc['interference_fraction']:.2f} %"
        + (
            f"; the others have {mc['loaded_pairs_without_interference']['mean']:.2f} loaded pairs at θ_T on average."
            if mc["loaded_pairs_without_interference"] and mc["interference_fraction"] > 0
            else "."
        ),
        "",
        "![Monte Carlo](monte_carlo.png)",
        "",
        "## The clearance analysis: assumptions",
        "",
    ]
    L += [f"- {k.replace('_', ' ')}: {v}." for k, v in s["clearance_assumptions"].items()]
    L += [
        f"- All solves converged: {'yes' if s['sweep']['all_solves_converged'] else 'NO (see summary.json)'}"
        + (f"; Monte Carlo: {mc['not_converged_solves']} solves did not converge." if mc["not_converged_solves"] else "."),
        "",
        "Files: `clearance_per_pin.png`, `clearance_vs_input.png`, `rotation_error.png`, `monte_carlo.png`: the plots above; "
        "`samples.npz` also holds the per-reducer clearances (`lost_motion_max_arcmin`, `loaded_pairs`, "
        "`tangential_clearance_mm`, …) and the reference reducer's curves (`reference_*`).",
        "",
    ]
    return L


def _cycle_note(revolutions: int, z_lobes: int | None) -> str:
    """What the grid covers of the cycle after which pins and tooth spaces pair again (z_a input revolutions)."""
    if not z_lobes or revolutions % z_lobes == 0:
        return "The grid covers whole output revolutions, the cycle after which pins and tooth spaces pair again."
    return (
        f"Pins and tooth spaces pair again only after z_a = {z_lobes} input revolutions (one output revolution); the grid "
        f"covers {revolutions} of them, so a maximum over it is a lower bound, and a minimum an upper bound, of the whole "
        "cycle's (more `[drive.grid] revolutions` extend it, at a proportional cost)."
    )


__all__ = ("report",)
