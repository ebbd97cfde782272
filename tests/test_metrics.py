"""Exact TE metrics: against closed forms and an independent dense + Brent reference."""

import math
from fractions import Fraction

import equinox as eqx
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import reference_extrema, trig_eval
from hypothesis import example, given, settings
from jax.test_util import check_grads

import gearte

SETTINGS = settings(max_examples=25, deadline=None)

# Metrics are objects, `metric(drive, signal)`; a sinusoidal drive reads a signal through its
# exact extrema, whatever the signal, so any such drive serves for bare signals.
ANY_DRIVE = gearte.ExplicitDrive([gearte.ExplicitTerm("a", 1)], gain=1.0)
METRICS = (gearte.Peak(), gearte.PeakToPeak(), gearte.RMS())


def te_metric(signal, metric):
    return metric(ANY_DRIVE, signal)


def make(amps, phases, freqs, gain=1.0):
    return gearte.to_signal(gearte.Components(np.asarray(amps, float), np.asarray(phases, float), freqs, gain=gain))


# Rational frequencies with small denominators, as drive kinematics produce them.
freq_st = st.builds(lambda n, d: Fraction(n, d), st.integers(-30, 30), st.sampled_from([1, 2, 3, 8, 24, 45]))


@st.composite
def components(draw, max_n=6):
    n = draw(st.integers(1, max_n))
    freqs = draw(st.lists(freq_st, min_size=n, max_size=n))
    amps = draw(st.lists(st.floats(0.0, 30.0), min_size=n, max_size=n))
    phases = draw(st.lists(st.floats(0.0, 2 * math.pi), min_size=n, max_size=n))
    return np.array(amps), np.array(phases), freqs


@st.composite
def signals(draw, max_n=6):
    """Components whose extrema are a real test: 2-6 terms at distinct non-zero frequencies, amplitudes 0.1-30 (no
    all-zero, single-term or subnormal draws, which the extrema's scale floor or a lone sine passes trivially)."""
    nonzero = freq_st.filter(lambda f: f != 0)
    freqs = draw(st.lists(nonzero, min_size=2, max_size=max_n, unique_by=abs))
    n = len(freqs)
    amps = draw(st.lists(st.floats(0.1, 30.0), min_size=n, max_size=n))
    phases = draw(st.lists(st.floats(0.0, 2 * math.pi), min_size=n, max_size=n))
    return np.array(amps), np.array(phases), freqs


def test_as_frequency():
    as_frequency = gearte.as_frequency
    assert as_frequency("11/24") == Fraction(11, 24)
    assert as_frequency(0.125) == Fraction(1, 8)
    assert as_frequency(3) == Fraction(3)
    for bad in ("seven", math.nan, True, 0.12345678912345):
        with pytest.raises(ValueError):
            as_frequency(bad)


def test_canonical_form_of_planetary_frequencies():
    s = make([1, 1, 1, 1], [0, 0, 0, 0], ["7/8", "-7/24", "1/8", 0])
    assert s.orders == (3, 7, 21)
    assert s.fundamental == Fraction(1, 24)
    assert s.hyper_period_revs == 24


@SETTINGS
@given(components(), st.floats(-3.0, 3.0))
def test_evaluate_matches_plain_sum(comp, gain):
    amps, phases, freqs = comp
    theta = np.linspace(-7.0, 50.0, 101)
    got = gearte.evaluate(make(amps, phases, freqs, gain), theta)
    # Rounding of sin(rθ + φ) grows with the argument (|rθ| ≤ 1500 rad here) and the amplitudes.
    atol = 1e-14 * (1 + abs(gain) * amps.sum()) * 1500
    np.testing.assert_allclose(got, gain * trig_eval(amps, phases, freqs, theta), rtol=1e-12, atol=atol)


