"""What a study kind is: a table of the study file, read and validated, then run around the Monte Carlo.

Every kind (`[allocation]`, `[budget]`, …) is one subclass of `AbstractStudyKind`, registered in
`gearte.cli.kinds.STUDY_KINDS`; the runner and the config reader never special-case one.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.schema import Table
from ..drives.protocol import Figure

if TYPE_CHECKING:
    from .config import Study


@dataclasses.dataclass
class Finish:
    """What a kind is told after the study's own Monte Carlo: the values (study unit), the typical
    sample's index, and a function giving any study's TE trace of that sample (input revolutions, study unit)."""

    values: np.ndarray
    typical: int
    trace: Callable[[Study, int], tuple[np.ndarray, np.ndarray]]


@dataclasses.dataclass
class KindOutcome:
    """The result of running a kind: the study to continue with, its summary entry (under `key`),
    its figures, a report section (Markdown lines, given the final summary), and an optional
    step after the study's own Monte Carlo. That step runs on the process that writes the results
    alone (in a several-process run, process 0): it must not compute across the processes."""

    study: Study
    key: str
    summary: dict
    figures: list[Figure] = dataclasses.field(default_factory=list)
    report: Callable[[dict], list[str]] = lambda summary: []
    finish: Callable[[Finish, dict], list[Figure]] | None = None


class AbstractStudyKind(abc.ABC):
    """One kind of study: its table name, how the table is read, and how it runs."""

    table: str

    @abc.abstractmethod
    def read(self, t: Table, study: Study) -> Any:
        """Validate the kind's table (every key; the caller refuses unknown ones) into a spec."""

    def check_absent(self, study: Study) -> None:
        """Raise a ConfigError if the study needs this kind's table but has none."""
        del study

    def check_together(self, study: Study) -> None:
        """Raise a ConfigError if this kind cannot run with the other kinds present."""
        del study

    def evaluations(self, study: Study, spec: Any) -> int:
        """At least how many drive samples (one sample's forward evaluation, or its equivalent) the kind computes
        besides the study's own Monte Carlo: `gearte run` adds them when it estimates a run before starting it (a
        lower bound: an optimiser's iterations beyond the first are not counted). 0 for a kind that computes no
        Monte Carlo of its own."""
        del study, spec
        return 0

    @abc.abstractmethod
    def run(self, study: Study, spec: Any, *, progress: bool | None) -> KindOutcome:
        """Run the kind before the study's Monte Carlo."""
