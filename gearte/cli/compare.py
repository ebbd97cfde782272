"""``gearte compare``: finished runs side by side (statistics table, overlaid histograms).

Runs are compared on what they share: one metric (the runs may be of different drives, and
angles in different units are converted to the first run's unit). Every run folder is read
defensively: a file, a damaged `summary.json` or `samples.npz`, or a missing field is refused
with a message naming the file; `samples.npz` is read without pickles.
"""

from __future__ import annotations

import json
import math
import zipfile
from pathlib import Path

import numpy as np

from .. import __version__
from ..core.units import ANGLE_UNITS, UNIT_SYMBOLS, angle_from_rad, number_text
from . import plots
from .io import OutputError, atomic_output_dir, check_output, write_json, written_files

#: The fields of a run's summary.json that a comparison reads (dotted paths).
_FIELDS = (
    "study.name",
    "study.title",
    "te.unit",
    "te.metric",
    "te.n",
    "te.min",
    "te.max",
    "te.mean",
    "te.std",
    "te.percentiles.99.73",
)


class RunFolderError(ValueError):
    """A folder given to `gearte compare` is not a readable finished run."""


def _fmt(x: float) -> str:
    return number_text(x, ".2f")


def _field(summary: dict, dotted: str, file: Path):
    # Percentile keys contain a dot ("99.73"): walk the known prefix, then take the rest as one key.
    head, _, rest = dotted.partition(".")
    v = summary.get(head) if isinstance(summary, dict) else None
    if rest.startswith("percentiles."):
        v = v.get("percentiles") if isinstance(v, dict) else None
        rest = rest.removeprefix("percentiles.")
    if isinstance(v, dict) and rest:
        v = v.get(rest)
    if v is None:
        raise RunFolderError(f"{file}: missing `{dotted}`; not a summary written by `gearte run` (run the study again)")
    if dotted.startswith("te.") and dotted not in ("te.unit", "te.metric"):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise RunFolderError(f"{file}: `{dotted}` must be a finite number, got {v!r}")
    elif dotted in ("study.name", "study.title", "te.unit", "te.metric") and not isinstance(v, str):
        raise RunFolderError(f"{file}: `{dotted}` must be a string, got {v!r}")
    return v


def read_run(folder: str | Path) -> tuple[dict, np.ndarray, np.ndarray | None]:
    """A finished run's summary, its per-sample values (`te`, in the summary's unit) and `te_rad` (None if absent)."""
    d = Path(folder)
    if not d.exists():
        raise RunFolderError(f"{d}: no such folder; give the results folder of a `gearte run`")
    if not d.is_dir():
        raise RunFolderError(f"{d}: a file, not a results folder; give the folder that `gearte run --out` wrote")
    sj = d / "summary.json"
    if not sj.is_file():
        if (d / "comparison.json").is_file():
            raise RunFolderError(f"{d}: a comparison, not a run; compare the run folders it compared")
        raise RunFolderError(f"{d}: not a finished gearte run (no summary.json); run `gearte run` first")
    try:
        summary = json.loads(sj.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise RunFolderError(f"{sj}: not UTF-8 text; the file is damaged (run the study again)") from None
    except json.JSONDecodeError as e:
        raise RunFolderError(
            f"{sj}: not valid JSON ({e.msg}, line {e.lineno} column {e.colno}); the file is damaged (run the study again)"
        ) from None
    except OSError as e:
        raise RunFolderError(f"{sj}: cannot read ({e.strerror})") from None
    if not isinstance(summary, dict):
        raise RunFolderError(f"{sj}: expected a JSON object, got {type(summary).__name__}; not a summary written by `gearte run`")
    for f in _FIELDS:
        _field(summary, f, sj)
    npz = d / "samples.npz"
    if not npz.is_file():
        if "streamed" in summary:
            kept = d / "samples_te.npy"  # a streamed run's values, written chunk by chunk with --keep-samples
            if kept.is_file():
                return summary, _kept_samples(kept, summary["te"]["n"]), None
            raise RunFolderError(
                f"{d}: a streamed run (statistics accumulated chunk by chunk) without its samples; run it with "
                "--keep-samples to compare it (its statistics are in its summary.json and report.md)"
            )
        raise RunFolderError(f"{d}: not a finished gearte run (no samples.npz); run `gearte run` first")
    damaged = f"{npz}: cannot be read as a NumPy .npz archive of numbers; the file is damaged (run the study again)"
    try:
        z = np.load(npz, allow_pickle=False)  # never pickles: a results folder may come from anywhere
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        raise RunFolderError(damaged) from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise RunFolderError(damaged)
    with z:
        if "te" not in z.files:
            raise RunFolderError(f"{npz}: has no `te` array; not written by `gearte run` (run the study again)")
        try:
            te = np.asarray(z["te"])
            te_rad = np.asarray(z["te_rad"]) if "te_rad" in z.files else None
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile):
            raise RunFolderError(damaged) from None
    n = summary["te"]["n"]
    for name, arr in (("te", te), ("te_rad", te_rad)):
        if arr is None:
            continue
        if arr.dtype.kind not in "fiu" or arr.shape != (n,) or not np.all(np.isfinite(arr)):
            raise RunFolderError(
                f"{npz}: `{name}` must hold {n:,} finite numbers (te.n of summary.json), got {arr.dtype} of shape {arr.shape}"
            )
    return summary, te.astype(float), None if te_rad is None else te_rad.astype(float)


