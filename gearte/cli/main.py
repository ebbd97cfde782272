"""The `gearte` command line.

gearte run CONFIG.toml --out DIR [--samples N] [--seed S] [--chunk-size C] [--progress/--no-progress] [--yes]
gearte compare RUN_DIR [RUN_DIR ...] --out DIR
gearte check CONFIG.toml [--samples N] [--seed S] [--chunk-size C]
gearte identify STUDY.toml RECORD.csv --out DIR
gearte assemble PARTS.csv --study STUDY.toml --out DIR
gearte grade --standard {1328-1:2013,1328-1:1995} --module M --diameter D [--face-width B] [--teeth Z] --grade G
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import os
import re
import shlex
import signal
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from .. import __version__
from ..core.cache import cache_wanted, enable_compilation_cache
from ..core.schema import ConfigError, OptionError
from .io import OutputError, check_output, deferred_interrupts, interrupt_received, reset_interrupts, sigterm_as_interrupt

if TYPE_CHECKING:
    from .config import Study

# The parser and the file's first checks import neither JAX nor matplotlib: `gearte --help` and a
# `gearte check` of a broken file answer at once. The modules that compute are imported by the
# commands that need them (and are reachable here as attributes, e.g. `main.run_study`).
_LAZY = {
    "CONFIRM_BYTES": ".run",
    "CONFIRM_SECONDS": ".run",
    "estimate_cost": ".run",
    "evaluations": ".run",
    "timing_threshold": ".run",
    "run_study": ".run",
    "compare_runs": ".compare",
    "load_study": ".config",
    "check_file": ".config",
    "iso1328_tolerances": "..standards.iso1328",
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(_import(_LAZY[name]), name)
    globals()[name] = value
    return value


def _import(module: str):
    """Import a module of gearte (relative to this one). An interrupt meanwhile is remembered, and raised once the
    import is complete: raised inside an extension's initialisation it would come out as another error, or worse."""
    with deferred_interrupts():
        return importlib.import_module(module, __package__)


def _lazy(name: str) -> Any:
    """`name` of this module: what a test put there, else the lazily imported one."""
    return globals()[name] if name in globals() else __getattr__(name)


