"""Benchmark: per-unit Monte Carlo time of the grid-based drives (cycloid-pin examples) and of the harmonic example,
against a plain NumPy implementation of the cycloid-pin computation at equal accuracy, in the same run.

For each study file, `gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=study.metric), key=seed,
n_samples=N)` with the drive and error model read by `gearte.cli.config.load_study`: the first call (compilation and
run) and the steady state (best of several further calls), reported per unit, in wall-clock time and in CPU time of
the process (all threads). For the cycloid-pin studies, `NumpyCycloid` below computes the same lost motion in plain
NumPy (float64, vectorised over units × input angles × pins, the error-free contact and the sines of the shared angles
once per drive, the derivatives of the Newton steps written out), on the same units' errors (drawn by gearte; their
drawing is not timed), checked against gearte's values; best chunk of units of those tried. NumPy runs on one thread,
gearte on every core: the CPU-time ratio compares the work, the wall-clock ratio what a user waits. The load average
is recorded: the machine's cores are shared, so compare results only at a similar load.

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
    "cycloid_yao2001_unmodified": 16_384,
    "cycloid_yao2001_modified": 16_384,
    "cycloid_yao2001_generating": 16_384,
    "harmonic_liu": 50_000,
}
#: Units of the NumPy baseline per study, and the chunks of units it is tried with (the best is reported).
NUMPY_UNITS = 1024
NUMPY_CHUNKS = (16, 32, 64)


#: The profile of the cycloid-pin solve (measured while developing it; appended to the results).
PROFILE = """## Profile (cycloid-pin, `examples/cycloid_yao2001_modified.toml`, blocks of 128 units)

Measured on the same machine (2 shared cores, load average 5–9 while measuring: CPU time of the process, all
threads, is the steadier figure; the XLA cost analysis is exact). Op times: `jax.profiler` trace of the jitted block,
summed by fusion kind.

| | 3.4–4.2 ms version | previous (0.22–0.30 ms at load 2) | now |
|---|---|---|---|
| XLA cost analysis per unit: flops | 1.4 M | 2.87 M | 1.96 M |
| XLA cost analysis per unit: transcendental calls | 122,000 | 13,900 | 13,900 |
| XLA cost analysis per unit: bytes accessed | | 5.25 MB | 4.51 MB |
| CPU per unit, same load, interleaved runs (4,096 units) | | 400–410 µs | 202–211 µs |
| wall per unit, same runs (load 5.3–5.7) | | 474–554 µs | 277–282 µs |

Where the time went in the previous version: 33 % in `pad` fusions and 26 % in YNNPACK reductions, i.e. the
stored stages (`materialise` was a maximum with −∞: each stage written into an array twice its size, then reduced);
the rest spread over many small fusions. Changes, each measured by the cost analysis and CPU time at the same load:

1. The derivatives of the Newton steps written out as jets (`_locus`: f, f′, f″ by the product and quotient rules)
   in place of nested `jax.jvp` through angle-addition formulas: 2.87 → 2.31 M flops.
2. Stages stored through a `fori_loop` of zero trips (its operands are never fused into consumers) in place of the
   maximum with −∞: 5.42 → 4.51 MB accessed, CPU 398 → 240 µs per unit at load 9.
3. The sines of the flank angles (t in [0, π]) by unreduced series (`_trig`): 2.44 → 1.96 M flops, 240 → 199 µs.

Tried and not kept: the first Newton step taken at the error-free contact in place of the chord step in cos t
(1.93 M flops, no measurable gain); blocks of 64 / 128 / 256 / 512 units: 188 / 166 / 343 / 383 µs CPU per unit
(128 kept: the larger blocks leave the cache); storing the generating deviation or its gathered per-space values
(no gain: the generating example stays about 2.5× the form-ground ones, its cost spread over the jets of e_n(φ)).
Now no fusion kind takes more than about 10 % of the time; the zero-trip loops and their copies about 15 %.

