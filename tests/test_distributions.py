"""Samplers against their laws (KS tests, as jax/tests/random_lax_test.py does) and phase rules."""

import math

import equinox as eqx
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from jax.test_util import check_grads
from scipy import stats
from scipy import stats as sps

import gearte
from gearte import ErrorModel, ErrorSource
from gearte.drives import wang2013

N = 20_000


def draw(law, key=0, n=N):
    return np.asarray(law.sample(jax.random.key(key), (n,)))


def test_rayleigh():
    x = draw(gearte.Rayleigh(6.5))
    assert stats.kstest(x, stats.rayleigh(scale=6.5).cdf).pvalue > 0.01


def test_rayleigh_truncated_at_the_tolerance_is_the_conditional_law():
    s, T = 6.5, 13.0
    x = draw(gearte.Rayleigh(s, truncate_at=T))
    assert x.max() <= T
    cond = lambda v: stats.rayleigh(scale=s).cdf(np.minimum(v, T)) / stats.rayleigh(scale=s).cdf(T)
    assert stats.kstest(x, cond).pvalue > 0.01
    # Tight truncation (most draws would be rejected by resampling) is still exact.
    y = draw(gearte.Rayleigh(10.0, truncate_at=1.0))
    cond2 = lambda v: stats.rayleigh(scale=10.0).cdf(np.minimum(v, 1.0)) / stats.rayleigh(scale=10.0).cdf(1.0)
    assert y.max() <= 1.0 and stats.kstest(y, cond2).pvalue > 0.01


def test_truncated_normal_uniform_normal_fixed():
    x = draw(gearte.TruncatedNormal(5.0, 4.0, 0.0, 12.0))
    a, b = (0 - 5) / 4, (12 - 5) / 4
    assert stats.kstest(x, stats.truncnorm(a, b, loc=5, scale=4).cdf).pvalue > 0.01
    assert stats.kstest(draw(gearte.Uniform(2.0, 9.0)), stats.uniform(2.0, 7.0).cdf).pvalue > 0.01
    assert stats.kstest(draw(gearte.Normal(3.0, 2.0)), stats.norm(3.0, 2.0).cdf).pvalue > 0.01
    np.testing.assert_array_equal(draw(gearte.Fixed(4.0), n=5), np.full(5, 4.0))


def test_signed_laws_for_deviations():
    # One law family for every drive: a deviation (a pin-radius error, a pitch error) is signed.
    np.testing.assert_array_equal(draw(gearte.Fixed(-1.5), n=5), np.full(5, -1.5))
    x = draw(gearte.Uniform(-3.0, 2.0))
    assert x.min() >= -3.0 and x.max() <= 2.0
    assert stats.kstest(x, stats.uniform(-3.0, 5.0).cdf).pvalue > 0.01
    # A tolerance band c ± h (the old SignedUniform).
    y = draw(gearte.Uniform.centred(2.0, 1.0))
    assert stats.kstest(y, stats.uniform(-1.0, 4.0).cdf).pvalue > 0.01
    np.testing.assert_allclose([float(gearte.Uniform.centred(2.0, 1.0).low), float(gearte.Uniform.centred(2.0, 1.0).high)], [-1.0, 3.0])


def test_a_budget_scales_a_band_about_its_centre_and_a_range_about_zero():
    """`scaled(f, about_centre=True)`, how a budget scales a deviation's law, by hand at the quartiles: a band
    (Uniform.centred, a Normal) keeps its centre and scales its spread; a range [low, high] and a truncated normal
    are scaled about 0 (low and high times f), as a magnitude is."""
    u = np.asarray([0.25, 0.5, 0.75])
    cases = (
        (gearte.Uniform.centred(2.0, 3.0), 3.0 + 2.0 * 2.0 * (2 * u - 1)),  # 3 ± 4
        (gearte.Normal(3.0, 1.0), 3.0 + 2.0 * sps.norm.ppf(u)),  # mean 3, std 2
        (gearte.Uniform(1.0, 5.0), 2.0 + 8.0 * u),  # [2, 10]
    )
    for law, want in cases:
        np.testing.assert_allclose(np.asarray(law.scaled(2.0, about_centre=True).ppf(jnp.asarray(u))), want, rtol=1e-12)
    t = gearte.TruncatedNormal(5.0, 4.0, 0.0, 12.0).scaled(2.0, about_centre=True)
    assert (float(t.mean), float(t.std), float(t.low), float(t.high)) == (10.0, 8.0, 0.0, 24.0)