class _Parser(argparse.ArgumentParser):
    """argparse's parser with its errors in one line, as every other gearte error (argparse prints the usage first)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _whole(text: str) -> int:
    """A whole number written in ASCII digits (Python's `int` also takes other scripts' digits and `1_000`)."""
    if not re.fullmatch(r"\s*[+-]?[0-9]+\s*", text):
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}")
    return int(text)


def _length_mm(text: str) -> float:
    """A length in mm written as an ASCII decimal number (Python's `float` also takes `1_0` and other scripts' digits)."""
    number = r"([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?|nan|inf|infinity"  # nan and inf: the check below names them
    if not re.fullmatch(rf"\s*[+-]?({number})\s*", text, flags=re.IGNORECASE):
        raise argparse.ArgumentTypeError(f"expected a number of mm, got {text!r}")
    return float(text)


def _positive_int(text: str) -> int:
    v = _whole(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be ≥ 1, got {v}")
    return v


def _seed(text: str) -> int:
    v = _whole(text)
    if not 0 <= v < 2**63:
        raise argparse.ArgumentTypeError(f"must be in [0, 2^63), got {v}")
    return v


def _overrides(p: argparse.ArgumentParser) -> None:
    p.add_argument("--samples", type=_positive_int, help="number of Monte Carlo samples (overrides the file)")
    p.add_argument("--seed", type=_seed, help="random seed (overrides the file)")
    p.add_argument("--chunk-size", type=_positive_int, help="samples between progress updates (results do not change)")


def _study(args) -> Study:
    study = _lazy("load_study")(args.config, samples=args.samples, seed=args.seed)
    if args.chunk_size is not None:
        study = dataclasses.replace(study, chunk_size=args.chunk_size)
    return study


def _size(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    if s < 2 * 86400:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.1f} days"


def _confirm(args, study: Study) -> None:
    """Estimate a large run before starting it; refuse one above the thresholds without --yes."""
    threshold = _lazy("timing_threshold")(study)
    if _lazy("evaluations")(study) <= threshold:
        return  # small enough to start at once (and not worth tracing the study twice)
    cost = _lazy("estimate_cost")(study, measure_above=threshold)
    if cost.seconds is None:
        return
    where = f"--samples {study.samples:,}" if args.samples is not None else f"{args.config}: [study] samples = {study.samples:,}"
    kinds = {t: n for t, n in cost.kind_samples.items() if n}
    counted = (
        f" ({study.samples:,} samples of the study's own and at least " + ", ".join(f"{n:,} of [{t}]" for t, n in kinds.items()) + ")"
        if kinds
        else ""
    )
    what = (
        f"about {_duration(cost.seconds)} of Monte Carlo at {cost.rate:,.0f} samples/s on this machine{counted}, and "
        f"{_size(cost.bytes)} of per-sample results held in memory and written to samples.npz"
        if cost.bytes
        else f"about {_duration(cost.seconds)} of Monte Carlo at {cost.rate:,.0f} samples/s on this machine{counted}, streamed "
        "(nothing held per sample)"
    )
    if cost.seconds > _lazy("CONFIRM_SECONDS") or cost.bytes > _lazy("CONFIRM_BYTES"):
        if not args.yes:
            fewer = (
                "give fewer samples"
                if sum(kinds.values()) <= study.samples
                else f"give fewer samples in {', '.join(f'[{t}]' for t in kinds)} (they count most)"
            )
            raise OutputError(f"{where}: {what}; add --yes to run it anyway, or {fewer}")
    print(f"gearte: {where}: {what}", file=sys.stderr)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="gearte", description="Transmission error of gear drives from their manufacturing and assembly errors.")
    p.add_argument("--version", action="version", version=f"gearte {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run a study file and write its results folder")
    r.add_argument("config", help="study file (TOML)")
    r.add_argument(
        "--out",
        required=True,
        help="results folder: new, empty, or an earlier gearte result (replaced atomically); a folder with other files is refused",
    )
    _overrides(r)
    r.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None, help="progress bar (default: on a terminal)")
    r.add_argument("--yes", action="store_true", help="run even when the estimated time or size is large (asked above 15 min or 2 GiB)")
    r.add_argument(
        "--compile-cache",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="keep compiled programs on disk for the next run (default: on; folder: $GEARTE_CACHE_DIR, else "
        "$XDG_CACHE_HOME/gearte/jax, else ~/.cache/gearte/jax; GEARTE_COMPILATION_CACHE=0 also turns it off)",
    )
    r.add_argument(
        "--keep-samples",
        action="store_true",
        help="a study streamed for its size (statistics accumulated chunk by chunk) also writes every sample's value to "
        "samples_te.npy, chunk by chunk; smaller studies always write samples.npz",
    )
    d = r.add_argument_group(
        "several machines (jax.distributed)",
        "every process runs the same command; each computes its share of the samples, process 0 writes the results",
    )
    d.add_argument("--processes", type=_positive_int, help="number of processes (with --process-id and --coordinator)")
    d.add_argument("--process-id", type=_whole, help="this process's number, 0 … processes − 1")
    d.add_argument("--coordinator", help="HOST:PORT of process 0's coordination service")
    d.add_argument(
        "--cluster", action="store_true", help="take processes, ids and coordinator from the cluster scheduler's environment (e.g. SLURM)"
    )
    c = sub.add_parser("compare", help="compare finished runs side by side")
    c.add_argument("runs", nargs="+", help="results folders of `gearte run`")
    c.add_argument("--out", required=True, help="folder for the comparison report (not one of the runs)")
    k = sub.add_parser("check", help="validate a study file without running it (every check `run` makes before computing)")
    k.add_argument("config")
    _overrides(k)
    g = sub.add_parser("grade", help="ISO 1328 tolerances (µm) of an accuracy grade, as JSON")
    g.add_argument(
        "--standard",
        required=True,
        choices=["1328-1:2013", "1328-1:1995"],
        help="ISO 1328-1:2013 (classes 1-11) or ISO 1328-1:1995/-2:1997 = GB/T 10095 (grades 0-12)",
    )
    g.add_argument("--module", required=True, type=_length_mm, help="normal module m, mm")
    g.add_argument("--diameter", required=True, type=_length_mm, help="reference diameter d, mm")
    g.add_argument("--face-width", type=_length_mm, help="face width b, mm (needed for F_beta; F_beta is null without it)")
    g.add_argument("--teeth", type=_whole, help="number of teeth z (optional; range-checked only)")
    g.add_argument("--grade", required=True, type=_whole, help="whole accuracy grade")
    _identify_parsers(sub)
    return p


def _identify_parsers(sub) -> None:
    """Register `identify` and `assemble` on the command line's sub-parsers."""
    p = sub.add_parser("identify", help="identify a drive's errors from a measured TE record (CSV or NPZ)")
    p.add_argument("config", help="study file (TOML) of the drive")
    p.add_argument("record", help="measured record: CSV or NPZ (see docs/identification.md)")
    p.add_argument("--out", required=True, help="results folder (new, empty, or an earlier gearte result)")
    p.add_argument(
        "--unit", action="append", default=[], metavar="QUANTITY=UNIT", help="unit of a column named without one, e.g. te=arcsec"
    )
    p.add_argument("--input-rpm", type=float, help="input speed, rpm (needed with a time column)")
    p.add_argument("--ratio", type=float, help="transmission ratio (default: the drive's)")
    p.add_argument("--adjust", default="", help="comma-separated sources to turn at re-assembly (any angle), e.g. sun_manufacturing")
    p.add_argument("--fit", default="", help="grid drives: comma-separated sources to identify (default: all; the others stay at zero)")
    p.add_argument("--seed", type=_whole, default=0, help="seed of the optimiser's starts")
    a = sub.add_parser("assemble", help="selective assembly of a batch of measured parts")
    a.add_argument("parts", help="CSV of parts: source,magnitude_um,phase_rad (or phase_deg), one row per part")
    a.add_argument("--study", required=True, help="study file (TOML) of the drive")
    a.add_argument("--out", required=True, help="results folder (new, empty, or an earlier gearte result)")
    a.add_argument("--seed", type=_whole, default=0, help="seed of the random start and of the random assemblies")
    a.add_argument("--random-batches", type=_positive_int, default=100, help="random assemblies of the same parts for the comparison (≥ 1)")


