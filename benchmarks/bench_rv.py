"""Benchmark: RV (K-H-V) equilibrium solves, gearte against SciPy on the same contact potential, in the same run.

The example `examples/rv_robot_joint.toml` (3 cranks, 2 discs, 40 pins, 97 output angles × 2 load directions):

- **gearte, one unit**: `RVKHV.response` of one Monte Carlo unit's errors (the 194 solves, warm-started along the
  grid), first call and best of further calls; per solve;
- **gearte, Monte Carlo**: `gearte.monte_carlo(gearte.TEStudy(drive, errors, metric=...), n_samples=N)`, per unit and
  per solve (the solves of a batch run one after another: see docs/rv.md);
- **SciPy**: the same `ContactSystem` of every angle of that unit, minimised one solve at a time by
  `scipy.optimize.minimize(method="trust-exact")` with the potential, its gradient and its (generalised) Hessian in
  NumPy, each solve started as gearte starts it (the previous angle's solution in gearte's order, `solve_order`,
  every body's translation turned by the output's turn between the two angles), gradient tolerance 1e-10 of the
  load or the force residual's rounding level at the start where that is larger (a preloaded unit's contact forces
  exceed the small load by orders of magnitude, and no solver gets its residual below their rounding), then the
  same rigid-limit step q − H⁻¹ f; its TE is checked against gearte's;
- **the target's study**: the same Monte Carlo at 360 output angles (720 solves per unit), in a fresh interpreter with
  one CPU device and with one per usable core (`XLA_FLAGS=--xla_force_host_platform_device_count=N`, as the `gearte`
  command sets it up), per unit after a warm-up, and the time 10,000 units would take at that rate.

    python benchmarks/bench_rv.py            # writes benchmarks/results/rv.md and .json
    python benchmarks/bench_rv.py --quick    # a smoke run with small sizes (results not written)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def numpy_system(s):
    import numpy as np

    return {k: np.asarray(getattr(s, k)) for k in ("G", "e", "k", "B", "eb", "c", "kb", "f", "mu")} | {"faces": s.faces}


def scipy_solve(s, q0=None, *, gtol_rel: float = 1e-10) -> tuple:
    """Minimise the contact potential of one system with SciPy from `q0` (default: the nominal position); the gradient
    tolerance is `gtol_rel` × the largest load term, or the rounding level of the force residual at `q0` where that
    is larger (64 machine epsilons of its largest term, gearte's own stopping level: see `rounding_level`). Returns
    (q, q_rigid, iterations, success)."""
    import numpy as np
    from scipy.optimize import minimize

    from gearte.drives.rv_khv_equilibrium import face_normals

    N = face_normals(s["faces"])
    G, e, k, B, eb, c, kb, f, mu = (s[x] for x in ("G", "e", "k", "B", "eb", "c", "kb", "f", "mu"))
    poly = c > 0

    def parts(q):
        p = G @ q + e
        r = np.einsum("bin,n->bi", B, q) + eb
        P = r @ N.T - c[:, None]
        return p, r, P

    def fun(q):
        p, r, P = parts(q)
        pos = np.maximum(P, 0.0)
        eb_ = 0.5 * kb * np.where(poly, np.sum(pos * pos, axis=-1), np.sum(r * r, axis=-1))
        return 0.5 * np.sum(k * np.maximum(p, 0.0) ** 2) + np.sum(eb_) + 0.5 * mu * q @ q - f @ q

    def jac(q):
        p, r, P = parts(q)
        force = kb[:, None] * np.where(poly[:, None], np.maximum(P, 0.0) @ N, r)
        return G.T @ (k * np.maximum(p, 0.0)) + np.einsum("bin,bi->n", B, force) + mu * q - f

    def hess(q):
        p, _, P = parts(q)
        H = (G.T * (k * (p > 0))) @ G
        K = np.einsum("bf,fi,fj->bij", (P > 0).astype(float), N, N)
        K = kb[:, None, None] * np.where(poly[:, None, None], K, np.eye(2))
        return H + np.einsum("bim,bij,bjn->mn", B, K, B) + mu * np.eye(q.size)

    q0 = np.zeros(G.shape[1]) if q0 is None else q0
    gtol = max(gtol_rel * float(np.max(np.abs(f))), rounding_level(s, q0))
    res = minimize(fun, q0, jac=jac, hess=hess, method="trust-exact", options={"gtol": gtol, "maxiter": 2000})
    q = res.x
    q_rigid = q - np.linalg.solve(hess(q), f)
    return q, q_rigid, int(res.nit), bool(res.success)


def rounding_level(s, q) -> float:
    """`ROUNDING_FACTOR` (gearte's, 64) machine epsilons of the largest term the force residual at q is computed from:
    the load, each contact's k (|g|·|q| + |e|) and each bearing's k (|B| |q| + |e_b| + c)."""
    import numpy as np

    from gearte.drives.rv_khv_equilibrium import ROUNDING_FACTOR

    aq = np.abs(q)
    unilateral = np.max(s["k"] * (np.abs(s["G"]) @ aq + np.abs(s["e"])), initial=0.0)
    bearing = np.max(
        s["kb"] * np.max(np.einsum("bin,n->bi", np.abs(s["B"]), aq) + np.abs(s["eb"]), axis=-1) + s["kb"] * s["c"], initial=0.0
    )
    return ROUNDING_FACTOR * float(np.finfo(float).eps) * max(float(np.max(np.abs(s["f"]))), float(unilateral), float(bearing))


_MC360_CODE = r"""
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import gearte
from gearte.cli.config import load_study
study = load_study(sys.argv[1])
n = int(sys.argv[2])
fn = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
gearte.monte_carlo(fn, key=3, n_samples=min(n, 8), progress=False)
t0 = time.perf_counter()
gearte.monte_carlo(fn, key=3, n_samples=n, progress=False)
print(json.dumps({"devices": jax.device_count(), "seconds": time.perf_counter() - t0}))
"""


def monte_carlo_360(units: int, devices: int) -> dict:
    """The example's Monte Carlo at 360 output angles (`points = 360` in a copy of the study file), `units` units after
    a warm-up of 8, in a fresh interpreter with `devices` CPU devices."""
    text = (ROOT / "examples" / "rv_robot_joint.toml").read_text()
    assert "points = 97\n" in text
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rv_robot_joint_360.toml"
        path.write_text(text.replace("points = 97\n", "points = 360\n", 1))
        env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
        env.update(XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}", JAX_PLATFORMS="cpu")
        proc = subprocess.run([sys.executable, "-c", _MC360_CODE, str(path), str(units)], cwd=ROOT, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"360-angle Monte Carlo failed ({proc.returncode}):\n{proc.stderr}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)

    import jax
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from bench_planetary_mc import best_of, machine_info, write_results

    import gearte
    from gearte.cli.config import load_study
    from gearte.drives.rv_khv import solve_order
    from gearte.drives.rv_khv_contacts import output_index, rv_system, translations

    study = load_study(ROOT / "examples" / "rv_robot_joint.toml")
    drive = study.drive
    n_units = 8 if args.quick else 64
    unit = jax.tree.map(lambda x: x[0], jax.vmap(study.errors.sample)(jax.random.key(7)[None]))
    solves = 2 * drive.points

    t0 = time.perf_counter()
    r = drive.response(unit)
    jax.block_until_ready(r.te)
    first = time.perf_counter() - t0
    one, _ = best_of(lambda: jax.block_until_ready(drive.response(unit).te), 2 if args.quick else 5)
    steps = np.asarray(r.steps)

    fn = gearte.TEStudy(drive, study.errors, metric=study.metric)
    gearte.monte_carlo(fn, key=1, n_samples=n_units)
    mc, _ = best_of(lambda: gearte.monte_carlo(fn, key=1, n_samples=n_units), 1 if args.quick else 2)

    # SciPy on the same systems, forward load, each started as gearte starts it (the previous solution in gearte's
    # order, turned with the drive), so both get the same help; checked against gearte's TE.
    thetas = np.asarray(drive.output_angles())
    order = np.asarray(solve_order(drive.z_pins - 1, drive.output_angles()))
    idx = order[: (24 if args.quick else drive.points)]
    err = drive.errors(unit)
    L = float(drive.stage.pin_circle_radius)
    i = output_index(drive)
    x = translations(drive.cranks, drive.discs)
    systems = [numpy_system(rv_system(drive, err, drive.output_angles()[j], 1.0)) for j in idx]
    t0 = time.perf_counter()
    out, q_prev = [], None
    for n, s in enumerate(systems):
        if q_prev is not None:  # every body's translation turned by the output's turn since the previous angle
            turn = thetas[idx[n]] - thetas[idx[n - 1]]
            u, v = q_prev[x], q_prev[x + 1]
            q_prev = q_prev.copy()
            q_prev[x], q_prev[x + 1] = np.cos(turn) * u - np.sin(turn) * v, np.sin(turn) * u + np.cos(turn) * v
        out.append(scipy_solve(s, q_prev))
        q_prev = out[-1][0]
    scipy_t = (time.perf_counter() - t0) / len(systems)
    te_scipy = np.asarray([o[1][i] / L for o in out])
    te_gearte = np.asarray(r.te[0])[idx]
    # SciPy and gearte may land on different solutions of a preloaded unit (its soft modes: docs/rv.md, known defect):
    # report the agreement as the share of angles within 1e-9 rad and the largest difference.
    diff = np.abs(te_scipy - te_gearte)
    agree = float(np.mean(diff < 1e-9))
    converged = np.asarray([o[3] for o in out], dtype=bool)
    diff_converged = diff[converged] if converged.any() else np.zeros(1)
    agree_converged = float(np.mean(diff_converged < 1e-9))

    per_solve_one = one / solves
    per_unit_mc = mc / n_units
    units_360 = 8 if args.quick else 32
    machine = machine_info()
    runs_360 = [monte_carlo_360(units_360, d) for d in sorted({1, int(machine["usable_cores"] or 1)})]
    rows_360 = [
        f"| {r['devices']} | {r['seconds'] / units_360 * 1e3:.0f} ms | {r['seconds'] / units_360 / (2 * 360) * 1e6:.0f} µs | "
        f"{r['seconds'] / units_360 * 1e4 / 60:.1f} min |"
        for r in runs_360
    ]
    md = "\n".join(
        [
            "# RV (K-H-V) equilibrium solves: gearte against SciPy",
            "",
            f"Example `examples/rv_robot_joint.toml`, {drive.points} output angles × 2 loads = {solves} solves per unit; "
            f"load average {os.getloadavg()[0]:.1f} at the start ({machine.get('cpu', '')}).",
            "",
            "| | time | per solve |",
            "|---|---|---|",
            f"| gearte, one unit, first call (compilation included) | {first:.2f} s | |",
            f"| gearte, one unit, steady | {one * 1e3:.1f} ms | {per_solve_one * 1e6:.0f} µs |",
            f"| gearte, Monte Carlo of {n_units} units, steady | {per_unit_mc * 1e3:.1f} ms per unit | "
            f"{per_unit_mc / solves * 1e6:.0f} µs |",
            f"| SciPy trust-exact, one solve at a time, started as gearte starts it ({len(systems)} solves, gtol 1e-10 × load "
            "or the residual's rounding level) "
            f"| | {scipy_t * 1e6:.0f} µs |",
            "",
            f"gearte's Newton iterations per solve (this unit): mean {steps.mean():.1f}, max {int(steps.max())}. "
            f"SciPy iterations: mean {np.mean([o[2] for o in out]):.1f}, converged {sum(o[3] for o in out)} of {len(out)}.",
            f"Speed-up per solve, SciPy / gearte (one unit): {scipy_t / per_solve_one:.1f}×; "
            f"Monte Carlo: {scipy_t / (per_unit_mc / solves):.1f}×. Target: ≤ 50 µs per solve, ≥ 100× SciPy.",
            f"Agreement of the forward rigid-limit TE: {100 * agree:.0f} % of the {len(idx)} angles within 1e-9 rad, "
            f"largest difference {diff.max() * 206264.8:.3g}″ (two solvers may stop at different points along a "
            "preloaded unit's soft modes: docs/rv.md, known defect); at the angles where SciPy reports convergence "
            f"({int(converged.sum())}): {100 * agree_converged:.0f} % within 1e-9 rad, largest difference "
            f"{diff_converged.max() * 206264.8:.3g}″.",
            "",
            f"The target's study: the same Monte Carlo at 360 output angles, both load directions (720 solves per unit), "
            f"{units_360} units after a warm-up of 8, in a fresh interpreter per device count. Target: 10,000 units in ≤ 5 min.",
            "",
            "| CPU devices | per unit | per solve | 10,000 units at this rate |",
            "|---|---|---|---|",
            *rows_360,
        ]
    )
    result = {
        "first_call_s": first,
        "one_unit_s": one,
        "per_solve_one_unit_us": per_solve_one * 1e6,
        "monte_carlo_units": n_units,
        "monte_carlo_per_unit_s": per_unit_mc,
        "scipy_per_solve_us": scipy_t * 1e6,
        "scipy_solves": len(systems),
        "te_agreement_share": agree,
        "te_max_difference_rad": float(diff.max()),
        "te_agreement_share_scipy_converged": agree_converged,
        "te_max_difference_scipy_converged_rad": float(diff_converged.max()),
        "monte_carlo_360": {"units": units_360, "runs": runs_360},
        "machine": machine,
    }
    write_results("rv", md, result, quick=args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
