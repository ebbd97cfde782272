"""The command line: the only part of gearte that reads study files, writes results and draws plots."""

from .main import main as main

__all__ = ["main"]