# The exact search is compiled once per signal structure (its orders), ~1-2 s each: the three
# whole-period properties below (exact against the dense reference, positively homogeneous in
# the amplitudes, invariant to a shift of the input angle) are checked on the same drawn
# structure, so each of the 25 examples compiles once instead of three times. Derandomized
# (as the study-file fuzzing is): every run draws the same 25 structures, so the persistent
# compilation cache serves them (10 s warm, measured, instead of 51 s, where fresh structures each
# compile anew on every run).
@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(signals(), st.floats(0.05, 20.0), st.floats(-100.0, 100.0))
# Beats of near-equal frequencies (many nearly equal maxima) and two equal crests a half-period apart (a tie).
@example((np.array([10.0, 9.0, 1.5]), np.array([0.3, 1.1, 2.0]), [Fraction(2), Fraction(91, 45), Fraction(1)]), 3.0, 17.0)
@example((np.array([5.0, 5.0]), np.array([0.0, 0.0]), [Fraction(1), Fraction(3)]), 0.5, -2.0)
def test_extrema_exact_linear_in_amplitudes_and_invariant_to_a_shift(comp, c, shift):
    amps, phases, freqs = comp
    base = make(amps, phases, freqs)
    # Exact against an independent dense + Brent reference.
    e = gearte.extrema(base)
    ref_max, ref_min = reference_extrema(amps, phases, freqs)
    scale = max(abs(ref_max), abs(ref_min), 1e-12)
    assert abs(float(e.max) - ref_max) <= 1e-6 * scale
    assert abs(float(e.min) - ref_min) <= 1e-6 * scale
    # The located angles really give those values.
    np.testing.assert_allclose(trig_eval(amps, phases, freqs, [float(e.theta_max)])[0], float(e.max), rtol=0, atol=1e-12 * scale)
    # Linear in the amplitudes: every metric of c·TE is c times the metric of TE.
    scaled = make(c * amps, phases, freqs)
    for m in METRICS:
        np.testing.assert_allclose(te_metric(scaled, m), c * te_metric(base, m), rtol=1e-9, atol=1e-12, err_msg=f"linear: {m.name}")
    # Starting the record elsewhere, φ_j → φ_j + r_j·δ, changes no whole-period metric.
    shifted = phases + np.array([float(f) for f in freqs]) * shift
    for m in METRICS:
        np.testing.assert_allclose(
            te_metric(make(amps, shifted, freqs), m), te_metric(base, m), rtol=1e-8, atol=1e-10, err_msg=f"shift: {m.name}"
        )


def test_extrema_beats_of_near_equal_frequencies():
    # Harmonic-drive-like beats: 2 and 91/45 (× input) add to many nearly equal maxima.
    amps, phases, freqs = [10.0, 9.0, 1.5], [0.3, 1.1, 2.0], [2, Fraction(91, 45), 1]
    e = gearte.extrema(make(amps, phases, freqs))
    ref_max, ref_min = reference_extrema(amps, phases, freqs)
    np.testing.assert_allclose([float(e.max), float(e.min)], [ref_max, ref_min], rtol=1e-9)


def test_extrema_under_a_large_offset_the_float32_grid_cannot_resolve():
    # The grid is evaluated in float32 (it only ranks blocks); its rounding bound enters the certificate. A constant
    # offset 2²³ times the oscillation puts the shape at float32's resolution: without that bound, a block whose
    # float32 maximum rounded down is wrongly certified away (in ~1 of 3 of these signals, by up to 17 % of the
    # oscillation); with it, every extremum is exact to float64's resolution at the offset.
    rng = np.random.default_rng(0)
    n, off = 200, 2.0**23
    ph = rng.uniform(0.0, 2.0 * math.pi, (n, 3))
    amps, freqs = np.array([1.0, 0.05, 0.05]), [21, 1, 2]
    comps = gearte.Components(
        np.broadcast_to(np.append(amps, off), (n, 4)), np.concatenate([ph, np.full((n, 1), math.pi / 2)], axis=1), [*freqs, 0], gain=1.0
    )
    e = gearte.extrema(gearte.to_signal(comps))
    tau = np.linspace(0.0, 2.0 * math.pi, 50_000, endpoint=False)
    dense = sum(amps[i] * np.sin(freqs[i] * tau[None, :] + ph[:, i : i + 1]) for i in range(3))
    # Exact ≥ the dense grid (to float64 rounding at 2²³: 2e-9), and above it by no more than the grid's own error.
    for got, ref in ((np.asarray(e.max) - off, dense.max(axis=1)), (-(np.asarray(e.min) - off), -dense.min(axis=1))):
        assert np.all(got >= ref - 1e-8)
        assert np.all(got <= ref + 21**2 * (2 * math.pi / 50_000) ** 2)


