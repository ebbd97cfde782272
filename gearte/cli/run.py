"""Run a validated study on any drive and write its results folder (summary.json, samples.npz, plots, report.md).

The flow is the same for every drive: the study kinds run first (allocation, budget, …), then
the Monte Carlo of the study's metric, the typical unit's TE trace, the drive's own outputs
(`AbstractDrive.study_outputs`), and the kinds' last steps; everything is written into a
temporary folder that replaces the results folder only when complete.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import importlib
import importlib.metadata
import math
import platform
import sys
import threading
import time
from pathlib import Path

import equinox
import jax
import numpy as np

from .. import __version__
from ..core.metrics import AbstractMetric
from ..core.units import UNIT_SYMBOLS, angle_from_rad
from ..drives.protocol import AbstractDrive, AbstractSinusoidalDrive, AbstractStudyContext, Figure, StudyOutputs
from ..studies.errors import ErrorModel, ErrorSource
from ..studies.laws import FixedPhase, Optimised
from ..studies.montecarlo import TEStudy, as_key, default_block_size, monte_carlo, statistics
from ..studies.streaming import StreamingStatistics
from .config import Study
from .io import atomic_output_dir, commit_point, write_json, written_files
from .kind_base import Finish, KindOutcome
from .kinds import STUDY_KINDS
from .run_report import report
from .samples_file import SamplesWriter


def versions() -> dict:
    """Versions of gearte and what it runs on, for summaries."""
    return {
        "gearte": __version__,
        "jax": jax.__version__,
        "equinox": equinox.__version__,
        "optimistix": importlib.metadata.version("optimistix"),
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def sample_errors(study: Study, index: int) -> dict:
    """The errors of sample `index` of `study`, regenerated from its key (one compiled program, as in the run)."""
    return _sample_jit(study.errors, as_key(study.seed), np.uint32(index))


@equinox.filter_jit
def _sample_jit(errors: ErrorModel, key, index):
    return errors.sample(jax.random.fold_in(key, index))


class RunContext(AbstractStudyContext):
    """What a drive's `study_outputs` is given: the study's settings, values and Monte Carlo."""

    def __init__(self, study: Study, values_rad: np.ndarray, outputs: dict[str, np.ndarray], progress: bool | None):
        self.study = study
        self.unit, self.seed, self.samples, self.chunk_size = study.unit, study.seed, study.samples, study.chunk_size
        self.progress, self.values_rad, self.model, self.metric = progress, values_rad, study.errors, study.metric
        self.outputs = outputs

    def monte_carlo(self, fn, *, desc: str) -> np.ndarray:
        return monte_carlo(fn, key=self.seed, n_samples=self.samples, chunk_size=self.chunk_size, progress=self.progress, desc=desc).values

    def sample_errors(self, index: int) -> dict:
        return sample_errors(self.study, index)


class _RunSample(equinox.Module):
    """One sample of a run: the study's metric and the drive's per-sample outputs, from one response."""

    study: TEStudy
    metric: AbstractMetric

    def __call__(self, key):
        errors = self.study.errors.sample(key)
        response = self.study.drive.response(errors)
        return self.metric(self.study.drive, response), self.study.drive.sample_outputs(errors, response)

    def batch(self, keys):
        """The samples of `keys` at once (see `TEStudy.batch`): a sinusoidal drive's metric on the whole batch."""
        drive = self.study.drive
        if not isinstance(drive, AbstractSinusoidalDrive):
            return jax.vmap(self)(keys)
        errors = jax.vmap(self.study.errors.sample)(keys)
        response = jax.vmap(drive.response)(errors)
        if type(drive).sample_outputs is AbstractDrive.sample_outputs:
            return self.metric(drive, response), {}
        # A drive with per-sample outputs: the metric per sample too, so that what both take from the response (the
        # harmonic drive's exact extrema) is one traced program, computed once (the same values: the metric on the
        # batch is the metric of each sample; 37 % less time per block for the harmonic example).
        return jax.vmap(lambda r: self.metric(drive, r))(response), jax.vmap(drive.sample_outputs)(errors, response)

    def bytes_per_sample(self) -> int:
        return self.study.bytes_per_sample()


