"""The command line: the only part of gearte that reads study files, writes results and draws plots."""

from .config import Study as Study
from .config import load_study as load_study
from .main import main as main
from .run import run_study as run_study

__all__ = ["Study", "load_study", "main", "run_study"]
