"""Count JAX's traces of Python functions: ``with traces() as seen: …`` then ``seen["name"]``.

A traced function (``jax.jit``, ``eqx.filter_jit``) is traced again only when its cache misses: a changed static
argument, a new shape, or a new function object (a ``jax.jit`` made inside the function called). Tests use it to
show that a second call with other values of the same shapes traces nothing. It reads JAX's public monitoring
events (``jax.monitoring``), whose trace event names the function."""

import collections
import contextlib
from collections.abc import Iterator

import jax.monitoring

_TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"
_LOWER_EVENT = "/jax/core/compile/jaxpr_to_mlir_module_duration"
_active: list[collections.Counter] = []
_active_lowerings: list[collections.Counter] = []


def _listener(event: str, duration: float, **kwargs) -> None:
    del duration
    if event == _TRACE_EVENT:
        for counter in _active:
            counter[str(kwargs.get("fun_name", "?"))] += 1
    elif event == _LOWER_EVENT:
        for counter in _active_lowerings:
            counter[str(kwargs.get("fun_name", "?"))] += 1


jax.monitoring.register_event_duration_secs_listener(_listener)


@contextlib.contextmanager
def traces() -> Iterator[collections.Counter]:
    """Function name → traces of it inside the block: the traces JAX reports, those begun from no other trace (a
    function traced inside another's trace, e.g. under ``jax.jacfwd``, is not seen: `lowerings` sees its program)."""
    seen: collections.Counter = collections.Counter()
    _active.append(seen)
    try:
        yield seen
    finally:
        _active.remove(seen)


@contextlib.contextmanager
def lowerings() -> Iterator[collections.Counter]:
    """Program name (``jit(name)``) → lowerings of it to XLA inside the block: every program built anew (then compiled,
    or read from the persistent cache). JAX reports a trace (`traces`) only when it starts from no other trace, so a
    ``jax.jit`` made inside the function called and used under ``jax.jacfwd`` or ``jax.vmap`` is traced unseen; the
    transformed program is still lowered anew on every call, and this sees it."""
    seen: collections.Counter = collections.Counter()
    _active_lowerings.append(seen)
    try:
        yield seen
    finally:
        _active_lowerings.remove(seen)
