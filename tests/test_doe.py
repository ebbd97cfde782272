"""Designs of experiments and quadratic response surfaces (`gearte.studies.doe`, `gearte.studies.response_surface`):
published run counts and geometry, rotatability, stratification, exact recovery of a quadratic, goodness-of-fit
statistics against their definitions, the box-constrained optimum, and the designs run on gearte drives."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.stats import norm

import gearte
from gearte.drives import wang2013
from gearte.drives.cycloid_pin import CycloidAnalysis, CycloidPin, LostMotion
from gearte.studies.doe import to_coded, to_natural


def quad_matrix(c):
    """The full quadratic's columns, written out independently of the library: 1, c_i, c_i², c_i c_j (i < j)."""
    c = np.atleast_2d(c)
    r = c.shape[1]
    cols = [np.ones(len(c))] + [c[:, i] for i in range(r)] + [c[:, i] ** 2 for i in range(r)]
    cols += [c[:, i] * c[:, j] for i in range(r) for j in range(i + 1, r)]
    return np.stack(cols, axis=1)


def on_sphere(rng, n, rho, radius):
    u = rng.normal(size=(n, rho))
    return radius * u / np.linalg.norm(u, axis=1, keepdims=True)


def prediction_variance(points, at):
    """x(at)ᵀ (XᵀX)⁻¹ x(at): the variance of the fitted quadratic at `at`, per unit σ²."""
    X = quad_matrix(points)
    M = np.linalg.inv(X.T @ X)
    xa = quad_matrix(at)
    return np.einsum("ij,jk,ik->i", xa, M, xa)


# ---------------------------------------------------------------- designs


@pytest.mark.parametrize("rho", [2, 3, 4, 5])
def test_central_composite_run_counts_and_geometry(rho):
    alpha = (2**rho) ** 0.25
    assert gearte.CentralComposite().runs(rho) == 2**rho + 2 * rho + 1
    for kind, corner, axial in (
        (gearte.Circumscribed(), 1.0, alpha),
        (gearte.Inscribed(), 1.0 / alpha, 1.0),
        (gearte.FaceCentred(), 1.0, 1.0),
    ):
        d = gearte.CentralComposite(kind, center_points=3)
        p = d.points(rho)
        assert p.shape == (2**rho + 2 * rho + 3, rho)
        corners, axials, centre = p[: 2**rho], p[2**rho : 2**rho + 2 * rho], p[2**rho + 2 * rho :]
        # The 2^ρ corners: every sign pattern once, at ±corner.
        np.testing.assert_allclose(np.abs(corners), corner, rtol=1e-15)
        assert len({tuple(np.sign(r)) for r in corners}) == 2**rho
        # 2ρ axial points: one non-zero coordinate, ±axial, each axis both ways.
        assert np.all(np.count_nonzero(axials, axis=1) == 1)
        np.testing.assert_allclose(np.abs(axials).sum(axis=1), axial, rtol=1e-15)
        assert sorted(map(tuple, np.sign(axials))) == sorted(map(tuple, np.concatenate([np.eye(rho), -np.eye(rho)])))
        assert np.all(centre == 0)
    assert gearte.CentralComposite().axial_distance(rho) == pytest.approx(alpha, rel=1e-15)
    assert gearte.CentralComposite(alpha=1.5).axial_distance(rho) == 1.5


def test_published_central_composite_counts():
    # Zhang, Chen & Wang: 9 runs for two variables, 25 for four.
    assert gearte.CentralComposite().runs(2) == 9 and gearte.CentralComposite().runs(4) == 25
    assert gearte.CentralComposite().axial_distance(2) == pytest.approx(math.sqrt(2), rel=1e-15)
    assert gearte.CentralComposite().axial_distance(4) == pytest.approx(2.0, rel=1e-15)


