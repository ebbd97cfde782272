"""How gearte gets float64.

Errors are micrometres on radii of hundreds of millimetres, and TE peaks are taken to
1e-6 relative: float32 (7 digits) is not enough. Importing gearte changes no global
state; the command line turns on JAX's 64-bit mode itself (`enable_x64`), and a library
user does it once before building any array::

    import jax
    jax.config.update("jax_enable_x64", True)

Every public entry point that builds or reads a TE (a drive's signal or response, the extrema,
`evaluate`, the Monte Carlo, optimisers, solvers and fits) calls `require_x64`, which raises a
clear error otherwise.
"""

import jax


def x64_enabled() -> bool:
    """Whether JAX is in 64-bit mode."""
    return bool(jax.config.read("jax_enable_x64"))


def enable_x64() -> None:
    """Turn on JAX's 64-bit mode (what `gearte` on the command line does before anything else)."""
    jax.config.update("jax_enable_x64", True)


def require_x64() -> None:
    """Raise if JAX is not in 64-bit mode (gearte's geometry needs float64)."""
    if not x64_enabled():
        raise RuntimeError(
            "gearte needs float64: JAX's 64-bit mode is off. Call "
            "`jax.config.update('jax_enable_x64', True)` (or `gearte.enable_x64()`) once, before "
            "building any array; the `gearte` command does this itself."
        )
