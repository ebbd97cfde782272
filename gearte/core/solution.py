"""Result codes of every gearte solve, and the one convention for reporting them.

As in optimistix: a solve returns a Module with a `result` field (a `RESULTS` item) and
takes `throw=`. With ``throw=True`` (the default) an unsuccessful solve raises, naming the
reason; with ``throw=False`` the caller checks ``solution.result == gearte.RESULTS.successful``
(per sample under `vmap`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import optimistix as optx


class RESULTS(optx.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """optimistix's result codes, plus those of gearte's own solves."""

    infeasible = "The specification cannot be met within the allowed tolerances (loosen the spec or the limits)."
    some_starts_failed = "The best start succeeded, but some of the other starts did not converge."
    contact_not_converged = "A contact solve did not converge for some pin or input position."


def promote(result) -> RESULTS:
    """An optimistix result as a gearte `RESULTS` item."""
    return RESULTS.promote(result)


def is_successful(result) -> bool:
    """Whether a (concrete, unbatched) result is `RESULTS.successful`."""
    return bool(np.all(np.asarray(result == RESULTS.successful)))


def result_name(result) -> str:
    """The name of a concrete `RESULTS` (or optimistix result) item, e.g. ``"successful"``."""
    r = result if getattr(result, "_enumeration", None) is RESULTS else RESULTS.promote(result)
    for name, item in RESULTS._name_to_item.items():  # pyright: ignore[reportAttributeAccessIssue]
        if bool(r == item):
            return name
    return "unknown"


def message(result) -> str:
    """The text of a concrete result (the first failing entry of a batched one)."""
    flat = np.asarray(result._value).ravel()  # pyright: ignore[reportAttributeAccessIssue]
    ok = int(np.asarray(RESULTS.successful._value))  # pyright: ignore[reportAttributeAccessIssue]
    bad = flat[flat != ok]
    index = int(bad[0]) if bad.size else int(flat[0])
    return RESULTS._index_to_message[index] or "successful"  # pyright: ignore[reportAttributeAccessIssue]


def check(result, *, throw: bool, what: str) -> None:
    """Raise if `throw` and `result` is not successful (outside jit; the message names `what`)."""
    if throw and not is_successful(result):
        raise RuntimeError(f"{what}: {message(result)} (pass throw=False to get the solution and inspect `result`)")


def where(ok, result) -> RESULTS:
    """`result` where `ok`, else `RESULTS.successful` (a jnp-friendly select)."""
    return RESULTS.where(jnp.asarray(ok), result, RESULTS.successful)  # pyright: ignore[reportArgumentType]