@pytest.mark.parametrize("rho", [2, 3, 4])
@pytest.mark.parametrize("kind", [gearte.Circumscribed(), gearte.Inscribed()], ids=["ccc", "cci"])
def test_rotatable_ccd_prediction_variance_depends_on_radius_only(rho, kind):
    rng = np.random.default_rng(rho)
    p = gearte.CentralComposite(kind, center_points=2).points(rho)
    scale = 1.0 if isinstance(kind, gearte.Circumscribed) else 1.0 / (2**rho) ** 0.25
    variances = []
    for radius in (0.3, 1.0, 1.7):
        v = prediction_variance(p, on_sphere(rng, 40, rho, radius * scale))
        np.testing.assert_allclose(v, v[0], rtol=1e-10)
        variances.append(v[0])
    assert len(set(np.round(variances, 6))) == 3  # ... and it does change with the radius
    # Another α is not rotatable: at equal radius the variance differs.
    q = gearte.CentralComposite(kind, alpha=1.2 * (2**rho) ** 0.25, center_points=2).points(rho)
    v = prediction_variance(q, on_sphere(rng, 40, rho, scale))
    assert np.ptp(v) > 1e-3 * v.mean()


def test_face_centred_design_is_not_rotatable_and_stays_in_the_cube():
    p = gearte.CentralComposite(gearte.FaceCentred()).points(3)
    assert np.max(np.abs(p)) == 1.0
    assert set(np.unique(p)) == {-1.0, 0.0, 1.0}
    v = prediction_variance(p, on_sphere(np.random.default_rng(0), 40, 3, 1.0))
    assert np.ptp(v) > 1e-2 * v.mean()


@pytest.mark.parametrize(("rho", "published"), [(3, 12), (4, 24), (5, 40), (6, 48), (7, 56)])
def test_box_behnken_counts_no_corners_and_estimable(rho, published):
    d = gearte.BoxBehnken(center_points=3)
    p = d.points(rho)
    assert p.shape == (published + 3, rho)
    assert set(np.unique(p)) <= {-1.0, 0.0, 1.0}
    # No corner points: every run has zeros (two or three variables at ±1, the rest at the centre).
    nz = np.count_nonzero(p, axis=1)
    assert np.all(nz < rho) and set(nz[:published]) == ({2} if rho <= 5 else {3})
    assert len({tuple(r) for r in p[:published]}) == published  # no repeated run
    # Every pair of variables varies together somewhere: the full quadratic is estimable.
    assert np.linalg.matrix_rank(quad_matrix(p)) == (rho + 1) * (rho + 2) // 2
    # Each variable is balanced: as many runs at +1 as at −1, and the linear columns are orthogonal.
    assert np.all(p.sum(axis=0) == 0)
    G = p.T @ p
    assert np.allclose(G, np.diag(np.diag(G)))


@pytest.mark.parametrize(("rho", "rotatable"), [(3, False), (4, True), (5, False), (7, True)])
def test_box_behnken_rotatable_for_four_and_seven_variables(rho, rotatable):
    # Box & Behnken (1960): their designs for 4 and 7 variables are rotatable, the others nearly so.
    v = prediction_variance(gearte.BoxBehnken().points(rho), on_sphere(np.random.default_rng(1), 60, rho, 0.8))
    assert (np.ptp(v) < 1e-10 * v.mean()) == rotatable


def test_full_factorial():
    p = gearte.FullFactorial(levels=3).points(3)
    assert p.shape == (27, 3) and len({tuple(r) for r in p}) == 27
    assert set(np.unique(p)) == {-1.0, 0.0, 1.0}
    p = gearte.FullFactorial(levels=4).points(2)
    assert p.shape == (16, 2)
    np.testing.assert_allclose(np.unique(p), [-1, -1 / 3, 1 / 3, 1], rtol=1e-15)


@pytest.mark.parametrize("centred", [False, True])
def test_latin_hypercube_one_run_per_stratum(centred):
    n, rho = 13, 4
    p = gearte.LatinHypercube(n, seed=5, centred=centred).points(rho)
    assert p.shape == (n, rho) and np.all(np.abs(p) <= 1)
    for j in range(rho):
        strata = np.floor((p[:, j] + 1) / 2 * n).astype(int)
        assert sorted(strata) == list(range(n))
        if centred:
            np.testing.assert_allclose((p[:, j] + 1) / 2 * n - strata, 0.5, atol=1e-12)
    np.testing.assert_array_equal(p, gearte.LatinHypercube(n, seed=5, centred=centred).points(rho))
    assert not np.array_equal(p, gearte.LatinHypercube(n, seed=6, centred=centred).points(rho))