def _interrupted(done: bool) -> int:
    signum = interrupt_received() or getattr(sys.exc_info()[1], "signum", None) or signal.SIGINT
    what = "after the command had finished" if done else "no results were written; an earlier result is untouched"
    print(f"gearte: interrupted ({signal.Signals(signum).name}); {what}", file=sys.stderr)
    return 128 + signum


def main(argv: list[str] | None = None) -> int:
    """Run the `gearte` command line; returns the exit status (2 for bad input, 128 + the signal when
    interrupted: 130 for Ctrl-C, 143 for SIGTERM)."""
    reset_interrupts()
    done = False
    try:
        with sigterm_as_interrupt():
            status = _main(argv)
            done = True
            if interrupt_received() is not None:
                raise KeyboardInterrupt
            return status
    except OptionError as e:  # an option or environment variable, not the file
        print(f"gearte: error: {e}", file=sys.stderr)
        return 2
    except ConfigError as e:
        print(f"gearte: error in config: {e}", file=sys.stderr)
        return 2
    except ValueError as e:  # OutputError and the library's argument checks
        print(f"gearte: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"gearte: error: {e.filename or ''}{': ' if e.filename else ''}{e.strerror or e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return _interrupted(done)
    except Exception as e:
        # An interrupt raised inside a compiled extension (e.g. while a module is imported) can come out as
        # another exception; the signal was remembered, so it is reported as what it is.
        if interrupt_received() is not None:
            return _interrupted(done)
        if _out_of_memory(e):
            print(
                "gearte: error: out of memory: the study holds more than this machine has; reduce its sample counts "
                "(--samples, [study] samples, or the samples of its [budget], [allocation], [sensitivity] or [doe] table) "
                "or the size of its model (the grid, slice or face counts of its [drive] tables)",
                file=sys.stderr,
            )
            return 2
        raise
    finally:
        reset_interrupts()


def _out_of_memory(e: BaseException) -> bool:
    """Whether `e` is Python's or XLA's out-of-memory error (XLA's comes as a runtime error: RESOURCE_EXHAUSTED, or
    INTERNAL with "Out of memory allocating" where the CPU runtime fails to allocate a buffer)."""
    if isinstance(e, MemoryError):
        return True
    text = str(e)
    return type(e).__name__ in ("JaxRuntimeError", "XlaRuntimeError") and ("RESOURCE_EXHAUSTED" in text or "Out of memory" in text)


def _distributed(args) -> None:
    """Join the processes of a several-machine run (`jax.distributed`), before JAX computes anything."""
    given = [getattr(args, k, None) is not None for k in ("processes", "process_id", "coordinator")]
    cluster = getattr(args, "cluster", False)
    if not any(given) and not cluster:
        return
    if cluster and any(given):
        raise OptionError(
            "--cluster takes the processes from the scheduler: give it alone, or give --processes, --process-id and --coordinator"
        )
    if not cluster and not all(given):
        raise OptionError("several processes need all three of --processes, --process-id and --coordinator (HOST:PORT)")
    if not cluster and not 0 <= args.process_id < args.processes:
        raise OptionError(f"--process-id must be in 0 … {args.processes - 1}, got {args.process_id}")
    if not cluster and (":" not in args.coordinator or not args.coordinator.rpartition(":")[2].isdigit()):
        raise OptionError(f"--coordinator must be HOST:PORT, got {args.coordinator!r}")
    import jax

    # CPU devices of different processes talk through gloo (GPUs use their own collectives).
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if cluster:
        try:
            jax.distributed.initialize()
        except ValueError as e:  # no scheduler's environment to read (JAX: "coordinator_address should be defined")
            raise OptionError(
                f"--cluster: no cluster scheduler's environment found ({e}); run the command under the scheduler "
                "(e.g. srun under SLURM), or give --processes, --process-id and --coordinator"
            ) from None
    else:
        jax.distributed.initialize(coordinator_address=args.coordinator, num_processes=args.processes, process_id=args.process_id)


def _cores_as_devices() -> None:
    """On a CPU, one XLA device per usable core (`GEARTE_CPU_DEVICES=N` to choose): the Monte Carlo shards its
    blocks over them (the results are bit-identical for any device count). Only before JAX is imported, and
    only if `XLA_FLAGS` does not already set the count."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "jax" in sys.modules or "xla_force_host_platform_device_count" in flags:
        return
    wanted = os.environ.get("GEARTE_CPU_DEVICES", "").strip()
    if wanted:
        if not re.fullmatch(r"[0-9]+", wanted) or int(wanted) < 1:
            raise OptionError(f"GEARTE_CPU_DEVICES: a whole number ≥ 1 of CPU devices, got {wanted!r}")
        count = int(wanted)
    else:
        count = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if count > 1:
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={count}".strip()


def _setup_jax(args) -> None:
    """What a computing command sets up first: CPU devices, float64, and the persistent compilation cache."""
    _cores_as_devices()
    if args.command == "run":
        _distributed(args)
    enable_x64 = _import("..core.precision").enable_x64
    if args.command != "grade":
        for module in ("..drives.registry", "..studies.montecarlo", ".kinds"):  # what building a study imports
            _import(module)
    # gearte's geometry needs float64; the command line turns it on before any array exists.
    enable_x64()
    if args.command != "grade" and getattr(args, "compile_cache", True) and cache_wanted():
        enable_compilation_cache()  # a second run of a study compiles nothing (gearte.core.cache)
        # An unreadable or unwritable cache entry only means compiling again: not the user's concern.
        warnings.filterwarnings("ignore", message=r"Error (reading|writing) persistent compilation cache entry")


def _main(argv: list[str] | None) -> int:
    args = _parser().parse_args(argv)
    several = args.command == "run" and (getattr(args, "cluster", False) or getattr(args, "processes", None) is not None)
    if args.command == "check" or several:
        # The file's own checks first, without JAX: a broken file is named at once (and, in a several-process run,
        # before joining the other processes, which would wait for this one).
        _lazy("check_file")(args.config, samples=args.samples, seed=args.seed)
    if several:
        check_output(args.out, inputs=[args.config])
    _setup_jax(args)
    if args.command == "grade":
        tol = _lazy("iso1328_tolerances")(
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
        study = _study(args)
        print(
            f"{args.config}: OK ({study.name}: {type(study.drive).__name__}, {len(study.errors.specs)} error sources, "
            f"metric {study.metric.name}, {study.samples:,} samples, seed {study.seed}"
            + (f"; {', '.join(f'[{k}]' for k in study.kinds)}" if study.kinds else "")
            + ")"
        )
        return 0
    if args.command in ("identify", "assemble"):
        identify_cmd = _import(".identify_cmd")
        command = "gearte " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
        return (identify_cmd.run_identify if args.command == "identify" else identify_cmd.run_assemble)(args, command)
    if args.command == "compare":
        _lazy("compare_runs")(args.runs, args.out)
        print(f"comparison written to {args.out}/report.md")
        return 0
    study = _study(args)
    check_output(args.out, inputs=[args.config])  # before anything is computed
    _confirm(args, study)
    command = "gearte " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    import jax

    if jax.process_index() != 0:
        # Another process of a several-machine run: it computes its share; process 0 writes the results.
        import tempfile

        with tempfile.TemporaryDirectory(prefix="gearte-process-") as scratch:
            _lazy("run_study")(study, Path(scratch) / "out", progress=False, command=command, keep_samples=False)
        return 0
    summary = _lazy("run_study")(
        study, args.out, progress=args.progress, command=command, inputs=[args.config], keep_samples=args.keep_samples
    )
    te = summary["te"]
    sym = {"arcsec": "″", "arcmin": "′", "urad": " µrad", "pairs": " pairs"}[te["unit"]]
    print(
        f"{study.name}: {te['metric']} over {te['n']:,} samples: mean {te['mean']:.2f}{sym}, std {te['std']:.2f}{sym}, "
        f"min {te['min']:.2f}{sym}, max {te['max']:.2f}{sym}, P99.73 {te['percentiles']['99.73']:.2f}{sym}"
    )
    print(f"report: {args.out}/report.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
