"""The README's Python example runs as written (with fewer samples)."""

import math
import re
from fractions import Fraction
from pathlib import Path

from helpers import reference_extrema

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
    # The example's deterministic TE is Wang et al.'s (2013) eq. (9), typed in from the paper, with the planet line at
    # 7/24 (the erratum, tests/test_planetary.py), the Table 1 tolerances and every β, γ = 0.3: its peak by the
    # dense-grid and Brent reference (294.82″).
    pi, b = math.pi, 0.3
    terms = [  # (E µm, frequency × ω_s, phase) of each term of eq. (9)
        (13, Fraction(7, 8), b + pi / 9),  # E_s
        (16, Fraction(7, 24), -b + 8 * pi / 9),  # E_p
        (12, Fraction(1, 8), -b + 8 * pi / 9),  # A_s
        (8, Fraction(0), b + 10 * pi / 9),  # A_p
        (15, Fraction(1, 8), -b - pi / 9),  # A_c
        (21, Fraction(1, 8), -b + pi / 9),  # E_r
        (16, Fraction(7, 24), -b + pi / 9),  # E_p
        (8, Fraction(0), b + 8 * pi / 9),  # A_p
        (15, Fraction(1, 8), -b + pi / 9),  # A_c
    ]
    k = -1 / (48000 * math.cos(pi / 9))  # rad per µm
    hi, lo = reference_extrema([k * e for e, _, _ in terms], [p for _, _, p in terms], [f for _, f, _ in terms])
    assert math.isclose(peak_arcsec, max(hi, -lo) * 180 * 3600 / pi, rel_tol=1e-6)
    assert round(peak_arcsec, 2) == 294.82