U = np.linspace(0.01, 0.99, 9)


@pytest.mark.parametrize(
    "law,params",
    [
        (gearte.Uniform(2.0, 9.0), ("low", "high")),
        (gearte.Normal(3.0, 2.0), ("mean", "std")),
        (gearte.TruncatedNormal(5.0, 4.0, 0.0, 12.0), ("mean", "std", "low", "high")),
        (gearte.Rayleigh(6.5, truncate_at=13.0), ("scale", "truncate_at")),
        (gearte.Rayleigh(6.5), ("scale",)),
    ],
    ids=lambda v: type(v).__name__ if isinstance(v, gearte.AbstractLaw) else "",
)
def test_inverse_cdf_gradients_in_the_law_parameters(law, params):
    # Budgets and sensitivities differentiate draws through the law parameters (reparameterised
    # draws = inverse CDF of fixed uniforms): check those derivatives against float64 differences.
    def f(theta):
        moved = eqx.tree_at(lambda m: tuple(getattr(m, n) for n in params), law, tuple(theta[i] for i in range(len(params))))
        return moved.ppf(jnp.asarray(U))

    theta = jnp.asarray([float(getattr(law, n)) for n in params])
    check_grads(jax.jit(f), (theta,), order=1, modes=["fwd", "rev"], eps=1e-6, atol=1e-8, rtol=1e-6)
    # ... and `sample` is the inverse CDF of uniform draws (a Normal draws its normals directly).
    if not isinstance(law, gearte.Normal):
        key = jax.random.key(5)
        np.testing.assert_allclose(law.sample(key, (7,)), law.ppf(jax.random.uniform(key, (7,), dtype=float)), rtol=1e-14)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.1, 50.0), st.one_of(st.none(), st.floats(0.3, 10.0)), st.lists(st.floats(0.0, 0.999), min_size=1, max_size=8))
def test_rayleigh_inverse_cdf_against_scipy(scale, ratio, u):
    # Conditioned on ≤ T (T = ratio · scale): F⁻¹(u) = F_R⁻¹(u · F_R(T)).
    law = gearte.Rayleigh(scale) if ratio is None else gearte.Rayleigh(scale, truncate_at=ratio * scale)
    ref = sps.rayleigh(scale=scale)
    p = np.asarray(u) * (1.0 if ratio is None else ref.cdf(ratio * scale))
    np.testing.assert_allclose(np.asarray(law.ppf(jnp.asarray(u))), ref.ppf(p), rtol=1e-10, atol=1e-12 * scale)


def test_uniform_phase():
    x = draw(gearte.UniformPhase())
    assert x.min() >= 0 and x.max() < 2 * math.pi
    assert stats.kstest(x, stats.uniform(0, 2 * math.pi).cdf).pvalue > 0.01


def _eccentricity_model(law):
    spec = {"e": gearte.SourceSpec("e", "eccentricity")}
    return ErrorModel({"e": ErrorSource(law, gearte.UniformPhase())}, spec)


