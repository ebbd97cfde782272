"""ISO 1328 accuracy grades against values worked out by hand from the standards' formulae."""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

import gearte
from gearte import cli

S2013, S1995 = "1328-1:2013", "1328-1:1995"
KEYS = ("f_pt", "F_p", "F_alpha", "F_beta", "F_r")

# --- ISO 1328-1:2013, m = 2 mm, d = 50 mm, b = 20 mm, worked by hand -------------------------
# √d = √50 = 7.0710678, √b = √20 = 4.4721360
# f_pT,5 = 0.001·50 + 0.4·2 + 5                      = 0.05 + 0.8 + 5                 = 5.85
# F_pT,5 = 0.002·50 + 0.55·7.0710678 + 0.7·2 + 12    = 0.1 + 3.8890873 + 1.4 + 12     = 17.3890873
# f_Hα,5 = 0.4·2 + 0.001·50 + 4 = 4.85 ; f_fα,5 = 0.55·2 + 5 = 6.1
# F_αT,5 = √(4.85² + 6.1²) = √(23.5225 + 37.21) = √60.7325                            = 7.7931059
# f_Hβ,5 = 0.05·7.0710678 + 0.35·4.4721360 + 4 = 0.3535534 + 1.5652476 + 4            = 5.9188010
# f_fβ,5 = 0.07·7.0710678 + 0.45·4.4721360 + 4 = 0.4949747 + 2.0124612 + 4            = 6.5074359
# F_βT,5 = √(5.9188010² + 6.5074359²) = √(35.0322 + 42.3467) = √77.3789              = 8.7965293
# F_rT,5 = 0.9·17.3890873                                                             = 15.6501786
G5_2013 = {"f_pt": 5.85, "F_p": 17.3890873, "F_alpha": 7.7931059, "F_beta": 8.7965293, "F_r": 15.6501786}
# Grade 5 rounded: 5.85 → 6.0 (0.5 µm step), 17.389 → 17, 7.793 → 8.0, 8.797 → 9.0, 15.650 → 16.
ROUNDED_2013_G5 = {"f_pt": 6.0, "F_p": 17.0, "F_alpha": 8.0, "F_beta": 9.0, "F_r": 16.0}
# Grade 8 = grade 5 × (√2)³ = × 2.8284271:
# 5.85 → 16.5463 → 17 ; 17.3891 → 49.1838 → 49 ; 7.7931 → 22.0422 → 22 ; 8.7965 → 24.8803 → 25 ;
# 15.6502 → 44.2654 → 44
ROUNDED_2013_G8 = {"f_pt": 17.0, "F_p": 49.0, "F_alpha": 22.0, "F_beta": 25.0, "F_r": 44.0}
# Grade 1 = grade 5 / 4: 1.4625 → 1.5 ; 4.3473 → 4.3 ; 1.9483 → 1.9 ; 2.1991 → 2.2 ; 3.9125 → 3.9 (0.1 µm step)
ROUNDED_2013_G1 = {"f_pt": 1.5, "F_p": 4.3, "F_alpha": 1.9, "F_beta": 2.2, "F_r": 3.9}
# Grade 11 = grade 5 × 8: 46.8 → 47 ; 139.113 → 139 ; 62.345 → 62 ; 70.372 → 70 ; 125.201 → 125
ROUNDED_2013_G11 = {"f_pt": 47.0, "F_p": 139.0, "F_alpha": 62.0, "F_beta": 70.0, "F_r": 125.0}
GEAR_2013 = dict(module=2.0, diameter=50.0, face_width=20.0)

