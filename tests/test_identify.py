"""Identification from measured TE records: exact recovery, interval coverage over seeded trials, the combined-phasor
rule (and its separation by a second record with a known turn), the Jacobian against finite differences, bad records."""

import math
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from trace_count import lowerings, traces

import gearte
from gearte.cli.config import load_study
from gearte.drives import ExplicitDrive, ExplicitTerm, wang2013
from gearte.identification import RecordError, diagnose, identification_problem, identify, read_record, reassemble, synthetic_record
from gearte.identification.fit import Z95, _solve
from gearte.identification.records import encoder_noise, write_record

ROOT = Path(__file__).resolve().parents[1]
PLANETARY = load_study(ROOT / "examples" / "planetary_wang2013_random.toml").drive
HARMONIC = load_study(ROOT / "examples" / "harmonic_liu.toml").drive
REVS, PPR = 24, 64  # the planetary hyper-period; lines up to 7/8 × input speed


def planetary_errors(seed=1):
    rng = np.random.default_rng(seed)
    tol = wang2013.TABLE1_TOLERANCES_UM
    return {
        n: gearte.Eccentricity(np.full(s.shape, float(tol[n])), rng.uniform(0, 2 * np.pi, s.shape))
        for n, s in PLANETARY.error_sources.items()
    }


def combined_ring_phasor(drive, e):
    """The 1/8 line of Wang et al.'s Table 2 (planet 1, η = 0): ring + sun assembly + carrier assembly, as one ring eccentricity.
    Ring: +E_r sin(… + β_r − α_n); sun assembly: −A_s sin(… + γ_s + α_w); carrier: +A_c [sin(… + γ_c + α_w) + sin(… + γ_c − α_n)]."""
    aw, an = float(drive.working_angle_external), float(drive.working_angle_internal)

    def z(name, extra, sign=1.0):
        return sign * float(e[name].magnitude[0]) * np.exp(1j * (float(e[name].phase[0]) + extra))

    total = z("ring_manufacturing", -an) + z("sun_assembly", aw, -1.0) + z("carrier_assembly", aw) + z("carrier_assembly", -an)
    w = total * np.exp(1j * an)  # the ring's own phase: the line carries β − α_n
    return abs(w), np.angle(w) % (2 * np.pi)


def check_intervals(dev, se):
    """`dev`, `se`: (trials, estimates) deviations from the truth and reported standard errors. Two-sided checks, each
    4 of its own σ wide, so that standard errors too small or too large fail: the coverage of the 95 % intervals
    against the binomial σ √(0.95·0.05/n) of its n trials (a coverage near 1 passes this alone), and the scatter
    std(dev)/mean(se) against 1 ± 4/√(2(n−1)) (the relative σ of a Gaussian sample's standard deviation; the
    standard errors themselves vary by under 2 % from trial to trial)."""
    n = dev.shape[0]
    coverage = np.mean(np.abs(dev) <= Z95 * se, axis=0)
    assert np.all(np.abs(coverage - 0.95) <= 4 * math.sqrt(0.95 * 0.05 / n)), coverage
    scatter = np.std(dev, axis=0, ddof=1) / np.mean(se, axis=0)
    assert np.all(np.abs(scatter - 1) <= 4 / math.sqrt(2 * (n - 1))), scatter


@pytest.fixture(scope="module")
def planetary():
    errs = planetary_errors()
    clean = synthetic_record(PLANETARY, errs, key=0, revolutions=REVS, points_per_rev=PPR)
    problem = identification_problem(PLANETARY, clean)
    return errs, clean, problem


def test_exact_recovery_and_combined_phasor(planetary):
    errs, clean, problem = planetary
    sol = _solve(problem, [jnp.asarray(clean.te)], jax.random.key(0))
    assert gearte.result_name(sol.result) == "successful"
    assert sol.labels == ("sun_manufacturing", "planet_manufacturing[0]", "ring_manufacturing")
    m_ring, p_ring = combined_ring_phasor(PLANETARY, errs)
    truth_m = [13.0, 16.0, m_ring]
    truth_p = [float(errs["sun_manufacturing"].phase[0]) % (2 * np.pi), float(errs["planet_manufacturing"].phase[0]) % (2 * np.pi), p_ring]
    np.testing.assert_allclose(np.asarray(sol.magnitude), truth_m, rtol=1e-8)
    np.testing.assert_allclose(np.angle(np.exp(1j * (np.asarray(sol.phase) - truth_p))), 0.0, atol=1e-8)
    kinds = {g.kind: g for g in sol.groups}
    assert kinds["combined"].members == ("ring_manufacturing", "sun_assembly", "carrier_assembly")
    assert kinds["combined"].frequencies == (gearte.as_frequency("1/8"),)
    assert "turn one of the sources carrier_assembly, sun_assembly" in kinds["combined"].advice
    assert kinds["unseen"].members == ("planet_manufacturing[1]", "planet_manufacturing[2]", "planet_assembly[1]", "planet_assembly[2]")
    assert kinds["constant"].members == ("planet_assembly[0]",)
    # a member of a combined phasor cannot be turned alone
    with pytest.raises(ValueError, match="shares its line with"):
        reassemble(PLANETARY, sol, adjust={"sun_assembly": None}, key=0)


