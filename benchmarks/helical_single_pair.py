"""Tip relief and the single pair's stiffness along its path (docs/helical.md, "Fluctuation against each amount").

The wind-turbine stage of `examples/dynamics/helical_wind_turbine.toml`, one modification amount at a time (the others
0), with the sliced mesh stiffness (`gearte.SlicedStiffness()`, every pair equally stiff along its path) and with
`gearte.SinglePairStiffness` (each pair stiffest at mid path): its ISO-consistent default (c = 0.75 (1 − 1/ε_α)) and
fixed end drops c = 0.4 and 0.7. Prints a markdown table of the fluctuations (µm). Not a speed benchmark; `make bench`
does not run it.

    python benchmarks/helical_single_pair.py      # about a minute on a 2-core CPU
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
AMOUNTS_UM = (0, 20, 40, 60, 80, 100, 130)


def main() -> None:
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    jax.config.update("jax_enable_x64", True)
    import gearte

    base = gearte.load_helical(ROOT / "examples" / "dynamics" / "helical_wind_turbine.toml")
    models = (
        ("slices", gearte.SlicedStiffness()),
        ("single pair, ISO (c = 0.28 / 0.35)", gearte.SinglePairStiffness()),
        ("single pair, c = 0.4", gearte.SinglePairStiffness(0.4)),
        ("single pair, c = 0.7", gearte.SinglePairStiffness(0.7)),
    )
    sweep = eqx.filter_jit(jax.vmap(lambda x, m: m.fluctuation(x), in_axes=(0, None)))
    print("| amount (µm) | stiffness model | " + " | ".join(str(a) for a in AMOUNTS_UM) + " |")
    print("|---|---|" + "---|" * len(AMOUNTS_UM))
    for index, label, mesh in (
        (0, "x₁ sun tip relief", 0),
        (2, "x₃ planet tip relief", 1),
        (1, "x₂ sun crowning", 0),
        (3, "x₄ planet crowning", 1),
    ):
        xs = np.zeros((len(AMOUNTS_UM), 4))
        xs[:, index] = AMOUNTS_UM
        for name, stiffness in models:
            model = eqx.tree_at(lambda m: m.stiffness_model, base, stiffness)
            values = np.asarray(sweep(jnp.asarray(xs), model))[:, mesh]
            where = "external" if mesh == 0 else "internal"
            print(f"| {label}, {where} | {name} | " + " | ".join(f"{v:.2f}" for v in values) + " |", flush=True)


if __name__ == "__main__":
    main()
