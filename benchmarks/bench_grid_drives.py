"""Benchmark: per-unit Monte Carlo time of the grid-based drives (cycloid-pin examples) and of the harmonic example.

For each study file, `gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=study.metric), key=seed,
n_samples=N)` with the drive and error model read by `gearte.cli.config.load_study`: the first call (compilation and
run) and the steady state (best of several further calls), reported per unit. The load average is recorded at the
start and end: the machine's cores are shared, so compare results only at a similar load.

Not (yet) measured here: a plain NumPy implementation of the same per-unit computation at equal accuracy.

    python benchmarks/bench_grid_drives.py            # writes benchmarks/results/grid_drives.md and .json
    python benchmarks/bench_grid_drives.py --quick    # a smoke run with small sizes (results not written)
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT / "benchmarks"))

STUDIES = {
    "cycloid_yao2001_unmodified": 4096,
    "cycloid_yao2001_modified": 4096,
    "cycloid_yao2001_generating": 4096,
    "harmonic_liu": 50_000,
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="steady-state repeats, best taken (default 5)")
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run; results are not written")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    from bench_planetary_mc import best_of, machine_info

    import gearte
    from gearte.cli.config import load_study

    info = machine_info()
    rows = []
    for name, n in STUDIES.items():
        n = max(256, n // 16) if args.quick else n
        study = load_study(ROOT / "examples" / f"{name}.toml")
        ts = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
        t0 = time.perf_counter()
        first = gearte.monte_carlo(ts, key=study.seed, n_samples=n, progress=False)
        t_first = time.perf_counter() - t0
        steady, runs = best_of(
            lambda ts=ts, study=study, n=n: gearte.monte_carlo(ts, key=study.seed, n_samples=n, progress=False),
            2 if args.quick else args.repeats,
        )
        row = {"study": name, "metric": study.metric.name, "samples": n, "block_size": first.block_size, "first_call_s": t_first,
               "steady_s": steady, "per_unit_us": steady / n * 1e6, "runs_s": runs, "load_after": list(os.getloadavg())}  # fmt: skip
        rows.append(row)
        print(
            f"{name}: {n:,} units, first call {t_first:.2f} s, steady {steady:.3f} s = {row['per_unit_us']:.1f} µs per unit, load {os.getloadavg()[0]:.2f}"
        )
    info["load_average_at_end"] = list(os.getloadavg())
    if args.quick:
        return 0
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "grid_drives.json").write_text(json.dumps({"machine": info, "results": rows}, indent=2) + "\n", encoding="utf-8")
    lines = [
        "# Benchmark: per-unit Monte Carlo time of the grid drives",
        "",
        "`python benchmarks/bench_grid_drives.py`: `gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=…), key=seed, n_samples=N)`"
        " for each study file, steady state = best of repeated calls (compiled code reused).",
        "",
        "## Machine",
        "",
        "| | |",
        "|---|---|",
        f"| CPU | {info['cpu']} ({info['usable_cores']} usable cores of {info['cpu_count']}) |",
        f"| load average at start / end (1 min) | {info['load_average_at_start'][0]:.2f} / {info['load_average_at_end'][0]:.2f} |",
        f"| gearte commit | {info['gearte_commit']} |",
        f"| versions | gearte {info['gearte']}, JAX {info['jax']} / jaxlib {info['jaxlib']} ({info['jax_backend']}), NumPy {info['numpy']}, Python {info['python']} |",
        f"| date (UTC) | {info['date_utc']} |",
        "",
        "## Results",
        "",
        "| study | metric | units | block | first call | steady state | per unit | load after |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| `examples/{r['study']}.toml` | {r['metric']} | {r['samples']:,} | {r['block_size']} | {r['first_call_s']:.2f} s | "
            f"{r['steady_s']:.3f} s | {r['per_unit_us']:.1f} µs | {r['load_after'][0]:.2f} |"
        )
    lines += ["", "Runs (s): " + "; ".join(f"{r['study']}: " + ", ".join(f"{x:.3f}" for x in r["runs_s"]) for r in rows), ""]
    (RESULTS / "grid_drives.md").write_text("\n".join(lines), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