def _trace_in_unit(study: Study, index: int) -> tuple[np.ndarray, np.ndarray]:
    tr = study.drive.trace(sample_errors(study, index))
    return tr.theta / (2 * math.pi), np.asarray(angle_from_rad(tr.te, study.unit))


def _plots():
    from . import plots  # matplotlib: imported when the first plot is drawn

    return plots


def _draw(figure: Figure, folder: Path) -> None:
    """Draw a declared figure: `plot` names a function of `gearte.cli.plots`, or ``"module:function"`` (a drive's
    own plots module beside it, e.g. ``"gearte.drives.cycloid_pin_plots:rotation_error"``)."""
    module, _, name = figure.plot.rpartition(":")
    fn = getattr(importlib.import_module(module) if module else _plots(), name, None)
    if fn is None:
        raise ValueError(f"figure {figure.filename}: no plot function {figure.plot!r}")
    fn(**figure.data, path=folder / figure.filename)


#: Samples above which `gearte run` times the study before starting it (`estimate_cost`), whatever the drive; a slow
#: drive's study (an equilibrium or an ODE per sample) is timed from `MEASURE_FACTOR` times the samples it times.
MEASURE_ABOVE = 1_000_000
MEASURE_FACTOR = 100
#: Estimated Monte Carlo time (s) and per-sample results (bytes) above which `gearte run` asks for --yes.
CONFIRM_SECONDS = 15 * 60
CONFIRM_BYTES = 2 * 2**30
#: Per-sample results (bytes) above which a plain study (no study kinds, no per-sample drive outputs) is
#: streamed: statistics accumulated chunk by chunk (`gearte.studies.streaming`), nothing held per sample.
HOLD_BYTES = 64 * 2**20
#: An angle metric beyond this (rad, about 2.9°) is far past the small errors every drive's model assumes (TE of arc
#: seconds to minutes): the run warns, in its output, report and summary (``warnings``).
SMALL_ANGLE_RAD = 0.05


@dataclasses.dataclass(frozen=True)
class Cost:
    """What a run will take: `bytes` of per-sample results (held in memory and written to samples.npz,
    before compression), and, when timed, `seconds` of Monte Carlo at `rate` samples per second: the study's own
    `samples` and at least `kind_samples` more that its study kinds compute (`kind_evaluations`)."""

    samples: int
    bytes: int
    seconds: float | None = None
    rate: float | None = None
    kind_samples: dict[str, int] = dataclasses.field(default_factory=dict)


def _sampler(study: Study) -> _RunSample:
    return _RunSample(TEStudy(study.drive, study.errors, metric=study.metric), study.metric)


def _phases_to_choose_held(study: Study) -> Study:
    """The study with every phase an allocation is to choose (`Optimised`) held at 0 rad: the same shapes and cost
    per sample, before the allocation has run."""
    src = study.errors.sources
    if not any(isinstance(s.phase, Optimised) for s in src.values()):
        return study
    held = {n: ErrorSource(s.magnitude, FixedPhase(0.0)) if isinstance(s.phase, Optimised) else s for n, s in src.items()}
    return dataclasses.replace(study, errors=ErrorModel(held, study.errors.specs))


def kind_evaluations(study: Study) -> dict[str, int]:
    """At least how many drive samples each study kind of `study` computes besides the study's own Monte Carlo, by
    table (`AbstractStudyKind.evaluations`)."""
    return {k.table: k.evaluations(study, study.kinds[k.table]) for k in STUDY_KINDS if k.table in study.kinds}


def evaluations(study: Study) -> int:
    """At least how many drive samples a run of `study` computes: its Monte Carlo's and its study kinds'."""
    return study.samples + sum(kind_evaluations(study).values())


def measured_samples(study: Study) -> int:
    """The samples `estimate_cost` times: two blocks (the Monte Carlo's compiled call, `default_block_size`)."""
    return 2 * default_block_size(_sampler(study).bytes_per_sample())


