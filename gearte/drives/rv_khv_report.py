"""RV (K-H-V) reducer: the Markdown report of an ``rv_khv`` study (`gearte.drives.rv_khv_outputs`).

The summary entries computed there (the reference unit, its spectrum and contact map, the Monte Carlo)
written out as the report's sections, every number with its unit.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .rv_khv import RVKHV


#: The Monte Carlo table's rows: summary key → label.
MC_ROWS = (
    ("lost_motion_max_arcmin", "lost motion, max over the grid (′)"),
    ("lost_motion_min_arcmin", "lost motion, min over the grid (′)"),
    ("te_p2p_forward_arcsec", "TE p-p, forward load (″)"),
    ("te_p2p_reverse_arcsec", "TE p-p, reverse load (″)"),
)


def _f(x, spec=".3f") -> str:
    return "—" if x is None else format(x, spec)


def report(drive: RVKHV, s: dict, *, metric: str) -> list[str]:
    """The report sections of the reference unit and of the Monte Carlo (Markdown lines)."""
    ref, spec, cm, mc, conv = s["reference_unit"], s["spectrum"], s["contact_map"], s["monte_carlo"], s["output_conventions"]
    sv = mc["solves"]
    L = ["", "## RV reducer: results", ""]
    if sv["samples_with_failed_solves"] or ref["solves"]["successful"] < ref["solves"]["count"]:
        L += [
            f"**WARNING: not every equilibrium solve succeeded.** Monte Carlo: {sv['samples_with_failed_solves']} of "
            f"{mc['samples']:,} samples have failed solves (successful share of all solves {sv['successful_share']:.6f}; "
            "samples "
            + ", ".join(f"#{b['index']} ({100 * b['solved_share']:.2f} % solved)" for b in sv["failed_samples"])
            + ("…" if sv["samples_with_failed_solves"] > len(sv["failed_samples"]) else "")
            + f"); reference unit: {ref['solves']['successful']} of {ref['solves']['count']} solves succeeded. "
            "Those samples' values include angles where the solve did not converge.",
            "",
        ]
    if ref["negative_lost_motion"] or mc["negative_lost_motion_fraction"]:
        L += [
            f"**WARNING: lost motion below −{mc['lost_motion_resolution_arcsec']:.2g}″** (TE(+) < TE(−), which no "
            "equilibrium gives): "
            + (f"the reference unit (min {ref['lost_motion_arcsec']['min']:.3f}″); " if ref["negative_lost_motion"] else "")
            + f"{100 * mc['negative_lost_motion_fraction']:.2f} % of the Monte Carlo samples. Their solves reported success; "
            "the values there are not rigid-limit equilibria.",
            "",
        ]
    g = ref["grid"]
    lmm, lms = ref["lost_motion_arcmin"], ref["lost_motion_arcsec"]
    tf, tr = ref["te_forward_arcsec"], ref["te_reverse_arcsec"]
    L += [
        "### The reference unit: TE under both load directions",
        "",
        f"Unit #{ref['index']}, {conv['reference_unit']}, solved at {g['points']} output angles over one output revolution "
        f"(every {g['spacing_deg']:.4g}°, from θ_o = 0), each under the forward and the reverse load, in the rigid limit. "
        "(The Monte Carlo takes the same quantities on the study grid of "
        f"{mc['grid_points']} output angles.)",
        "",
        "| load | min (″) | max (″) | mean (″) | p-p (″) |",
        "|---|---|---|---|---|",
        f"| forward (+, carrier CCW) | {tf['min']:.3f} | {tf['max']:.3f} | {tf['mean']:.3f} | **{tf['p2p']:.3f}** |",
        f"| reverse (−, carrier CW) | {tr['min']:.3f} | {tr['max']:.3f} | {tr['mean']:.3f} | **{tr['p2p']:.3f}** |",
        "",
        "| lost motion TE(+) − TE(−) | max | min | mean |",
        "|---|---|---|---|",
        f"| ′ | **{lmm['max']:.4f}** | {lmm['min']:.4f} | {lmm['mean']:.4f} |",
        f"| ″ | {lms['max']:.2f} | {lms['min']:.2f} | {lms['mean']:.2f} |",
        "",
        *_grid_note(ref, mc),
        f"The maximum is at θ_o = {ref['lost_motion_max_at_output_deg']:.3f}°; the lost motion is 0 (within "
        f"{mc['lost_motion_resolution_arcsec']:.2g}″: the parts preloaded, no play) at {100 * ref['zero_lost_motion_share']:.1f} % "
        "of the angles." + (" **It is negative beyond that somewhere (see the warning above).**" if ref["negative_lost_motion"] else ""),
        "",
        "![TE for both load directions](te_both_directions.png)",
        "",
        "### Spectrum of the forward TE",
        "",
        f"Discrete Fourier transform of the forward TE of unit #{ref['index']} on the {spec['grid_points']} angles above: "
        f"orders 0 … {spec['highest_resolved_order']} cycles per output revolution are resolved; a higher order k appears at "
        "|k − p round(k/p)| (p the number of angles). Amplitude A_k = 2|X_k|/p, mean "
        f"{spec['mean_arcsec']:.3f}″.",
        "",
        "| order (per output rev) | amplitude (″) | drive orders that land here |",
        "|---|---|---|",
    ]
    L += [
        f"| {ln['order']} | {ln['amplitude_arcsec']:.3f} | {', '.join(str(o) for o in ln['drive_orders_here']) or ''} |"
        for ln in spec["lines"]
    ]
    L += ["", "The drive's own orders and where the grid shows them:", "", "| order | source | on this grid at |", "|---|---|---|"]
    L += [f"| {d['order']} | {d['name']} | {d['appears_at_order']}{' (aliased)' if d['aliased'] else ''} |" for d in spec["drive_orders"]]
    L += ["", "![spectrum](spectrum.png)", "", "### Contact map (forward load)", ""]
    L += [
        f"A contact carries load when its force exceeds {cm['loaded_when_force_above']}. Contacts: "
        + "; ".join(f"{c['group']} {c['first']}–{c['last']}" for c in cm["contacts"])
        + " (mesh flanks: crank 1 +, −, crank 2 +, −, …; + is the flank whose line of action points counter-clockwise "
        "about the reducer's axis at the crank).",
        "",
        "| contacts loaded at each output angle | mean | min | max | of |",
        "|---|---|---|---|---|",
    ]
    for d in range(drive.discs):
        for suffix, label in (("", "forward"), ("_reverse", "reverse")):
            q = cm[f"loaded_pins_disc_{d + 1}{suffix}"]
            L.append(f"| pins of disc {d + 1}, {label} load | {q['mean']:.2f} | {q['min']:.0f} | {q['max']:.0f} | {q['of']} |")
    for suffix, label in (("", "forward"), ("_reverse", "reverse")):
        q = cm[f"loaded_mesh_flanks{suffix}"]
        L.append(f"| mesh flanks, {label} load | {q['mean']:.2f} | {q['min']:.0f} | {q['max']:.0f} | {q['of']} |")
    L += ["", "![contact map](contact_map.png)", "", "### Monte Carlo", ""]
    L += [
        f"{mc['samples']:,} reducers, each solved at {mc['grid_points']} output angles under both loads "
        f"({sv['per_sample']} equilibrium solves per reducer); successful share of all solves: "
        f"**{_f(sv['successful_share'], '.6f')}**"
        + (
            f" ({sv['samples_with_failed_solves']} samples with failed solves, see the warning above)."
            if sv["samples_with_failed_solves"]
            else " (every solve succeeded)."
        ),
        "",
        "| quantity | mean | std | P50 | P95 | P99.73 | min | max |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, label in MC_ROWS:
        q = mc[name]
        pc = q["percentiles"]
        L.append(
            f"| {label} | {_f(q['mean'])} | {_f(q['std'])} | {_f(pc.get('50'))} | {_f(pc.get('95'))} | {_f(pc.get('99.73'))} | "
            f"{_f(q['min'])} | {_f(q['max'])} |"
        )
    L += [
        "",
        f"Reducers with no play somewhere on the grid (lost motion min within {mc['lost_motion_resolution_arcsec']:.2g}″ of 0: "
        f"errors forced into the hyperstatic assembly preload the parts): {100 * mc['zero_lost_motion_somewhere_fraction']:.2f} %"
        + (
            f"; **with a negative lost motion beyond that (see the warning above): {100 * mc['negative_lost_motion_fraction']:.2f} %**."
            if mc["negative_lost_motion_fraction"]
            else "; none has a negative lost motion beyond it."
        ),
        "std is the sample standard deviation (n − 1); percentiles by linear interpolation.",
        "",
        "![Monte Carlo](monte_carlo.png)",
        "",
        "The lost motion's histogram is `histogram.png` above (the study's metric)."
        if metric == "lost_motion"
        else "The lost motion's histogram is the first panel of `monte_carlo.png`.",
        "",
        "### Assumptions of these outputs",
        "",
    ]
    L += [f"- {k.replace('_', ' ')}: {v}." for k, v in conv.items()]
    L += [
        "",
        "Files: `te_both_directions.png`, `spectrum.png`, `contact_map.png`, `monte_carlo.png`: the plots above; "
        "`reference_unit.npz`: the reference unit's curves (TE both ways, lost motion, forces and loaded contacts, spectrum); "
        "`samples.npz` also holds every reducer's `lost_motion_max_arcmin`, `lost_motion_min_arcmin`, `te_p2p_forward_arcsec`, "
        "`te_p2p_reverse_arcsec` and `solved` (the share of its solves that succeeded).",
        "",
    ]
    return L


def _grid_note(ref: dict, mc: dict) -> list[str]:
    """The reference unit on the Monte Carlo's grid against the finer grid above: what the study grid misses."""
    g = ref.get("on_study_grid")
    if not g or g["grid_points"] == ref["grid"]["points"]:
        return []
    tf, tr, lmm = ref["te_forward_arcsec"], ref["te_reverse_arcsec"], ref["lost_motion_arcmin"]
    return [
        f"On the Monte Carlo's grid of {g['grid_points']} output angles the same unit has TE p-p "
        f"{g['te_p2p_forward_arcsec']:.3f}″ (forward) and {g['te_p2p_reverse_arcsec']:.3f}″ (reverse) and lost motion "
        f"{g['lost_motion_max_arcmin']:.4f}′ at most, against {tf['p2p']:.3f}″, {tr['p2p']:.3f}″ and {lmm['max']:.4f}′ on the "
        f"{ref['grid']['points']} angles above: the study grid misses up to {100 * g['understated_by']:.1f} % of them "
        "between its angles, so the Monte Carlo's TE p-p and lost-motion figures (and a budget on them) are low by about "
        "as much. A finer `[drive.grid] points` narrows it, at a proportional cost.",
        "",
    ]


__all__ = ("report",)