# --- ISO 1328-1:1995, m = 3 mm, d = 80 mm, b = 30 mm, worked by hand -------------------------
# Ranges: 2 < m ≤ 3.5 → m = √(2·3.5) = √7 = 2.6457513 ; 50 < d ≤ 125 → d = √6250 = 79.056942,
# √d = 8.8913971 ; 20 < b ≤ 40 → b = √800 = 28.284271, √b = 5.3182959 ; √m = 1.6265766
# f_pt,5 = 0.3(2.6457513 + 0.4·8.8913971) + 4 = 0.3·6.2023101 + 4                     = 5.8606930
# F_p,5  = 0.3·2.6457513 + 1.25·8.8913971 + 7 = 0.7937254 + 11.1142464 + 7             = 18.9079718
# F_α,5  = 3.2·1.6265766 + 0.22·8.8913971 + 0.7 = 5.2050450 + 1.9561074 + 0.7          = 7.8611524
# F_β,5  = 0.1·8.8913971 + 0.63·5.3182959 + 4.2 = 0.8891397 + 3.3505264 + 4.2          = 8.4396661
# F_r,5  = 0.24·2.6457513 + 1.0·8.8913971 + 5.6 = 0.6349803 + 8.8913971 + 5.6          = 15.1263774
G5_1995 = {"f_pt": 5.8606930, "F_p": 18.9079718, "F_alpha": 7.8611524, "F_beta": 8.4396661, "F_r": 15.1263774}
# Grade 5 rounded: 5.861 → 6.0 ; 18.908 → 19 ; 7.861 → 8.0 ; 8.440 → 8.5 ; 15.126 → 15
ROUNDED_1995_G5 = {"f_pt": 6.0, "F_p": 19.0, "F_alpha": 8.0, "F_beta": 8.5, "F_r": 15.0}
# Grade 7 = × 2: 11.721 → 12 ; 37.816 → 38 ; 15.722 → 16 ; 16.879 → 17 ; 30.253 → 30
ROUNDED_1995_G7 = {"f_pt": 12.0, "F_p": 38.0, "F_alpha": 16.0, "F_beta": 17.0, "F_r": 30.0}
# Grade 0 = / 2^2.5 = / 5.6568542: 1.0360 → 1.0 ; 3.3425 → 3.3 ; 1.3897 → 1.4 ; 1.4919 → 1.5 ; 2.6740 → 2.7
ROUNDED_1995_G0 = {"f_pt": 1.0, "F_p": 3.3, "F_alpha": 1.4, "F_beta": 1.5, "F_r": 2.7}
GEAR_1995 = dict(module=3.0, diameter=80.0, face_width=30.0)


@pytest.mark.parametrize("grade,expected", [(5, ROUNDED_2013_G5), (8, ROUNDED_2013_G8), (1, ROUNDED_2013_G1), (11, ROUNDED_2013_G11)])
def test_2013_rounded_values_by_hand(grade, expected):
    assert gearte.iso1328_tolerances(standard=S2013, grade=grade, **GEAR_2013) == expected


@pytest.mark.parametrize("grade,expected", [(5, ROUNDED_1995_G5), (7, ROUNDED_1995_G7), (0, ROUNDED_1995_G0)])
def test_1995_rounded_values_by_hand(grade, expected):
    assert gearte.iso1328_tolerances(standard=S1995, grade=grade, **GEAR_1995) == expected


@pytest.mark.parametrize("standard,gear,g5", [(S2013, GEAR_2013, G5_2013), (S1995, GEAR_1995, G5_1995)])
@pytest.mark.parametrize("quantity", KEYS)
@pytest.mark.parametrize("grade", [1.0, 5.0, 6.5, 8.0, 11.0])
def test_unrounded_values_by_hand(standard, gear, g5, quantity, grade):
    expected = g5[quantity] * math.sqrt(2.0) ** (grade - 5.0)
    got = gearte.iso1328_tolerance(quantity, standard=standard, grade=grade, **gear)
    np.testing.assert_allclose(float(got), expected, rtol=1e-7)


