"""The study kinds, in the order they run: a new kind is one class and one line here."""

from __future__ import annotations

from .allocation_kind import Allocation
from .budget_kind import Budget
from .doe_kind import Doe
from .kind_base import AbstractStudyKind
from .modification_kind import Modification
from .sensitivity_kind import Sensitivity

STUDY_KINDS: tuple[AbstractStudyKind, ...] = (
    Allocation(),
    Budget(),
    Sensitivity(),
    Modification(),
    Doe(),
)
