"""What `gearte.allocate_rule` minimises over the unknown phases: the rule objectives, by name.

Apart from `gearte.optimise.allocation` (which re-exports them) so that reading a study file's
``[allocation] objective`` imports no solver.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

__all__ = ["RULE_OBJECTIVES", "AbstractRuleObjective", "Expected", "Robust", "WorstCase"]


class AbstractRuleObjective(eqx.Module):
    """What `allocate_rule` minimises over the unknown phases (`WorstCase`, `Expected`, `Robust`)."""

    name: ClassVar[str]


class WorstCase(AbstractRuleObjective):
    """The worst case: magnitudes at the tolerances, the worst unknown phases (exact; every unknown phase must
    drive one frequency)."""

    name: ClassVar[str] = "worst_case"


class Expected(AbstractRuleObjective):
    """The expected TE: magnitudes at the tolerances, mean over uniform unknown phases."""

    name: ClassVar[str] = "expected"


class Robust(AbstractRuleObjective):
    """The expected TE with the magnitudes drawn by their laws too (e.g. Rayleigh within the tolerance)."""

    name: ClassVar[str] = "robust"


#: The rule objectives by name (a study file's ``[allocation] objective``).
RULE_OBJECTIVES: dict[str, type[AbstractRuleObjective]] = {c.name: c for c in (WorstCase, Expected, Robust)}
