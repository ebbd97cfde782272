"""The RV budget on the fine grid: `examples/rv_robot_joint_budget.toml` takes its metrics on 9 output angles; this
checks a budget run's tolerances on the 97-angle grid of the tolerance study (docs/rv.md, "Tolerance budget").

1. The budget's tolerances (from the run's summary.json) on `--units` fresh units at 97 angles × 2 loads: the yield of
   all three constraints (lost motion, TE p-p forward and reverse ≤ 1′) and of each, P99.73 and the maximum.
2. The cheapest uniform scaling of the nominal tolerances that meets the three constraints on that grid, calibrated
   as gearte's budget calibrates (each constraint's quantile at the target + 4 binomial standard errors, at most
   1 − 1/n, within its spec) on `--units` fresh units, by bisection in log scale to 1 %; then verified on as many
   other fresh units.

Not a speed benchmark: it checks a result, and prints one line per step. The Monte Carlo runs on every local device
(set XLA_FLAGS=--xla_force_host_platform_device_count=N for one per CPU core, as the `gearte` command does).

    gearte run examples/rv_robot_joint_budget.toml --out out/rv_budget
    XLA_FLAGS=--xla_force_host_platform_device_count=2 python benchmarks/rv_budget_fine_grid.py out/rv_budget/summary.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARCMIN_PER_RAD = 60 * 180 / math.pi
METRICS = ("lost_motion", "peak_to_peak", "peak_to_peak_reverse")


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("summary", type=Path, help="summary.json of a `gearte run` of examples/rv_robot_joint_budget.toml")
    ap.add_argument("--units", type=int, default=2000, help="fresh units per check (default 2000)")
    ap.add_argument("--points", type=int, default=97, help="output angles of the fine grid (default 97)")
    args = ap.parse_args()

    import tempfile

    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import gearte
    from gearte.cli.budget_kind import _scaled_study
    from gearte.cli.config import load_study
    from gearte.cli.run import _RunSample

    budget = json.loads(args.summary.read_text())["budget"]
    text = (ROOT / "examples" / "rv_robot_joint_budget.toml").read_text(encoding="utf-8")
    fine = text.replace("points = 9 ", f"points = {args.points} ").replace("trace_points = 18", f"trace_points = {4 * args.points}")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rv_budget_fine.toml"
        path.write_text(fine, encoding="utf-8")
        study = load_study(path)
    assert getattr(study.drive, "points", None) == args.points, "the example's grid line changed: update this script"
    spec = study.kinds["budget"]
    n = args.units
    quantile = min(0.9973 + 4 * math.sqrt(0.9973 * 0.0027 / n), 1 - 1 / n)
    t0 = time.perf_counter()

    def run(tolerances: dict, key: int) -> dict:
        s = _scaled_study(study, spec, tolerances)
        fn = _RunSample(gearte.TEStudy(s.drive, s.errors, metric=s.metric), s.metric)
        lm, out = gearte.monte_carlo(fn, key=key, n_samples=n, progress=False).values
        v = {
            "lost_motion": np.asarray(lm),
            "peak_to_peak": np.asarray(out["te_pp"]),
            "peak_to_peak_reverse": np.asarray(out["te_pp_reverse"]),
        }
        solved = np.asarray(out["solved"])
        # A unit with a failed solve counts as missing every spec (as gearte's budget counts it for a yield).
        return {k: np.where(solved < 1.0, 1e3, x * ARCMIN_PER_RAD) for k, x in v.items()} | {"solved": solved}

    def describe(label: str, v: dict, key: int) -> str:
        every = np.logical_and.reduce([v[m] <= 1.0 for m in METRICS])
        parts = [f"{m} yield {np.mean(v[m] <= 1.0):.4f}, P99.73 {np.percentile(v[m], 99.73):.3f}′, max {v[m].max():.3f}′" for m in METRICS]
        return (
            f"{label}: {n:,} fresh units (key {key}), {args.points} angles × 2 loads: yield of all three {every.mean():.4f}; "
            + "; ".join(parts)
            + f"; share of solves that succeeded {v['solved'].mean():.6f}; {time.perf_counter() - t0:.0f} s"
        )

    print(describe(f"budget's tolerances (cost {budget['cost']:.4f})", run(budget["tolerances_um"], 4242), 4242), flush=True)

    def scaled(scale: float) -> dict:
        return {k: scale * v for k, v in spec.nominal.items()}

    def ok(v: dict) -> bool:
        return all(np.quantile(v[m], quantile) <= 1.0 for m in METRICS)

    lo, hi = 0.6, round(float(budget["baseline_scale"]), 4)  # from 0.6 up to the 9-angle grid's uniform scaling
    if not ok(run(scaled(lo), 97001)):
        print(f"uniform scaling × {lo} misses the constraints on {args.points} angles: widen the search")
        return
    while math.log(hi / lo) > 0.01:
        mid = math.sqrt(lo * hi)
        good = ok(run(scaled(mid), 97001))
        print(
            f"uniform scaling × {mid:.4f}: {'meets' if good else 'misses'} the calibration ({time.perf_counter() - t0:.0f} s)", flush=True
        )
        lo, hi = (mid, hi) if good else (lo, mid)
    cost = sum(float(c(lo * spec.nominal[k])) for k, c in spec.costs.items())
    print(
        describe(
            f"uniform scaling × {lo:.4f} of the nominal tolerances (cost {cost:.4f}), calibrated on key 97001",
            run(scaled(lo), 97002),
            97002,
        )
    )


if __name__ == "__main__":
    main()
