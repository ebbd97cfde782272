"""Write the example measured record and parts list (synthetic, from known errors; seeded):

    python examples/records/make_records.py

- planetary_wang2013_record.csv: a TE record of the Wang et al. (2013) drive of
  examples/planetary_wang2013_random.toml, every eccentricity at its Table 1 tolerance with the
  phases below, sampled at 64 points per input revolution over 24 revolutions (the hyper-period), with
  Gaussian output-encoder noise of 0.4″ and 2^20 counts per revolution.
- planetary_wang2013_parts.csv: 50 suns, 150 planets and 50 rings with measured eccentricity phasors
  (Rayleigh magnitudes, scale = tolerance/2, truncated at the tolerance; uniform phases).
"""

from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import gearte  # noqa: E402
from gearte.cli.config import load_study  # noqa: E402
from gearte.drives import wang2013  # noqa: E402

HERE = Path(__file__).resolve().parent
TOL = wang2013.TABLE1_TOLERANCES_UM  # µm, Wang et al. (2013), Table 1
PHASES = {
    "sun_manufacturing": 0.6,
    "planet_manufacturing": 2.1,
    "ring_manufacturing": 4.0,
    "sun_assembly": 1.2,
    "planet_assembly": 5.0,
    "carrier_assembly": 3.3,
}


def true_errors(drive):
    return {n: gearte.Eccentricity(np.full(s.shape, float(TOL[n])), np.full(s.shape, PHASES[n])) for n, s in drive.error_sources.items()}


def main():
    drive = load_study(HERE.parent / "planetary_wang2013_random.toml").drive
    rec = gearte.synthetic_record(
        drive, true_errors(drive), key=2024, revolutions=24, points_per_rev=64, noise=2e-6, counts_per_rev=2**20, input_rpm=60.0
    )
    gearte.write_record(HERE / "planetary_wang2013_record.csv", rec, unit="arcsec", digits=7)
    rng = np.random.default_rng(2024)
    rows = [
        "# 50 suns, 150 planets, 50 rings: measured eccentricity phasors (synthetic; see make_records.py)",
        "source,magnitude_um,phase_rad",
    ]
    for name, count in (("sun_manufacturing", 50), ("planet_manufacturing", 150), ("ring_manufacturing", 50)):
        m = np.minimum(rng.rayleigh(TOL[name] / 2, count), TOL[name])
        p = rng.uniform(0, 2 * np.pi, count)
        rows += [f"{name},{a:.3f},{b:.4f}" for a, b in zip(m, p)]
    (HERE / "planetary_wang2013_parts.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