def test_closed_forms():
    a, phi = 3.0, 0.7
    s = make([a], [phi], [Fraction(5, 3)])
    np.testing.assert_allclose(gearte.peak(s), a, rtol=1e-12)
    np.testing.assert_allclose(gearte.peak_to_peak(s), 2 * a, rtol=1e-12)
    np.testing.assert_allclose(gearte.rms(s), a / math.sqrt(2), rtol=1e-12)
    # Two equal-frequency components add as phasors: |A1 e^{iφ1} + A2 e^{iφ2}|.
    a1, a2, p1, p2 = 5.0, 3.0, 0.2, 2.5
    s2 = make([a1, a2], [p1, p2], [2, 2])
    np.testing.assert_allclose(gearte.peak(s2), abs(a1 * np.exp(1j * p1) + a2 * np.exp(1j * p2)), rtol=1e-12)
    # π apart: |A1 − A2| (Wang et al. 2013, sec. 1).
    np.testing.assert_allclose(gearte.peak(make([a1, a2], [0.4, 0.4 + math.pi], [2, 2])), a1 - a2, rtol=1e-12)
    # A constant is part of the peak (it is "max |Δθ|"), not of the peak-to-peak.
    s3 = make([a, 2.0], [phi, math.pi / 2], [1, 0])
    np.testing.assert_allclose(gearte.peak(s3), a + 2.0, rtol=1e-12)
    np.testing.assert_allclose(gearte.peak_to_peak(s3), 2 * a, rtol=1e-12)
    np.testing.assert_allclose(gearte.rms(s3), math.sqrt(4.0 + a * a / 2), rtol=1e-12)


def test_metric_objects_are_the_exact_functions():
    s = make([3.0, 2.0, 1.0], [0.7, 0.1, 1.0], ["5/3", "1/3", 0])
    for m, f in zip(METRICS, (gearte.peak, gearte.peak_to_peak, gearte.rms)):
        assert isinstance(m, gearte.AbstractMetric)
        assert float(m(ANY_DRIVE, s)) == float(f(s))
        # Exact metrics of a sinusoidal TE are Lipschitz already: their optimiser surrogate is the value itself.
        assert float(m.smooth(ANY_DRIVE, s)) == float(f(s))
        assert m.quantity == "angle" and m.homogeneous and not m.higher_is_better and m.label and m.describe()
    # A sinusoidal drive offers the three, peak first (the default metric of a study).
    assert [m.name for m in METRICS] == list(ANY_DRIVE.metrics) == ["peak", "peak_to_peak", "rms"]


def test_spectrum_lines():
    s = make([5.0, 3.0, 2.0], [0.2, 2.5, 1.0], ["7/8", "7/8", "-1/8"])
    sp = gearte.spectrum(s)
    assert sp.freq == (Fraction(1, 8), Fraction(7, 8))
    np.testing.assert_allclose(sp.amplitude, [2.0, abs(5 * np.exp(0.2j) + 3 * np.exp(2.5j))], rtol=1e-12)
    # 2 sin(−θ/8 + 1) = 2 sin(θ/8 + π − 1)
    np.testing.assert_allclose(np.mod(float(sp.phase[0]), 2 * math.pi), math.pi - 1.0, rtol=1e-12)


def test_zero_errors_zero_te_and_finite_gradients():
    freqs = ["7/8", "7/24", "1/8", 0]

    def f(metric):
        return lambda a, p: te_metric(gearte.to_signal(gearte.Components(a, p, freqs)), metric)

    a0, p0 = jnp.zeros(4), jnp.zeros(4)
    for metric in METRICS:
        assert float(f(metric)(a0, p0)) == 0.0
        ga, gp = jax.grad(f(metric), argnums=(0, 1))(a0, p0)
        assert np.all(np.isfinite(ga)) and np.all(np.isfinite(gp))
    g = jax.grad(lambda a: gearte.smooth_peak(gearte.to_signal(gearte.Components(a, p0, freqs)), width=1e-3))(a0)
    assert np.all(np.isfinite(g))


