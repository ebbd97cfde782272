"""How gearte gets float64.

Errors are micrometres on radii of hundreds of millimetres, and TE peaks are
taken to 1e-6 relative: float32 (7 digits) is not enough. gearte therefore turns
on JAX's 64-bit mode when it is imported (``jax_enable_x64``), unless the
environment variable ``GEARTE_X64=0`` is set. Public entry points call
`require_x64`, which raises a clear error if 64-bit mode has since been turned off.
"""

import os

import jax

_OPT_OUT = os.environ.get("GEARTE_X64", "1").strip().lower() in {"0", "false", "no", "off"}

if not _OPT_OUT:
    jax.config.update("jax_enable_x64", True)


def x64_enabled() -> bool:
    """Whether JAX is in 64-bit mode."""
    return bool(jax.config.jax_enable_x64)


def require_x64() -> None:
    """Raise if JAX is not in 64-bit mode (gearte's geometry needs float64)."""
    if not x64_enabled():
        raise RuntimeError(
            "gearte needs float64: JAX's 64-bit mode is off. Call "
            "`jax.config.update('jax_enable_x64', True)` before using gearte, or unset "
            "GEARTE_X64=0 (gearte turns 64-bit mode on at import unless told not to)."
        )