def test_coverage_of_95_percent_intervals(planetary):
    """200 seeded records (Gaussian encoder noise 0.4″ and 2^20 counts per revolution): each identified magnitude and
    phase lies within its 95 % interval in 95 % of the trials, and its scatter over the trials is its reported standard
    error (both checked two-sided, see `check_intervals`)."""
    errs, clean, problem = planetary
    m_ring, p_ring = combined_ring_phasor(PLANETARY, errs)
    truth_m = np.array([13.0, 16.0, m_ring])
    truth_p = np.array([float(errs["sun_manufacturing"].phase[0]), float(errs["planet_manufacturing"].phase[0]), p_ring])
    ratio = float(PLANETARY.ratio)
    dev, se = [], []
    for trial in range(200):
        te = encoder_noise(clean.theta, clean.te, key=trial, ratio=ratio, noise=2e-6, counts_per_rev=2**20)
        sol = _solve(problem, [jnp.asarray(te)], jax.random.key(trial))
        m, p = np.asarray(sol.magnitude), np.asarray(sol.phase)
        dev.append(np.concatenate([m - truth_m, np.angle(np.exp(1j * (p - truth_p)))]))
        se.append(np.concatenate([np.asarray(sol.magnitude_se), np.asarray(sol.phase_se)]))
    check_intervals(np.array(dev), np.array(se))


def test_second_record_with_a_turn_separates_the_combined_phasor(planetary):
    errs, _clean, _ = planetary
    turns = [{}, {"sun_assembly": math.pi / 2}, {"carrier_assembly": 2.0}]
    recs = [synthetic_record(PLANETARY, errs, key=0, revolutions=REVS, points_per_rev=PPR, turns=t) for t in turns]
    sol = identify(PLANETARY, recs, turns=turns, key=0)
    assert set(sol.labels) >= {"ring_manufacturing", "sun_assembly", "carrier_assembly"}
    assert not [g for g in sol.groups if g.kind == "combined"]
    for name in ("ring_manufacturing", "sun_assembly", "carrier_assembly"):
        i = sol.labels.index(name)
        assert abs(float(sol.magnitude[i]) - float(errs[name].magnitude[0])) < 1e-7
        assert abs(np.angle(np.exp(1j * (float(sol.phase[i]) - float(errs[name].phase[0]))))) < 1e-8


@pytest.fixture(scope="module")
def harmonic():
    rng = np.random.default_rng(3)
    errs = {
        n: gearte.Eccentricity(rng.uniform(2, 10, s.shape), rng.uniform(0, 2 * np.pi, s.shape)) for n, s in HARMONIC.error_sources.items()
    }
    rec = synthetic_record(HARMONIC, errs, key=0, revolutions=45, points_per_rev=400)
    return errs, rec, identification_problem(HARMONIC, rec)


