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
#: Event → the counters open for it (one per `with` block).
_open: dict[str, list[collections.Counter]] = {_TRACE_EVENT: [], _LOWER_EVENT: []}


def _listener(event: str, duration: float, **kwargs) -> None:
    del duration
    for counter in _open.get(event, ()):
        counter[str(kwargs.get("fun_name", "?"))] += 1


jax.monitoring.register_event_duration_secs_listener(_listener)


@contextlib.contextmanager
def _counting(event: str) -> Iterator[collections.Counter]:
    seen: collections.Counter = collections.Counter()
    _open[event].append(seen)
    try:
        yield seen
    finally:
        _open[event].remove(seen)


def traces() -> contextlib.AbstractContextManager[collections.Counter]:
    """Function name → traces of it inside the block: the traces JAX reports, those begun from no other trace (a
    function traced inside another's trace, e.g. under ``jax.jacfwd``, is not seen: `lowerings` sees its program)."""
    return _counting(_TRACE_EVENT)


def lowerings() -> contextlib.AbstractContextManager[collections.Counter]:
    """Program name (``jit(name)``) → lowerings of it to XLA inside the block: every program built anew (then compiled,
    or read from the persistent cache). JAX reports a trace (`traces`) only when it starts from no other trace, so a
    ``jax.jit`` made inside the function called and used under ``jax.jacfwd`` or ``jax.vmap`` is traced unseen; the
    transformed program is still lowered anew on every call, and this sees it."""
    return _counting(_LOWER_EVENT)