def timing_threshold(study: Study) -> int:
    """Samples above which `gearte run` times `study` before starting it: `MEASURE_ABOVE`, or `MEASURE_FACTOR`
    times the samples it times if fewer (a drive of large blocks is fast per sample; one of small blocks, such as
    the RV reducer's equilibria, is slow, and an hour's run of it may hold a few thousand units). The timing then
    costs at most about 1/`MEASURE_FACTOR` of the run, and its compilation is the run's own."""
    return min(MEASURE_ABOVE, MEASURE_FACTOR * measured_samples(study))


def estimate_cost(study: Study, *, measure_above: int | None = None) -> Cost:
    """Estimate a run of the study: its per-sample results' size from their shapes, and, where the run computes more
    than `measure_above` samples (default: `timing_threshold`; its own and at least its study kinds', `evaluations`),
    its time from a timed compiled call of two blocks of samples (after a first call that compiles it; a few seconds,
    more for a grid drive). The study kinds' samples are counted at the rate of the study's own (a lower bound:
    a kind's gradient costs more than a sample, and an optimiser's iterations beyond the first are not counted)."""
    fn = _sampler(_phases_to_choose_held(study))
    shapes = jax.eval_shape(fn, as_key(0))
    per = 3 * 8 + sum(int(np.prod(x.shape)) * x.dtype.itemsize for x in jax.tree.leaves(shapes[1]))  # te, te_rad, index
    nbytes = 0 if _streams(study) else per * study.samples
    kinds = kind_evaluations(study)
    total = study.samples + sum(kinds.values())
    if total <= (timing_threshold(study) if measure_above is None else measure_above):
        return Cost(study.samples, nbytes, kind_samples=kinds)
    # The smallest compiled call (two blocks), run twice: the second is timed.
    n = measured_samples(study)
    monte_carlo(fn, key=study.seed, n_samples=n, chunk_size=n, progress=False)
    t0 = time.perf_counter()
    monte_carlo(fn, key=study.seed, n_samples=n, chunk_size=n, progress=False)
    rate = n / max(time.perf_counter() - t0, 1e-9)
    return Cost(study.samples, nbytes, total / rate, rate, kinds)


def run_study(
    study: Study,
    out: str | Path,
    *,
    progress: bool | None = None,
    command: str | None = None,
    inputs: tuple[str | Path, ...] | list[str | Path] = (),
    keep_samples: bool = False,
) -> dict:
    """Run `study` and write its results folder `out` atomically. Returns the summary dict.

    `out` is checked before anything is computed (`gearte.cli.io.check_output`: never a folder holding
    files gearte did not write, nor one of `inputs`); the results are written into a temporary folder
    beside it that replaces it only when complete.
    """
    with atomic_output_dir(out, inputs=(study.source_path, *inputs)) as tmp:
        summary = _run(study, tmp, progress=progress, command=command, keep_samples=keep_samples)
        commit_point()
    return summary


def _streams(study: Study) -> bool:
    """Whether `gearte run` streams this study: a plain study (no study kinds, and a drive with neither per-sample
    outputs nor study outputs of its own) whose per-sample results would exceed `HOLD_BYTES`. Decided from the
    drive's class, without tracing the study."""
    drive = type(study.drive)
    plain = not study.kinds and drive.sample_outputs is AbstractDrive.sample_outputs and drive.study_outputs is AbstractDrive.study_outputs
    return plain and 3 * 8 * study.samples > HOLD_BYTES


def _one_value(sampler: _RunSample, study: Study, index: int, angle: bool) -> float:
    """The metric of sample `index` alone (its key regenerated), in the study's unit."""
    v, _ = equinox.filter_jit(sampler)(jax.random.fold_in(as_key(study.seed), index))
    return float(angle_from_rad(v, study.unit)) if angle else float(v)