def test_1995_published_table_rows():
    # ISO 1328-1:1995 / GB/T 10095.1-2008, 5 ≤ d ≤ 20 mm, 0.5 ≤ m ≤ 2 mm: evaluated at d = 10, m = 1.
    # F_p,5 = 0.3·1 + 1.25·√10 + 7 = 0.3 + 3.9528471 + 7 = 11.2528471; its row over grades 0–12:
    F_p_row = [2.0, 2.8, 4.0, 5.5, 8.0, 11.0, 16.0, 23.0, 32.0, 45.0, 64.0, 90.0, 127.0]
    # f_pt,5 = 0.3(1 + 0.4·√10) + 4 = 4.6794733; grades 5–9:
    f_pt_row = [4.7, 6.5, 9.5, 13.0, 19.0]
    for d, m in [(5.0, 0.5), (10.0, 1.0), (20.0, 2.0), (13.3, 1.7)]:  # anywhere in the cell, limits included
        got = [gearte.iso1328_tolerances(standard=S1995, module=m, diameter=d, grade=q)["F_p"] for q in range(13)]
        assert got == F_p_row
        assert [gearte.iso1328_tolerances(standard=S1995, module=m, diameter=d, grade=q)["f_pt"] for q in range(5, 10)] == f_pt_row

    # Scaling the rounded grade-5 value (11 µm) would give 22 at grade 7 and 88 at grade 11,
    # not the tabulated 23 and 90: the unrounded value is scaled (by √2 per grade: 22.505694 and 90.022777), then rounded.
    def F_p(q, rounded=True):
        if rounded:
            return gearte.iso1328_tolerances(standard=S1995, module=1.0, diameter=10.0, grade=q)["F_p"]
        return float(gearte.iso1328_tolerance("F_p", standard=S1995, module=1.0, diameter=10.0, grade=q))

    assert F_p(5) == 11.0
    assert (F_p(7), F_p(11)) == (23.0, 90.0) != (round(F_p(5) * 2.0), round(F_p(5) * 8.0))
    np.testing.assert_allclose(
        [F_p(5, False), F_p(7, False), F_p(11, False)], np.array([1, 2, 8]) * (0.3 + 1.25 * math.sqrt(10.0) + 7), rtol=1e-12
    )


def test_1995_range_limits_belong_to_the_lower_range():
    def f_pt(m, d):
        return float(gearte.iso1328_tolerance("f_pt", standard=S1995, module=m, diameter=d, grade=5))

    # d = 20 is in 5 ≤ d ≤ 20 (mean 10); d just above 20 is in 20 < d ≤ 50 (mean √1000).
    m1 = 1.0  # 0.5 ≤ m ≤ 2, mean 1
    assert f_pt(m1, 20.0) == pytest.approx(0.3 * (1.0 + 0.4 * math.sqrt(10.0)) + 4.0, rel=1e-12)
    assert f_pt(m1, 20.0001) == pytest.approx(0.3 * (1.0 + 0.4 * math.sqrt(math.sqrt(1000.0))) + 4.0, rel=1e-12)
    # m = 2 is in 0.5 ≤ m ≤ 2 (mean 1); m just above 2 is in 2 < m ≤ 3.5 (mean √7).
    assert f_pt(2.0, 10.0) == pytest.approx(0.3 * (1.0 + 0.4 * math.sqrt(10.0)) + 4.0, rel=1e-12)
    assert f_pt(2.0001, 10.0) == pytest.approx(0.3 * (math.sqrt(7.0) + 0.4 * math.sqrt(10.0)) + 4.0, rel=1e-12)

    # b = 10 is in 4 ≤ b ≤ 10 (mean √40), b = 10.5 in 10 < b ≤ 20 (mean √200); d = 10 → √d = √10.
    def F_beta(b):
        return float(gearte.iso1328_tolerance("F_beta", standard=S1995, module=1.0, diameter=10.0, face_width=b, grade=5))

    assert F_beta(10.0) == pytest.approx(0.1 * math.sqrt(10.0) + 0.63 * 40.0**0.25 + 4.2, rel=1e-12)
    assert F_beta(10.5) == pytest.approx(0.1 * math.sqrt(10.0) + 0.63 * 200.0**0.25 + 4.2, rel=1e-12)
    # The outermost limits are inside the standard.
    gearte.iso1328_tolerances(standard=S1995, module=70.0, diameter=10000.0, face_width=1000.0, grade=12)
    gearte.iso1328_tolerances(standard=S1995, module=0.5, diameter=5.0, face_width=4.0, grade=0)


def test_2013_uses_the_gear_itself_not_range_means():
    # 2013: f_pT,5 at m = 2, d = 20 is 0.02 + 0.8 + 5 = 5.82; at m = 2.0001 it moves by 0.4·0.0001.
    a = float(gearte.iso1328_tolerance("f_pt", standard=S2013, module=2.0, diameter=20.0, grade=5))
    b = float(gearte.iso1328_tolerance("f_pt", standard=S2013, module=2.0001, diameter=20.0, grade=5))
    assert a == pytest.approx(5.82, rel=1e-12) and b - a == pytest.approx(0.4e-4, rel=1e-6)


