"""`gearte identify` and `gearte assemble`: results folders, and bad input refused with exit status 2."""

import json
from pathlib import Path

from gearte import cli

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "examples" / "planetary_wang2013_random.toml"
RECORD = ROOT / "examples" / "records" / "planetary_wang2013_record.csv"


def test_identify_writes_its_folder(tmp_path):
    out = tmp_path / "id"
    assert cli.main(["identify", str(STUDY), str(RECORD), "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert sorted(p.name for p in out.iterdir()) == sorted(s["files"]) == ["measured_vs_identified.png", "report.md", "summary.json"]
    rows = {r["source"]: r for r in s["identified"]}
    # the example's true sun eccentricity (examples/records/make_records.py): 13 µm at 0.6 rad
    lo, hi = rows["sun_manufacturing"]["magnitude_95_um"]
    assert lo <= 13.0 <= hi
    assert next(g["kind"] for g in s["groups"]) == "combined"


def test_bad_record_and_parts_are_refused(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("input_angle_rad,te_arcsec\n" + "\n".join(f"{i * 0.1},1" for i in [0, 2, 1] + list(range(3, 30))))
    assert cli.main(["identify", str(STUDY), str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearte: error") and "must increase strictly" in err and "Traceback" not in err
    parts = tmp_path / "parts.csv"
    parts.write_text("source,magnitude_um,phase_rad\nmoon_manufacturing,1,0\n")
    assert cli.main(["assemble", str(parts), "--study", str(STUDY), "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "not an error source" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.csv", "parts.csv"]


def test_an_unknown_adjust_source_is_refused_before_the_fit(tmp_path, capsys, monkeypatch):
    from gearte.cli import identify_cmd

    def no_fit(*a, **k):
        raise AssertionError("fitted before checking --adjust")

    monkeypatch.setattr(identify_cmd, "_solve", no_fit)
    assert cli.main(["identify", str(STUDY), str(RECORD), "--out", str(tmp_path / "o"), "--adjust", "nosuchsource"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gearte: error: --adjust: 'nosuchsource': not an error source") and "Traceback" not in err
    assert not any(tmp_path.iterdir())


def test_parts_files_are_refused_naming_the_file_and_its_own_line(tmp_path, capsys):
    """Parts CSV mistakes name the file and the line as the file numbers it (comments and blank lines counted)."""
    ok = "sun_manufacturing,1,0\n" + "planet_manufacturing,1,0\n" * 3 + "ring_manufacturing,1,0\n"  # one drive
    cases = [
        ("binary", b"source,magnitude_um,phase_rad\n\xff\xfe,1,0\n", "not a UTF-8 text file"),
        (
            "both",
            "source,magnitude_um,phase_rad,phase_deg\nsun_manufacturing,1,0,0\n",
            "line 1: the header names both phase_rad and phase_deg",
        ),
        ("comment", "# measured 2026-11-28\n\nsource,magnitude_um,phase_rad\n" + ok + "sun_manufacturing,-1,0\n", "line 9: the magnitude"),
        ("uneven", "source,magnitude_um,phase_rad\n" + ok + "sun_manufacturing,2,0\n", "drives but the other part types make"),
    ]
    for name, text, message in cases:
        parts = tmp_path / f"{name}.csv"
        (parts.write_bytes if isinstance(text, bytes) else parts.write_text)(text)  # type: ignore[operator]
        assert cli.main(["assemble", str(parts), "--study", str(STUDY), "--out", str(tmp_path / "a")]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"gearte: error in config: {parts}: ") and message in err and "Traceback" not in err, (name, err)
    assert not (tmp_path / "a").exists()