@pytest.mark.parametrize(
    "make,match",
    [
        # A magnitude cannot be negative: signed laws are legal (deviations are signed), so the check
        # is where a law becomes a magnitude (the error model) and where a magnitude is given (Eccentricity).
        (lambda: _eccentricity_model(gearte.Fixed(-1.0)), "negative"),
        (lambda: _eccentricity_model(gearte.Uniform(-1.0, 2.0)), "negative"),
        (lambda: gearte.Eccentricity(-5.0, 0.0), "negative"),
        (lambda: gearte.Eccentricity([1.0, -5.0], 0.0), "negative"),
        (lambda: gearte.Uniform.centred(-1.0), "negative"),
        (lambda: gearte.Fixed(float("nan")), "finite"),
        (lambda: gearte.Uniform(5.0, 1.0), "high"),
        (lambda: gearte.Rayleigh(0.0), "> 0"),
        (lambda: gearte.Rayleigh(1.0, truncate_at=-2.0), "> 0"),
        (lambda: gearte.Normal(1.0, -1.0), "negative"),
        (lambda: gearte.TruncatedNormal(1.0, 1.0, 3.0, 2.0), "low < high"),
        (lambda: gearte.RelativePhase("", 0.0), "name"),
    ],
)
def test_bad_laws(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def specs(counts):
    """Declared eccentricity sources with these instance counts (as a drive's `error_sources`)."""
    return {n: gearte.SourceSpec(n, "eccentricity", shape=(c,)) for n, c in counts.items()}


def test_relative_phase_rule_and_per_planet_broadcast():
    counts = specs({"a": 1, "b": 3, "c": 1})
    model = ErrorModel(
        {
            "a": ErrorSource(gearte.Fixed(1.0), gearte.UniformPhase()),
            "b": ErrorSource(gearte.Fixed(2.0), gearte.RelativePhase("a", 7 * math.pi / 9)),
            "c": ErrorSource(gearte.Fixed(3.0), gearte.RelativePhase("a", -1.0)),
        },
        counts,
    )
    e = jax.vmap(model.sample)(jax.random.split(jax.random.key(3), 100))
    np.testing.assert_allclose(e["b"].phase - e["a"].phase, 7 * math.pi / 9, atol=1e-12)
    np.testing.assert_allclose(e["c"].phase[:, 0] - e["a"].phase[:, 0], -1.0, atol=1e-12)
    assert e["b"].phase.shape == (100, 3)


def test_magnitude_and_deviation_laws_in_the_error_model():
    spec = {"e": gearte.SourceSpec("e", "eccentricity"), "d": gearte.SourceSpec("d", "deviation", shape=(4,))}
    # A signed deviation takes a signed law, and no phase.
    model = ErrorModel({"e": ErrorSource(gearte.Fixed(2.0), gearte.FixedPhase(0.5)), "d": ErrorSource(gearte.Fixed(-1.0))}, spec)
    e = model.sample(jax.random.key(0))
    np.testing.assert_array_equal(e["d"], np.full(4, -1.0))
    np.testing.assert_array_equal(e["e"].magnitude, [2.0])
    with pytest.raises(ValueError, match="no phase law"):
        ErrorModel({"e": ErrorSource(1.0, gearte.UniformPhase()), "d": ErrorSource(1.0, gearte.UniformPhase())}, spec)
    with pytest.raises(ValueError, match="phase law"):
        ErrorModel({"e": ErrorSource(1.0), "d": ErrorSource(1.0)}, spec)
    # A normal magnitude is allowed, as in 0.1: a negative draw is that magnitude at the opposite phase.
    m = _eccentricity_model(gearte.Normal(5.0, 1.0))
    assert m.sample(jax.random.key(1))["e"].magnitude.shape == (1,)
    # Checked on Wang et al.'s planetary (Table 1 tolerances, fixed phases): the sun's eccentricity drawn at −13 µm
    # (a normal law of zero spread) at phase 0.4 gives the TE of +13 µm at 0.4 + π.
    drive = wang2013.table1_drive()
    fixed = {n: ErrorSource(gearte.Fixed(t), gearte.FixedPhase(0.1 * i)) for i, (n, t) in enumerate(wang2013.TABLE1_TOLERANCES_UM.items())}
    negative = ErrorModel(
        dict(fixed, sun_manufacturing=ErrorSource(gearte.Normal(-13.0, 0.0), gearte.FixedPhase(0.4))), drive.error_sources
    )
    opposite = ErrorModel(
        dict(fixed, sun_manufacturing=ErrorSource(gearte.Fixed(13.0), gearte.FixedPhase(0.4 + math.pi))), drive.error_sources
    )
    e_neg, e_opp = negative.sample(jax.random.key(2)), opposite.sample(jax.random.key(2))
    sun = e_neg["sun_manufacturing"]
    z = np.asarray(sun.magnitude) * np.exp(1j * np.asarray(sun.phase))  # the drawn phasor, however it is written
    np.testing.assert_allclose(z, [13.0 * np.exp(1j * (0.4 + math.pi))], rtol=1e-15, atol=1e-13)
    s_neg, s_opp = drive.signal(e_neg), drive.signal(e_opp)
    assert float(jnp.max(jnp.abs(s_neg.sin_coef))) > 1e-5  # rad: the TE is not zero
    for a, b in ((s_neg.offset, s_opp.offset), (s_neg.cos_coef, s_opp.cos_coef), (s_neg.sin_coef, s_opp.sin_coef)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-18)
    peak = [float(gearte.TEStudy(drive, mod, metric=gearte.Peak())(jax.random.key(2))) for mod in (negative, opposite)]
    assert peak[0] == pytest.approx(peak[1], rel=1e-12)


def test_rule_errors():
    counts = specs({"a": 1, "b": 1})
    with pytest.raises(ValueError, match="cycle"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("b")), "b": ErrorSource(1.0, gearte.RelativePhase("a"))}, counts)
    with pytest.raises(ValueError, match="not an error source"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("z")), "b": ErrorSource(1.0, 0.0)}, counts)
    with pytest.raises(ValueError, match="cannot follow"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("b")), "b": ErrorSource(1.0, 0.0)}, specs({"a": 1, "b": 3}))
    with pytest.raises(ValueError, match="missing"):
        ErrorModel({"a": ErrorSource(1.0, 0.0)}, counts)
    with pytest.raises(ValueError, match="unknown"):
        ErrorModel({"a": ErrorSource(1.0, 0.0), "b": ErrorSource(1.0, 0.0), "x": ErrorSource(1.0, 0.0)}, counts)