@pytest.mark.parametrize(
    "value,expected",
    [
        (10.49, 10.0),
        (10.5, 11.0),
        (10.0001, 10.0),
        (10.0, 10.0),
        (9.76, 10.0),
        (9.74, 9.5),
        (7.25, 7.5),
        (5.0, 5.0),
        (5.2, 5.0),
        (4.96, 5.0),
        (4.94, 4.9),
        (0.84, 0.8),
        (0.0, 0.0),
        (123.5, 124.0),
    ],
)
def test_round_tolerance(value, expected):
    assert gearte.round_tolerance(value) == expected


def test_round_tolerance_is_monotone():
    v = np.linspace(0.0, 40.0, 40001)
    r = [gearte.round_tolerance(x) for x in v]
    assert np.all(np.diff(r) >= 0)
    assert np.max(np.abs(np.asarray(r) - v)) <= 0.5 + 1e-12


@pytest.mark.parametrize("standard,gear", [(S2013, GEAR_2013), (S1995, GEAR_1995)])
@pytest.mark.parametrize("quantity", KEYS)
def test_grade_tolerance_round_trip(standard, gear, quantity):
    g = jnp.linspace(-2.0, 14.0, 33)
    t = gearte.iso1328_tolerance(quantity, standard=standard, grade=g, **gear)
    back = gearte.grade_for_tolerance(t, quantity=quantity, standard=standard, **gear)
    np.testing.assert_allclose(back, g, atol=1e-12)
    # One grade is a factor √2; two grades halve the tolerance.
    np.testing.assert_allclose(t[4:] / t[:-4], 2.0, rtol=1e-12)


@pytest.mark.parametrize("standard,gear", [(S2013, GEAR_2013), (S1995, GEAR_1995)])
@pytest.mark.parametrize("quantity", KEYS)
def test_nearest_grade_is_the_coarsest_grade_within_the_budget(standard, gear, quantity):
    lo, hi = gearte.grade_range(standard)
    published = [gearte.iso1328_tolerances(standard=standard, grade=q, **gear)[quantity] for q in range(lo, hi + 1)]
    for q, value in zip(range(lo, hi + 1), published):
        kw = dict(quantity=quantity, standard=standard, **gear)
        assert gearte.nearest_grade(value, **kw) == q  # exactly the published value: that grade
        if q < hi:
            assert gearte.nearest_grade(value + 1e-9, **kw) == q  # a little more is not the next grade yet
        if q > lo:
            assert gearte.nearest_grade(value - 1e-9, **kw) == q - 1  # a little less needs a finer grade
    assert gearte.nearest_grade(10 * published[-1], quantity=quantity, standard=standard, **gear) == hi
    with pytest.raises(ValueError, match="finer than"):
        gearte.nearest_grade(0.9 * published[0], quantity=quantity, standard=standard, **gear)


def test_nearest_grade_example():
    # 2013, m = 2, d = 50: F_p is 17 (grade 5), 24.59 → 25 (grade 6), 34.8 → 35 (grade 7).
    # A budget of 30 µm: grade 6 (25 µm) meets it, grade 7 (35 µm) does not.
    kw = dict(quantity="F_p", standard=S2013, module=2.0, diameter=50.0)
    assert gearte.nearest_grade(30.0, **kw) == 6
    assert gearte.nearest_grade(35.0, **kw) == 7
    assert gearte.nearest_grade(24.9, **kw) == 5


@pytest.mark.parametrize("standard,gear", [(S2013, GEAR_2013), (S1995, GEAR_1995)])
@pytest.mark.parametrize("quantity", KEYS)
def test_gradients_of_the_continuous_law(standard, gear, quantity):
    def T(g):
        return gearte.iso1328_tolerance(quantity, standard=standard, grade=g, **gear)

    def Q(t):
        return gearte.grade_for_tolerance(t, quantity=quantity, standard=standard, **gear)

    for g in [1.3, 5.0, 9.7]:
        check_grads(T, (g,), order=2, modes=["fwd", "rev"])
        # dT/dQ = T ln2 / 2, and by central differences.
        dT = jax.grad(T)(g)
        np.testing.assert_allclose(dT, float(T(g)) * math.log(2.0) / 2.0, rtol=1e-12)
        h = 1e-5
        np.testing.assert_allclose(dT, (float(T(g + h)) - float(T(g - h))) / (2 * h), rtol=1e-8)
    for t in [3.0, 20.0, 75.0]:
        np.testing.assert_allclose(jax.grad(Q)(t), 2.0 / (t * math.log(2.0)), rtol=1e-12)
        check_grads(Q, (t,), order=2, modes=["fwd", "rev"])


