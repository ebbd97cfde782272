"""Cost–tolerance models: values and derivatives by hand, monotonicity, smoothness, validation."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import gearte

GEAR = dict(quantity="F_p", standard="1328-1:2013", module=2.0, diameter=50.0)
T5 = 0.002 * 50 + 0.55 * math.sqrt(50.0) + 0.7 * 2 + 12  # unrounded grade-5 F_p of GEAR = 17.3890873 µm


def T_at(grade):
    """Unrounded F_p of GEAR at a continuous grade, by hand: T5 · 2^((Q − 5)/2)."""
    return T5 * 2.0 ** ((grade - 5.0) / 2.0)


@pytest.mark.parametrize(
    "model,T,value,slope",
    [
        # a + b/T = 2 + 30/5 = 8 ; d/dT = −b/T² = −30/25 = −1.2
        (gearte.Reciprocal(2.0, 30.0), 5.0, 8.0, -1.2),
        # a + b/T² = 1 + 50/25 = 3 ; d/dT = −2b/T³ = −100/125 = −0.8
        (gearte.ReciprocalSquare(1.0, 50.0), 5.0, 3.0, -0.8),
        # a + b e^(−kT) = 1 + 4 e^(−1) = 1 + 1.4715178 ; d/dT = −k b e^(−kT) = −2 e^(−1) = −0.7357589
        (gearte.Exponential(1.0, 4.0, 0.5), 2.0, 2.4715177646857693, -0.7357588823428847),
        # a T^(−k) = 10 · 4^(−1.5) = 10/8 = 1.25 ; d/dT = −k a T^(−k−1) = −1.5 · 10 · 4^(−2.5) = −15/32
        (gearte.Power(10.0, 1.5), 4.0, 1.25, -0.46875),
    ],
)
def test_values_and_derivatives_by_hand(model, T, value, slope):
    np.testing.assert_allclose(model(T), value, rtol=1e-14)
    np.testing.assert_allclose(jax.grad(model)(T), slope, rtol=1e-14)
    check_grads(model, (T,), order=2, modes=["fwd", "rev"])


def test_normalised_models_cost_one_at_the_reference():
    for m in [
        gearte.Reciprocal.normalised(10.0),
        gearte.ReciprocalSquare.normalised(10.0),
        gearte.Exponential.normalised(10.0),
        gearte.Exponential.normalised(10.0, k=0.3),
        gearte.Power.normalised(10.0),
        gearte.Power.normalised(10.0, k=2.5),
    ]:
        np.testing.assert_allclose(m(10.0), 1.0, rtol=1e-14)
    # Halving the tolerance: ×2 (reciprocal), ×4 (reciprocal-square), ×2^k (power).
    np.testing.assert_allclose(gearte.Reciprocal.normalised(10.0)(5.0), 2.0, rtol=1e-14)
    np.testing.assert_allclose(gearte.ReciprocalSquare.normalised(10.0)(5.0), 4.0, rtol=1e-14)
    np.testing.assert_allclose(gearte.Power.normalised(10.0, k=2.5)(5.0), 2.0**2.5, rtol=1e-14)
    # Exponential with k = 1/T_ref: e^(−(T − T_ref)/T_ref); at T = 2 T_ref that is e^(−1).
    np.testing.assert_allclose(gearte.Exponential.normalised(10.0)(20.0), math.exp(-1.0), rtol=1e-14)
    assert float(gearte.Reciprocal.normalised(10.0).a) == 0.0


def _grade_table():
    return gearte.GradeTable({4: 10.0, 5: 4.0, 7: 2.0, 9: 1.5}, **GEAR)


MODELS = [
    gearte.Reciprocal(0.5, 20.0),
    gearte.ReciprocalSquare(0.5, 200.0),
    gearte.Exponential(0.2, 3.0, 0.1),
    gearte.Power(7.0, 1.3),
    _grade_table(),
]


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__)
def test_decreasing_vmap_and_gradients(model):
    T = jnp.geomspace(2.0, 200.0, 401)
    # Compiled (one program each, rather than one tiny program per operation and shape).
    c = jax.jit(jax.vmap(model))(T)
    np.testing.assert_allclose(c, jax.jit(lambda t: model(t))(T), rtol=1e-14)
    assert np.all(np.diff(np.asarray(c)) < 0)
    g = jax.jit(jax.vmap(jax.grad(model)))(T)
    assert np.all(np.asarray(g) < 0)
    compiled = jax.jit(lambda t: model(t))  # compiled once for the derivative checks' many evaluations
    for t in [3.0, 17.0, 41.0, 150.0]:
        check_grads(compiled, (t,), order=1, modes=["fwd", "rev"], eps=1e-6)
    # Compiles once for every tolerance.
    f = jax.jit(eqx.debug.assert_max_traces(lambda t: model(t), max_traces=1))
    for t in [4.0, 5.0, 6.0]:
        f(jnp.asarray(t))


def test_gradients_with_respect_to_the_coefficients():
    # d/db (a + b/T) = 1/T ; d/da = 1
    g = eqx.filter_grad(lambda m: m(4.0))(gearte.Reciprocal(1.0, 3.0))
    assert float(g.a) == 1.0 and float(g.b) == 0.25
    # d/dk (a T^(−k)) = −a T^(−k) ln T = −2 · 4^(−1) · ln 4
    g = eqx.filter_grad(lambda m: m(4.0))(gearte.Power(2.0, 1.0))
    np.testing.assert_allclose(g.k, -0.5 * math.log(4.0), rtol=1e-14)


def test_grade_table_hits_the_table_at_whole_grades():
    table = {4: 10.0, 5: 4.0, 7: 2.0, 9: 1.5}
    m = gearte.GradeTable(table, **GEAR)
    for q, c in table.items():
        np.testing.assert_allclose(m(T_at(q)), c, rtol=1e-12)
    np.testing.assert_allclose(m.grade(T_at(6.3)), 6.3, rtol=1e-12)


def test_a_grade_as_dear_as_the_next_finer_one_is_allowed():
    # A coarser grade must not cost more; the same cost is a shop's price list, and the curve is flat between them.
    m = gearte.GradeTable({5: 2.0, 6: 2.0, 7: 1.0}, **GEAR)
    for q, c in ((5, 2.0), (5.5, 2.0), (6, 2.0), (7, 1.0)):
        np.testing.assert_allclose(m(T_at(q)), c, rtol=1e-12)


def test_grade_table_interpolation_by_hand():
    # {4: 10, 5: 4, 7: 2}: y = ln c = [2.3025851, 1.3862944, 0.6931472] at grades [4, 5, 7], h = [1, 2]
    # secants δ0 = (1.3862944 − 2.3025851)/1 = −0.9162907, δ1 = (0.6931472 − 1.3862944)/2 = −0.3465736
    # node slopes: d(4) = δ0, d(7) = δ1, d(5) = (w1 + w2)/(w1/δ0 + w2/δ1), w1 = 2·2 + 1 = 5, w2 = 2 + 2·1 = 4:
    #   d(5) = 9 / (5/−0.9162907 + 4/−0.3465736) = 9 / (−5.4567817 − 11.5415603) = −0.5294644
    # at grade 6 (t = 1/2 in [5, 7], h = 2): y = (y(5) + y(7))/2 + h (d(5) − d(7))/8
    #   = 1.0397208 + 2·(−0.5294644 + 0.3465736)/8 = 1.0397208 − 0.0457227 = 0.9939981 → c = e^y
    m = gearte.GradeTable({4: 10.0, 5: 4.0, 7: 2.0}, **GEAR)
    np.testing.assert_allclose(m(T_at(6.0)), math.exp(0.9939981), rtol=1e-6)
    # at grade 4.5 (t = 1/2 in [4, 5], h = 1): y = (2.3025851 + 1.3862944)/2 + (−0.9162907 + 0.5294644)/8
    #   = 1.8444398 − 0.0483533 = 1.7960865 → c = e^y
    np.testing.assert_allclose(m(T_at(4.5)), math.exp(1.7960865), rtol=1e-6)


def test_grade_table_two_grades_is_a_power_law_everywhere():
    # {5: 4, 7: 1}: ln c falls by ln 4 over 2 grades, s = −ln 2 per grade; Q = 5 + 2 log2(T/T5), so
    # c = 4 (T/T5)^(−2): the power law with k = −2s/ln 2 = 2, also beyond both ends.
    m = gearte.GradeTable({5: 4.0, 7: 1.0}, **GEAR)
    for q in [1.0, 3.0, 5.0, 6.0, 7.0, 9.5, 14.0]:
        np.testing.assert_allclose(m(T_at(q)), 4.0 * 2.0 ** (-(q - 5.0)), rtol=1e-12)
    p = gearte.Power(4.0 * T5**2, 2.0)
    T = jnp.geomspace(1.0, 400.0, 50)
    np.testing.assert_allclose(m(T), p(T), rtol=1e-12)


def test_grade_table_beyond_the_ends_continues_the_end_slopes():
    m = _grade_table()  # {4: 10, 5: 4, 7: 2, 9: 1.5}
    # finer than grade 4: slope ln(4/10) per grade → two grades finer than 4: 10 · (10/4)² = 62.5
    np.testing.assert_allclose(m(T_at(2.0)), 62.5, rtol=1e-12)
    # coarser than grade 9: slope ln(1.5/2)/2 per grade → two grades coarser than 9: 1.5 · 0.75 = 1.125
    np.testing.assert_allclose(m(T_at(11.0)), 1.125, rtol=1e-12)


def test_grade_table_is_c1_and_monotone():
    m = _grade_table()
    logc = jax.jit(lambda q: jnp.log(m(jnp.asarray(T5) * 2.0 ** ((q - 5.0) / 2.0))))
    dlogc = jax.jit(jax.grad(lambda q: jnp.log(m(jnp.asarray(T5) * 2.0 ** ((q - 5.0) / 2.0)))))
    for node in [4.0, 5.0, 7.0, 9.0]:
        left, right = float(dlogc(jnp.asarray(node - 1e-7))), float(dlogc(jnp.asarray(node + 1e-7)))
        np.testing.assert_allclose(left, right, rtol=1e-5, atol=1e-8)
    q = np.linspace(0.0, 13.0, 2601)
    y = np.array([float(logc(jnp.asarray(x))) for x in q[::13]])
    assert np.all(np.diff(y) < 0)
    # No overshoot between nodes: ln c within the values of the interval's ends.
    cost_of = jax.jit(jax.vmap(m))
    for a, b, ca, cb in [(4, 5, 10.0, 4.0), (5, 7, 4.0, 2.0), (7, 9, 2.0, 1.5)]:
        c = np.asarray(cost_of(jnp.asarray(T_at(np.linspace(a, b, 101)))))
        assert c.max() <= ca * (1 + 1e-12) and c.min() >= cb * (1 - 1e-12)


def test_describe():
    assert gearte.Reciprocal(2.0, 30.0).describe() == "reciprocal, c = 2 + 30/T (T in µm)"
    assert "Spotts" in gearte.ReciprocalSquare(1.0, 50.0).describe()
    assert "exp(−0.5·T)" in gearte.Exponential(1.0, 4.0, 0.5).describe()
    assert "Sutherland" in gearte.Power(10.0, 1.5).describe()
    d = _grade_table().describe()
    assert "F_p" in d and "4: 10" in d and "9: 1.5" in d
    with pytest.raises(TypeError):
        gearte.AbstractCostModel()


@pytest.mark.parametrize(
    "make,match",
    [
        (lambda: gearte.Reciprocal(-1.0, 1.0), r"Reciprocal.a: must be ≥ 0"),
        (lambda: gearte.Reciprocal(0.0, 0.0), r"Reciprocal.b: must be > 0"),
        (lambda: gearte.Reciprocal(float("nan"), 1.0), r"Reciprocal.a: must be a finite number"),
        (lambda: gearte.ReciprocalSquare(0.0, float("inf")), r"ReciprocalSquare.b: must be a finite number"),
        (lambda: gearte.Exponential(0.0, 1.0, 0.0), r"Exponential.k: must be > 0"),
        (lambda: gearte.Exponential(0.0, -1.0, 1.0), r"Exponential.b: must be > 0"),
        (lambda: gearte.Power(0.0, 1.0), r"Power.a: must be > 0"),
        (lambda: gearte.Power(1.0, "x"), r"Power.k: expected a number"),
        (lambda: gearte.Reciprocal.normalised(0.0), r"T_ref: must be > 0"),
        (lambda: gearte.Power.normalised(-2.0), r"T_ref: must be > 0"),
        (lambda: gearte.GradeTable({5: 1.0}, **GEAR), "at least two grades"),
        (lambda: gearte.GradeTable({5: 2.0, 12: 1.0}, **GEAR), "grade 12 is outside"),
        (lambda: gearte.GradeTable({5: 2.0, 6.5: 1.0}, **GEAR), "whole numbers"),
        (lambda: gearte.GradeTable({5: 2.0, 6: 3.0}, **GEAR), "grade 6 costs more"),
        (lambda: gearte.GradeTable({5: 2.0, 6: 0.0}, **GEAR), r"costs_by_grade\[6\]: must be > 0"),
        (lambda: gearte.GradeTable({5: 2.0, 6: 1.0}, **{**GEAR, "quantity": "F_beta"}), "face width"),
        (lambda: gearte.GradeTable({5: 2.0, 6: 1.0}, **{**GEAR, "diameter": 1.0}), r"5 ≤ d ≤ 15000"),
    ],
)
def test_bad_coefficients(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.parametrize("model", MODELS, ids=lambda m: type(m).__name__)
@pytest.mark.parametrize("T", [0.0, -1.0, float("nan"), float("inf"), np.array([3.0, -1.0])])
def test_bad_tolerances(model, T):
    with pytest.raises(ValueError, match="tolerance T must be finite and > 0"):
        model(T)


def test_bad_tolerance_under_jit_raises_unless_throw_is_false():
    m = gearte.Reciprocal(1.0, 2.0)
    for bad in (-1.0, 0.0):  # zero too: its cost would be infinite
        with pytest.raises(Exception, match="tolerance T must be finite and > 0"):
            jax.jit(lambda t: m(t))(jnp.asarray(bad)).block_until_ready()
    c = jax.jit(lambda t: m(t, throw=False))(jnp.asarray(-1.0))
    assert float(c) == -1.0  # 1 + 2/(−1): no check, the formula as written
