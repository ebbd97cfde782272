"""What the README tells a user holds: public names only, the files gearte writes, the extrema bound,
what `make demo` runs, and papers cited by author and year."""

import importlib
import re
from pathlib import Path

import gearte
import gearte.core.extrema

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_readme_names_only_public_gearte_objects():
    names = set(re.findall(r"`(gearte(?:\.[A-Za-z_][A-Za-z0-9_]*)+)", README))
    assert len(names) > 20, names
    for name in sorted(names):
        parts = name.split(".")
        assert not any(p.startswith("_") for p in parts), f"README sends users to a private name: {name}"
        if name.endswith(".py"):
            continue  # a file of the layout section
        obj = gearte
        for i, p in enumerate(parts[1:], start=1):
            if not hasattr(obj, p):
                obj = importlib.import_module(".".join(parts[: i + 1]))  # a module such as gearte.drives.cycloid_pin
            else:
                obj = getattr(obj, p)


def test_readme_describes_the_files_gearte_writes():
    section = README.split("### Results folders", 1)[1].split("\n## ", 1)[0]
    described = set(re.findall(r"`([a-z_]+\.(?:png|npz|json|md))`", section))
    source = "\n".join(p.read_text(encoding="utf-8") for p in (ROOT / "gearte").rglob("*.py"))
    written = set(re.findall(r"[\"']([a-z_]+\.(?:png|npz|json|md))[\"']", source))
    assert {"report.md", "summary.json", "samples.npz", "histogram.png", "trace.png", "comparison.json", "overlay.png"} <= described
    assert described <= written | {"report.md"}, described - written
    assert written - {"study-files.md"} <= described, f"files gearte writes that the README does not describe: {written - described}"


def test_readme_states_the_extrema_bound_the_code_claims():
    claimed = re.search(r"≤ (1e-\d+) relative", gearte.core.extrema.__doc__ or "")
    stated = re.findall(r"within (1e-\d+) relative", README)
    assert claimed and stated == [claimed.group(1)], (claimed, stated)


def test_readme_describes_what_make_demo_runs():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    demo = makefile.split("\ndemo:", 1)[1].split("\n\n", 1)[0]
    runs = re.findall(r"gearte run (examples/\S+)", demo)
    assert len(runs) == 3 and "gearte compare" in demo
    assert "runs three planetary studies and compares them" in README
    assert "after compilation" in README


def test_papers_cited_by_author_and_year_not_by_seed_numbers():
    assert not re.search(r"seed 0\d\d", README)
    for cite in ("Wang et al. (2013)", "Yao & Liang 2001"):
        assert cite in README, cite