**`gearte run` (per-sample outputs included).** The Monte Carlo of `gearte run` also computes each unit's report vector
(an analysis at the report's input angle with its normal clearances): 2.08 M flops and 229 µs CPU per unit against
1.96 M and 184 µs for the metric alone (218 µs without the normal clearances: the normal-clearance search is about
5 % and was left as it is). `gearte run examples/cycloid_yao2001_modified.toml --samples N --out DIR --yes`, compiled
code cached, N = 4,000 and 20,000: Monte Carlo 4.8–6.1 s and 10.0–10.7 s, 0.29–0.33 ms per additional unit at load
5.5; the whole run 20–28 s, most of it the reference reducer's analysis, the sensitivities and the plots.
"""


# ---------------------------------------------------------------- the NumPy baseline


# Second-order jets (value, d/dt, d²/dt²) for the Newton steps: the derivatives written out, no autodiff.
def _jmul(a, b):
    return a[0] * b[0], a[0] * b[1] + a[1] * b[0], a[0] * b[2] + 2.0 * a[1] * b[1] + a[2] * b[0]


def _jdiv(a, b):
    q0 = a[0] / b[0]
    q1 = (a[1] - q0 * b[1]) / b[0]
    return q0, q1, (a[2] - 2.0 * q1 * b[1] - q0 * b[2]) / b[0]


def _jlin(*terms):
    """Σ c_k a_k of jets a_k and plain (broadcastable) coefficients c_k."""
    return tuple(sum(c * a[i] for c, a in terms) for i in range(3))


class NumpyCycloid:
    """The contact solve and lost motion of `gearte.drives.cycloid_pin_solve`, written in plain NumPy.

    Vectorised over units × input angles × pins (float64 throughout): the error-free contact and the sines and
    cosines of the shared angles once per drive, then per chunk of units the same steps as gearte (one chord step in
    cos t, two steps to the root of the local quadratic model in t with the derivatives written out, the final
    evaluation and arctangent); `np.sin`/`np.cos`/`np.arctan2` for the rest.
    """

    def __init__(self, drive):
        import numpy as np

        self.np = np
        zb, za = drive.z_pins, drive.z_lobes
        self.zb, self.za, self.flank_errors = zb, za, drive.process.flank_errors
        self.R, self.a = float(drive.pin_circle_radius), float(drive.eccentricity)
        self.r = float(drive.pin_radius)
        self.RZ, self.rZ = float(drive.wheel_pin_circle_radius), float(drive.wheel_pin_radius)
        self.m = float(drive.modification.rotation)
        self.K = self.a * zb / self.RZ
        th = np.asarray(drive.input_angles(), dtype=float)
        self.theta = th
        j = np.arange(zb)
        psi = th[:, None] + j * (2 * np.pi / zb)  # (P, J)
        self.sn, self.cn = np.sin(psi), np.cos(psi)
        glob = psi - j * 2 * np.pi
        w = glob / (2 * np.pi) + 1e-9
        k = np.floor(w + 0.5)
        self.side = np.where(w - k >= 0.0, 1.0, -1.0)
        self.phi = glob - k * 2 * np.pi
        self.space = np.mod(k.astype(np.int64), za)
        self.st, self.ct = np.sin(-th * (zb / za))[:, None], np.cos(-th * (zb / za))[:, None]
        # The error-free contact's cos t* (Newton in c on the even part, as gearte's `nominal_cosine`).
        R, a = self.R, self.a
        rho2 = R * R + a * a - 2 * R * a * np.cos(self.phi)
        d = self.rZ - self.r
        c = np.cos(self.phi)
        for _ in range(8):
            val, der = self._even(d, c)
            c = np.clip(c - (val - rho2) / np.where(der < 0, der, -1.0), -1.0, 1.0)
        self.c0 = c
        self.t0 = np.arccos(c)
        self.trig0 = self._trig(self.t0)
        self.trig_0 = self._trig(np.zeros_like(c))
        self.trig_pi = self._trig(np.full_like(c, np.pi))

    def _even(self, d, c):
        """|X|² = A² + B² − 2ABc at cos t = c and its derivative in c (d: per unit, broadcast)."""
        np, K = self.np, self.K
        S = np.sqrt(1.0 + K * K - 2.0 * K * c)
        S3 = S * S * S
        A, B = self.RZ - d / S, self.a - d * K / S
        dA, dB = -d * K / S3, -d * K * K / S3
        return A * A + B * B - 2.0 * A * B * c, 2.0 * (A * dA + B * dB) - 2.0 * (dA * B + A * dB) * c - 2.0 * A * B

    def _trig(self, t):
        np = self.np
        u, v = t / self.za, t * (self.zb / self.za)
        return np.sin(u), np.cos(u), np.sin(v), np.cos(v)

    def _locus_jet(self, g, trig, order):
        """X + W (mm) as jets in t of the given order (0: values only; 2: value, first and second derivative)."""
        np = self.np
        s = self.side
        su, cu, sv, cv = trig
        su, sv = s * su, s * sv
        wu, wv = 1.0 / self.za, self.zb / self.za
        if order == 0:
            Su, Cu, Sv, Cv = (su, 0, 0), (cu, 0, 0), (sv, 0, 0), (cv, 0, 0)
        else:
            Su = (su, s * wu * cu, -wu * wu * su)
            Cu = (cu, -s * wu * su, -wu * wu * cu)
            Sv = (sv, s * wv * cv, -wv * wv * sv)
            Cv = (cv, -s * wv * sv, -wv * wv * cv)
        K, RZ, a = self.K, self.RZ, self.a
        cphi = cu * cv + su * sv
        sphi = sv * cu - cv * su
        S2 = 1.0 + K * K - 2.0 * K * cphi
        S = np.sqrt(S2)
        if order == 0:
            Cp, Sp, Sj = (cphi, 0, 0), (sphi, 0, 0), (S, 0, 0)
        else:
            Cp = (cphi, -s * sphi, -cphi)  # cos φ = cos t
            Sp = (sphi, s * cphi, -sphi)  # sin φ = s sin t
            S1 = K * s * sphi / S
            Sj = (S, S1, (K * cphi - S1 * S1) / S)
        d = (g["d"], 0, 0)
        if self.flank_errors:
            eps_c = _jlin((g["chain_cos"], Sp), (g["chain_sin"], Cp))
            delta_p = _jlin(
                (g["pitch_sin"] * g["pitch"], Cu), (g["pitch_cos"] * g["pitch"], Su), (-g["pitch_sin"] * g["pitch"], (1.0, 0, 0))
            )
            inner = _jlin((a, eps_c), (a * self.za, delta_p))
            num = _jlin(
                (g["slide"], (1.0, 0, 0)), (-g["slide"] * K, Cp), (-g["across"] * K, Sp), (-g["crank"], Cp), (g["crank"] * K, (1.0, 0, 0))
            )
            num = _jlin((1.0, num), (-1.0, _jmul(inner, Sp)))
            dn = _jdiv(num, Sj)
            d = (g["d"] - dn[0] + g["wheel"], -dn[1], -dn[2])
        nx = _jdiv(_jlin((1.0, Su), (-K, Sv)), Sj)
        ny = _jdiv(_jlin((1.0, Cu), (-K, Cv)), Sj)
        dnx, dny = _jmul(d, nx), _jmul(d, ny)
        x = _jlin((RZ, Su), (-a, Sv), (-1.0, dnx))
        y = _jlin((RZ, Cu), (-a, Cv), (-1.0, dny))
        return (x[0] + g["wx"], x[1], x[2]), (y[0] + g["wy"], y[1], y[2])

    def _f(self, g, trig, order=0):
        x, y = self._locus_jet(g, trig, order)
        f = _jlin((1.0, _jmul(x, x)), (1.0, _jmul(y, y)))
        return (f[0] - g["rho2"], f[1], f[2]), x, y

    def geometry(self, e, um=1e-3):
        """Per unit (leading axis), angle and pin: the pin centres, the offsets W, |C|², the factor F, d."""
        np = self.np
        za, th = self.za, self.theta
        U = e["pin_radius"].shape[0]
        R1 = self.R + e["pin_circle_radius"] * um  # (U,)
        se, ce = np.sin(e["pin_tangential"] * um / R1[:, None]), np.cos(e["pin_tangential"] * um / R1[:, None])  # (U, J)
        rad = R1[:, None] + e["pin_radial"] * um
        A1 = self.a + e["eccentricity"] * um
        pe = e["pin_circle_eccentricity_phase"][:, None] + th  # (U, P)
        obx = (
            (e["pin_wheel_offset"] * np.cos(e["pin_wheel_offset_phase"]))[:, None]
            + e["pin_circle_eccentricity"][:, None] * np.cos(pe)
            - (e["disc_offset"] * np.cos(e["disc_offset_phase"]))[:, None]
        )
        oby = (
            (e["pin_wheel_offset"] * np.sin(e["pin_wheel_offset_phase"]))[:, None]
            + e["pin_circle_eccentricity"][:, None] * np.sin(pe)
            - (e["disc_offset"] * np.sin(e["disc_offset_phase"]))[:, None]
        )
        obx, oby = obx[:, :, None] * um, oby[:, :, None] * um - A1[:, None, None]
        sn, cn = self.sn[None], self.cn[None]
        rad, se, ce = rad[:, None, :], se[:, None, :], ce[:, None, :]
        cx = obx - rad * (sn * ce + cn * se)
        cy = oby + rad * (cn * ce - sn * se)
        beta = np.arange(za) * (2 * np.pi / za) + e["index_offset"][:, None] + e["indexing"]  # (U, za)
        g = {}
        ex = (e["setup_eccentricity"] * np.cos(e["setup_phase"]) + e["mandrel_runout"] * np.cos(e["mandrel_phase"])) * um
        ey = (e["setup_eccentricity"] * np.sin(e["setup_phase"]) + e["mandrel_runout"] * np.sin(e["mandrel_phase"])) * um
        n = self.space
        if self.flank_errors:
            beta = beta + e["pitch_accumulated"][:, None] * np.sin(np.arange(za) * (2 * np.pi / za) + e["pitch_accumulated_phase"][:, None])
            dx, dy = 0.0, np.zeros((U, za))
            pa = np.arange(za) * (2 * np.pi / za) + e["pitch_accumulated_phase"][:, None]
            g["slide"] = ((e["dressing_y"][:, None] + e["infeed"]) * um)[:, n]
            g["across"] = (e["dressing_x"] * um)[:, None, None]
            g["wheel"] = (e["wheel_radius"] * um)[:, None, None]
            g["crank"] = (e["generating_eccentricity"] * um)[:, None, None]
            g["chain_cos"] = (e["generating_chain"] * np.cos(e["generating_chain_phase"]))[:, None, None]
            g["chain_sin"] = (e["generating_chain"] * np.sin(e["generating_chain_phase"]))[:, None, None]
            g["pitch"] = e["pitch_accumulated"][:, None, None]
            g["pitch_sin"], g["pitch_cos"] = np.sin(pa)[:, n], np.cos(pa)[:, n]
        else:
            dx, dy = (e["dressing_x"] * um)[:, None], (e["dressing_y"][:, None] + e["infeed"]) * um
        sb, cb = np.sin(beta), np.cos(beta)
        vx = dx - (cb * ex[:, None] - sb * ey[:, None])
        vy = dy - (sb * ex[:, None] + cb * ey[:, None])
        vx, vy, sb, cb = vx[:, n], vy[:, n], sb[:, n], cb[:, n]
        sm, cm = self.side * np.sin(self.m), np.cos(self.m)
        g["wx"], g["wy"] = cm * vx - sm * vy, sm * vx + cm * vy
        rx, ry = cb * cm - sb * sm, sb * cm + cb * sm
        rx, ry = rx * self.ct - ry * self.st, rx * self.st + ry * self.ct
        g["rho2"] = cx * cx + cy * cy
        g["fx"], g["fy"] = cx * rx - cy * ry, cx * ry + cy * rx
        g["d"] = (self.rZ - (self.r + e["pin_radius"] * um))[:, None, None]
        return g

    def rotations(self, e):
        """Rotation to contact (rad), reachable, interference and converged of every unit, angle and pin."""
        np = self.np
        g = self.geometry(e)
        interference = self._f(g, self.trig_0)[0][0] > 0.0
        reachable = self._f(g, self.trig_pi)[0][0] >= 0.0
        f0 = self._f(g, self.trig0)[0][0]
        slope = self._even(g["d"], self.c0)[1]
        c1 = np.clip(self.c0 - f0 / np.where(slope < 0, slope, -1.0), -1.0, 1.0)
        t = np.arccos(c1)
        lo = np.where(f0 <= 0, self.t0, 0.0)
        hi = np.where(f0 > 0, self.t0, np.pi)
        for _ in range(2):
            (val, d1, d2), _, _ = self._f(g, self._trig(t), 2)
            lo = np.where(val <= 0, np.maximum(lo, t), lo)
            hi = np.where(val > 0, np.minimum(hi, t), hi)
            disc = d1 * d1 - 2.0 * val * d2
            sq = np.sqrt(np.maximum(disc, 0.0))
            den = np.where(d1 >= 0, d1 + sq, d2)
            num = np.where(d1 >= 0, -2.0 * val, sq - d1)
            with np.errstate(divide="ignore", invalid="ignore"):
                step = np.where(disc >= 0, num / np.where(den != 0, den, 1.0), -val / np.where(d1 != 0, d1, 1.0))
            tn = t + step
            inside = ((tn >= lo) & (tn <= hi)) | (np.abs(step) <= 1e-6)
            tn = np.where(inside & np.isfinite(tn), tn, 0.5 * (lo + hi))
            t = np.where(val == 0, t, tn)
        t = np.where(interference, 0.0, np.where(reachable, t, np.pi))
        _, x, y = self._f(g, self._trig(t), 0)
        x, y = x[0], y[0]
        rot = np.arctan2(g["fy"] * x - g["fx"] * y, g["fx"] * x + g["fy"] * y)
        resid = np.abs(np.sqrt(x * x + y * y) - np.sqrt(g["rho2"]))
        converged = (resid < 1e-9) | ~reachable | interference
        return rot, reachable, interference, converged

    def lost_motion(self, e):
        """The lost motion's maximum over the input-angle grid (rad) of every unit (the `lost_motion` metric)."""
        np = self.np
        rot, reachable, _, _ = self.rotations(e)
        drive_side = self.side > 0
        fwd = np.where(drive_side & reachable, rot, np.inf).min(axis=-1)
        rev = np.where(~drive_side & reachable, rot, -np.inf).max(axis=-1)
        return (fwd - rev).max(axis=-1)


# ---------------------------------------------------------------- the runs


def _timed(fn, repeats: int) -> tuple[float, float, list[float]]:
    """(best wall s, best CPU s of the process, all wall times) of `repeats` calls."""
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus), walls


