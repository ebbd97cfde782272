"""Measured records and the checks around identification, each against a value known by construction: the TE of an
output turning backwards, the input speed read from time and angle columns, the uniform grid a non-uniform record is
put on, the amplitudes and unexplained lines of a diagnosis, a grid drive's record read between the grid's angles and
its degrees of freedom, the Nyquist refusal at exactly two samples per period, a combined per-planet member refused at
re-assembly, and `gearte.record`'s start time, shortest record and line separation."""

import math
from fractions import Fraction
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte.drives import ExplicitDrive, ExplicitTerm
from gearte.identification import RecordError, diagnose, identification_problem, identify, read_record, reassemble, synthetic_record

ARCSEC = 180.0 * 3600.0 / math.pi  # arcsec per rad


def _csv(tmp_path, header, columns, meta=""):
    """A CSV file of these columns, every value to 17 significant digits (exact in float64)."""
    rows = "\n".join(",".join(f"{v:.17g}" for v in row) for row in zip(*columns))
    p = tmp_path / "record.csv"
    p.write_text(meta + header + "\n" + rows + "\n")
    return p


# 1-3. read_record


def test_output_turning_backwards_gives_the_te_in_its_own_direction(tmp_path):
    """TE = s·(θ_out − s·θ_in/i) with s the sign of the output's turning: an output turning backwards
    (θ_out = −θ_in/i − TE, leading by TE in its own, negative, direction) gives +TE, as the same TE does forwards."""
    theta = 2 * np.pi / 64 * np.arange(200)
    te = 3e-5 * np.sin(2 * theta + 0.4) + 1e-5 * np.cos(theta)
    back = read_record(_csv(tmp_path, "input_angle_rad,output_angle_rad", [theta, -theta / 8 - te], "# ratio = 8\n"))
    np.testing.assert_allclose(back.te, te, rtol=0, atol=1e-13)
    fwd = read_record(_csv(tmp_path, "input_angle_rad,output_angle_rad", [theta, theta / 8 + te], "# ratio = 8\n"))
    np.testing.assert_allclose(fwd.te, te, rtol=0, atol=1e-13)


def test_input_speed_is_read_from_time_and_angle_columns(tmp_path):
    """At 184 rpm the input turns 184/60 rev/s: θ = 2π·184/60·t, and the record's input_rpm is 184."""
    t = np.arange(300) / 500.0  # s
    theta = 2 * np.pi * 184.0 / 60.0 * t
    rec = read_record(_csv(tmp_path, "time_s,input_angle_rad,te_arcsec", [t, theta, 2.0 * np.sin(theta)]))
    assert rec.input_rpm == pytest.approx(184.0, rel=1e-12)


def test_non_uniform_record_is_interpolated_onto_its_median_step_from_its_first_sample(tmp_path):
    """Input angles a little off a uniform grid (±20 % of a step), TE linear in θ (so linear interpolation is exact):
    the record lies on θ₀ + k·median step, every step within the span, and its TE is the line there."""
    j = np.arange(300)
    h = 2 * np.pi / 100
    theta = 0.37 + h * (j + 0.2 * np.sin(1.3 * j))
    d = np.diff(theta)
    step = float(np.median(d))
    assert np.max(np.abs(d - step)) > 0.1 * step  # far from uniform (MeasuredRecord would refuse it as it is)
    line = lambda x: 5.0 + 3.0 * x  # arcsec
    rec = read_record(_csv(tmp_path, "input_angle_rad,te_arcsec", [theta, line(theta)]))
    count = int(np.floor((theta[-1] - theta[0]) / step)) + 1
    grid = theta[0] + step * np.arange(count)
    assert len(rec.theta) == count and rec.theta[0] == theta[0]
    np.testing.assert_allclose(rec.theta, grid, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.te, line(grid) / ARCSEC, rtol=0, atol=1e-15)


# 4. diagnose


def two_line_drive():
    return ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 3)], gain=1e-5)


