"""The RV drive's small load: where the rigid limit does not depend on its size (docs/rv.md, "Size of the small load").

Units of `examples/rv_robot_joint_tolerances.toml` (key 7, 97 output angles × 2 loads) solved with `deflection_mm` set
to each value; per value: units with a lost motion below −0.5″ at some angle (impossible at equilibrium), the most
negative, units with a failed solve, the mean over units of the maximum lost motion (′) and of the forward TE p-p (″).
Not a speed benchmark: it checks an accuracy setting, and prints a markdown table.

    python benchmarks/rv_load_window.py               # 400 units (about 6 minutes on a 2-core CPU)
    python benchmarks/rv_load_window.py --units 20    # a smoke run
"""

from __future__ import annotations

import argparse
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFLECTIONS_MM = (1e-7, 1e-9, 1e-10, 1e-11, 1e-12)
ARCSEC_PER_RAD = 206264.80624709636


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=400)
    args = ap.parse_args()

    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    from gearte import RESULTS
    from gearte.cli.config import load_study

    study = load_study(ROOT / "examples" / "rv_robot_joint_tolerances.toml")
    keys = jax.random.split(jax.random.PRNGKey(7), args.units)
    print(
        "| deflection_mm | units with lost motion < −0.5″ | most negative (″) | units with a failed solve | mean max lost motion (′) | mean TE p-p forward (″) |"
    )
    print("|---|---|---|---|---|---|")
    for defl in DEFLECTIONS_MM:
        drive = eqx.tree_at(lambda d: d.deflection_mm, study.drive, jnp.asarray(defl))
        r = jax.jit(jax.vmap(lambda k, drive=drive: drive.response(study.errors.sample(k))))(keys)
        te = np.asarray(r.te) * ARCSEC_PER_RAD
        lm = te[:, 0] - te[:, 1]
        lowest = np.min(lm, axis=1)
        failed = int(np.sum(~np.all(np.asarray(r.result == RESULTS.successful), axis=(1, 2))))
        print(
            f"| {defl:g} | {int(np.sum(lowest < -0.5))} | {min(float(lowest.min()), 0.0):.2f} | {failed} | "
            f"{np.mean(np.max(lm, axis=1)) / 60:.4f} | {np.mean(np.ptp(te[:, 0], axis=1)):.2f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