def numpy_baseline(study, values, *, units: int, repeats: int, chunks=NUMPY_CHUNKS) -> dict:
    """The NumPy lost motion of the study's first `units` units: agreement with gearte's `values` and per-unit times."""
    import jax
    import numpy as np

    from gearte.drives.cycloid_pin_geometry import checked_errors
    from gearte.studies.montecarlo import sample_keys

    drive = study.drive
    keys = sample_keys(jax.random.PRNGKey(study.seed) if isinstance(study.seed, int) else study.seed, 0, units)
    errs = jax.jit(jax.vmap(lambda k: checked_errors(drive, study.errors.sample(k))))(keys)
    e = {f: np.asarray(getattr(errs, f), dtype=float) for f in type(errs).__dataclass_fields__}
    base = NumpyCycloid(drive)
    ref = np.asarray(values)[:units]
    got = np.concatenate([base.lost_motion({k: v[i : i + 64] for k, v in e.items()}) for i in range(0, units, 64)])
    out = {"units": units, "max_abs_diff_rad": float(np.max(np.abs(got - ref))), "chunks": {}}
    for chunk in chunks:

        def run(chunk=chunk):
            for i in range(0, units, chunk):
                base.lost_motion({k: v[i : i + chunk] for k, v in e.items()})

        wall, cpu, _ = _timed(run, repeats)
        out["chunks"][chunk] = {"wall_us": wall / units * 1e6, "cpu_us": cpu / units * 1e6}
    best = min(out["chunks"], key=lambda c: out["chunks"][c]["wall_us"])
    out["best_chunk"] = best
    out["per_unit_us"] = out["chunks"][best]["wall_us"]
    out["per_unit_cpu_us"] = out["chunks"][best]["cpu_us"]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5, help="steady-state repeats, best taken (default 5)")
    ap.add_argument("--quick", action="store_true", help="small sizes for a smoke run; results are not written")
    args = ap.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    from bench_planetary_mc import machine_info

    import gearte
    from gearte.cli.config import load_study

    info = machine_info()
    rows = []
    for name, n in STUDIES.items():
        n = max(256, n // 64) if args.quick else n
        study = load_study(ROOT / "examples" / f"{name}.toml")
        ts = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
        t0 = time.perf_counter()
        first = gearte.monte_carlo(ts, key=study.seed, n_samples=n, progress=False)
        t_first = time.perf_counter() - t0
        steady, cpu, runs = _timed(
            lambda ts=ts, study=study, n=n: gearte.monte_carlo(ts, key=study.seed, n_samples=n, progress=False),
            2 if args.quick else args.repeats,
        )
        row = {"study": name, "metric": study.metric.name, "samples": n, "block_size": first.block_size, "first_call_s": t_first,
               "steady_s": steady, "per_unit_us": steady / n * 1e6, "per_unit_cpu_us": cpu / n * 1e6, "runs_s": runs,
               "load_after": list(os.getloadavg())}  # fmt: skip
        msg = f"{name}: {n:,} units, first call {t_first:.2f} s, steady {steady:.3f} s = {row['per_unit_us']:.1f} µs per unit ({row['per_unit_cpu_us']:.1f} µs CPU)"
        if study.drive.type_name == "cycloid_pin":
            units = 64 if args.quick else NUMPY_UNITS
            npb = numpy_baseline(
                study, first.values, units=units, repeats=1 if args.quick else 3, chunks=(32,) if args.quick else NUMPY_CHUNKS
            )
            if not npb["max_abs_diff_rad"] < 1e-9:
                raise SystemExit(f"{name}: the NumPy baseline differs from gearte by {npb['max_abs_diff_rad']:.3g} rad")
            row["numpy"] = npb
            row["speedup_wall"] = npb["per_unit_us"] / row["per_unit_us"]
            row["speedup_cpu"] = npb["per_unit_cpu_us"] / row["per_unit_cpu_us"]
            msg += (
                f"; NumPy {npb['per_unit_us']:.1f} µs per unit (chunk {npb['best_chunk']}, agrees to {npb['max_abs_diff_rad']:.1e} rad):"
                f" {row['speedup_wall']:.1f}x wall, {row['speedup_cpu']:.1f}x CPU"
            )
        rows.append(row)
        print(msg + f", load {os.getloadavg()[0]:.2f}")
    info["load_average_at_end"] = list(os.getloadavg())
    if args.quick:
        return 0
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "grid_drives.json").write_text(json.dumps({"machine": info, "results": rows}, indent=2) + "\n", encoding="utf-8")
    lines = [
        "# Benchmark: per-unit Monte Carlo time of the grid drives",
        "",
        "`python benchmarks/bench_grid_drives.py`: `gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=…), key=seed, n_samples=N)`"
        " for each study file, steady state = best of repeated calls (compiled code reused); for the cycloid-pin studies the"
        " same lost motion in plain NumPy (`NumpyCycloid` in the script: float64, vectorised over units × angles × pins, the"
        " same solve with its derivatives written out) on the first units' errors, checked against gearte's values.",
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
        "Per unit: wall-clock time (CPU time of the process, all threads, in brackets).",
        "",
        "| study | metric | units | block | first call | steady state | per unit | NumPy per unit (units, chunk) | NumPy − gearte | speed-up wall / CPU | load after |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "numpy" in r:
            b = r["numpy"]
            np_cols = (f"{b['per_unit_us']:.1f} µs ({b['per_unit_cpu_us']:.1f}) ({b['units']:,}, {b['best_chunk']}) | "
                       f"{b['max_abs_diff_rad']:.1e} rad | {r['speedup_wall']:.1f}× / {r['speedup_cpu']:.1f}×")  # fmt: skip
        else:
            np_cols = "– | – | –"
        lines.append(
            f"| `examples/{r['study']}.toml` | {r['metric']} | {r['samples']:,} | {r['block_size']} | {r['first_call_s']:.2f} s | "
            f"{r['steady_s']:.3f} s | {r['per_unit_us']:.1f} µs ({r['per_unit_cpu_us']:.1f}) | {np_cols} | {r['load_after'][0]:.2f} |"
        )
    lines += ["", "Runs (s): " + "; ".join(f"{r['study']}: " + ", ".join(f"{x:.3f}" for x in r["runs_s"]) for r in rows), "", PROFILE]
    (RESULTS / "grid_drives.md").write_text("\n".join(lines), encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