def test_continuous_law_traces_under_jit_and_vmap():
    f = jax.jit(jax.vmap(lambda g: gearte.iso1328_tolerance("F_p", standard=S2013, grade=g, **GEAR_2013)))
    got = f(jnp.array([5.0, 7.0, 9.0]))
    np.testing.assert_allclose(got, 17.3890873 * np.array([1.0, 2.0, 4.0]), rtol=1e-7)


def test_f_beta_needs_the_face_width():
    t = gearte.iso1328_tolerances(standard=S2013, module=2.0, diameter=50.0, grade=6)
    assert set(t) == {"f_pt", "F_p", "F_alpha", "F_r"}
    with pytest.raises(ValueError, match="face width"):
        gearte.iso1328_tolerance("F_beta", standard=S2013, module=2.0, diameter=50.0, grade=6.0)


def test_eccentricity_from_runout():
    assert float(gearte.eccentricity_from_runout(16.0)) == 8.0
    np.testing.assert_array_equal(gearte.eccentricity_from_runout(np.array([0.0, 3.0, 44.0])), [0.0, 1.5, 22.0])
    # From a grade: 2013, m = 2, d = 50, grade 8 → F_r = 44 µm → e = 22 µm.
    F_r = gearte.iso1328_tolerances(standard=S2013, grade=8, **GEAR_2013)["F_r"]
    assert float(gearte.eccentricity_from_runout(F_r)) == 22.0
    with pytest.raises(ValueError, match="run-out"):
        gearte.eccentricity_from_runout(-1.0)
    with pytest.raises(ValueError, match="run-out"):
        gearte.eccentricity_from_runout(float("nan"))


def _tol(**kw):
    base = dict(standard=S2013, module=2.0, diameter=50.0, face_width=20.0, grade=6)
    base.update(kw)
    return lambda: gearte.iso1328_tolerances(**base)