def test_diagnosis_reads_each_lines_amplitude_and_lists_no_noise_as_unexplained():
    """A record of two model lines (a at 1, b at 3 × input speed: 1e-4 and 6e-5 rad, each with a cosine and a sine
    part), a line the model lacks (5 ×, 5e-7 rad) and white noise (σ = 1e-7 rad, 512 samples): each line's measured
    amplitude is its true one to the noise (least squares: σ√(2/n) per coefficient); the 5 × line is the one
    unexplained line, the noise's own spectral lines (a few σ√(2/n)) are not listed."""
    d = two_line_drive()
    n, sigma = 512, 1e-7
    theta = 2 * np.pi / 64 * np.arange(n)
    amp = {1: 1e-4, 3: 6e-5}
    noise = sigma * np.random.default_rng(7).standard_normal(n)
    te = 2e-6 + amp[1] * np.sin(theta + 0.3) + amp[3] * np.sin(3 * theta + 2.2) + 5e-7 * np.sin(5 * theta + 0.4) + noise
    rec = gearte.identification.MeasuredRecord(theta=theta, te=te, input_rpm=60.0)
    sol = identify(d, rec, key=0)
    dg = diagnose(identification_problem(d, rec), sol, rec)
    assert {ln.frequency: ln.measured for ln in dg.lines}.keys() == {Fraction(1), Fraction(3)}
    for ln in dg.lines:
        assert ln.measured == pytest.approx(amp[int(ln.frequency)], abs=6 * sigma * math.sqrt(2 / n))
    assert len(dg.unexplained) == 1, dg.unexplained
    ((f, a),) = dg.unexplained
    assert f == pytest.approx(5.0, abs=1e-3) and a == pytest.approx(5e-7, rel=0.05)


# 5. a grid drive's identification


class Ramp(gearte.AbstractGridDrive):
    """A grid drive whose TE on its grid (`points` angles over one input revolution) is slope · 1e-6 · θ/2π rad:
    linear in θ, so that a record's linear interpolation between its samples is exact."""

    type_name: ClassVar[str] = "test_ramp"
    points: int

    def __init__(self, points: int = 64):
        self.points = points

    @property
    def error_sources(self):
        return {"slope": gearte.SourceSpec("slope", "deviation", shape=())}

    def input_angles(self):
        return jnp.arange(self.points, dtype=float) * (2 * math.pi / self.points)

    def response(self, errors):
        e = self.checked(errors)
        return {"te": e["slope"] * 1e-6 * self.input_angles() / (2 * math.pi)}

    def te(self, response):
        return response["te"]

    @property
    def metrics(self):
        return {}

    def trace(self, errors):
        raise NotImplementedError

    @classmethod
    def from_table(cls, table):
        raise NotImplementedError


def test_grid_drive_record_between_the_grids_angles_is_interpolated():
    """A record whose step (0.7 grid steps) and start (0.23 grid steps) put its samples between the grid's angles (at
    least 0.03 grid steps off each, at a different place at each): read at the grid angles by linear interpolation, it
    is exactly the line there, and the slope (5 µm) and constant (3e-6 rad) are identified exactly."""
    drive = Ramp(64)
    h = 2 * math.pi / 64
    theta = 0.23 * h + 0.7 * h * np.arange(90)
    rec = gearte.identification.MeasuredRecord(theta=theta, te=3e-6 + 5.0 * 1e-6 * theta / (2 * math.pi))
    problem = identification_problem(drive, rec)
    (rows,) = problem.rows
    g = np.asarray(drive.input_angles())[rows]
    assert g[0] > theta[0] and not np.any(np.isclose((g[:, None] - theta[None, :]), 0.0, atol=0.02 * h))
    np.testing.assert_allclose(np.asarray(problem.measured([rec.te])[0]), 3e-6 + 5e-6 * g / (2 * math.pi), rtol=0, atol=1e-18)
    sol = identify(drive, rec, key=0)
    assert float(sol.magnitude[0]) == pytest.approx(5.0, abs=1e-9)
    assert float(sol.offset[0]) == pytest.approx(3e-6, abs=1e-15)
    assert float(sol.residual_rms) < 1e-15


def test_grid_drive_refuses_a_record_with_no_degree_of_freedom():
    """One parameter and one record constant need 3 grid angles for one degree of freedom (σ² = |r|²/(n − p)): a record
    over 2 is refused, one over 3 is identified exactly."""
    drive = Ramp(64)
    h = 2 * math.pi / 64

    def rec(samples):
        theta = 9.9 * h + 0.3 * h * np.arange(samples)
        return gearte.identification.MeasuredRecord(theta=theta, te=1e-6 + 4e-6 * theta / (2 * math.pi), source="short.csv")

    two = rec(5)  # 9.9 … 11.1 grid steps: angles 10, 11
    with pytest.raises(RecordError, match=r"short\.csv: the records hold 2 angles of the drive's grid for 1 parameters and 1 constant"):
        identification_problem(drive, two)
    three = rec(9)  # 9.9 … 12.3: angles 10, 11, 12
    assert [len(r) for r in identification_problem(drive, three).rows] == [3]
    sol = identify(drive, three, key=0)
    assert float(sol.magnitude[0]) == pytest.approx(4.0, abs=1e-9)
    assert math.isfinite(float(sol.sigma)) and float(sol.sigma) < 1e-15


