"""The README's Python example runs as written (with fewer samples)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_example_runs(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert blocks, "README has no Python example"
    code = blocks[0].replace("n_samples=50_000", "n_samples=500")
    assert code != blocks[0], "the example's sample count moved; update this test"
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    out = capsys.readouterr().out
    assert "'percentiles'" in out
    peak_arcsec = float(out.splitlines()[0])
    assert 100.0 < peak_arcsec < 460.0  # within the span of the planetary Monte Carlo