def test_harmonic_classes_are_combined_and_cs_phase_is_modulo_pi(harmonic):
    errs, rec, _ = harmonic
    sol = identify(HARMONIC, rec, key=0)
    assert sol.labels == ("cs_pitch", "fs_pitch", "wg_shaft_runout", "cs_tooth_to_tooth")
    np.testing.assert_allclose(np.asarray(sol.phase_period), [np.pi, np.pi, 2 * np.pi, 2 * np.pi])
    # Each class line is identified exactly: the model with the identified errors reproduces the record.
    model = np.asarray(gearte.evaluate(HARMONIC.signal(sol.errors), jnp.asarray(rec.theta))) + float(sol.offset[0])
    assert np.max(np.abs(model - rec.te)) < 1e-12
    # the CS class phasor, by hand (Liu's eq. 2: e sin(2(θ + Θ + α_n))/cos α_n for run-outs, no 1/cos α_n for F_p)
    g, a = float(HARMONIC.gain()), float(HARMONIC.pressure_angle)
    z = 0j
    for s in HARMONIC.sources:
        if s.source_class == "circular_spline":
            f = 1.0 if s.kind == "cumulative_pitch" else 1.0 / math.cos(a)
            z += g * f * float(errs[s.name].magnitude[0]) * np.exp(2j * (float(errs[s.name].phase[0]) + a))
    assert abs(float(sol.magnitude[0]) * g - abs(z)) < 1e-9 * abs(z)
    dg = diagnose(identification_problem(HARMONIC, rec), sol, rec)
    top = dg.lines[0]
    assert top.frequency == 2 and top.parts[0][0] == "cs_pitch" and abs(top.parts[0][1] - 1.0) < 1e-9
    assert "flex_bearing_runout" in top.parts[0][3]


def test_coverage_of_95_percent_intervals_harmonic(harmonic):
    """The harmonic example's four identified phasors (the CS and FS class phasors, the wave generator's run-out and the
    CS tooth-to-tooth line) from 200 seeded records with encoder noise (2 µrad, 2^20 counts per revolution): each
    magnitude and phase lies within its 95 % interval in 95 % of the trials, and its scatter over the trials is its
    reported standard error (both checked two-sided, see `check_intervals`). The truth is the noise-free
    identification, which reproduces the noise-free record to 1e-12 rad (above)."""
    _errs, rec, problem = harmonic
    exact = _solve(problem, [jnp.asarray(rec.te)], jax.random.key(0))
    truth_m, truth_p, period = np.asarray(exact.magnitude), np.asarray(exact.phase), np.asarray(exact.phase_period)
    dev, se = [], []
    for trial in range(200):
        te = encoder_noise(rec.theta, rec.te, key=1000 + trial, ratio=float(HARMONIC.ratio), noise=2e-6, counts_per_rev=2**20)
        sol = _solve(problem, [jnp.asarray(te)], jax.random.key(trial))
        m, p = np.asarray(sol.magnitude), np.asarray(sol.phase)
        dp = (p - truth_p + period / 2) % period - period / 2  # phases known modulo their period
        dev.append(np.concatenate([m - truth_m, dp]))
        se.append(np.concatenate([np.asarray(sol.magnitude_se), np.asarray(sol.phase_se)]))
    check_intervals(np.array(dev), np.array(se))


def test_jacobian_matches_finite_differences(planetary):
    _, clean, problem = planetary
    z = [jnp.asarray(problem.q_factors[0]).T @ jnp.asarray(clean.te)]
    y = jnp.asarray([3.0, -4.0, 5.0, 1.0, -2.0, 7.0, 10.0])
    jac = np.asarray(jax.jacfwd(lambda v: problem._residual(v, z))(y))
    h = 1e-5
    fd = np.stack(
        [
            (np.asarray(problem._residual(y.at[i].add(h), z)) - np.asarray(problem._residual(y.at[i].add(-h), z))) / (2 * h)
            for i in range(len(y))
        ],
        axis=1,
    )
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.abs(jac).max())


def test_reassembly_predicts_lower_te(planetary):
    _errs, clean, problem = planetary
    sol = _solve(problem, [jnp.asarray(clean.te)], jax.random.key(0))
    alloc = reassemble(PLANETARY, sol, adjust={"sun_manufacturing": None, "planet_manufacturing": None}, key=0, starts=4)
    assert float(alloc.te) < float(alloc.te_before)
    # te_before is the record's own peak about its constant (exact, so at least the sampled peak, and within 1 % of it)
    sampled = float(np.max(np.abs(clean.te - float(sol.offset[0]))))
    assert sampled - 1e-12 <= float(alloc.te_before) <= 1.01 * sampled