# 6. Nyquist


def test_record_at_exactly_two_samples_per_period_of_the_fastest_line_is_refused():
    """The fastest line (3 × input speed) sampled 6 times per input revolution is at Nyquist: refused; 7 are enough."""
    d = two_line_drive()
    at = synthetic_record(d, d.zero_errors(), key=0, revolutions=4, points_per_rev=6)
    with pytest.raises(RecordError, match=r"6 samples per input revolution; the line at 3 × input speed needs more than 6 \(Nyquist\)"):
        identification_problem(d, at)
    above = synthetic_record(d, d.zero_errors(), key=0, revolutions=4, points_per_rev=7)
    assert identification_problem(d, above).labels == ("a", "b")


# 7. re-assembly of a combined phasor's per-planet member


def test_per_planet_member_of_a_combined_phasor_cannot_be_turned():
    """Sun and planets of 12 teeth: the planet's eccentricity (planet 1's path) acts on the sun's line (3/4 × input
    speed), so sun_manufacturing and planet_manufacturing[0] are one combined phasor; turning the planets
    (planet_manufacturing, the source of the member planet_manufacturing[0]) is refused as turning the sun is."""
    d = gearte.Planetary2KH(12, 12, 36, module=1.0)
    rng = np.random.default_rng(2)
    errs = {n: gearte.Eccentricity(rng.uniform(5, 15, s.shape), rng.uniform(0, 2 * np.pi, s.shape)) for n, s in d.error_sources.items()}
    rec = synthetic_record(d, errs, key=0, revolutions=4, points_per_rev=16)
    sol = identify(d, rec, key=0)
    assert ("combined", ("sun_manufacturing", "planet_manufacturing[0]")) in [(g.kind, g.members) for g in sol.groups]
    with pytest.raises(ValueError, match=r"adjust: 'planet_manufacturing' shares its line with sun_manufacturing"):
        reassemble(d, sol, adjust={"planet_manufacturing": None}, key=0)
    with pytest.raises(ValueError, match=r"adjust: 'sun_manufacturing' shares its line with planet_manufacturing\[0\]"):
        reassemble(d, sol, adjust={"sun_manufacturing": None}, key=0)
    group = next(g for g in sol.groups if g.kind == "combined")
    assert "turn one of the sources planet_manufacturing" in group.advice


def test_instances_of_one_source_on_one_line_are_named_and_not_offered_a_turn():
    """Three load-sharing planets: their eccentricities act on one line together, one combined phasor of one
    source. The refusal names them (it had named nobody) and the advice does not offer a turn, which turns every
    planet together and keeps their combination."""
    d = gearte.Planetary2KH(12, 36, 84, module=1.0, coupling=gearte.LoadSharing())
    rng = np.random.default_rng(3)
    errs = {n: gearte.Eccentricity(rng.uniform(5, 15, s.shape), rng.uniform(0, 2 * np.pi, s.shape)) for n, s in d.error_sources.items()}
    sol = identify(d, synthetic_record(d, errs, key=0, revolutions=4, points_per_rev=64), key=0)
    group = next(g for g in sol.groups if g.kind == "combined" and g.members[0].startswith("planet_manufacturing"))
    assert group.members == ("planet_manufacturing[0]", "planet_manufacturing[1]", "planet_manufacturing[2]")
    assert "instances of one source, planet_manufacturing" in group.advice and "turn one of" not in group.advice
    with pytest.raises(ValueError, match=r"adjust: 'planet_manufacturing' has its instances planet_manufacturing\[0\], .* on one line"):
        reassemble(d, sol, adjust={"planet_manufacturing": None}, key=0)


# 8. gearte.record and spectral_lines