@pytest.mark.parametrize("scramble", [True, False])
def test_sobol_balance_on_powers_of_two(scramble):
    m = 5
    p = gearte.SobolSequence(2**m, scramble=scramble, seed=3).points(2)
    if not scramble:  # the plain sequence is not random: it needs no seed, and is the same with any
        np.testing.assert_array_equal(gearte.SobolSequence(2**m, scramble=False).points(2), p)
    u = (p + 1) / 2
    assert p.shape == (32, 2) and np.all((u >= 0) & (u < 1))
    # A two-dimensional Sobol' sequence is a (0, m, 2)-net: every 2^a × 2^(m−a) box holds one point.
    for a in range(m + 1):
        cells = np.floor(u[:, 0] * 2**a).astype(int) * 2 ** (m - a) + np.floor(u[:, 1] * 2 ** (m - a)).astype(int)
        assert sorted(cells) == list(range(2**m)), a
    q = gearte.SobolSequence(16, scramble=scramble, seed=3).points(5)
    for j in range(5):
        assert sorted(np.floor((q[:, j] + 1) / 2 * 16).astype(int)) == list(range(16))
    if not scramble:
        np.testing.assert_array_equal(p[0], [-1.0, -1.0])  # the plain sequence starts at the origin


def test_variable_levels_from_a_normal_model():
    mean, std = 12.0, 2.5
    v = gearte.Variable.normal("x1", mean, std, unit="µm")
    q = norm.ppf([0.01, 0.5, 0.99], loc=mean, scale=std)  # eq. 17: the levels are these quantiles
    np.testing.assert_allclose(v.natural([-1.0, 0.0, 1.0]), q, rtol=1e-12)
    np.testing.assert_allclose(v.coded(q), [-1.0, 0.0, 1.0], atol=1e-12)
    # A CCD's axial points lie at mean ± α z₀.₉₉ σ (coded units are linear in natural ones).
    np.testing.assert_allclose(v.natural(math.sqrt(2)), mean + math.sqrt(2) * 2.3263478740408408 * std, rtol=1e-12)
    assert "99 %" in v.basis
    r = gearte.Variable("E", 2.0, 10.0)
    np.testing.assert_allclose(r.natural([-1, 0, 1]), [2, 6, 10])
    np.testing.assert_allclose(r.coded([2, 6, 10]), [-1, 0, 1])


# ---------------------------------------------------------------- response surfaces


