"""Identification of a grid drive (the cycloid-pin reducer of Yao & Liang 2001): exact recovery from a noise-free
record, a source the rotation error cannot see reported unseen (and why), 95 % intervals over noisy records, bad input.

One identification problem (four sources adjusted on the 52-angle grid of the example) is compiled once and
solved for every record."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte.cli.config import load_study
from gearte.drives.cycloid_pin import CycloidPin
from gearte.identification import RecordError, identification_problem, identify, synthetic_record
from gearte.identification.fit import _solve
from gearte.identification.records import MeasuredRecord, encoder_noise

ROOT = Path(__file__).resolve().parents[1]
CYCLOID = load_study(ROOT / "examples" / "cycloid_yao2001_modified.toml").drive
assert isinstance(CYCLOID, CycloidPin)
ADJUST = ["dressing_x", "setup_eccentricity", "pin_circle_eccentricity", "setup_phase"]
TRUTH = {"dressing_x": 1.5, "setup_eccentricity": 20.0, "pin_circle_eccentricity": 15.0}  # µm; every other source 0
NOISE = 2e-6  # rad (0.41″), the output encoder's noise


@pytest.fixture(scope="module")
def clean():
    return synthetic_record(CYCLOID, TRUTH, key=0)


@pytest.fixture(scope="module")
def problem(clean):
    return identification_problem(CYCLOID, clean, adjust=ADJUST)


def test_record_on_the_trace_grid(problem, clean):
    # 16 angles per pin pitch over one input revolution (the trace's), of which every 8th is one of the drive's
    # grid (2 per pitch): the record is read there as it is, without interpolation error.
    assert len(clean.theta) == 16 * 26
    assert np.isclose(clean.points_per_rev, 16 * 26)
    assert [len(r) for r in problem.rows] == [52]
    np.testing.assert_allclose(np.asarray(problem.measured([clean.te])[0]), np.asarray(clean.te)[::8], rtol=0, atol=1e-15)


def test_exact_recovery(problem, clean):
    sol = identify(CYCLOID, clean, adjust=ADJUST, key=0)  # throw=True: a failed solve raises
    assert gearte.result_name(sol.result) == "successful"
    assert sol.labels == ("dressing_x", "setup_eccentricity", "pin_circle_eccentricity")
    np.testing.assert_allclose(np.asarray(sol.magnitude), [1.5, 20.0, 15.0], rtol=0, atol=1e-6)
    assert np.all(np.isnan(np.asarray(sol.phase)))  # deviations: signed values, no phase
    assert float(sol.residual_rms) < 1e-12  # rad
    # The identified drive gives the record also between the grid's angles (its trace, 8 angles per grid step),
    # less the record's constant.
    model = CYCLOID.trace(sol.errors).te
    np.testing.assert_allclose(model + float(sol.offset[0]), np.asarray(clean.te), rtol=0, atol=1e-12)
    assert float(sol.errors["setup_phase"]) == 0.0  # unseen: held at its start


def test_unseen_source(problem, clean):
    (unseen,) = [g for g in problem.groups if g.kind == "unseen"]
    assert unseen.members == ("setup_phase",)
    # Why: the blank's set-up error displaces the profile by ΔA e^{iφ}; with ΔA = 0 the angle φ moves nothing.
    np.testing.assert_array_equal(CYCLOID.trace({}).te, CYCLOID.trace({"setup_phase": 1.0}).te)
    # From a start with ΔA ≠ 0 the phase is seen, and identified.
    seen = identification_problem(CYCLOID, clean, adjust=ADJUST, start={"setup_eccentricity": 10.0})
    assert "setup_phase" in seen.labels
    assert not [g for g in seen.groups if g.kind == "unseen"]


def test_noisy_intervals(problem, clean):
    """200 records with the encoder's noise (a solve takes milliseconds once compiled). Each check is two-sided and 4 of
    its own σ wide, so that standard errors too small or too large fail: each source's 95 % intervals hold the truth
    in 95 % of the records (binomial σ √(0.95·0.05/n)); the scatter of its values over the records is its mean
    standard error, std/mean(se) = 1 ± 4/√(2(n−1)) (a Gaussian sample's standard deviation); σ is estimated to
    4·(1/√(2·48))/√n on average (52 grid angles less three sources and the record's constant: 48 degrees of freedom)."""
    truth = np.array([1.5, 20.0, 15.0])
    n = 200
    dev, ses, sigmas = [], [], []
    for seed in range(n):
        te = encoder_noise(clean.theta, clean.te, key=seed + 1, ratio=float(CYCLOID.ratio), noise=NOISE)
        sol = _solve(problem, [jnp.asarray(te)], jax.random.key(0))
        assert gearte.result_name(sol.result) == "successful"
        m = np.asarray(sol.magnitude)
        dev.append(m - truth)
        ses.append(np.asarray(sol.magnitude_se))
        sigmas.append(float(sol.sigma))
        # The eccentricities, which the record's grid rows see well, to a few µm.
        assert np.all(np.abs(m[1:] - truth[1:]) < 3.0)
    dev, ses = np.array(dev), np.array(ses)
    coverage = np.mean(np.abs(dev) <= 1.959963984540054 * ses, axis=0)
    assert np.all(np.abs(coverage - 0.95) <= 4 * np.sqrt(0.95 * 0.05 / n)), coverage
    scatter = np.std(dev, axis=0, ddof=1) / np.mean(ses, axis=0)
    assert np.all(np.abs(scatter - 1) <= 4 / np.sqrt(2 * (n - 1))), scatter
    assert abs(np.mean(sigmas) / NOISE - 1) <= 4 / np.sqrt(2 * 48) / np.sqrt(n), np.mean(sigmas) / NOISE


def test_bad_input(clean):
    coarse = MeasuredRecord(theta=np.asarray(clean.theta)[::16], te=np.asarray(clean.te)[::16], source="coarse.csv")
    with pytest.raises(RecordError, match=r"coarse\.csv: 26 samples per input revolution, coarser than the drive's grid"):
        identification_problem(CYCLOID, coarse, adjust=ADJUST)
    short = MeasuredRecord(theta=np.asarray(clean.theta)[:7], te=np.asarray(clean.te)[:7], source="short.csv")
    with pytest.raises(RecordError, match=r"short\.csv: the record spans"):
        identification_problem(CYCLOID, short, adjust=ADJUST)
    with pytest.raises(ValueError, match=r"adjust: name each source once.*unknown \['crank'\]"):
        identification_problem(CYCLOID, clean, adjust=["crank"])
    with pytest.raises(ValueError, match="start: unknown sources"):
        identification_problem(CYCLOID, clean, adjust=ADJUST, start={"crank": 1.0})
    with pytest.raises(ValueError, match="leave revolutions and points_per_rev out"):
        synthetic_record(CYCLOID, TRUTH, key=0, revolutions=1, points_per_rev=64)


def test_command_line_identifies_a_grid_drive(tmp_path, clean, capsys):
    import json

    from gearte import cli
    from gearte.identification import write_record

    study = ROOT / "examples" / "cycloid_yao2001_modified.toml"
    rec = tmp_path / "record.csv"
    write_record(rec, clean, unit="arcsec", digits=12)
    out = tmp_path / "id"
    assert cli.main(["identify", str(study), str(rec), "--out", str(out), "--fit", ",".join(ADJUST)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert sorted(p.name for p in out.iterdir()) == sorted(s["files"]) == ["measured_vs_identified.png", "report.md", "summary.json"]
    assert s["result"] == "successful" and s["grid_angles"] == 52
    rows = {r["source"]: r for r in s["identified"]}
    for name, value in TRUTH.items():
        assert abs(rows[name]["value"] - value) < 1e-6, name  # µm; the record's 12 digits cost nothing here
    assert set(s["held_at_zero"]) == set(CYCLOID.error_sources) - set(ADJUST)
    assert [g["members"] for g in s["groups"] if g["kind"] == "unseen"] == [["setup_phase"]]
    # re-assembly needs a sinusoidal drive; a wrong source name is refused before anything is written
    for extra, match in ((["--adjust", "setup_phase"], "--adjust: re-assembly"), (["--fit", "moon"], "--fit: ['moon']")):
        assert cli.main(["identify", str(study), str(rec), "--out", str(tmp_path / "o"), *extra]) == 2
        err = capsys.readouterr().err
        assert match in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()