def _signal(lines):
    """The TE Σ A sin(kθ + φ) over (k, A, φ) as a `gearte.TESignal` (A sin(kθ + φ) = A sin φ cos kθ + A cos φ sin kθ)."""
    return gearte.TESignal(
        offset=jnp.asarray(0.0),
        cos_coef=jnp.asarray([a * math.sin(p) for _, a, p in lines]),
        sin_coef=jnp.asarray([a * math.cos(p) for _, a, p in lines]),
        orders=tuple(k for k, _, _ in lines),
        fundamental=Fraction(1),
    )


def test_lines_of_a_record_started_late_have_their_phases_at_t_0():
    """At 60 rpm (θ = 2π t, 0 at t = 0) a record from t₀ = 0.13 s: its input angles start at 0.26π, and its lines
    A sin(2π f t + φ) read the phases φ at t = 0, not those at its first sample (φ + 2π f t₀)."""
    lines = [(3, 2e-5, 0.7), (5, 1e-5, 2.0)]
    rec = gearte.record(_signal(lines), input_rpm=60.0, duration_s=2.0, sample_rate_hz=128.0, start_s=0.13)
    assert rec.time[0] == pytest.approx(0.13) and rec.theta[0] == pytest.approx(0.26 * math.pi, rel=1e-14)
    np.testing.assert_allclose(rec.te, sum(a * np.sin(2 * np.pi * k * rec.time + p) for k, a, p in lines), rtol=0, atol=1e-18)
    found = gearte.spectral_lines(rec)
    assert len(found.freq_cpm) == 2
    np.testing.assert_allclose(found.freq_cpm, [180.0, 300.0], rtol=1e-9)
    np.testing.assert_allclose(found.amplitude, [2e-5, 1e-5], rtol=1e-8)
    np.testing.assert_allclose(np.angle(np.exp(1j * (found.phase - [0.7, 2.0]))), 0.0, atol=1e-8)


def test_record_of_exactly_16_samples_is_accepted_and_15_refused():
    sig = _signal([(1, 1e-5, 0.0)])
    rec = gearte.record(sig, input_rpm=60.0, duration_s=1.0, sample_rate_hz=16.0)
    assert len(rec.time) == len(rec.te) == 16
    with pytest.raises(ValueError, match=r"record: 1 s at 15 Hz is only 15 samples \(at least 16\)"):
        gearte.record(sig, input_rpm=60.0, duration_s=1.0, sample_rate_hz=15.0)


def test_spectral_lines_refuse_a_separation_under_the_hann_main_lobe():
    """Lines closer than 2 bins are inside one Hann main lobe: a separation of 1.9 bins (or 0, or NaN) is refused;
    2 bins is accepted."""
    rec = gearte.record(_signal([(3, 2e-5, 0.7)]), input_rpm=60.0, duration_s=2.0, sample_rate_hz=128.0)
    for bad in (1.9, 0.0, math.nan):
        with pytest.raises(ValueError, match=r"min_separation_bins: must be ≥ 2 \(the Hann main lobe\)"):
            gearte.spectral_lines(rec, min_separation_bins=bad)
    assert gearte.spectral_lines(rec, min_separation_bins=2.0).freq_cpm == pytest.approx([180.0], rel=1e-9)


def test_identify_names_a_bad_argument_before_it_fits():
    """Turns as one dict (not one per record), a turn per planet (turns turn a whole source), starts or steps below
    one, something that is not a record: refused naming the argument, before any fit."""
    d = two_line_drive()
    theta = 2 * np.pi / 64 * np.arange(256)
    rec = gearte.identification.MeasuredRecord(theta=theta, te=1e-4 * np.sin(theta) + 6e-5 * np.sin(3 * theta))
    for kwargs, match in (
        (dict(turns={"a": 1.0}), r"turns: one dict per record"),
        (dict(turns=[{"a": [0.0, 1.0]}]), r"turns\['a'\]: one angle \(rad\) per source"),
        (dict(turns=[{"a": float("nan")}]), r"turns\['a'\]: must be finite"),
        (dict(starts=0), r"identify: starts: must be ≥ 1, got 0"),
        (dict(max_steps=0), r"identify: max_steps: must be ≥ 1, got 0"),
    ):
        with pytest.raises(ValueError, match=match):
            identify(d, rec, key=0, **kwargs)
    with pytest.raises(ValueError, match=r"records: every record must be a MeasuredRecord"):
        identify(d, [rec, theta], key=0)  # pyright: ignore[reportArgumentType]
