"""Validation of user-given numbers, shared by every model: messages name the field and the fix."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer
from jaxtyping import PRNGKeyArray


def as_float(name: str, value, *, positive: bool = False, nonnegative: bool = False, hint: str = "") -> float:
    """`value` as a finite float; raises ValueError naming `name` (with `hint` on a sign error)."""
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be a finite number, got {value!r}")
    note = f" ({hint})" if hint else ""
    if positive and not v > 0:
        raise ValueError(f"{name}: must be > 0, got {v:g}{note}")
    if nonnegative and v < 0:
        raise ValueError(f"{name}: must be ≥ 0, got {v:g}{note}")
    return v


def as_int(name: str, value, *, minimum: int) -> int:
    """`value` as a whole number ≥ `minimum` (a float with no fractional part is accepted)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise ValueError(f"{name}: must be a whole number, got {value!r}")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name}: must be ≥ {minimum}, got {value}")
    return value


def check_names(given, expected, *, what: str) -> None:
    """Raise a ValueError, `what` followed by the names missing from `given` and those it has beyond `expected`, unless
    `given` (a mapping or a collection of names) names exactly `expected`."""
    missing = [n for n in expected if n not in given]
    unknown = [n for n in given if n not in expected]
    if missing or unknown:
        raise ValueError(what + (f"; missing {missing}" if missing else "") + (f"; unknown {unknown}" if unknown else ""))


def check_array_values(name: str, value, *, nonnegative: bool = False, unit: str = "") -> None:
    """Check user-given numbers (Python numbers, lists, NumPy arrays): finite, and ≥ 0 if asked.

    JAX arrays pass unchecked: they are computed inside gearte (and may be traced).
    """
    if isinstance(value, jax.Array):
        return
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number or an array of numbers, got {value!r}") from None
    u = f" {unit}" if unit else ""
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    if nonnegative and np.any(arr < 0):
        raise ValueError(f"{name}: must be ≥ 0{u} (a magnitude cannot be negative; turn the phase by π instead), got {value!r}")


def is_traced(value) -> bool:
    """Whether `value` is a JAX tracer (inside jit, grad or vmap), whose values cannot be checked in Python."""
    return isinstance(value, Tracer)


def check_option(
    name: str, value, kind: type, choices: Mapping[str, type], *, what: str = "must be", named: str | None = "in a study file"
) -> Any:
    """`value` if it is an instance of the option class `kind`; else a `ValueError` that names the classes to use
    (`choices`: by their names, `named` where they are written so, e.g. in study files; None: nowhere but here), with
    the instance to write where the class itself was passed, and the class where its name was."""
    if isinstance(value, kind):
        return value
    names = " or ".join(f"{c.__name__}()" for c in choices.values())
    if isinstance(value, str) and value in choices:
        cls = choices[value].__name__
        hint = f" (gearte.{cls}() is {value!r} {named})" if named else f" (for {value!r}, write gearte.{cls}())"
    elif isinstance(value, type) and issubclass(value, kind):
        hint = f" (an instance: {value.__name__}())"
    else:
        hint = ""
    raise ValueError(f"{name}: {what} {names}, got {value!r}{hint}")


def as_key(key: int | PRNGKeyArray) -> PRNGKeyArray:
    """A `jax.random` key from an integer seed or a key."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        if not 0 <= int(key) < 2**63:
            raise ValueError(f"seed must be a whole number in [0, 2⁶³), got {key}")
        return jax.random.key(int(key))
    if isinstance(key, jax.Array) and jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key
    raise ValueError(f"key: expected an integer seed or a jax.random.key(...), got {key!r}")