def test_gradient_finite_at_ties():
    # A pure sinusoid: max = −min exactly, so `peak` is a max over a tie.
    g = jax.grad(lambda a: gearte.peak(gearte.to_signal(gearte.Components(a, jnp.array([0.3]), [1]))))(jnp.array([2.0]))
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, [1.0], rtol=1e-9)


@pytest.mark.parametrize("metric", METRICS, ids=lambda m: m.name)
def test_gradients_against_finite_differences(metric):
    rng = np.random.default_rng(3)
    freqs = ["7/8", "7/24", "1/8", "1/8", 0, "-7/24"]
    amps = rng.uniform(2, 20, len(freqs))
    phases = rng.uniform(0, 2 * math.pi, len(freqs))

    def f(a, p):
        return te_metric(gearte.to_signal(gearte.Components(a, p, freqs, gain=1e-5)), metric)

    # Away from ties the exact metrics are smooth: check first-order derivatives in float64.
    check_grads(f, (jnp.asarray(amps), jnp.asarray(phases)), order=1, modes=["rev"], eps=1e-6, atol=1e-9, rtol=1e-6)


def test_smooth_peak_bounds_and_gradient():
    rng = np.random.default_rng(4)
    freqs = ["7/8", "7/24", "1/8", 0]
    amps, phases = rng.uniform(1, 10, 4), rng.uniform(0, 6, 4)
    s = make(amps, phases, freqs)
    width = 0.05
    sp = float(gearte.smooth_peak(s, width=width))
    exact = float(gearte.peak(s))
    m = 16 * 21 * 2  # grid points of both signs
    assert exact - 0.02 * exact <= sp <= exact + width * math.log(m)
    check_grads(
        lambda a: gearte.smooth_peak(gearte.to_signal(gearte.Components(a, phases, freqs)), width=width),
        (jnp.asarray(amps),),
        order=2,
        modes=["rev"],
        eps=1e-5,
        atol=1e-6,
        rtol=1e-5,
    )
    with pytest.raises(ValueError, match="width"):
        gearte.smooth_peak(s, width=0.0)


def test_vmap_equals_loop():
    rng = np.random.default_rng(5)
    freqs = ["7/8", "7/24", "1/8", 0]
    amps, phases = rng.uniform(0, 10, (20, 4)), rng.uniform(0, 6, (20, 4))
    f = lambda a, p: gearte.peak(gearte.to_signal(gearte.Components(a, p, freqs)))
    batched = jax.vmap(f)(amps, phases)
    one = jax.jit(f)  # one sample at a time (compiled once for all 20)
    looped = [one(a, p) for a, p in zip(amps, phases)]
    # Batched and unbatched code may round differently in the last bit.
    np.testing.assert_allclose(np.asarray(batched), np.asarray(looped), rtol=1e-13, atol=0)


def test_no_recompilation_for_new_values():
    freqs = ["7/8", "7/24", "1/8", 0]

    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def f(a, p):
        return gearte.peak(gearte.to_signal(gearte.Components(a, p, freqs)))

    rng = np.random.default_rng(6)
    for _ in range(3):
        f(jnp.asarray(rng.uniform(0, 9, 4)), jnp.asarray(rng.uniform(0, 6, 4)))


def test_bad_options():
    s = make([1.0], [0.0], [1])
    with pytest.raises(ValueError, match="oversample"):
        gearte.extrema(s, oversample=4)
    # Metrics are objects now: a name is refused where a metric is chosen (the study), naming what to give.
    model = gearte.ErrorModel({"a": gearte.ErrorSource(1.0, gearte.UniformPhase())}, ANY_DRIVE.error_sources)
    with pytest.raises(ValueError, match="metric"):
        gearte.TEStudy(ANY_DRIVE, model, metric="max")
    with pytest.raises(ValueError, match="last axis"):
        gearte.Components(np.ones(3), np.ones(2), [1, 2, 3])
