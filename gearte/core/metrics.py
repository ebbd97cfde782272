"""Metrics: the figures of merit a study takes of a drive's response, as objects.

A metric carries its own name, label, physical quantity (an angle in rad, or a count) and
sense, its exact value (for reports) and a smooth surrogate (for optimisers), as
optimistix passes a norm or a solver rather than a string. A drive offers the metrics that
fit its response (`AbstractDrive.metrics`); the study file names one of them.

The sinusoidal-drive metrics here read a TE signal through the drive's exact extrema
(``drive.extrema(signal)``); grid-drive metrics (lost motion, loaded pairs, …) live beside
their drive.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, Literal, Protocol

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .extrema import Extrema, rms
from .signal import TESignal

Quantity = Literal["angle", "count"]


class _HasExtrema(Protocol):
    def extrema(self, signal: TESignal) -> Extrema: ...


class AbstractMetric(eqx.Module):
    """A scalar figure of merit of one drive's response.

    Class variables: `name` (study-file name), `label` (axis label), `quantity` ("angle":
    rad inside, reported in ″/′; "count"), `higher_is_better` (a spec is a lower bound, as
    for loaded pairs) and `homogeneous` (positively homogeneous of degree 1 in the error
    magnitudes for a linear drive, which tolerance budgets exploit).
    """

    name: ClassVar[str]
    label: ClassVar[str]
    quantity: ClassVar[Quantity]
    higher_is_better: ClassVar[bool] = False
    homogeneous: ClassVar[bool] = False
    #: The unit reports use for this metric (e.g. "arcmin" for a lost motion); None: the study's unit.
    report_unit: ClassVar[str | None] = None

    @abc.abstractmethod
    def __call__(self, drive: Any, response: Any) -> Float[Array, ""]:
        """The exact value (rad for angles)."""

    def smooth(self, drive: Any, response: Any) -> Float[Array, ""]:
        """A surrogate with finite, informative gradients for optimisers (the exact value by default)."""
        return self(drive, response)

    @abc.abstractmethod
    def describe(self) -> str:
        """What the metric is, for reports."""


class Peak(AbstractMetric):
    """Peak ``max_θ |TE(θ)|`` over the whole hyper-period (includes constant offsets; Wang et al.'s "amplitude")."""

    name: ClassVar[str] = "peak"
    label: ClassVar[str] = "peak |Δθ|"
    quantity: ClassVar[Quantity] = "angle"
    homogeneous: ClassVar[bool] = True

    def __call__(self, drive: _HasExtrema, response: TESignal) -> Float[Array, ""]:
        e = drive.extrema(response)
        return jnp.maximum(e.max, -e.min)

    def describe(self) -> str:
        return 'peak = max over the whole hyper-period of |Δθ(θ_in)| (includes constant offsets; the "amplitude" of Wang et al. 2013)'


class PeakToPeak(AbstractMetric):
    """Peak-to-peak ``max TE − min TE`` over the hyper-period: the ISO / catalogue sense."""

    name: ClassVar[str] = "peak_to_peak"
    label: ClassVar[str] = "peak-to-peak Δθ"
    quantity: ClassVar[Quantity] = "angle"
    homogeneous: ClassVar[bool] = True

    def __call__(self, drive: _HasExtrema, response: TESignal) -> Float[Array, ""]:
        e = drive.extrema(response)
        return e.max - e.min

    def describe(self) -> str:
        return "peak-to-peak = max Δθ − min Δθ over the whole hyper-period (ISO / catalogue sense)"


class RMS(AbstractMetric):
    """Root mean square of the TE over the hyper-period, exact by Parseval."""

    name: ClassVar[str] = "rms"
    label: ClassVar[str] = "RMS Δθ"
    quantity: ClassVar[Quantity] = "angle"
    homogeneous: ClassVar[bool] = True

    def __call__(self, drive: Any, response: TESignal) -> Float[Array, ""]:
        del drive
        return rms(response)

    def describe(self) -> str:
        return "RMS of Δθ over the hyper-period (exact, by Parseval)"


def public_name(cls: type) -> str:
    """How a user writes class `cls`: ``gearte.Name`` when gearte exports it, else its module path."""
    import gearte  # at call time: the package has loaded

    if getattr(gearte, cls.__name__, None) is cls:
        return f"gearte.{cls.__name__}"
    return f"{cls.__module__}.{cls.__qualname__}"


def check_offered(metric: Any, drive: Any, *, what: str = "metric") -> None:
    """Raise a ValueError naming the drive's own metric classes unless `metric` is one of them (a metric object of
    the same name and class: the cycloid-pin drive's ``lost_motion`` is not the RV reducer's)."""
    offered = drive.metrics
    if not isinstance(metric, AbstractMetric):
        first = public_name(type(next(iter(offered.values()))))
        raise ValueError(f"{what}: give a metric object such as {first}(), got {metric!r}")
    if metric.name in offered and type(offered[metric.name]) is type(metric):
        return
    choices = ", ".join(f"{public_name(type(m))}()" for m in offered.values())
    raise ValueError(f"{what}: {type(drive).__name__} offers {choices}; got {public_name(type(metric))}()")