def _monte_carlo_streamed(study: Study, sampler: _RunSample, tmp: Path, *, progress: bool | None, keep_samples: bool):
    """The study's Monte Carlo with nothing held per sample: exact n, min, max, mean and std, percentiles from a
    mergeable histogram sketch with their error bounds, a histogram for the plot, and the typical sample (the first
    sample in the sketch's bin of the median); with `keep_samples`, the values written to ``samples_te.npy`` chunk by
    chunk."""
    angle = study.metric.quantity == "angle"
    unit = study.unit if angle else "pairs"
    acc = StreamingStatistics()
    writer = SamplesWriter(tmp / "samples_te.npy", study.samples) if keep_samples else None

    def on_chunk(start: int, vals) -> None:
        te_rad, _ = vals
        v = np.asarray(angle_from_rad(te_rad, study.unit) if angle else te_rad, dtype=np.float64)
        acc.update(v)
        if writer is not None:
            writer.write(v)
        commit_point()

    block = default_block_size(sampler.bytes_per_sample())
    chunk = study.chunk_size or 64 * block
    try:
        mc = monte_carlo(
            sampler,
            key=study.seed,
            n_samples=study.samples,
            chunk_size=chunk,
            progress=progress,
            desc=study.name,
            keep=False,
            on_chunk=on_chunk,
        )
    except BaseException:
        if writer is not None:
            writer.close(complete=False)
        raise
    if writer is not None:
        writer.close()
    stats = acc.statistics(unit=unit)
    summary = {
        "method": "streamed: nothing held per sample; n, min, max, mean, std exact (blockwise, merged pairwise); "
        f"percentiles from a histogram of the values' top {acc.bits} mantissa bits, each within its stated bound",
        "percentile_error_bounds": acc.quantile_errors(),
        "typical_sample": "the first sample in the sketch bin of the median",
        "samples_file": "samples_te.npy" if keep_samples else None,
    }
    return mc, stats, acc.sample_near(stats.percentiles["50"]), summary, acc.histogram(80)


class _TraceWarmUp:
    """Loads the programs of the report's TE trace (a sinusoidal drive's: cheap) in a background thread once the
    Monte Carlo's first chunk is back, i.e. while the devices compute the others (XLA releases the GIL): the trace
    of the typical sample then runs the programs already loaded. Only a warm-up: a failure here is left to the
    real call to report."""

    def __init__(self, study: Study):
        self.study = study
        self.wanted = isinstance(study.drive, AbstractSinusoidalDrive)
        self.thread: threading.Thread | None = None

    def on_chunk(self, start: int, values) -> None:
        del start, values
        if self.thread is None:
            self.thread = threading.Thread(target=self._warm, daemon=True)
            self.thread.start()

    def _warm(self) -> None:
        try:
            self.study.drive.trace(sample_errors(self.study, 0))
        except Exception:  # a warm-up only: the real call reports any error
            pass

    def join(self) -> None:
        if self.thread is not None:
            self.thread.join()


def _writes() -> bool:
    """Whether this process writes the results: always, but in a several-process run (`jax.distributed`) only
    process 0 does (the others run into a scratch folder, `gearte.cli.main`)."""
    return jax.process_index() == 0


def _take_part(study: Study, values_rad: np.ndarray | None, outputs: dict, progress: bool | None) -> dict:
    """The rest of a run on a process that does not write (`_writes`): the drive's study outputs, which may run Monte
    Carlos over every process's devices (a streamed study has none). Not the typical unit's TE trace, the study
    kinds' finishing steps, the plots, the report or the files: process 0 alone computes and writes these, so the
    other processes neither compile their programs (JAX's compilation cache serves process 0 alone) nor draw."""
    if values_rad is not None:
        study.drive.study_outputs(RunContext(study, values_rad, outputs, progress))
    return {}


