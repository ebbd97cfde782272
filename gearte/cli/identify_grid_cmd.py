"""`gearte identify` for a grid drive (cycloid-pin; any `AbstractGridDrive` that states its TE on its grid).

The sources named by ``--fit`` (default: all) are identified by Levenberg–Marquardt on the drive's own model at
its grid angles (`gearte.identification.fit_grid`); the others stay at zero. Written atomically like every run:
summary.json, report.md and measured_vs_identified.png (the record and the identified model's TE on the grid).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .. import __version__
from ..core.solution import result_name
from ..core.units import UNIT_SYMBOLS, angle_from_rad
from ..identification import MeasuredRecord, identify
from ..identification.fit import Z95
from ..studies.montecarlo import as_key
from .io import atomic_output_dir, write_json, written_files


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def summary_header(study, args, rec, command: str) -> dict:
    """The first entries of an identification's summary.json: version, command, study, record and its size."""
    return {
        "gearte_version": __version__,
        "command": command,
        "study": study.name,
        "record": str(args.record),
        "samples": len(rec.te),
        "revolutions": rec.revolutions,
    }


def run_identify_grid(args, command: str, study, rec: MeasuredRecord) -> int:
    drive = study.drive
    if args.adjust:
        raise ValueError(
            "--adjust: re-assembly from identified phasors needs a drive whose TE is a sum of sinusoids; for a grid drive "
            "name the sources to identify with --fit"
        )
    fit = [s.strip() for s in args.fit.split(",") if s.strip()] or None
    if fit is not None:
        unknown = [s for s in fit if s not in drive.error_sources]
        if unknown:
            raise ValueError(f"--fit: {unknown} are not error sources of this drive; use some of {list(drive.error_sources)}")
    unit = study.unit
    sym = UNIT_SYMBOLS[unit]
    conv = float(angle_from_rad(1.0, unit))
    with atomic_output_dir(args.out, inputs=[args.config, args.record]) as tmp:
        sol = identify(drive, rec, adjust=fit, key=as_key(args.seed), throw=False)
        rows = []
        for i, lab in enumerate(sol.labels):
            spec = drive.error_sources[lab.split("[")[0]]
            m, ms, p, ps = (float(x[i]) for x in (sol.magnitude, sol.magnitude_se, sol.phase, sol.phase_se))
            row = {"source": lab, "kind": spec.kind, "unit": spec.unit, "value": m, "se": ms, "interval_95": [m - Z95 * ms, m + Z95 * ms]}
            if spec.kind == "eccentricity":
                row.update(phase_rad=_finite(p), phase_se_rad=_finite(ps), phase_95_rad=[_finite(p - Z95 * ps), _finite(p + Z95 * ps)])
            rows.append(row)
        theta = np.asarray(drive.input_angles())
        model = np.asarray(drive.te(drive.response(sol.errors))) + float(sol.offset[0])
        summary = {
            **summary_header(study, args, rec, command),
            "drive": drive.type_name,
            "method": "Levenberg-Marquardt on the drive's model at its grid angles (docs/identification.md, Grid drives)",
            "grid_angles": int(theta.size),
            "result": result_name(sol.result),
            "unit": unit,
            "residual_rms": float(sol.residual_rms) * conv,
            "identified": rows,
            "held_at_zero": [n for n in drive.error_sources if fit is not None and n not in fit],
            "groups": [{"kind": g.kind, "members": list(g.members), "advice": g.advice} for g in sol.groups],
        }
        _plot(rec, theta, model, conv, sym, tmp / "measured_vs_identified.png")
        (tmp / "report.md").write_text(_report(summary, sym), encoding="utf-8")
        summary["files"] = written_files(tmp, "summary.json")
        write_json(tmp / "summary.json", summary)
    print(f"identified {len(sol.labels)} sources ({summary['result']}); residual RMS {summary['residual_rms']:.3g}{sym}")
    print(f"report: {args.out}/report.md")
    return 0 if summary["result"] == "successful" else 1


def _report(s: dict, sym: str) -> str:
    out = [
        f"# Identification: {s['study']} ({s['drive']}, a grid drive)",
        "",
        f"Record `{s['record']}`: {s['samples']:,} samples over {s['revolutions']:.4g} input revolutions, read at the "
        f"drive's {s['grid_angles']} grid angles. Method: {s['method']}.",
        "",
        f"Solve: {s['result']}; residual RMS {s['residual_rms']:.3g}{sym}.",
        "",
        "## Identified errors (95 % intervals)",
        "",
        "| source | value | 95 % | phase rad | 95 % |",
        "|---|---|---|---|---|",
    ]
    for r in s["identified"]:
        ph = (
            f"{r['phase_rad']:.4g} | {r['phase_95_rad'][0]:.4g} … {r['phase_95_rad'][1]:.4g}" if r.get("phase_rad") is not None else "— | —"
        )
        out.append(f"| {r['source']} | {r['value']:.4g} {r['unit']} | {r['interval_95'][0]:.4g} … {r['interval_95'][1]:.4g} | {ph} |")
    if s["held_at_zero"]:
        out += ["", f"Held at zero (not identified): {', '.join(s['held_at_zero'])}."]
    out += ["", "## Identifiability", ""] + ([f"- **{g['kind']}**: {g['advice']}." for g in s["groups"]] or ["- every source separable."])
    out += ["", "![measured vs identified](measured_vs_identified.png)", "", f"Command: `{s['command']}`", ""]
    return "\n".join(out)


def _plot(rec: MeasuredRecord, theta: np.ndarray, model: np.ndarray, conv: float, sym: str, path: Path) -> None:
    fig = Figure(figsize=(9, 4.5), dpi=100)
    ax = fig.subplots()
    ax.plot(np.asarray(rec.theta) / (2 * math.pi), np.asarray(rec.te) * conv, lw=0.7, color="#4477aa", label="measured")
    ax.plot(theta / (2 * math.pi), model * conv, "o", ms=3, color="#cc3311", label="identified model (grid angles)")
    ax.set_xlabel("input revolutions")
    ax.set_ylabel(f"TE ({sym})")
    ax.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path)
