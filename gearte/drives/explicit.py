"""A drive given by its TE components directly, e.g. a paper's closed-form equation.

Each term is ``scale · E_source · sin(freq θ + sign · φ_source + offset)`` and the
output TE is ``gain`` (rad/µm) times their sum.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..core.grid import check_frequencies
from ..core.schema import ConfigError, Table
from ..core.signal import Components, FrequencyLike, as_frequency
from ..core.units import ARCSEC_PER_RAD
from .protocol import AbstractSinusoidalDrive, Eccentricity, SourceSpec


class ExplicitTerm(eqx.Module):
    """One term ``scale · E_source · sin(frequency θ + phase_sign · φ_source + offset)``.

    `frequency` is a multiple of the input speed; `offset` in rad; `phase_sign` is +1 or −1.
    """

    source: str = eqx.field(static=True)
    frequency: Fraction = eqx.field(static=True)
    phase_sign: int = eqx.field(static=True)
    offset: Float[Array, ""]
    scale: Float[Array, ""]

    def __init__(self, source: str, frequency: FrequencyLike, *, phase_sign: int = 1, offset: float = 0.0, scale: float = 1.0):
        if not isinstance(source, str) or not source:
            raise ValueError("ExplicitTerm.source: name the error source (a string)")
        if phase_sign not in (1, -1):
            raise ValueError(f"ExplicitTerm.phase_sign: must be +1 or −1, got {phase_sign!r}")
        for nm, v in (("offset", offset), ("scale", scale)):
            if not math.isfinite(float(v)):
                raise ValueError(f"ExplicitTerm.{nm}: must be finite, got {v!r}")
        self.source = source
        self.frequency = as_frequency(frequency, name=f"term {source}: frequency")
        self.phase_sign = int(phase_sign)
        self.offset = jnp.asarray(float(offset))
        self.scale = jnp.asarray(float(scale))


class ExplicitDrive(AbstractSinusoidalDrive):
    """TE given as explicit sinusoidal terms of named error sources.

    **Arguments:**

    - `terms`: the `ExplicitTerm`s.
    - `gain`: output angle per µm, rad/µm (sign included).
    - `name`: a description for reports.
    """

    terms: tuple[ExplicitTerm, ...]
    gain: Float[Array, ""]
    name: str = eqx.field(static=True)

    def __init__(self, terms: Sequence[ExplicitTerm], *, gain: float, name: str = "explicit components"):
        if not terms:
            raise ValueError("ExplicitDrive: give at least one term")
        if not math.isfinite(float(gain)) or float(gain) == 0.0:
            raise ValueError(f"ExplicitDrive.gain: must be finite and non-zero (rad/µm), got {gain!r}")
        self.terms = tuple(terms)
        check_frequencies([t.frequency for t in self.terms], what="terms")
        self.gain = jnp.asarray(float(gain))
        self.name = name

    type_name: ClassVar[str] = "explicit"

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        return {t.source: SourceSpec(t.source, "eccentricity") for t in self.terms}

    @classmethod
    def from_table(cls, table: Table) -> ExplicitDrive:
        """``[drive] type = "explicit"``: gain_rad_per_um, optional name, and a list of ``[[drive.terms]]``
        (source, frequency as a number or a fraction string, optional phase_sign ±1, offset_deg/_rad, scale)."""
        t = table
        gain = t.number("gain_rad_per_um")
        name = t.string("name", "explicit components")
        raw = t.get("terms")
        if not isinstance(raw, list) or not raw:
            raise ConfigError(f"{t.where} terms: give a list of [[drive.terms]] tables (source, frequency, phase_sign, offset_rad)")
        terms = []
        for i, item in enumerate(raw):
            tt = Table(item, f"[[drive.terms]] #{i + 1}")
            freq = tt.get("frequency")
            if isinstance(freq, bool) or not isinstance(freq, (int, float, str)):
                raise ConfigError(f"{tt.where} frequency: expected a number or a fraction string like '7/24'")
            try:
                terms.append(
                    ExplicitTerm(
                        tt.string("source"),
                        freq,
                        phase_sign=tt.integer("phase_sign", 1),
                        offset=tt.angle("offset", 0.0),
                        scale=tt.number("scale", 1.0),
                    )
                )
            except ValueError as e:
                raise ConfigError(f"{tt.where}: {e}") from None
            tt.finish()
        try:
            return cls(terms, gain=gain, name=name)
        except ValueError as e:
            raise ConfigError(f"{t.where}: {e}") from None

    def components(self, errors: Mapping[str, Eccentricity]) -> Components:
        e = self.checked(errors)
        amp = jnp.stack([t.scale * e[t.source].magnitude[0] for t in self.terms], axis=-1)
        phase = jnp.stack([t.phase_sign * e[t.source].phase[0] + t.offset for t in self.terms], axis=-1)
        labels = [f"{t.source} ({t.frequency})" for t in self.terms]
        return Components(amp, phase, [t.frequency for t in self.terms], gain=self.gain, labels=labels)

    def describe(self) -> list[tuple[str, str]]:
        rows = [("drive", self.name), ("gain", f"{float(self.gain) * ARCSEC_PER_RAD:.6g}″/µm")]
        for t in self.terms:
            sign = "+" if t.phase_sign > 0 else "−"
            off = float(t.offset)
            shift = f" {'+' if off > 0 else '−'} {abs(off):.6g} rad" if off != 0 else ""
            rows.append((f"term {t.source}", f"{float(t.scale):g}·E sin({t.frequency}·θ {sign} φ{shift})"))
        return rows