def _csv(tmp_path, text, name="r.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_read_record_forms_agree(tmp_path, planetary):
    _, clean, _ = planetary
    write_record(tmp_path / "a.csv", clean, unit="arcsec", digits=12)
    a = read_record(tmp_path / "a.csv")
    np.testing.assert_allclose(a.te, clean.te, atol=1e-15 + 1e-11 * np.abs(clean.te).max())
    out_deg = np.degrees(clean.theta / 8 + clean.te)
    rows = "\n".join(f"{t:.15g},{o:.15g}" for t, o in zip(np.degrees(clean.theta), out_deg))
    b = read_record(_csv(tmp_path, "# ratio = 8\ninput_angle_deg,output_angle_deg\n" + rows))
    np.testing.assert_allclose(b.te, clean.te, atol=1e-12)
    t = clean.theta / (2 * np.pi) * 60 / 30.0  # 30 rpm
    np.savez(tmp_path / "c.npz", time_s=t, te=clean.te * 206264.80624709636, input_rpm=30.0)
    c = read_record(tmp_path / "c.npz", units={"te": "arcsec"})
    np.testing.assert_allclose(c.theta, clean.theta, atol=1e-12)
    np.testing.assert_allclose(c.te, clean.te, atol=1e-15)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "input_angle_rad,te_arcsec\n" + "\n".join(f"{i * 0.1},{1.0}" for i in [0, 1, 2, 1.5] + list(range(3, 20))),
            "must increase strictly",
        ),
        ("input_angle_rad,te_arcsec\n" + "\n".join(f"{i * 0.1},{1.0}" for i in list(range(10)) + list(range(14, 30))), "gap in the record"),
        ("input_angle_rad,te\n" + "\n".join(f"{i * 0.1},1" for i in range(20)), "has no unit"),
        ("input_angle_rad,te_furlong\n" + "\n".join(f"{i * 0.1},1" for i in range(20)), "unknown unit 'furlong'"),
        ("input_angle_rad,te_rad\n" + "\n".join(f"{i * 0.1},{30 * math.sin(i)}" for i in range(20)), "check the TE column's unit"),
        (
            "# ratio = 8\ninput_angle_rad,output_angle_rad\n" + "\n".join(f"{i * 0.1},{math.degrees(i * 0.1 / 8)}" for i in range(20)),
            "check the angle units",
        ),
        ("time_s,te_arcsec\n" + "\n".join(f"{i * 0.1},1" for i in range(20)), "needs the input speed"),
        ("input_angle_rad,te_arcsec\n" + "\n".join(f"{i * 0.1},nan" for i in range(20)), "not a finite number"),
        # The file's own line numbers (the header is line 2 here), and no reader's warning or 0-based row.
        ("# input_rpm = 60\ninput_angle_rad,te_arcsec\n0,1\n0.1,abc\n", r"line 4: 'abc' is not a number"),
        ("input_angle_rad,te_arcsec\n0,1\n0.1,1,2\n", r"line 3: 3 values but 2 column names"),
        ("input_angle_rad,te_arcsec\n\n# nothing measured\n", "no data rows below the header"),
    ],
)
def test_bad_records_are_refused(tmp_path, text, message):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a reader's own warning (an empty file) would reach the user
        with pytest.raises(RecordError, match=message):
            read_record(_csv(tmp_path, text))


def test_too_short_or_too_slow_record_says_how_long(planetary):
    errs, _, _ = planetary
    short = synthetic_record(PLANETARY, errs, key=0, revolutions=6, points_per_rev=PPR, input_rpm=60.0)
    with pytest.raises(RecordError, match=r"needs at least 1/1/8 = 8 revolutions \(8 s at 60 rpm\)"):
        identify(PLANETARY, short, key=0)
    slow = synthetic_record(PLANETARY, errs, key=0, revolutions=REVS, points_per_rev=1)
    with pytest.raises(RecordError, match="Nyquist"):
        identify(PLANETARY, slow, key=0)


def test_a_second_problem_of_the_same_drive_traces_and_compiles_nothing():
    """`identification_problem` twice for one drive and record grid, other turn values: the second call traces and
    lowers nothing (the coefficients, their Jacobian and the signal's layout are jitted once at module level, not made
    anew in each call), and it reads the second call's turn: turned by 0, the second record repeats the first and a, b
    (one line) stay combined; turned by π/2 it separates them."""
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 1, offset=0.3), ExplicitTerm("c", 3)], gain=1e-5)
    rec = synthetic_record(d, d.zero_errors(), key=0, revolutions=2, points_per_rev=32)
    first = identification_problem(d, [rec, rec], turns=[{}, {"b": 0.0}])
    assert [(g.kind, g.members) for g in first.groups] == [("combined", ("a", "b"))]
    with traces() as seen, lowerings() as lowered:
        second = identification_problem(d, [rec, rec], turns=[{}, {"b": math.pi / 2}])
    assert not seen and not lowered, (dict(seen), dict(lowered))
    assert second.labels == ("a", "b", "c") and not second.groups
    assert second.turns == ((), (("b", math.pi / 2),))
