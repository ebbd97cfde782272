"""``[sensitivity]``: pathwise sensitivities of the Monte Carlo means to the parameters of the error laws
(`gearte.pathwise_sensitivities`), for any drive."""

from __future__ import annotations

import dataclasses
import difflib
from typing import TYPE_CHECKING

from ..core.schema import MAX_SAMPLES, ConfigError, Table
from ..studies.sensitivity_pathwise import pathwise_report, pathwise_sensitivities, pathwise_summary
from .kind_base import AbstractStudyKind, KindOutcome

if TYPE_CHECKING:
    from .config import Study


@dataclasses.dataclass(frozen=True)
class SensitivitySpec:
    """`[sensitivity]`: `pathwise_samples` samples, metrics `pathwise_metrics` (names of the drive's metrics)."""

    pathwise_samples: int
    pathwise_metrics: tuple[str, ...]


class Sensitivity(AbstractStudyKind):
    """Pathwise sensitivities of the means of the drive's metrics to every law parameter."""

    table = "sensitivity"

    def read(self, t: Table, study: Study) -> SensitivitySpec:
        n = t.integer("pathwise_samples", 64, minimum=1, maximum=MAX_SAMPLES)
        offered = study.drive.metrics
        names = t.get("pathwise_metrics", [study.metric.name])
        if not isinstance(names, list) or not names or not all(isinstance(x, str) for x in names):
            raise ConfigError(f"{t.where} pathwise_metrics: give a list of metric names, some of {list(offered)}")
        for x in names:
            if x not in offered:
                hint = difflib.get_close_matches(x, list(offered), n=1)
                raise ConfigError(
                    f"{t.where} pathwise_metrics: {x!r} is not a metric of {study.drive.type_name}"
                    + (f" (did you mean {hint[0]!r}?)" if hint else "")
                    + f"; use some of {list(offered)}"
                )
        return SensitivitySpec(n, tuple(names))

    def evaluations(self, study: Study, spec: SensitivitySpec) -> int:
        # a gradient per sample and metric (counted as one evaluation: a lower bound)
        return spec.pathwise_samples * len(spec.pathwise_metrics)

    def run(self, study: Study, spec: SensitivitySpec, *, progress: bool | None) -> KindOutcome:
        del progress
        metrics = study.drive.metrics
        res = pathwise_sensitivities(
            study.drive, study.errors, [metrics[m] for m in spec.pathwise_metrics], key=study.seed, n_samples=spec.pathwise_samples
        )
        entry = pathwise_summary(res, study.errors, metrics, unit=study.unit)
        return KindOutcome(
            study=study, key="tolerance_sensitivities", summary=entry, report=lambda s: pathwise_report(s["tolerance_sensitivities"])
        )
