"""Error sources and the error model of a drive: how every declared source is drawn.

`ErrorSource` pairs laws with one source a drive declares (`SourceSpec`): an eccentricity
source has a magnitude law and a phase law or assembly rule; a deviation source (a signed
value, such as a pin-radius error) has one value law. `ErrorModel.sample` turns a key into
the concrete errors the drive's `response` takes.

Keys: source j (in the drive's declared order) uses ``fold_in(key, j)``; an eccentricity
splits it into a magnitude key and a phase key, a deviation uses it as it is.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from ..drives.protocol import Eccentricity, SourceSpec
from .laws import AbstractLaw, AbstractPhase, AbstractRule, AbstractValueLaw, Fixed, FixedPhase, RelativePhase, Sinusoid


class ErrorSource(eqx.Module):
    """How one error source is drawn.

    **Arguments:**

    - `magnitude`: the law of the value: for an eccentricity its magnitude (µm, never
      negative), for a deviation its signed value (µm or rad). A number means `Fixed`.
    - `phase`: for an eccentricity, the law or assembly rule of its phase (rad; a number
      means `FixedPhase`); None for a deviation.
    """

    magnitude: AbstractLaw
    phase: AbstractPhase | None

    def __init__(self, magnitude: AbstractLaw | float, phase: AbstractPhase | float | None = None):
        self.magnitude = magnitude if isinstance(magnitude, AbstractLaw) else Fixed(magnitude)
        self.phase = phase if isinstance(phase, AbstractPhase) or phase is None else FixedPhase(phase)

    def describe(self, unit: str = "µm") -> tuple[str, str]:
        """(value law, phase law) lines for reports."""
        return self.magnitude.describe(unit), ("—" if self.phase is None else self.phase.describe())


def order_sources(sources: Mapping[str, ErrorSource]) -> list[str]:
    """Names in an order where every rule's reference comes first; raises on cycles or unknown references."""
    done: list[str] = []
    state: dict[str, int] = {}

    def visit(name: str, chain: tuple[str, ...]):
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            raise ValueError("phase rules form a cycle: " + " → ".join(chain + (name,)) + "; one phase must be random or fixed")
        state[name] = 1
        rule = sources[name].phase
        ref = rule.reference if isinstance(rule, AbstractRule) else None
        if ref is not None:
            if ref not in sources:
                raise ValueError(
                    f"error source {name!r}: its phase rule refers to {ref!r}, which is not an error source here; "
                    f"use one of {sorted(sources)}"
                )
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
    - `specs`: the drive's declared sources, ``drive.error_sources``.
    """

    sources: dict[str, ErrorSource]
    specs: dict[str, SourceSpec] = eqx.field(static=True)
    order: tuple[str, ...] = eqx.field(static=True)

    def __init__(self, sources: Mapping[str, ErrorSource], specs: Mapping[str, SourceSpec]):
        unknown = sorted(set(sources) - set(specs))
        if unknown:
            raise ValueError(f"unknown error source(s) {unknown}; this drive has {list(specs)}")
        missing = sorted(set(specs) - set(sources))
        if missing:
            raise ValueError(f"missing error source(s) {missing}: give each a law (a fixed 0 leaves one out)")
        for n, spec in specs.items():
            src = sources[n]
            if not isinstance(src, ErrorSource):
                raise ValueError(f"error source {n!r}: expected an ErrorSource, got {type(src).__name__}")
            # A phase law draws a deviation that is itself an angle (a cycloid set-up phase), never a magnitude; a
            # Sinusoid draws a signed pattern of deviations over tooth spaces or pins. (A law of the user's own may be.)
            if spec.kind == "eccentricity" and isinstance(src.magnitude, (AbstractPhase, Sinusoid)):
                raise ValueError(
                    f"error source {n!r}: the magnitude of an eccentricity is drawn by a value law (Fixed, Uniform, "
                    f"Normal, TruncatedNormal, Rayleigh), not {type(src.magnitude).__name__}"
                )
            if spec.kind == "eccentricity":
                if src.phase is None:
                    raise ValueError(f"error source {n!r} is an eccentricity: give it a phase law or assembly rule")
                # A bounded law reaching below 0 is a mistake; a Normal magnitude (unbounded) is allowed:
                # its negative draws are magnitudes with the phase turned by π.
                if isinstance(src.magnitude, AbstractValueLaw) and -math.inf < src.magnitude.lower() < 0:
                    raise ValueError(
                        f"error source {n!r}: its magnitude law ({src.magnitude.describe()}) can draw negative values; "
                        "a magnitude cannot be negative (turn its phase by π instead)"
                    )
            elif src.phase is not None:
                raise ValueError(f"error source {n!r} is a signed deviation ({spec.unit}); it has no phase law")
        self.sources = {n: sources[n] for n in specs}
        self.specs = dict(specs)
        self.order = tuple(order_sources(self.sources))
        for n in self.order:
            rule = self.sources[n].phase
            if isinstance(rule, RelativePhase) and self.specs[rule.to].count not in (1, self.specs[n].count):
                raise ValueError(
                    f"error source {n!r} ({self.specs[n].count} instances) cannot follow the phase of {rule.to!r} "
                    f"({self.specs[rule.to].count} instances)"
                )

    @property
    def counts(self) -> dict[str, int]:
        """Instances per source."""
        return {n: s.count for n, s in self.specs.items()}

    def replace(self, **sources: ErrorSource) -> ErrorModel:
        """A copy with some sources drawn otherwise."""
        return ErrorModel({**self.sources, **sources}, self.specs)

    def sample(self, key: PRNGKeyArray) -> dict[str, Any]:
        """Draw one set of errors (`Eccentricity` per eccentricity source, an array per deviation)."""
        names = list(self.specs)
        out: dict[str, Any] = {}
        for name in self.order:
            src, spec = self.sources[name], self.specs[name]
            k = jax.random.fold_in(key, names.index(name))
            if spec.kind == "deviation":
                out[name] = jnp.asarray(src.magnitude.sample(k, spec.shape), dtype=float)
                continue
            k_mag, k_ph = jax.random.split(k)
            mag = src.magnitude.sample(k_mag, spec.shape)
            rule = src.phase
            if isinstance(rule, RelativePhase):
                ref = out[rule.to].phase
                phase = jnp.broadcast_to(ref.reshape(()) if spec.shape == () else ref, spec.shape) + rule.offset
            else:
                assert rule is not None
                phase = rule.sample(k_ph, spec.shape)
            out[name] = Eccentricity(mag, phase)
        return {n: out[n] for n in names}


def check_drive_model(drive: Any, model: Any, *, name: str = "model") -> None:
    """Raise a ValueError naming the argument `name` unless `model` is an `ErrorModel` of `drive`'s error sources (the
    same names in the same order, the same declarations)."""
    if not isinstance(model, ErrorModel):
        raise ValueError(f"{name}: expected an ErrorModel (gearte.ErrorModel(sources, drive.error_sources)), got {type(model).__name__}")
    if list(model.specs) != list(drive.error_sources) or model.specs != drive.error_sources:
        raise ValueError(f"{name}: the error model's sources {list(model.specs)} do not match the drive's {list(drive.error_sources)}")