def test_source_keys_follow_the_drives_declared_order():
    """Source j of a sample draws from fold_in(key, j), j its index in the drive's declared order: here z, b, m, which
    is neither alphabetical (b, m, z), nor the order the sources are given in (b, m, z), nor the order they are drawn in
    (m before z, whose phase follows m's: m, z, b). An eccentricity splits its key into magnitude and phase keys."""
    drive = gearte.ExplicitDrive([gearte.ExplicitTerm(n, f) for n, f in (("z", 1), ("b", 2), ("m", 3))], gain=1e-5)
    assert list(drive.error_sources) == ["z", "b", "m"]
    model = ErrorModel(
        {
            "b": ErrorSource(gearte.Uniform(1.0, 2.0), gearte.UniformPhase()),
            "m": ErrorSource(gearte.Uniform(3.0, 5.0), gearte.UniformPhase()),
            "z": ErrorSource(gearte.Uniform(6.0, 9.0), gearte.RelativePhase("m", 0.3)),
        },
        drive.error_sources,
    )
    assert model.order != ("z", "b", "m")  # drawn in another order than declared
    key = jax.random.key(17)
    e = model.sample(key)

    def by_hand(j, low, high):
        k_mag, k_ph = jax.random.split(jax.random.fold_in(key, j))
        u = float(jax.random.uniform(k_mag, (1,), dtype=float)[0])
        return low + (high - low) * u, 2 * math.pi * float(jax.random.uniform(k_ph, (1,), dtype=float)[0])

    z_mag, _ = by_hand(0, 6.0, 9.0)
    b_mag, b_ph = by_hand(1, 1.0, 2.0)
    m_mag, m_ph = by_hand(2, 3.0, 5.0)
    assert list(e) == ["z", "b", "m"]
    for name, mag, ph in (("z", z_mag, m_ph + 0.3), ("b", b_mag, b_ph), ("m", m_mag, m_ph)):
        assert float(e[name].magnitude[0]) == pytest.approx(mag, rel=1e-15), name
        assert float(e[name].phase[0]) == pytest.approx(ph, rel=1e-15), name