def _run(study: Study, tmp: Path, *, progress: bool | None, command: str | None, keep_samples: bool = False) -> dict:
    t_start = time.perf_counter()
    writes = _writes()
    if writes:
        # The plots' library loads in the background while the Monte Carlo computes (XLA releases the GIL).
        threading.Thread(target=importlib.import_module, args=("matplotlib.figure",), daemon=True).start()
    original = study
    outcomes: list[KindOutcome] = []
    for kind in STUDY_KINDS:
        if kind.table in study.kinds:
            outcome = kind.run(study, study.kinds[kind.table], progress=progress)
            outcomes.append(outcome)
            commit_point()  # an interrupt swallowed while compiling stops the run at the next phase
            study = outcome.study
    commit_point()
    sampler = _sampler(study)
    angle = study.metric.quantity == "angle"
    unit = study.unit if angle else "pairs"
    streamed = _streams(study)
    if streamed:
        mc, stats, typical, stream_summary, hist = _monte_carlo_streamed(study, sampler, tmp, progress=progress, keep_samples=keep_samples)
        if not writes:
            return _take_part(study, None, {}, progress)
        values = values_rad = None
        outputs: dict = {}
    else:
        warm = _TraceWarmUp(study)
        mc = monte_carlo(
            sampler,
            key=study.seed,
            n_samples=study.samples,
            chunk_size=study.chunk_size,
            progress=progress,
            desc=study.name,
            on_chunk=warm.on_chunk if warm.wanted and writes else None,
        )
        warm.join()
        values_rad, outputs = mc.values
        if not writes:
            return _take_part(study, values_rad, outputs, progress)
        values = angle_from_rad(values_rad, study.unit) if angle else values_rad
        stats = statistics(values, unit=unit)
        # A typical sample (closest to the median) for the TE trace; its draws are regenerated from its key.
        typical = int(np.argmin(np.abs(values - stats.percentiles["50"])))
        stream_summary, hist = None, None
    sym = UNIT_SYMBOLS[study.unit]
    errs = sample_errors(study, typical)
    typical_value = float(values[typical]) if values is not None else _one_value(sampler, study, typical, angle)
    tr = study.drive.trace(errs)
    te_trace = np.asarray(angle_from_rad(tr.te, study.unit))
    mx, mn = float(angle_from_rad(tr.max, study.unit)), float(angle_from_rad(tr.min, study.unit))

    summary = {
        "gearte_version": __version__,
        "study": {
            "name": study.name,
            "title": study.title,
            "description": study.description,
            "config": study.source_path,
            "command": command,
        },
        "te": stats.to_dict() | {"metric": study.metric.name},
        "samples": study.samples,
        "seed": study.seed,
        "chunk_size": mc.chunk_size,
        "block_size": mc.block_size,
        "drive": {"type": study.drive.type_name} | dict(study.drive.describe()),
        "errors": {
            name: {
                "kind": spec.kind,
                "tolerance": study.tolerances[name],
                "unit": spec.unit,
                "count": spec.count,
                "phase_symbol": spec.symbol,
                "magnitude": src.describe(spec.unit)[0],
                "phase": src.describe(spec.unit)[1],
            }
            for (name, src), spec in zip(study.errors.sources.items(), study.errors.specs.values())
        },
        "typical_sample": {
            "index": typical,
            "te": typical_value,
            "trace_input_revs": tr.span_revs,
            "max": mx,
            "min": mn,
            "theta_max_rad": tr.theta_max,
            "theta_min_rad": tr.theta_min,
        }
        # A sinusoidal drive's trace is its whole hyper-period; a grid drive's is its grid's window (its accuracy line).
        | ({"hyper_period_input_revs": tr.span_revs} if isinstance(study.drive, AbstractSinusoidalDrive) else {}),
        "assumptions": {
            "metric": study.metric.describe(),
            "random_keys": "sample i uses jax.random.fold_in(jax.random.key(seed), i); error source j of a sample uses fold_in(that key, j)",
            "precision": "float64 throughout (jax_enable_x64)",
            "accuracy": study.drive.accuracy(),
            "phases": "uniform on [0, 2π) unless a rule or fixed value is given",
            "notes": list(study.notes),
        },
        "timing_s": {"monte_carlo": mc.seconds, "total": None},
        "devices": mc.devices,
        "processes": jax.process_count(),
        "versions": versions(),
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
    }
    if stream_summary is not None:
        summary["streamed"] = stream_summary
    figures: list[Figure] = []
    for o in outcomes:
        summary[o.key] = o.summary
        figures += o.figures
    finish = Finish(values=np.asarray(values), typical=typical, trace=_trace_in_unit)
    for o in outcomes:
        if o.finish is not None:
            figures += o.finish(finish, summary)
    if original.errors is not study.errors and "allocation" not in summary:
        summary["study"]["source_rules"] = {n: s.phase.describe() for n, s in original.errors.sources.items() if s.phase is not None}

    commit_point()
    # A streamed study is a plain one (`_streams`): its drive has no study outputs of its own.
    extra = StudyOutputs() if values_rad is None else study.drive.study_outputs(RunContext(study, values_rad, outputs, progress))
    commit_point()
    clash = set(extra.summary) & set(summary)
    if clash:
        raise ValueError(f"{type(study.drive).__name__}.study_outputs: keys {sorted(clash)} are already in summary.json")
    summary.update(extra.summary)
    figures += extra.figures

    for f in figures:
        _draw(f, tmp)
    if not streamed:
        arrays = {
            "te": values,
            "te_rad": values_rad,
            "unit": unit,
            "metric": study.metric.name,
            "seed": study.seed,
            "index": np.arange(study.samples),
        } | dict(extra.arrays)
        # Stored, not compressed: per-sample values do not compress (about 5 %), and deflating them costs a second per 10⁶.
        np.savez(tmp / "samples.npz", **arrays)
    for name, content in extra.files.items():
        np.savez_compressed(tmp / name, **content)
    _plots().histogram(
        values,
        stats,
        unit=study.unit,
        metric=study.metric.label,
        title=study.title,
        path=tmp / "histogram.png",
        counts=hist,
    )
    _plots().trace(
        tr.theta / (2 * math.pi),
        te_trace,
        unit=study.unit,
        path=tmp / "trace.png",
        title=f"TE of a typical sample (#{typical}, {study.metric.name} {typical_value:.1f}{sym if angle else ''}) "
        f"over {tr.span_revs} input revolutions",
        marks=[(tr.theta_max / (2 * math.pi), mx, f"max {mx:.1f}{sym}"), (tr.theta_min / (2 * math.pi), mn, f"min {mn:.1f}{sym}")],
    )
    largest = max(abs(stats.min), abs(stats.max))
    if angle and largest / float(angle_from_rad(1.0, study.unit)) > SMALL_ANGLE_RAD:
        summary["warnings"] = [
            f"the {study.metric.name} reaches {largest:.4g}{sym}, beyond {SMALL_ANGLE_RAD:g} rad: far past the small errors "
            "the drive's model assumes; check the drive's dimensions and their units against the error magnitudes"
        ] + list(summary.get("warnings", ()))
    if jax.process_index() == 0:  # one line each for a several-process run
        for w in summary.get("warnings", ()):
            print(f"gearte: warning: {w}", file=sys.stderr)
    summary["timing_s"]["total"] = time.perf_counter() - t_start
    text = report(study, summary, errs, tr)
    for o in outcomes:
        text += "\n".join(o.report(summary))
    text += "\n".join(extra.report) + ("\n" if extra.report else "")
    if stream_summary is not None:
        bounds = ", ".join(f"P{p} ±{b:.3g}{sym if angle else ''}" for p, b in stream_summary["percentile_error_bounds"].items())
        text += (
            "\n## Streamed study\n\n"
            f"{study.samples:,} samples were summarised chunk by chunk without holding them: n, min, max, mean and std are "
            f"exact; the percentiles come from a histogram of the values' top {StreamingStatistics().bits} mantissa bits and "
            f"are each within its bound ({bounds}). The typical sample is the first one in the histogram bin of the median."
            + (
                " Every sample's value is in `samples_te.npy`."
                if stream_summary["samples_file"]
                else " No per-sample file was written (`--keep-samples` writes one)."
            )
            + "\n"
        )
    (tmp / "report.md").write_text(text, encoding="utf-8")
    summary["files"] = written_files(tmp, "summary.json")  # what gearte wrote here: a later run replaces only these
    write_json(tmp / "summary.json", summary)
    return summary
