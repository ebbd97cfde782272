"""The `gearte` command line.

gearte run CONFIG.toml --out DIR [--samples N] [--seed S] [--chunk-size C] [--progress/--no-progress]
gearte compare RUN_DIR [RUN_DIR ...] --out DIR
gearte check CONFIG.toml
gearte grade --standard {1328-1:2013,1328-1:1995} --module M --diameter D [--face-width B] [--teeth Z] --grade G
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import shlex
import sys

from .. import __version__
from ..core.precision import enable_x64
from ..core.schema import ConfigError
from ..standards.iso1328 import iso1328_tolerances
from .compare import compare_runs
from .config import load_study
from .io import sigterm_as_interrupt
from .run import run_study


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {v}")
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 0 <= v < 2**63:
        raise argparse.ArgumentTypeError(f"must be in [0, 2^63), got {v}")
    return v


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gearte", description="Transmission error of gear drives from their manufacturing and assembly errors."
    )
    p.add_argument("--version", action="version", version=f"gearte {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a study file and write its results folder")
    r.add_argument("config", help="study file (TOML)")
    r.add_argument("--out", required=True, help="results folder (written atomically; replaced if it exists)")
    r.add_argument("--samples", type=_positive_int, help="number of Monte Carlo samples (overrides the file)")
    r.add_argument("--seed", type=_seed, help="random seed (overrides the file)")
    r.add_argument("--chunk-size", type=_positive_int, help="samples per compiled batch (memory bound; results do not change)")
    r.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None, help="progress bar (default: on a terminal)")
    c = sub.add_parser("compare", help="compare finished runs side by side")
    c.add_argument("runs", nargs="+", help="results folders of `gearte run`")
    c.add_argument("--out", required=True, help="folder for the comparison report")
    k = sub.add_parser("check", help="validate a study file without running it")
    k.add_argument("config")
    g = sub.add_parser("grade", help="ISO 1328 tolerances (µm) of an accuracy grade, as JSON")
    g.add_argument(
        "--standard",
        required=True,
        choices=["1328-1:2013", "1328-1:1995"],
        help="ISO 1328-1:2013 (classes 1-11) or ISO 1328-1:1995/-2:1997 = GB/T 10095 (grades 0-12)",
    )
    g.add_argument("--module", required=True, type=float, help="normal module m, mm")
    g.add_argument("--diameter", required=True, type=float, help="reference diameter d, mm")
    g.add_argument("--face-width", type=float, help="face width b, mm (needed for F_beta; F_beta is null without it)")
    g.add_argument("--teeth", type=int, help="number of teeth z (optional; range-checked only)")
    g.add_argument("--grade", required=True, type=int, help="whole accuracy grade")
    return p


def main(argv: list[str] | None = None) -> int:
    """Run the `gearte` command line; returns the exit status (2 for bad input, 130 when interrupted)."""
    args = _parser().parse_args(argv)
    # gearte's geometry needs float64; the command line turns it on before any array exists.
    enable_x64()
    try:
        with sigterm_as_interrupt():
            if args.command == "grade":
                tol = iso1328_tolerances(
                    standard=args.standard,
                    module=args.module,
                    diameter=args.diameter,
                    face_width=args.face_width,
                    grade=args.grade,
                    teeth=args.teeth,
                )
                out = {
                    "standard": args.standard,
                    "grade": args.grade,
                    "module_mm": args.module,
                    "diameter_mm": args.diameter,
                    "face_width_mm": args.face_width,
                    "unit": "um",
                }
                out.update({k: tol.get(k) for k in ("f_pt", "F_p", "F_alpha", "F_beta", "F_r")})
                print(json.dumps(out, ensure_ascii=False))
                return 0
            if args.command == "check":
                study = load_study(args.config)
                print(
                    f"{args.config}: OK ({study.name}: {type(study.drive).__name__}, {len(study.errors.specs)} error sources, "
                    f"metric {study.metric.name}, {study.samples:,} samples, seed {study.seed}"
                    + (f"; {', '.join(f'[{k}]' for k in study.kinds)}" if study.kinds else "")
                    + ")"
                )
                return 0
            if args.command == "compare":
                compare_runs(args.runs, args.out)
                print(f"comparison written to {args.out}/report.md")
                return 0
            study = load_study(args.config, samples=args.samples, seed=args.seed)
            if args.chunk_size is not None:
                study = dataclasses.replace(study, chunk_size=args.chunk_size)
            command = "gearte " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
            summary = run_study(study, args.out, progress=args.progress, command=command)
            te = summary["te"]
            sym = {"arcsec": "″", "arcmin": "′", "urad": " µrad", "pairs": " pairs"}[te["unit"]]
            print(
                f"{study.name}: {te['metric']} over {te['n']:,} samples: mean {te['mean']:.2f}{sym}, std {te['std']:.2f}{sym}, "
                f"min {te['min']:.2f}{sym}, max {te['max']:.2f}{sym}, P99.73 {te['percentiles']['99.73']:.2f}{sym}"
            )
            print(f"report: {args.out}/report.md")
            return 0
    except ConfigError as e:
        print(f"gearte: error in config: {e}", file=sys.stderr)
        return 2
    except (ValueError, FileExistsError) as e:
        print(f"gearte: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gearte: interrupted; no results were written", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