def random_quadratic(rng, rho):
    return rng.normal(size=(rho + 1) * (rho + 2) // 2)


@pytest.mark.parametrize(
    ("design", "rho"),
    [(gearte.CentralComposite(center_points=2), 2), (gearte.CentralComposite(gearte.FaceCentred()), 3), (gearte.BoxBehnken(), 4)],
)
def test_response_surface_recovers_a_quadratic_exactly(design, rho):
    rng = np.random.default_rng(10 + rho)
    eta = random_quadratic(rng, rho)
    lows, highs = rng.uniform(-5, 0, rho), rng.uniform(1, 20, rho)
    vs = [gearte.Variable(f"v{i}", lows[i], highs[i]) for i in range(rho)]

    def fn(x, args):
        c = (x - (lows + highs) / 2) / ((highs - lows) / 2)  # coded by hand
        return quad_matrix(np.asarray(c)[None, :])[0] @ eta

    run = gearte.run_design(fn, design, vs)
    assert not run.vectorised  # a NumPy function: evaluated in a loop
    s = gearte.fit_response_surface(run.natural, run.responses, variables=run.variables)
    np.testing.assert_allclose(s.coefficients, eta, rtol=0, atol=1e-10)
    assert s.terms[: rho + 1] == ("1", *(v.name for v in vs))
    assert s.terms[-1] == f"v{rho - 2}*v{rho - 1}" and len(s.terms) == len(eta)
    assert s.named()["1"] == pytest.approx(eta[0], abs=1e-10)
    assert s.r2 == pytest.approx(1.0, abs=1e-12) and s.adj_r2 == pytest.approx(1.0, abs=1e-12)
    assert s.press == pytest.approx(0.0, abs=1e-18) and s.pred_r2 == pytest.approx(1.0, abs=1e-12)
    x = np.stack([rng.uniform(lows, highs) for _ in range(7)])
    np.testing.assert_allclose(s.predict(x), [fn(xi, None) for xi in x], rtol=1e-10, atol=1e-10)


def test_goodness_of_fit_against_definitions_and_leave_one_out_refits():
    rng = np.random.default_rng(3)
    rho = 3
    design = gearte.BoxBehnken(center_points=3)
    c = design.points(rho)
    y = quad_matrix(c) @ random_quadratic(rng, rho) + 0.3 * rng.normal(size=len(c)) + 0.4 * c[:, 0] ** 3
    s = gearte.fit_response_surface(c, y)
    X = quad_matrix(c)
    n, p = X.shape
    # Eq. 16 literally: η = (XᵀX)⁻¹Xᵀy.
    eta = np.linalg.inv(X.T @ X) @ X.T @ y
    np.testing.assert_allclose(s.coefficients, eta, rtol=1e-9, atol=1e-12)
    e = y - X @ eta
    sse, ssy = e @ e, np.sum((y - y.mean()) ** 2)
    assert s.r2 == pytest.approx(1 - sse / ssy, rel=1e-12)
    assert s.r2 == pytest.approx(np.sum((X @ eta - y.mean()) ** 2) / ssy, rel=1e-10)  # SSR/SSY, eq. 18
    assert s.adj_r2 == pytest.approx(1 - (sse / (n - p)) / (ssy / (n - 1)), rel=1e-12)
    # PRESS by refitting without each run in turn.
    press = 0.0
    for i in range(n):
        keep = np.arange(n) != i
        b = np.linalg.lstsq(X[keep], y[keep], rcond=None)[0]
        press += (y[i] - X[i] @ b) ** 2
    assert s.press == pytest.approx(press, rel=1e-9)
    assert s.pred_r2 == pytest.approx(1 - press / ssy, rel=1e-9)
    assert s.pred_r2 < s.adj_r2 < s.r2 < 1
    np.testing.assert_allclose(s.residuals, e, atol=1e-12)
    np.testing.assert_allclose(s.leverage, np.diag(X @ np.linalg.inv(X.T @ X) @ X.T), rtol=1e-10)


def test_press_is_undefined_with_one_centre_point_of_a_rotatable_ccd():
    # Every non-centre run of the rotatable CCD for ρ = 2 lies on one circle; without the centre,
    # the intercept and the squares are confounded: the centre's leverage is 1.
    c = gearte.CentralComposite().points(2)
    y = quad_matrix(c) @ np.arange(1.0, 7.0) + np.sin(7 * c[:, 0])
    s = gearte.fit_response_surface(c, y)
    assert s.leverage[-1] == pytest.approx(1.0, abs=1e-12)
    assert math.isnan(s.press) and math.isnan(s.pred_r2) and 0 < s.r2 < 1
    s2 = gearte.fit_response_surface(gearte.CentralComposite(center_points=2).points(2), np.append(y, y[-1]))
    assert math.isfinite(s2.press) and math.isfinite(s2.pred_r2)


def surface_from(eta, names=("a", "b")):
    c = gearte.CentralComposite(gearte.FaceCentred(), center_points=2).points(len(names))
    vs = [gearte.Variable(n, -1.0, 1.0) for n in names]
    return gearte.fit_response_surface(c, quad_matrix(c) @ np.asarray(eta, dtype=float), variables=vs)


def test_interior_optimum_is_the_stationary_point():
    # y = 3 + (a − 0.3)² + 2 (b + 0.2)² + 0.5 a b, expanded.
    eta = [3 + 0.09 + 0.08, -0.6, 0.8, 1.0, 2.0, 0.5]
    s = surface_from(eta)
    B = np.array([[1.0, 0.25], [0.25, 2.0]])
    xs = -0.5 * np.linalg.solve(B, [-0.6, 0.8])
    ca = s.canonical()
    assert ca.nature == "minimum"
    np.testing.assert_allclose(ca.eigenvalues, np.linalg.eigvalsh(B), rtol=1e-10)
    np.testing.assert_allclose(ca.stationary_coded, xs, rtol=1e-10)
    # The surface's value there, evaluated from the fitted polynomial itself (the summary's stationary value).
    assert ca.stationary_value == pytest.approx(quad_matrix(xs[None])[0] @ eta, rel=1e-12)
    o = s.optimum("minimise")
    assert o.interior and o.at_bounds == ()
    np.testing.assert_allclose(o.natural, xs, rtol=1e-10)
    assert o.value == pytest.approx(quad_matrix(xs[None])[0] @ eta, rel=1e-12)
    # The maximum of a convex surface is at a corner.
    m = s.optimum("maximise")
    assert len(m.at_bounds) == 2
    corners = np.array(list(itertools.product((-1, 1), repeat=2)), dtype=float)
    assert m.value == pytest.approx(np.max(quad_matrix(corners) @ eta), rel=1e-12)


@pytest.mark.parametrize(
    ("eta", "nature"),
    [
        ([0.0, 3.0, -1.0, 1.0, 0.5, 0.2], "minimum"),  # stationary point outside the box: optimum on an edge
        ([1.0, 0.3, 0.2, 1.0, -1.5, 0.4], "saddle"),
        ([0.0, 0.5, -0.3, -1.0, -0.7, 0.1], "maximum"),
    ],
)
def test_box_constrained_optimum_against_brute_force(eta, nature):
    s = surface_from(eta)
    assert s.canonical().nature == nature
    g = np.linspace(-1, 1, 401)
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    f = quad_matrix(grid) @ eta
    for goal, sign in (("minimise", 1.0), ("maximise", -1.0)):
        o = s.optimum(goal)
        # Exact: no grid point, and no L-BFGS-B start, does better.
        assert sign * o.value <= sign * (f.min() if sign > 0 else f.max()) + 1e-12
        assert sign * o.value >= sign * (f.min() if sign > 0 else f.max()) - 1e-4
        for x0 in corners_and_centre():
            r = minimize(lambda x, sign=sign: sign * (quad_matrix(x[None])[0] @ eta), x0, method="L-BFGS-B", bounds=[(-1, 1)] * 2)
            assert sign * o.value <= r.fun + 1e-9
    o = s.optimum("minimise")
    if nature == "minimum":
        assert ("a", "low") in o.at_bounds and not o.interior  # the stationary point (a ≈ −1.5) is outside


def corners_and_centre():
    return [np.array(c, dtype=float) for c in itertools.product((-0.9, 0.0, 0.9), repeat=2)]


def test_optimum_bounds_in_natural_units_and_of_the_design():
    c = gearte.CentralComposite(center_points=2).points(2)  # axial points at ±√2
    vs = [gearte.Variable("a", 0.0, 10.0), gearte.Variable("b", 1.0, 3.0)]
    y = (c[:, 0] - 1.3) ** 2 + (c[:, 1] + 0.2) ** 2  # minimum at coded (1.3, −0.2): outside ±1, inside ±√2
    s = gearte.fit_response_surface(np.stack([vs[0].natural(c[:, 0]), vs[1].natural(c[:, 1])], axis=1), y, variables=vs)
    assert s.optimum().at_bounds == (("a", "high"),)
    np.testing.assert_allclose(s.optimum().natural, [10.0, vs[1].natural(-0.2)], rtol=1e-12)
    d = s.optimum(bounds="design")
    assert d.interior
    np.testing.assert_allclose(d.coded, [1.3, -0.2], rtol=1e-10)
    np.testing.assert_allclose(d.bounds, [[5 - 5 * math.sqrt(2), 5 + 5 * math.sqrt(2)], [2 - math.sqrt(2), 2 + math.sqrt(2)]])
    n = s.optimum(bounds=[(0.0, 4.0), (1.0, 3.0)])
    np.testing.assert_allclose(n.natural, [4.0, vs[1].natural(-0.2)], rtol=1e-12)


def test_ridge_and_three_variable_canonical_analysis():
    s = surface_from([1.0, 0.2, 0.0, 1.0, 1.0, 2.0])  # (a + b)² + 0.2 a + 1: B singular
    assert s.canonical().nature == "ridge" and np.all(np.isnan(s.canonical().stationary_coded))
    o = s.optimum()
    g = np.linspace(-1, 1, 201)
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    assert o.value <= np.min(quad_matrix(grid) @ np.array([1.0, 0.2, 0.0, 1.0, 1.0, 2.0])) + 1e-12
    s3 = surface_from([0, 0, 0, 0, 1.0, 2.0, -3.0, 0, 0, 0], names=("a", "b", "c"))
    np.testing.assert_allclose(s3.canonical().eigenvalues, [-3, 1, 2], rtol=1e-10)
    assert s3.canonical().nature == "saddle"


# ---------------------------------------------------------------- run_design on gearte models


def test_run_design_vmaps_a_jax_function_and_loops_otherwise():
    vs = [gearte.Variable("a", 0.0, 2.0), gearte.Variable("b", -1.0, 1.0)]
    jfn = lambda x, k: jnp.stack([k * x[0] ** 2 + x[1], jnp.sin(x[0])])
    nfn = lambda x, k: np.array([k * float(x[0]) ** 2 + float(x[1]), math.sin(float(x[0]))])
    a = gearte.run_design(jfn, gearte.FullFactorial(3), vs, 2.0)
    b = gearte.run_design(nfn, gearte.FullFactorial(3), vs, 2.0)
    assert a.vectorised and not b.vectorised
    assert a.responses.shape == (9, 2)
    np.testing.assert_allclose(a.responses, b.responses, rtol=1e-14)
    np.testing.assert_allclose(a.natural[:, 0], np.repeat([0.0, 1.0, 2.0], 3))
    with pytest.raises(jax.errors.ConcretizationTypeError):
        gearte.run_design(nfn, gearte.FullFactorial(3), vs, 2.0, vectorise=True)


@pytest.mark.parametrize("rho", [3, 4])
def test_run_design_of_three_and_four_variables_maps_every_coordinate(rho):
    """Every variable's column, coded and natural, and every coordinate of x reaches the model (a design of more than
    two variables; none of the designs, mappings or the run may stop at two). The points are written out by hand."""
    lows, highs = [0.0, -1.0, 10.0, 100.0][:rho], [2.0, 1.0, 20.0, 300.0][:rho]
    vs = [gearte.Variable(f"v{i}", lows[i], highs[i]) for i in range(rho)]
    weights = 10.0 ** np.arange(rho)  # the response tells every coordinate apart
    jfn = lambda x, args: jnp.dot(x, jnp.asarray(weights)) + args
    nfn = lambda x, args: float(np.dot(np.asarray(x), weights)) + args
    # A two-level full factorial: every corner, the last variable changing fastest; natural = the range's ends.
    corners = np.array(list(itertools.product(*[(lo, hi) for lo, hi in zip(lows, highs)])))
    # A rotatable CCD: corners, then each variable at ∓α (α = (2^ρ)^¼) with the others at the centre, then the centre.
    alpha = (2.0**rho) ** 0.25
    centre, half = (np.array(lows) + np.array(highs)) / 2, (np.array(highs) - np.array(lows)) / 2
    axial = [centre + s * alpha * half * np.eye(rho)[i] for i in range(rho) for s in (-1.0, 1.0)]
    ccd = np.concatenate([corners, np.array(axial), centre[None, :]])
    # Box-Behnken: each pair of variables at (±1, ±1), the others at the centre, then three centre points.
    bb = []
    for i, j in itertools.combinations(range(rho), 2):
        for si, sj in itertools.product((-1.0, 1.0), repeat=2):
            bb.append(centre + si * half * np.eye(rho)[i] + sj * half * np.eye(rho)[j])
    bb = np.concatenate([np.array(bb), np.tile(centre, (3, 1))])
    for design, natural in ((gearte.FullFactorial(2), corners), (gearte.CentralComposite(), ccd), (gearte.BoxBehnken(), bb)):
        for fn in (jfn, nfn):
            run = gearte.run_design(fn, design, vs, 0.5)
            assert run.vectorised == (fn is jfn)
            assert run.natural.shape == run.coded.shape == (len(natural), rho), design
            np.testing.assert_allclose(run.natural, natural, rtol=1e-14, atol=1e-13)
            np.testing.assert_allclose(run.coded, (natural - centre) / half, rtol=1e-14, atol=1e-14)
            np.testing.assert_allclose(run.responses, natural @ weights + 0.5, rtol=1e-14)
    # Space-filling designs: every column in its variable's range, and coded ↔ natural both ways for each.
    for design in (gearte.LatinHypercube(16, seed=1), gearte.SobolSequence(16, seed=1)):
        run = gearte.run_design(jfn, design, vs, 0.0)
        assert run.natural.shape == (16, rho)
        assert np.all((run.natural >= np.array(lows)) & (run.natural <= np.array(highs)))
        np.testing.assert_allclose(run.natural, centre + run.coded * half, rtol=1e-14)
        np.testing.assert_allclose(to_coded(run.natural, vs), run.coded, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(to_natural(run.coded, vs), run.natural, rtol=1e-14)
        np.testing.assert_allclose(run.responses, run.natural @ weights, rtol=1e-14)


@pytest.fixture(scope="module")
def planetary_fn():
    """Wang et al.'s (2013) Table 1 drive at fixed phases: the peak TE (″) as a function of the sun's and the ring's
    manufacturing eccentricities x (µm), the other sources at `args` × their Table 1 tolerances."""
    drive = wang2013.table1_drive()
    T = wang2013.TABLE1_TOLERANCES_UM
    phases = dict(zip(T, (0.4, 1.1, 2.0, 2.9, 0.0, 5.0)))

    def peak(x, args):
        errs = {}
        for name, tol in T.items():
            mag = {"sun_manufacturing": x[0], "ring_manufacturing": x[1]}.get(name, jnp.asarray(args * tol))
            shape = drive.error_sources[name].shape
            errs[name] = gearte.Eccentricity(jnp.broadcast_to(mag, shape), jnp.full(shape, phases[name]))
        return gearte.Peak()(drive, drive.response(errs)) * (180 * 3600 / math.pi)  # ″

    return peak


class GivenPoints(gearte.AbstractDesign):
    """A design of given coded points (any `AbstractDesign` subclass runs through `run_design`)."""

    coded: np.ndarray

    def points(self, n_vars):
        assert n_vars == self.coded.shape[1]
        return self.coded

    def describe(self):
        return f"{len(self.coded)} given points"


def test_planetary_peak_te_over_two_eccentricities(planetary_fn):
    T = wang2013.TABLE1_TOLERANCES_UM
    vs = [
        gearte.Variable("E_s", 0.0, T["sun_manufacturing"], unit="µm"),
        gearte.Variable("E_r", 0.0, T["ring_manufacturing"], unit="µm"),
    ]
    design = gearte.CentralComposite(gearte.FaceCentred(), center_points=2)
    # The two eccentricities alone: the peak is 0 at no error and, the TE being linear in the errors, doubles
    # when both double.
    run = gearte.run_design(planetary_fn, design, vs, jnp.asarray(0.0))
    assert run.vectorised and run.responses.shape == (10,)
    y = {tuple(x): v for x, v in zip(run.natural, run.responses)}
    assert y[0.0, 0.0] == 0.0 and y[13.0, 21.0] > 0
    assert y[13.0, 21.0] == pytest.approx(2 * y[6.5, 10.5], rel=1e-12)
    assert y[0.0, 21.0] == pytest.approx(2 * y[0.0, 10.5], rel=1e-12)
    s = gearte.fit_response_surface(run.natural, run.responses, variables=run.variables)
    assert s.r2 > 0.99
    assert set(s.optimum("minimise").at_bounds) == {("E_s", "low"), ("E_r", "low")}
    assert set(s.optimum("maximise").at_bounds) == {("E_s", "high"), ("E_r", "high")}
    # With the other sources at a quarter of their tolerances, the ring's eccentricity partly cancels them at these
    # phases: the surface's minimum is inside the E_r range, where a direct scan of the model finds it (in runs of
    # 10, so that the compiled design is reused).
    run = gearte.run_design(planetary_fn, design, vs, jnp.asarray(0.25))
    o = gearte.fit_response_surface(run.natural, run.responses, variables=run.variables).optimum()
    assert o.at_bounds == (("E_s", "low"),)
    scan = np.stack([-np.ones(90), np.linspace(-1.0, 1.0, 90)], axis=1)  # coded: E_s = 0, E_r over its range
    true = np.concatenate(
        [gearte.run_design(planetary_fn, GivenPoints(scan[i : i + 10]), vs, jnp.asarray(0.25)).responses for i in range(0, 90, 10)]
    )
    e_r = vs[1].natural(scan[:, 1])
    assert abs(o.natural[1] - e_r[np.argmin(true)]) < 0.5
    at_optimum = gearte.run_design(planetary_fn, GivenPoints(np.tile(o.coded, (10, 1))), vs, jnp.asarray(0.25)).responses[0]
    assert at_optimum == pytest.approx(true.min(), rel=0.01)


def test_cycloid_lost_motion_over_two_deviations():
    d = CycloidPin(
        26,
        pin_circle_radius=195.0,
        pin_radius=13.5,
        eccentricity=6.0,
        wheel_pin_circle_radius=194.785,
        wheel_pin_radius=13.88,
        analysis=CycloidAnalysis(positions_per_pitch=1),
    )
    arcmin = 180 * 60 / math.pi

    def lost_motion(x, args):
        return LostMotion()(d, d.response({"pin_radius": x[0], "eccentricity": x[1]})) * arcmin

    vs = [gearte.Variable("pin_radius", -30.0, 30.0, unit="µm"), gearte.Variable("eccentricity", -20.0, 20.0, unit="µm")]
    run = gearte.run_design(lost_motion, gearte.CentralComposite(center_points=2), vs)
    assert run.responses.shape == (10,) and np.all(np.isfinite(run.responses)) and np.all(run.responses > 0)
    assert run.responses[-1] == pytest.approx(float(lost_motion(jnp.asarray([0.0, 0.0]), None)), rel=1e-12)
    s = gearte.fit_response_surface(run.natural, run.responses, variables=run.variables)
    # A larger pin (less clearance) lowers the lost motion: the surface's minimum is at the largest pin radius.
    assert s.coefficients[1] < 0 and ("pin_radius", "high") in s.optimum().at_bounds


# ---------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: gearte.FullFactorial(levels=1), "levels"),
        (lambda: gearte.CentralComposite(gearte.FaceCentred(), alpha=2.0), "face-centred"),
        (lambda: gearte.CentralComposite(alpha=-1.0), "alpha"),
        (lambda: gearte.CentralComposite(center_points=0), "center_points"),
        (lambda: gearte.CentralComposite("ccc"), "Circumscribed"),  # pyright: ignore[reportArgumentType]
        (lambda: gearte.BoxBehnken().points(2), "3 to 7"),
        (lambda: gearte.BoxBehnken().points(8), "3 to 7"),
        (lambda: gearte.SobolSequence(10, seed=0), "8 or 16"),
        (lambda: gearte.SobolSequence(16), "give its seed"),
        (lambda: gearte.LatinHypercube(1, seed=0), "LatinHypercube.n"),
        (lambda: gearte.LatinHypercube(4, seed=-1), "seed"),
        (lambda: gearte.Variable("a", 2.0, 1.0), "above low"),
        (lambda: gearte.Variable("a", 0.0, math.inf), "finite"),
        (lambda: gearte.Variable.normal("a", 1.0, 0.0), "std"),
        (lambda: gearte.run_design(3, gearte.FullFactorial(), [gearte.Variable("a", 0, 1)]), "fn"),
        (lambda: gearte.run_design(lambda x, a: x[0], "ccd", [gearte.Variable("a", 0, 1)]), "design"),
        (lambda: gearte.run_design(lambda x, a: x[0], gearte.FullFactorial(), []), "at least one"),
        (lambda: gearte.run_design(lambda x, a: x[0], gearte.FullFactorial(), [gearte.Variable("a", 0, 1)] * 2), "repeated"),
        (lambda: gearte.fit_response_surface(gearte.FullFactorial(2).points(2), np.ones(4)), "determine only"),
        (lambda: gearte.fit_response_surface(np.zeros((9, 2)), np.ones(8)), "one response per run"),
        (lambda: gearte.fit_response_surface(gearte.FullFactorial(3).points(2), np.full(9, math.nan)), "finite"),
        (lambda: surface_from([0, 0, 0, 1, 1, 0]).optimum("min"), "goal"),
        (lambda: surface_from([0, 0, 0, 1, 1, 0]).optimum(bounds=[(0, 1)]), "bounds"),
        (lambda: surface_from([0, 0, 0, 1, 1, 0]).optimum(bounds="box"), "bounds"),
        (lambda: surface_from([0, 0, 0, 1, 1, 0]).predict(np.zeros(3)), "one per variable"),
    ],
)
def test_bad_input_is_refused_with_the_fix(make, match):
    with pytest.raises(ValueError, match=match):
        make()
