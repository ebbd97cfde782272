"""Run a notebook top to bottom in an IPython shell inside the test process.

A Jupyter kernel (ipykernel) is an IPython shell behind a messaging layer; here the shell is
created directly, so the notebook runs exactly its cells (magics, display of a cell's last
expression, tracebacks) without a kernel process. Running in the test process shares what
is already compiled: a notebook that calls the same gearte functions on the same shapes as the
tests of its subject does not compile them again (see `conftest.py`, which runs each notebook on
the worker that runs those tests).

The notebook sees what a user's kernel sees: the folder of the notebook as working directory,
JAX's standard dtype promotion (the suite itself runs with strict promotion), a non-interactive
matplotlib backend, and its own namespace.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import jax
import nbformat
from IPython.core.interactiveshell import InteractiveShell
from traitlets.config import Config


class NotebookCellError(AssertionError):
    """A notebook cell raised: the notebook's name, the cell's number and source, and the error."""


def run_notebook(path: Path, *, ipython_dir: Path) -> int:
    """Execute every code cell of the notebook at `path` in order; returns the number of code cells run.

    Raises `NotebookCellError` at the first cell that raises (its number and source, the error chained).
    """
    import matplotlib.pyplot as plt

    nb = nbformat.read(path, as_version=4)
    config = Config()
    config.HistoryManager.enabled = False  # no history database under the user's home
    config.InteractiveShell.colors = "nocolor"
    shell = InteractiveShell(config=config, ipython_dir=str(ipython_dir))
    shell.user_ns["__name__"] = "__main__"
    cwd = Path.cwd()
    ran = 0
    try:
        os.chdir(path.parent)
        with jax.numpy_dtype_promotion("standard"), warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=".*non-interactive.*cannot be shown", category=UserWarning)
            for i, cell in enumerate(nb.cells):
                if cell.cell_type != "code":
                    continue
                result = shell.run_cell(cell.source, store_history=False, silent=False)
                ran += 1
                err = result.error_before_exec or result.error_in_exec
                if err is not None:
                    raise NotebookCellError(
                        f"{path.name}: cell {i} raised {type(err).__name__}: {err}\n--- cell source ---\n{cell.source}"
                    ) from err
    finally:
        os.chdir(cwd)
        plt.close("all")
        shell.cleanup()
        InteractiveShell.clear_instance()
    return ran
