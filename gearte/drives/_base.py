"""What every drive model provides."""

from __future__ import annotations

import abc
from typing import Mapping

import equinox as eqx
import jax.numpy as jnp

from .._errors import Eccentricity
from .._signal import Components, TESignal, to_signal


class AbstractDrive(eqx.Module):
    """A drive turns a set of errors into sinusoidal TE components at its output.

    Subclasses declare `error_sources` (name → number of instances) and
    `phase_symbols` (the paper's symbol of each source's phase, for reports and
    rules), and implement `components`.
    """

    @property
    @abc.abstractmethod
    def error_sources(self) -> dict[str, int]:
        """Error source names and how many instances of each (1, or one per planet)."""

    @property
    def phase_symbols(self) -> dict[str, str]:
        """The phase symbol of each source (e.g. ``"beta_s"``); defaults to the source name."""
        return {n: n for n in self.error_sources}

    @abc.abstractmethod
    def components(self, errors: Mapping[str, Eccentricity]) -> Components:
        """Sinusoidal components of the output TE for these errors."""

    def signal(self, errors: Mapping[str, Eccentricity]) -> TESignal:
        """The output TE (rad) for these errors, over its hyper-period."""
        return to_signal(self.components(errors))

    def describe(self) -> list[tuple[str, str]]:
        """(parameter, value) rows for reports."""
        return []

    @property
    def tolerances_um(self) -> dict[str, float]:
        """Tolerances (µm) the drive itself declares for its error sources, by name; none by default.

        A study file may then leave out ``tolerance_um`` in ``[errors.NAME]``.
        """
        return {}

    def te_study(self, errors, *, metric: str = "peak"):
        """The per-sample Monte Carlo function (``key -> metric``, rad) that `gearte run` uses.

        `TEStudy` by default; a drive overrides it when it has a cheaper exact way to take
        its metric (it must accept the same `metric` names).
        """
        from .._montecarlo import TEStudy

        return TEStudy(self, errors, metric=metric)

    def study_outputs(self, study, values_rad, folder) -> tuple[dict, list[str]]:
        """Drive-specific results of a `gearte run`, beyond the TE statistics.

        Called with the validated study, the per-sample metric values (rad) and the
        (temporary) results folder, where it may write plots. Returns the entries to add
        to ``summary.json`` and Markdown lines to append to ``report.md``. None by default.
        """
        del study, values_rad, folder
        return {}, []

    def _checked(self, errors: Mapping[str, Eccentricity]) -> dict[str, Eccentricity]:
        """Check names and shapes (at trace time) and broadcast to one entry per instance."""
        unknown = sorted(set(errors) - set(self.error_sources))
        missing = sorted(set(self.error_sources) - set(errors))
        if unknown or missing:
            raise ValueError(
                f"{type(self).__name__}: errors must name exactly {sorted(self.error_sources)}"
                + (f"; unknown {unknown}" if unknown else "") + (f"; missing {missing}" if missing else "")
            )
        out = {}
        for name, count in self.error_sources.items():
            e = errors[name]
            if not isinstance(e, Eccentricity):
                raise ValueError(f"{type(self).__name__}: errors[{name!r}] must be an Eccentricity(magnitude_um, phase_rad)")
            for what, arr in (("magnitude", e.magnitude), ("phase", e.phase)):
                if arr.shape not in ((), (1,), (count,)):
                    raise ValueError(f"{type(self).__name__}: errors[{name!r}].{what} must be a scalar or have shape ({count},), got {arr.shape}")
            out[name] = Eccentricity(jnp.broadcast_to(e.magnitude.reshape(-1) if e.magnitude.ndim else e.magnitude, (count,)),
                                     jnp.broadcast_to(e.phase.reshape(-1) if e.phase.ndim else e.phase, (count,)))
        return out
