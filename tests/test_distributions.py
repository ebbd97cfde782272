"""Samplers against their laws (KS tests, as jax/tests/random_lax_test.py does) and phase rules."""

import math

import jax
import numpy as np
import pytest
from scipy import stats

import gearte
from gearte._errors import ErrorModel, ErrorSource

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


def test_uniform_phase():
    x = draw(gearte.UniformPhase())
    assert x.min() >= 0 and x.max() < 2 * math.pi
    assert stats.kstest(x, stats.uniform(0, 2 * math.pi).cdf).pvalue > 0.01


@pytest.mark.parametrize("make,match", [
    (lambda: gearte.Fixed(-1.0), "negative"),
    (lambda: gearte.Fixed(float("nan")), "finite"),
    (lambda: gearte.Uniform(5.0, 1.0), "high"),
    (lambda: gearte.Rayleigh(0.0), "> 0"),
    (lambda: gearte.Rayleigh(1.0, truncate_at=-2.0), "> 0"),
    (lambda: gearte.Normal(1.0, -1.0), "negative"),
    (lambda: gearte.TruncatedNormal(1.0, 1.0, 3.0, 2.0), "low < high"),
    (lambda: gearte.RelativePhase("", 0.0), "name"),
])
def test_bad_laws(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_relative_phase_rule_and_per_planet_broadcast():
    counts = {"a": 1, "b": 3, "c": 1}
    model = ErrorModel({
        "a": ErrorSource(gearte.Fixed(1.0), gearte.UniformPhase()),
        "b": ErrorSource(gearte.Fixed(2.0), gearte.RelativePhase("a", 7 * math.pi / 9)),
        "c": ErrorSource(gearte.Fixed(3.0), gearte.RelativePhase("a", -1.0)),
    }, counts)
    e = jax.vmap(model.sample)(jax.random.split(jax.random.key(3), 100))
    np.testing.assert_allclose(e["b"].phase - e["a"].phase, 7 * math.pi / 9, atol=1e-12)
    np.testing.assert_allclose(e["c"].phase[:, 0] - e["a"].phase[:, 0], -1.0, atol=1e-12)
    assert e["b"].phase.shape == (100, 3)


def test_rule_errors():
    counts = {"a": 1, "b": 1}
    with pytest.raises(ValueError, match="cycle"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("b")), "b": ErrorSource(1.0, gearte.RelativePhase("a"))}, counts)
    with pytest.raises(ValueError, match="not an error source"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("z")), "b": ErrorSource(1.0, 0.0)}, counts)
    with pytest.raises(ValueError, match="cannot follow"):
        ErrorModel({"a": ErrorSource(1.0, gearte.RelativePhase("b")), "b": ErrorSource(1.0, 0.0)}, {"a": 1, "b": 3})
    with pytest.raises(ValueError, match="missing"):
        ErrorModel({"a": ErrorSource(1.0, 0.0)}, counts)
    with pytest.raises(ValueError, match="unknown"):
        ErrorModel({"a": ErrorSource(1.0, 0.0), "b": ErrorSource(1.0, 0.0), "x": ErrorSource(1.0, 0.0)}, counts)
