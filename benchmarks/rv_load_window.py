"""The RV drive's small load: where the rigid limit does not depend on its size (docs/rv.md, "Size of the small load").

Units of `examples/rv_robot_joint_tolerances.toml` (key 7, 97 output angles × 2 loads) solved with `deflection_mm` set
to each value and the regularisation μ following it (gearte's default) or held (`--regularisation`); per value: units
with a lost motion below −0.5″ and below −0.01″ at some angle (impossible at equilibrium), the most negative, units
with a failed solve, the mean over units of the maximum lost motion (′) and of the forward TE p-p (″). Not a speed
benchmark: it checks an accuracy setting, and prints a markdown table.

    python benchmarks/rv_load_window.py                                   # 400 units (about 8 minutes on a 2-core CPU)
    python benchmarks/rv_load_window.py --regularisation 1e-12 --deflections 1e-9 1e-10 1e-11   # μ held
    python benchmarks/rv_load_window.py --units 20                        # a smoke run
"""

from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFLECTIONS_MM = (1e-8, 1e-9, 1e-10, 1e-11)
ARCSEC_PER_RAD = 206264.80624709636


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=400)
    ap.add_argument("--deflections", type=float, nargs="+", default=DEFLECTIONS_MM, help="deflection_mm values (mm)")
    ap.add_argument(
        "--regularisation",
        type=float,
        default=None,
        help="μ / k for every load (default: gearte's, REGULARISATION_PER_MM × deflection_mm, which follows the load)",
    )
    args = ap.parse_args()

    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from gearte import RESULTS
    from gearte.cli.config import load_study
    from gearte.drives.rv_khv_contacts import REGULARISATION_PER_MM

    study = load_study(ROOT / "examples" / "rv_robot_joint_tolerances.toml")
    keys = jax.random.split(jax.random.PRNGKey(7), args.units)
    print(
        "| deflection_mm | μ / k | units with lost motion < −0.5″ | < −0.01″ | most negative (″) | units with a failed solve "
        "| mean max lost motion (′) | mean TE p-p forward (″) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for defl in args.deflections:
        mu = REGULARISATION_PER_MM * defl if args.regularisation is None else args.regularisation
        drive = eqx.tree_at(lambda d: (d.deflection_mm, d.regularisation), study.drive, (jnp.asarray(defl), jnp.asarray(mu)))
        r = jax.jit(jax.vmap(lambda k, drive=drive: drive.response(study.errors.sample(k))))(keys)
        te = np.asarray(r.te) * ARCSEC_PER_RAD
        lm = te[:, 0] - te[:, 1]
        lowest = np.min(lm, axis=1)
        failed = int(np.sum(~np.all(np.asarray(r.result == RESULTS.successful), axis=(1, 2))))
        print(
            f"| {defl:g} | {mu:g} | {int(np.sum(lowest < -0.5))} | {int(np.sum(lowest < -0.01))} | {min(float(lowest.min()), 0.0):.4f} | "
            f"{failed} | {np.mean(np.max(lm, axis=1)) / 60:.4f} | {np.mean(np.ptp(te[:, 0], axis=1)):.3f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
