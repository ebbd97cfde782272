"""Error sources: an eccentricity-like error has a magnitude (µm) and a phase (rad).

`ErrorModel` says, for each error source a drive declares, how its magnitude and
phase are drawn; `ErrorModel.sample` turns a key into the concrete errors that
the drive turns into TE.
"""

from __future__ import annotations

from typing import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from ._distributions import AbstractMagnitude, AbstractPhase, Fixed, FixedPhase, Optimised, RelativePhase


class Eccentricity(eqx.Module):
    """An error vector: `magnitude` µm at `phase` rad (arrays; one entry per planet for per-planet sources)."""

    magnitude: Float[Array, "*n"]
    phase: Float[Array, "*n"]

    def __init__(self, magnitude: ArrayLike, phase: ArrayLike = 0.0):
        self.magnitude = jnp.asarray(magnitude, dtype=float)
        self.phase = jnp.asarray(phase, dtype=float)


class ErrorSource(eqx.Module):
    """How one error source is drawn: a magnitude law and a phase law or rule."""

    magnitude: AbstractMagnitude
    phase: AbstractPhase

    def __init__(self, magnitude: AbstractMagnitude | float, phase: AbstractPhase | float):
        self.magnitude = magnitude if isinstance(magnitude, AbstractMagnitude) else Fixed(magnitude)
        self.phase = phase if isinstance(phase, AbstractPhase) else FixedPhase(phase)


def _order(sources: Mapping[str, ErrorSource]) -> list[str]:
    """Names in an order where every rule's reference comes first; raises on cycles."""
    done: list[str] = []
    state: dict[str, int] = {}

    def visit(name: str, chain: tuple[str, ...]):
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            raise ValueError("phase rules form a cycle: " + " → ".join(chain + (name,)) + "; one phase must be random or fixed")
        state[name] = 1
        rule = sources[name].phase
        ref = rule.to if isinstance(rule, RelativePhase) else rule.relative_to if isinstance(rule, Optimised) else None
        if ref is not None:
            if ref not in sources:
                raise ValueError(f"error source {name!r}: its phase rule refers to {ref!r}, which is not an error source here; use one of {sorted(sources)}")
            visit(ref, chain + (name,))
        state[name] = 2
        done.append(name)

    for n in sources:
        visit(n, ())
    return done


class ErrorModel(eqx.Module):
    """The error sources of a drive and how each is drawn.

    **Arguments:**

    - `sources`: mapping from source name to `ErrorSource`.
    - `counts`: mapping from source name to how many instances the drive has
      (1, or the number of planets for per-planet sources); usually `drive.error_sources`.
    """

    sources: dict[str, ErrorSource]
    counts: dict[str, int] = eqx.field(static=True)
    order: tuple[str, ...] = eqx.field(static=True)

    def __init__(self, sources: Mapping[str, ErrorSource], counts: Mapping[str, int]):
        unknown = sorted(set(sources) - set(counts))
        if unknown:
            raise ValueError(f"unknown error source(s) {unknown}; this drive has {sorted(counts)}")
        missing = sorted(set(counts) - set(sources))
        if missing:
            raise ValueError(f"missing error source(s) {missing}: give each a magnitude and a phase (use magnitude 0 to leave one out)")
        self.sources = {n: sources[n] for n in counts}
        self.counts = dict(counts)
        self.order = tuple(_order(self.sources))
        for n in self.order:
            rule = self.sources[n].phase
            if isinstance(rule, RelativePhase) and self.counts[rule.to] not in (1, self.counts[n]):
                raise ValueError(f"error source {n!r} ({self.counts[n]} instances) cannot follow the phase of {rule.to!r} ({self.counts[rule.to]} instances)")

    def sample(self, key: PRNGKeyArray) -> dict[str, Eccentricity]:
        """Draw one set of errors. Each source uses its own key, folded in by position."""
        names = list(self.counts)
        out: dict[str, Eccentricity] = {}
        for name in self.order:
            src = self.sources[name]
            shape = (self.counts[name],)
            k_mag, k_ph = jax.random.split(jax.random.fold_in(key, names.index(name)))
            mag = src.magnitude.sample(k_mag, shape)
            rule = src.phase
            if isinstance(rule, Optimised):
                raise ValueError(f"error source {name!r}: its phase is to be chosen by the allocation optimiser; "
                                 "resolve the rule first (gearte.allocate_rule, or a study file's [allocation])")
            if isinstance(rule, RelativePhase):
                phase = jnp.broadcast_to(out[rule.to].phase, shape) + rule.offset
            else:
                phase = rule.sample(k_ph, shape)
            out[name] = Eccentricity(mag, phase)
        return {n: out[n] for n in names}
