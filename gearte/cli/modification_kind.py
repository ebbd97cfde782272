"""``[modification]``: choose the profile modification of a cycloid-pin disc for the reference reducer
(Yao & Liang 2001; `gearte.optimise_modification`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..core.schema import Table
from .kind_base import AbstractStudyKind, KindOutcome

if TYPE_CHECKING:
    from ..optimise.modification import ModificationSpec
    from .config import Study


class Modification(AbstractStudyKind):
    """Profile-modification optimiser of a cycloid-pin reducer (`gearte.optimise.modification`)."""

    table = "modification"

    # The cycloid-pin modules load with the first study that has this table (a study of another drive needs none).
    def read(self, t: Table, study: Study) -> ModificationSpec:
        from ..optimise.modification import ModificationSpec

        return ModificationSpec.from_table(t, study.drive)

    def run(self, study: Study, spec: ModificationSpec, *, progress: bool | None) -> KindOutcome:
        from ..drives.cycloid_pin import CycloidPin
        from ..optimise.modification import modification_report, modification_summary

        del progress
        drive = study.drive
        assert isinstance(drive, CycloidPin)  # checked when the table was read
        # An infeasible spec is reported (the best start, marked infeasible), not raised.
        sol = spec.solve(drive, throw=False)
        entry = modification_summary(drive, spec, sol)
        return KindOutcome(
            study=study,
            key="optimised_modification",
            summary=entry,
            report=lambda s: modification_report(drive, s["optimised_modification"]),
        )
