"""Benchmark: gearte's exact extrema on signals that test its certificate, against the same algorithm in NumPy.

`gearte.extrema` grids the signal at 16 points per period of its fastest order, refines the best blocks in float64
and continues, round after round, until a rigorous bound shows that no other block can hold more. One round settles
a planetary of small tooth counts; a fast order of large amplitude (large coprime tooth counts) leaves tens of humps
within the bound of the maximum, and many orders make a large compiled search. Measured, in one run:

1. **Drives** (`gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=gearte.Peak()))`, the random-assembly study
   `examples/planetary_wang2013_random.toml` with its tooth counts as given and changed to coprime ones): the first
   call (compilation and run) and the steady state (best of repeats), per sample.
2. **Signals** (random coefficients, normal, on the orders given): `gearte.extrema` on a batch, first call and
   steady state. Each is checked against a dense NumPy grid of 32 points per period of the fastest order: a grid value above gearte's maximum (or below its
   minimum) would be a missed extremum; the largest such excess, relative to the span, is reported (≤ 0).
3. **NumPy baseline**: the same algorithm without its certificate (the best two blocks per direction, two Newton
   steps, vectorised; the tables of cos kτᵢ, sin kτᵢ computed once, not timed), per signal, and its largest error
   against gearte, relative to the span: without the certificate it misses the extremum of near-tied signals.

Writes `benchmarks/results/extrema.md` and `extrema.json` and prints the tables.

    python benchmarks/bench_extrema.py            # the full benchmark (a few minutes)
    python benchmarks/bench_extrema.py --quick    # a smoke run with small sizes (results not written)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import tomllib
from fractions import Fraction
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
sys.path.insert(0, str(ROOT / "benchmarks"))
STUDY = ROOT / "examples" / "planetary_wang2013_random.toml"

#: (label, tooth counts sun/planet/ring, samples): the example's, and coprime ones of the same layout.
DRIVES = [
    ("planetary 12/36/84 (the example)", (12, 36, 84), 50_000),
    ("planetary 31/23/77 (coprime)", (31, 23, 77), 20_000),
    ("planetary 41/37/115 (coprime)", (41, 37, 115), 5_000),
]
#: (label, orders, signals): random coefficients, every order of unit standard deviation.
SIGNALS = [
    ("3 orders to 2,387 (the 31/23/77 drive's)", (713, 1771, 2387), 2_000),
    ("16 orders to 16,384", tuple(int(k) for k in np.linspace(1, 16_384, 16)), 256),
    ("orders 1 and 65,536", (1, 65_536), 16),
]


def drive_study(teeth: tuple[int, int, int], samples: int):
    import gearte

    raw = tomllib.loads(STUDY.read_text(encoding="utf-8"))
    raw["drive"].update(z_sun=teeth[0], z_planet=teeth[1], z_ring=teeth[2])
    return gearte.build_study(raw, str(STUDY), samples=samples)


def dense_excess(c0, a, b, orders, e_max, e_min) -> float:
    """Largest grid value above gearte's maximum (or below its minimum), relative to the span: > 0 is a miss."""
    m = 32 * max(orders)
    kt = (np.outer(np.asarray(orders, dtype=np.int64), np.arange(m, dtype=np.int64)) % m) * (2 * math.pi / m)
    basis = np.concatenate([np.cos(kt), np.sin(kt)])
    worst = -np.inf
    rows = max(1, 2**24 // (8 * m))
    for s0 in range(0, len(c0), rows):
        sl = slice(s0, s0 + rows)
        g = c0[sl, None] + np.concatenate([a[sl], b[sl]], axis=1) @ basis
        span = g.max(axis=1) - g.min(axis=1)
        worst = max(worst, float(np.max((g.max(axis=1) - e_max[sl]) / span)), float(np.max((e_min[sl] - g.min(axis=1)) / span)))
    return worst


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="steady-state repeats, best taken (default 3)")
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run; results are not written")
    args = ap.parse_args(argv)
    scale = 0.02 if args.quick else 1.0

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    from bench_planetary_mc import best_of, machine_info, refined_extrema

    import gearte
    from gearte.core.signal import TESignal

    info = machine_info()
    print(f"{info['cpu']}, {info['usable_cores']} usable cores; gearte {info['gearte']}, JAX {info['jax']}")
    drives, signals = [], []

    for label, teeth, samples in DRIVES:
        n = max(64, int(samples * scale))
        study = drive_study(teeth, n)
        ts = gearte.TEStudy(study.drive, study.errors, metric=gearte.Peak())
        orders = study.drive.signal(study.drive.zero_errors()).orders
        t0 = time.perf_counter()
        gearte.monte_carlo(ts, key=study.seed, n_samples=n, progress=False)
        first = time.perf_counter() - t0
        steady = best_of(lambda ts=ts, n=n, seed=study.seed: gearte.monte_carlo(ts, key=seed, n_samples=n, progress=False), args.repeats)[0]
        row = {"case": label, "orders": list(orders), "samples": n, "first_s": first, "steady_s": steady, "per_sample_us": 1e6 * steady / n}
        drives.append(row)
        print(
            f"{label}: orders {orders}, {n:,} samples: first call {first:.2f} s, steady {steady:.3f} s ({row['per_sample_us']:.1f} µs per sample)"
        )

    rng = np.random.default_rng(20261129)
    for label, orders, count in SIGNALS:
        n = max(4, int(count * scale))
        a, b, c0 = rng.normal(size=(n, len(orders))), rng.normal(size=(n, len(orders))), rng.normal(size=n)
        sig = TESignal(offset=jnp.asarray(c0), cos_coef=jnp.asarray(a), sin_coef=jnp.asarray(b), orders=orders, fundamental=Fraction(1))
        t0 = time.perf_counter()
        e = jax.block_until_ready(gearte.extrema(sig))
        first = time.perf_counter() - t0
        steady = best_of(lambda sig=sig: jax.block_until_ready(gearte.extrema(sig)), args.repeats)[0]
        e_max, e_min = np.asarray(e.max), np.asarray(e.min)
        excess = dense_excess(c0, a, b, orders, e_max, e_min)
        t0 = time.perf_counter()
        n_max, n_min = refined_extrema(c0, a, b, orders)
        t_numpy = time.perf_counter() - t0
        span = e_max - e_min
        numpy_error = float(np.max(np.maximum(e_max - n_max, n_min - e_min) / span))
        row = {
            "case": label,
            "orders": len(orders),
            "highest_order": max(orders),
            "signals": n,
            "first_s": first,
            "steady_s": steady,
            "per_signal_ms": 1e3 * steady / n,
            "dense_grid_excess": excess,
            "numpy_per_signal_ms": 1e3 * t_numpy / n,
            "numpy_max_error": numpy_error,
        }
        signals.append(row)
        print(
            f"{label}: {n:,} signals: first call {first:.2f} s, steady {steady:.3f} s ({row['per_signal_ms']:.3f} ms per signal), "
            f"dense-grid excess {excess:.1e}; NumPy {row['numpy_per_signal_ms']:.3f} ms per signal, error {numpy_error:.1e}"
        )
        if excess > 1e-12:
            raise RuntimeError(f"{label}: a dense grid found more than gearte's extremum ({excess:.2e} of the span)")

    if args.quick:
        print("(--quick: results not written)")
        return 0
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "extrema.json").write_text(
        json.dumps({"machine": info, "drives": drives, "signals": signals}, indent=2) + "\n", encoding="utf-8"
    )
    lines = [
        "# Benchmark: exact extrema on signals that test the certificate",
        "",
        "`python benchmarks/bench_extrema.py`; what is measured is described in the script's docstring and in `benchmarks/README.md`.",
        "",
        f"Machine: {info['cpu']} ({info['usable_cores']} usable cores), load average at start {info['load_average_at_start']}; "
        f"gearte {info['gearte']} at {info['gearte_commit']}, JAX {info['jax']}, NumPy {info['numpy']}; {info['date_utc']}.",
        "",
        "## Monte Carlo of a planetary drive (random assembly, peak |Δθ|), one CPU device",
        "",
        "| drive | orders | samples | first call | steady state | per sample |",
        "|---|---|---|---|---|---|",
    ]
    for r in drives:
        lines.append(
            f"| {r['case']} | {', '.join(f'{k:,}' for k in r['orders'])} | {r['samples']:,} | {r['first_s']:.2f} s | {r['steady_s']:.3f} s "
            f"| {r['per_sample_us']:.1f} µs |"
        )
    lines += [
        "",
        "## `gearte.extrema` on random signals, against the same algorithm in NumPy without its certificate",
        "",
        "| signals | count | first call | steady state | per signal | dense grid above gearte | NumPy per signal | NumPy's largest error |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in signals:
        lines.append(
            f"| {r['case']} | {r['signals']:,} | {r['first_s']:.2f} s | {r['steady_s']:.3f} s | {r['per_signal_ms']:.3f} ms "
            f"| {r['dense_grid_excess']:.1e} of the span | {r['numpy_per_signal_ms']:.3f} ms | {r['numpy_max_error']:.1e} of the span |"
        )
    lines += [
        "",
        'A dense grid\'s value can never exceed the true maximum: "dense grid above gearte" ≤ 0 means that gearte missed',
        "no extremum the grid sees. The NumPy baseline stops after its two best blocks: its error is what the",
        "certificate's later rounds find.",
        "",
    ]
    (RESULTS / "extrema.md").write_text("\n".join(lines), encoding="utf-8")
    print(f"wrote {RESULTS / 'extrema.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
