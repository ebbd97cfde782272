"""`gearte identify STUDY.toml RECORD.csv --out DIR` and `gearte assemble PARTS.csv --study STUDY.toml --out DIR`.

Both write their results folder atomically (summary.json, report.md, plots), like `gearte run`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .. import __version__
from ..core.schema import ConfigError
from ..core.solution import result_name
from ..core.units import UNIT_SYMBOLS, angle_from_rad
from ..drives.protocol import AbstractGridDrive, AbstractSinusoidalDrive, Eccentricity
from ..identification import IdentificationProblem, assemble_batch, diagnose, identification_problem, read_record, reassemble
from ..identification.fit import Z95, _solve
from ..studies.montecarlo import as_key
from .config import load_study
from .identify_grid_cmd import run_identify_grid, summary_header
from .io import atomic_output_dir, write_json, written_files


def _units(items: list[str]) -> dict[str, str]:
    out = {}
    for it in items:
        if "=" not in it:
            raise ValueError(f"--unit {it!r}: write QUANTITY=UNIT, e.g. te=arcsec")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def _sinusoidal(study, path) -> AbstractSinusoidalDrive:
    if not isinstance(study.drive, AbstractSinusoidalDrive):
        raise ConfigError(
            f"{path}: [drive] type = {study.drive.type_name!r} computes its TE on a grid; gearte assemble needs a "
            "drive whose TE is a sum of sinusoids (planetary_2kh, harmonic, explicit); gearte identify also takes a grid drive's "
            "study (docs/identification.md, Grid drives)"
        )
    return study.drive


def run_identify(args, command: str) -> int:
    study = load_study(args.config)
    given = getattr(study.drive, "ratio", None)
    ratio = args.ratio if args.ratio is not None else (float(given) if given is not None else None)
    if isinstance(study.drive, AbstractGridDrive):
        rec = read_record(args.record, units=_units(args.unit), input_rpm=args.input_rpm, ratio=ratio)
        return run_identify_grid(args, command, study, rec)
    if args.fit:
        raise ValueError(
            "--fit: only for a grid drive; a sinusoidal drive's identification fits every source (see --adjust for re-assembly)"
        )
    drive = _sinusoidal(study, args.config)
    rec = read_record(args.record, units=_units(args.unit), input_rpm=args.input_rpm, ratio=ratio)
    adjust = {s.strip(): None for s in args.adjust.split(",") if s.strip()}
    unknown = sorted(set(adjust) - set(drive.error_sources))
    if unknown:  # before the fit
        raise ValueError(
            f"--adjust: {', '.join(map(repr, unknown))}: not an error source of this drive; use some of {sorted(drive.error_sources)}"
        )
    with atomic_output_dir(args.out, inputs=[args.config, args.record]) as tmp:
        problem = identification_problem(drive, rec)
        assert isinstance(problem, IdentificationProblem)  # a sinusoidal drive's
        sol = _solve(problem, [np.asarray(rec.te)], as_key(args.seed))
        diag = diagnose(problem, sol, rec)
        alloc = reassemble(drive, sol, adjust=adjust, key=args.seed) if adjust else None
        unit = study.unit
        sym = UNIT_SYMBOLS[unit]
        conv = float(angle_from_rad(1.0, unit))
        rows = []
        for i, lab in enumerate(sol.labels):
            m, ms, p, ps = (float(x[i]) for x in (sol.magnitude, sol.magnitude_se, sol.phase, sol.phase_se))
            rows.append(
                {
                    "source": lab,
                    "magnitude_um": m,
                    "magnitude_se_um": ms,
                    "magnitude_95_um": [m - Z95 * ms, m + Z95 * ms],
                    "phase_rad": p,
                    "phase_se_rad": ps,
                    "phase_95_rad": [p - Z95 * ps, p + Z95 * ps],
                    "phase_period_rad": float(sol.phase_period[i]),
                }
            )
        summary = {
            **summary_header(study, args, rec, command),
            "result": result_name(sol.result),
            "unit": unit,
            "residual_rms": float(sol.residual_rms) * conv,
            "identified": rows,
            "groups": [
                {"kind": g.kind, "members": list(g.members), "representative": g.representative, "advice": g.advice} for g in sol.groups
            ],
            "lines": [
                {
                    "frequency": str(ln.frequency),
                    "measured": ln.measured * conv,
                    "identified": ln.identified * conv,
                    "parts": [{"source": lab, "share": sh, "amplitude": a * conv, "members": list(mem)} for lab, sh, a, mem in ln.parts],
                }
                for ln in diag.lines
            ],
            "unexplained_lines": [{"frequency": f, "amplitude": a * conv} for f, a in diag.unexplained],
        }
        if alloc is not None:
            summary["reassembly"] = {
                "adjust": list(adjust),
                "phases_rad": {k: np.asarray(v).tolist() for k, v in alloc.phases.items()},
                "te_before": float(alloc.te_before) * conv,
                "te_after": float(alloc.te) * conv,
                "metric": type(alloc.metric).__name__,
            }
        _plot_identify(diag, conv, sym, tmp / "measured_vs_identified.png", rec)
        (tmp / "report.md").write_text(_identify_report(summary, sym), encoding="utf-8")
        summary["files"] = written_files(tmp, "summary.json")
        write_json(tmp / "summary.json", summary)
    print(f"identified {len(sol.labels)} phasors ({summary['result']}); residual RMS {summary['residual_rms']:.3g}{sym}")
    print(f"report: {args.out}/report.md")
    return 0


def _identify_report(s: dict, sym: str) -> str:
    out = [
        f"# Identification: {s['study']}",
        "",
        f"Record `{s['record']}`: {s['samples']:,} samples over {s['revolutions']:.4g} input revolutions.",
        "",
    ]
    out += [f"Solve: {s['result']}; residual RMS {s['residual_rms']:.3g}{sym}.", "", "## Identified errors (95 % intervals)", ""]
    out += ["| source | magnitude µm | 95 % | phase rad | 95 % |", "|---|---|---|---|---|"]
    for r in s["identified"]:
        per = "" if math.isclose(r["phase_period_rad"], 2 * math.pi) else f" (mod {r['phase_period_rad']:.4g})"
        out.append(
            f"| {r['source']} | {r['magnitude_um']:.4g} | {r['magnitude_95_um'][0]:.4g} … {r['magnitude_95_um'][1]:.4g} | "
            f"{r['phase_rad']:.4g}{per} | {r['phase_95_rad'][0]:.4g} … {r['phase_95_rad'][1]:.4g} |"
        )
    out += ["", "## Identifiability", ""] + [f"- **{g['kind']}**: {g['advice']}." for g in s["groups"]]
    out += [
        "",
        "## Diagnosis: lines of the record",
        "",
        f"| line × input speed | measured {sym} | identified {sym} | parts (share) |",
        "|---|---|---|---|",
    ]
    for ln in s["lines"]:
        parts = "; ".join(
            f"{p['source']} {100 * p['share']:.0f} %" + (f" (with {', '.join(p['members'][1:])})" if len(p["members"]) > 1 else "")
            for p in ln["parts"]
        )
        out.append(f"| {ln['frequency']} | {ln['measured']:.4g} | {ln['identified']:.4g} | {parts or '—'} |")
    un = s["unexplained_lines"]
    out += [
        "",
        "Lines of the residual that no modelled source explains: "
        + (", ".join(f"{u['frequency']:.4g} × ({u['amplitude']:.3g}{sym})" for u in un) or "none")
        + ".",
    ]
    if "reassembly" in s:
        r = s["reassembly"]
        out += [
            "",
            "## Re-assembly",
            "",
            f"Turning {', '.join(r['adjust'])}: {r['metric']} {r['te_before']:.4g}{sym} → {r['te_after']:.4g}{sym} predicted.",
        ]
        out += [f"- {k}: phase {v} rad" for k, v in r["phases_rad"].items()]
    out += ["", "![measured vs identified](measured_vs_identified.png)", "", f"Command: `{s['command']}`", ""]
    return "\n".join(out)


def _plot_identify(diag, conv: float, sym: str, path: Path, rec) -> None:
    fig = Figure(figsize=(9, 7), dpi=100)
    ax1, ax2 = fig.subplots(2, 1)
    revs = diag.theta / (2 * math.pi)
    ax1.plot(revs, diag.measured * conv, lw=0.6, label="measured", color="#4477aa")
    ax1.plot(revs, diag.identified * conv, lw=0.8, label="identified model", color="#cc3311")
    ax1.set_xlabel("input revolutions")
    ax1.set_ylabel(f"TE ({sym})")
    ax1.legend(loc="upper right")
    n = len(diag.measured)
    w = np.hanning(n)
    for y, lab, col in ((diag.measured, "measured", "#4477aa"), (diag.measured - diag.identified, "residual", "#999999")):
        amp = 2 * np.abs(np.fft.rfft((y - y.mean()) * w)) / w.sum()
        f = np.fft.rfftfreq(n, d=rec.step / (2 * math.pi))
        ax2.semilogy(f, np.maximum(amp * conv, 1e-6), lw=0.6, label=lab, color=col)
    for ln in diag.lines:
        ax2.axvline(float(ln.frequency), color="#cc3311", lw=0.5, ls=":")
    ax2.set_xlabel("frequency (× input speed)")
    ax2.set_ylabel(f"amplitude ({sym})")
    ax2.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(path)


def _read_parts(path: str, drive) -> dict[str, Eccentricity]:
    """The parts of a CSV file: a header naming source, magnitude_um and one of phase_rad, phase_deg, then one row per
    part. Blank lines and lines starting with # are skipped; errors name the file's own line numbers."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not a UTF-8 text file (byte {e.start}); save the parts as CSV text") from None
    lines = [(i, ln) for i, ln in enumerate(text.splitlines(), start=1) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ConfigError(f"{path}: empty; give a header source,magnitude_um,phase_rad and one row per part")
    head = [h.strip() for h in lines[0][1].split(",")]
    if "phase_rad" in head and "phase_deg" in head:
        raise ConfigError(f"{path}: line {lines[0][0]}: the header names both phase_rad and phase_deg; keep one")
    repeated = sorted({h for h in head if head.count(h) > 1})
    if repeated:
        raise ConfigError(f"{path}: line {lines[0][0]}: the header names {', '.join(repeated)} more than once")
    phase_col = "phase_rad" if "phase_rad" in head else "phase_deg" if "phase_deg" in head else None
    if "source" not in head or "magnitude_um" not in head or phase_col is None:
        raise ConfigError(f"{path}: the header must name source, magnitude_um and phase_rad (or phase_deg), got {', '.join(head)}")
    specs = drive.error_sources
    data: dict[str, list[tuple[float, float]]] = {}
    for i, ln in lines[1:]:
        cells = [c.strip() for c in ln.split(",")]
        if len(cells) != len(head):
            raise ConfigError(f"{path}: line {i}: {len(cells)} values for {len(head)} columns")
        row = dict(zip(head, cells))
        src = row["source"]
        if src not in specs:
            raise ConfigError(f"{path}: line {i}: {src!r} is not an error source of the drive; use one of {', '.join(specs)}")
        try:
            m, p = float(row["magnitude_um"]), float(row[phase_col])
        except ValueError:
            raise ConfigError(f"{path}: line {i}: magnitude and phase must be numbers") from None
        if not (math.isfinite(m) and m >= 0 and math.isfinite(p)):
            raise ConfigError(f"{path}: line {i}: the magnitude must be finite and ≥ 0 µm, the phase finite")
        data.setdefault(src, []).append((m, math.radians(p) if phase_col == "phase_deg" else p))
    return {s: Eccentricity(np.array([v[0] for v in rows]), np.array([v[1] for v in rows])) for s, rows in data.items()}


def run_assemble(args, command: str) -> int:
    study = load_study(args.study)
    drive = _sinusoidal(study, args.study)
    parts = _read_parts(args.parts, drive)
    with atomic_output_dir(args.out, inputs=[args.study, args.parts]) as tmp:
        try:
            out = assemble_batch(drive, parts, key=args.seed, metric=study.metric, random_batches=args.random_batches)
        except ValueError as e:
            if str(e).startswith("parts"):  # the batch's own checks (counts of each part type): name the file
                raise ConfigError(f"{args.parts}: {str(e).removeprefix('parts: ')}") from None
            raise
        unit = study.unit
        sym = UNIT_SYMBOLS[unit]
        conv = float(angle_from_rad(1.0, unit))
        rand_worst = out.random_worst * conv
        summary = {
            "gearte_version": __version__,
            "command": command,
            "study": study.name,
            "drives": len(out.te),
            "unit": unit,
            "metric": study.metric.name,
            "selective": {"worst": out.worst * conv, "p99.73": out.p9973 * conv, "mean": float(np.mean(out.te)) * conv},
            "random": {
                "worst_median": float(np.median(rand_worst)),
                "worst_min": float(np.min(rand_worst)),
                "p99.73_all": float(np.percentile(out.random_te, 99.73)) * conv,
                "mean": float(np.mean(out.random_te)) * conv,
                "batches": int(len(rand_worst)),
            },
            "random_matching_optimised_turns_worst": float(out.random_matched_te.max()) * conv,
        }
        rows = ["drive,source,position,part,turn_rad,te_" + unit]
        for d in range(len(out.te)):
            for s, a in out.assignment.items():
                for j in range(a.shape[1]):
                    rows.append(f"{d},{s},{j},{int(a[d, j])},{float(out.turns[s][d, j]):.9g},{out.te[d] * conv:.6g}")
        (tmp / "assembly.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
        fig = Figure(figsize=(8, 4.5), dpi=100)
        ax = fig.subplots()
        ax.hist(out.random_te.ravel() * conv, bins=60, alpha=0.6, density=True, label="random assembly", color="#999999")
        ax.hist(out.te * conv, bins=20, alpha=0.8, density=True, label="selective assembly", color="#4477aa")
        ax.set_xlabel(f"{study.metric.name} TE ({sym})")
        ax.legend()
        fig.tight_layout()
        fig.savefig(tmp / "te_selective_vs_random.png")
        s, r = summary["selective"], summary["random"]
        report = [
            f"# Selective assembly: {study.name}",
            "",
            f"{summary['drives']} drives from the measured parts of `{args.parts}`; {study.metric.name} TE.",
            "",
            "| assembly | worst | P99.73 | mean |",
            "|---|---|---|---|",
            f"| selective (matching and turns) | {s['worst']:.4g}{sym} | {s['p99.73']:.4g}{sym} | {s['mean']:.4g}{sym} |",
            f"| random ({r['batches']} batches: median of the worst; all drives) | {r['worst_median']:.4g}{sym} | {r['p99.73_all']:.4g}{sym} | {r['mean']:.4g}{sym} |",
            f"| random matching, turns optimised | {summary['random_matching_optimised_turns_worst']:.4g}{sym} | | |",
            "",
            "Which parts go together and at which turns: `assembly.csv`. Method: docs/identification.md.",
            "",
            "![TE selective vs random](te_selective_vs_random.png)",
            "",
            f"Command: `{command}`",
            "",
        ]
        (tmp / "report.md").write_text("\n".join(report), encoding="utf-8")
        summary["files"] = written_files(tmp, "summary.json")
        write_json(tmp / "summary.json", summary)
    print(
        f"selective assembly: worst {summary['selective']['worst']:.4g}{sym} (random: median worst {summary['random']['worst_median']:.4g}{sym})"
    )
    print(f"report: {args.out}/report.md")
    return 0