def _kept_samples(path: Path, n: int) -> np.ndarray:
    """The TE of every sample of a streamed run kept with --keep-samples (``samples_te.npy``, the study's unit)."""
    try:
        te = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError):
        raise RunFolderError(f"{path}: cannot be read as a NumPy .npy array; the file is damaged (run the study again)") from None
    if te.dtype.kind not in "fiu" or te.shape != (n,):
        raise RunFolderError(f"{path}: must hold {n:,} numbers (te.n of summary.json), got {te.dtype} of shape {te.shape}")
    values = np.asarray(te, dtype=float)
    if not np.all(np.isfinite(values)):
        raise RunFolderError(f"{path}: holds values that are not finite; the file is damaged (run the study again)")
    return values


def compare_runs(run_dirs: list[str | Path], out: str | Path) -> dict:
    """Compare finished runs: a table of their statistics and overlaid histograms, written atomically to `out`.

    The runs must share one metric; they may be of different drives, and angles in different units are
    shown in the first run's unit. `out` is refused when it is, holds or lies inside one of the runs, and when it
    holds another run (a comparison replaces only a comparison or an empty folder of gearte's).
    """
    resolved = check_output(out, inputs=run_dirs)
    if (resolved / "summary.json").is_file():
        raise OutputError(
            f"--out {out}: holds a gearte run (summary.json, samples); a comparison would replace it: "
            "choose another folder for the comparison"
        )
    runs = [(Path(d), *read_run(d)) for d in run_dirs]
    metrics = {r[1]["te"]["metric"] for r in runs}
    if len(metrics) > 1:
        listed = ", ".join(f"{r[1]['te']['metric']} ({r[0]})" for r in runs)
        raise RunFolderError(f"the runs measure different metrics: {listed}; compare runs of one metric ([study] metric)")
    metric = metrics.pop()
    unit = runs[0][1]["te"]["unit"]
    units = {r[1]["te"]["unit"] for r in runs}
    if len(units) > 1 and not all(u in ANGLE_UNITS for u in units):
        raise RunFolderError(f"the runs are in units {sorted(units)} that cannot be converted into each other; compare like with like")
    drives = sorted({str((r[1].get("drive") or {}).get("type", "?")) for r in runs})
    sym = UNIT_SYMBOLS.get(unit, f" {unit}")
    rows, series = [], []
    base = None
    for d, summ, te_values, te_rad in runs:
        te = summ["te"]
        u = te["unit"]
        if u == unit:
            conv, values = 1.0, te_values
        else:  # another angle unit: through rad
            conv = float(angle_from_rad(1.0, unit)) / float(angle_from_rad(1.0, u))
            values = np.asarray(angle_from_rad(te_rad, unit)) if te_rad is not None else te_values * conv
        if base is None:
            base = te["mean"] * conv
        rows.append(
            {
                "run": str(d),
                "name": summ["study"]["name"],
                "title": summ["study"]["title"],
                "drive": str((summ.get("drive") or {}).get("type", "?")),
                "n": te["n"],
                "min": te["min"] * conv,
                "max": te["max"] * conv,
                "mean": te["mean"] * conv,
                "std": te["std"] * conv,
                "p99.73": te["percentiles"]["99.73"] * conv,
                "mean_vs_first": te["mean"] * conv / base if base else float("nan"),
            }
        )
        series.append((summ["study"]["title"], values))
    result = {"gearte_version": __version__, "unit": unit, "metric": metric, "drives": drives, "runs": rows}
    with atomic_output_dir(out, inputs=run_dirs) as tmp:
        plots.overlay_histograms(series, unit=unit, metric=metric, path=tmp / "overlay.png")
        plots.grid_of_histograms(series, unit=unit, metric=metric, path=tmp / "histograms.png")
        lines = [
            "# Comparison of TE studies",
            "",
            f"Metric: {metric}; unit {unit} ({sym.strip()}).",
            "",
        ]
        if len(drives) > 1:
            lines += [f"The runs are of different drives ({', '.join(drives)}); they are compared on the metric they share.", ""]
        if len(units) > 1:
            lines += [f"Runs in other units ({', '.join(sorted(units - {unit}))}) are converted to {unit}.", ""]
        lines += [
            "| study | drive | n | min | max | mean | std | P99.73 | mean / first |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r['title']} (`{r['run']}`) | {r['drive']} | {r['n']:,} | {_fmt(r['min'])} | {_fmt(r['max'])} | {_fmt(r['mean'])} | "
                f"{_fmt(r['std'])} | {_fmt(r['p99.73'])} | {r['mean_vs_first']:.3f} |"
            )
        lines += [
            "",
            "![overlaid histograms](overlay.png)",
            "",
            "![histograms side by side](histograms.png)",
            "",
            "Each study's own report (assumptions, drive, error laws) is `report.md` in its folder.",
            "",
        ]
        (tmp / "report.md").write_text("\n".join(lines), encoding="utf-8")
        result["files"] = written_files(tmp, "comparison.json")
        write_json(tmp / "comparison.json", result)
    return result
