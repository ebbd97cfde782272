"""The command line: the only part of gearte that reads study files, writes results and draws plots.

Its names are loaded on first use, so that `gearte --help` imports neither JAX nor matplotlib.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# `main` is imported now (it is light): the name must be the function, not the submodule `gearte.cli.main`.
from .main import main as main

if TYPE_CHECKING:
    from .config import Study as Study
    from .config import load_study as load_study
    from .run import run_study as run_study

_LAZY = {"Study": ".config", "load_study": ".config", "run_study": ".run"}

__all__ = ["Study", "load_study", "main", "run_study"]


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