@pytest.mark.parametrize(
    "make,match",
    [
        (_tol(standard="1328-1:2008"), "standard: expected one of"),
        (_tol(module=0.4), r"module = 0.4 mm is outside the range of ISO 1328-1:2013: 0.5 ≤ m ≤ 70"),
        (_tol(module=71.0), r"0.5 ≤ m ≤ 70"),
        (_tol(diameter=4.0), r"5 ≤ d ≤ 15000"),
        (_tol(diameter=15001.0), r"5 ≤ d ≤ 15000"),
        (_tol(face_width=3.0), r"4 ≤ b ≤ 1200"),
        (_tol(face_width=1300.0), r"4 ≤ b ≤ 1200"),
        (_tol(standard=S1995, diameter=12000.0), r"ISO 1328-1:1995: 5 ≤ d ≤ 10000"),
        (_tol(standard=S1995, face_width=1100.0), r"4 ≤ b ≤ 1000"),
        (_tol(module=float("nan")), "module: must be finite"),
        (_tol(diameter="big"), "diameter: expected a number"),
        (_tol(grade=0), "grade 0 is outside ISO 1328-1:2013's grades 1"),
        (_tol(grade=12), "grade 12 is outside"),
        (_tol(standard=S1995, grade=13), "grade 13 is outside ISO 1328-1:1995's grades 0"),
        (_tol(standard=S1995, grade=-1), "grade -1 is outside"),
        (_tol(grade=5.5), "whole grades only"),
        (_tol(grade=True), "whole number"),
        (_tol(grade=float("inf")), "whole grades only"),
        (_tol(teeth=4), r"5 ≤ z ≤ 1000"),
        (_tol(teeth=1001), r"5 ≤ z ≤ 1000"),
        (_tol(teeth=20.5), "teeth: expected a whole number"),
        (lambda: gearte.iso1328_tolerance("F_x", standard=S2013, module=2.0, diameter=50.0, grade=5.0), "quantity"),
        (lambda: gearte.iso1328_tolerance("F_p", standard=S2013, module=2.0, diameter=50.0, grade=float("nan")), "grade: must be finite"),
        (lambda: gearte.grade_for_tolerance(0.0, quantity="F_p", standard=S2013, module=2.0, diameter=50.0), "> 0"),
        (lambda: gearte.grade_for_tolerance(np.array([3.0, -1.0]), quantity="F_p", standard=S2013, module=2.0, diameter=50.0), "> 0"),
        (lambda: gearte.nearest_grade(float("nan"), quantity="F_p", standard=S2013, module=2.0, diameter=50.0), "> 0"),
        (lambda: gearte.nearest_grade(-3.0, quantity="F_p", standard=S2013, module=2.0, diameter=50.0), "> 0"),
        (lambda: gearte.round_tolerance(-0.1), "≥ 0"),
    ],
)
def test_bad_inputs(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_teeth_in_range_and_1995_has_no_teeth_range():
    a = gearte.iso1328_tolerances(standard=S2013, grade=6, teeth=25, **GEAR_2013)
    assert a == gearte.iso1328_tolerances(standard=S2013, grade=6, **GEAR_2013)
    gearte.iso1328_tolerances(standard=S1995, grade=6, teeth=3, **GEAR_1995)
    gearte.iso1328_tolerances(standard=S1995, grade=6, teeth=1, **GEAR_1995)
    with pytest.raises(ValueError, match=r"teeth: must be ≥ 1, got 0"):
        gearte.iso1328_tolerances(standard=S1995, grade=6, teeth=0, **GEAR_1995)


def test_grade_range():
    assert gearte.grade_range(S2013) == (1, 11) and gearte.grade_range(S1995) == (0, 12)


# --- command line ----------------------------------------------------------------------------


def test_cli_grade_2013(capsys):
    assert cli.main(["grade", "--standard", S2013, "--module", "2", "--diameter", "50", "--face-width", "20", "--grade", "8"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert {k: out[k] for k in KEYS} == ROUNDED_2013_G8
    assert out["standard"] == S2013 and out["grade"] == 8 and out["module_mm"] == 2.0
    assert out["diameter_mm"] == 50.0 and out["face_width_mm"] == 20.0


def test_cli_grade_1995_without_face_width(capsys):
    assert cli.main(["grade", "--standard", S1995, "--module", "3", "--diameter", "80", "--grade", "7"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(KEYS) <= set(out)
    assert out["F_beta"] is None and out["face_width_mm"] is None
    assert {k: out[k] for k in KEYS if k != "F_beta"} == {k: v for k, v in ROUNDED_1995_G7.items() if k != "F_beta"}


@pytest.mark.parametrize(
    "args,match",
    [
        (["--standard", S2013, "--module", "2", "--diameter", "50", "--grade", "0"], "grade 0 is outside"),
        (["--standard", S1995, "--module", "100", "--diameter", "50", "--grade", "5"], "0.5 ≤ m ≤ 70"),
        (["--standard", S2013, "--module", "2", "--diameter", "nan", "--grade", "5"], "diameter: must be finite"),
    ],
)
def test_cli_grade_invalid_input(args, match, capsys):
    assert cli.main(["grade", *args]) == 2
    err = capsys.readouterr().err
    assert "gearte: error:" in err and match in err


@pytest.mark.parametrize("value", ["1_0", "\uff11", "2mm"])
def test_cli_grade_lengths_in_ascii_decimals_only(value, capsys):
    """Python's float reads 1_0 as 10 and full-width digits as digits: a length option takes ASCII decimals only."""
    with pytest.raises(SystemExit) as e:
        cli.main(["grade", "--standard", S2013, "--module", value, "--diameter", "50", "--grade", "5"])
    assert e.value.code == 2
    assert f"argument --module: expected a number of mm, got {value!r}" in capsys.readouterr().err


@pytest.mark.parametrize(
    "args",
    [
        ["--standard", "1328", "--module", "2", "--diameter", "50", "--grade", "5"],
        ["--standard", S2013, "--module", "2", "--diameter", "50", "--grade", "5.5"],
        ["--standard", S2013, "--module", "2", "--diameter", "50"],
    ],
)
def test_cli_grade_argument_errors_exit_2(args, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["grade", *args])
    assert e.value.code == 2
    assert "gearte grade: error" in capsys.readouterr().err
