"""Every notebook in notebooks/ runs top to bottom without an error.

Each notebook is executed cell by cell in an IPython shell in the test process
(`notebook_runner.run_notebook`: what a Jupyter kernel runs, without the kernel process),
from the notebooks folder, with ``GEARTE_NOTEBOOK_SAMPLES=2000`` (and ``GEARTE_NOTEBOOK_RV_UNITS=24``
for the RV reducer, whose units are equilibrium solves) so that the Monte Carlo studies stay short. Each runs on the worker that runs the tests of its subject
(`conftest.NOTEBOOK_GROUPS`), so it reuses their compiled functions.
Notebooks are kept in the repository without outputs; that is checked too.
"""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from notebook_runner import run_notebook

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
SAMPLES = "2000"
RV_UNITS = "24"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_runs(path: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path):
    monkeypatch.setenv("GEARTE_NOTEBOOK_SAMPLES", SAMPLES)
    monkeypatch.setenv("GEARTE_NOTEBOOK_RV_UNITS", RV_UNITS)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    assert run_notebook(path, ipython_dir=tmp_path / "ipython") > 0


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_stored_without_outputs(path: Path):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    dirty = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and (c.get("outputs") or c.get("execution_count") is not None)]
    assert not dirty, f"{path.name}: clear the outputs before committing (code cells {dirty} have outputs or execution counts)"


def test_a_raising_cell_fails_the_run(tmp_path: Path):
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("x = 1"), nbformat.v4.new_markdown_cell("text"), nbformat.v4.new_code_cell("1 / (x - 1)")]
    path = tmp_path / "bad.ipynb"
    nbformat.write(nb, path)
    with pytest.raises(AssertionError, match=r"bad.ipynb: cell 2 raised ZeroDivisionError"):
        run_notebook(path, ipython_dir=tmp_path / "ipython")
