"""Tolerance budgets: smooth statistic, homogeneity, gradients, verified yield, infeasibility, study files."""

import functools
import json
import math
import re
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy import stats as sps

import gearte
from gearte import ConfigError, budget_problem, cli, contributions, optimise_budget, smooth_quantile, uniform_scaling
from gearte.cli.config import load_study
from gearte.drives import ExplicitDrive, ExplicitTerm
from gearte.optimise.budget import _tight_tolerances_jit
from gearte.optimise.budget_model import common_draws

ROOT = Path(__file__).resolve().parents[1]
GAIN = 1e-5


def two_source_problem(spec=20 * GAIN, target=0.99, **kw):
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 3)], gain=GAIN)
    law = lambda t: gearte.Rayleigh(t / 2, truncate_at=t)
    model = gearte.ErrorModel(
        {"a": gearte.ErrorSource(law(10.0), gearte.UniformPhase()), "b": gearte.ErrorSource(law(10.0), gearte.UniformPhase())},
        d.error_sources,
    )
    # b costs four times as much to tighten: the budget should tighten a more.
    costs = {"a": gearte.Reciprocal(0.0, 10.0), "b": gearte.Reciprocal(0.0, 40.0)}
    return budget_problem(d, model, costs=costs, nominal={"a": 10.0, "b": 10.0}, spec=spec, statistic=gearte.Yield(target), **kw)


def study_at(p, tolerances):
    """The Monte Carlo study of a budget problem at these tolerances: each budgeted law scaled by T/T_nominal.

    Built from public pieces only, independently of the budget's own common-random-number
    machinery; `gearte.monte_carlo(study, key=k)` draws sample i with fold_in(k, i), the same
    keys as the budget's `contributions(key=k)` (one key convention for every study).
    """
    model = p.model.replace(
        **{
            n: gearte.ErrorSource(p.model.sources[n].magnitude.scaled(tolerances[n] / float(p.nominal[n])), p.model.sources[n].phase)
            for n in p.names
        }
    )
    return gearte.TEStudy(p.drive, model, metric=p.constraints[0].metric)


def te_samples(p, tolerances, key, n):
    """The exact metric (rad) of samples 0 … n − 1 at these tolerances.

    One block size for every call (blocks of 1000): every study of the two-source problem, at any
    tolerances and sample count, reuses one compiled program.
    """
    return gearte.monte_carlo(study_at(p, tolerances), key=key, n_samples=n, block_size=1000, chunk_size=2000).values


@functools.partial(jax.jit, static_argnums=1)
def _smooth_statistic(x, target, width):
    return smooth_quantile(x, target, width * jnp.mean(x))


def statistic(p, x):
    """The budget's smooth yield statistic: the kernel-smoothed target-quantile, width relative to the mean."""
    return _smooth_statistic(jnp.asarray(x), p.constraints[0].statistic.target, p.width)


def test_smooth_quantile_tends_to_the_empirical_one_and_has_exact_gradients():
    x = jnp.asarray(np.random.default_rng(0).normal(size=4001))
    np.testing.assert_allclose(smooth_quantile(x, 0.95, 1e-4), np.quantile(x, 0.95), atol=2e-3)
    # Compiled once each (check_grads evaluates them many times).
    q_fixed = jax.jit(lambda v: smooth_quantile(v, 0.9, 0.05))
    q_data = jax.jit(lambda v: smooth_quantile(v, 0.9, 0.02 * jnp.mean(jnp.abs(v))))
    g = jax.grad(q_fixed)(x)
    np.testing.assert_allclose(float(jnp.sum(g)), 1.0, rtol=1e-12)  # shifting every sample shifts the quantile
    assert float(jnp.min(g)) >= 0
    check_grads(q_fixed, (x[:200],), order=1, modes=["rev"], eps=1e-6, atol=1e-7, rtol=1e-5)
    # A width that depends on the data (as the budget's does) is differentiated through as well.
    check_grads(q_data, (x[:200],), order=1, modes=["rev"], eps=1e-6, atol=1e-7, rtol=1e-5)
    # ... and then the smoothed quantile is homogeneous: q(s·x) = s·q(x).
    xp = jnp.abs(x)
    np.testing.assert_allclose(
        smooth_quantile(3.0 * xp, 0.9, 0.02 * jnp.mean(3.0 * xp)), 3.0 * smooth_quantile(xp, 0.9, 0.02 * jnp.mean(xp)), rtol=1e-12
    )


def test_te_is_homogeneous_in_the_tolerances_and_contributions_add_up():
    p = two_source_problem()
    assert p.homogeneous  # a linear drive's peak, magnitudes toleranced about 0: the exact scaling the optimiser uses
    t = {"a": 4.0, "b": 7.0}
    x = te_samples(p, t, 1, 2000)
    np.testing.assert_allclose(te_samples(p, {k: 2.5 * v for k, v in t.items()}, 1, 2000), 2.5 * x, rtol=1e-12)
    c = contributions(p, t, key=1, n_samples=2000)
    # Euler's theorem for a degree-1 homogeneous statistic.
    np.testing.assert_allclose(sum(c.values()), float(statistic(p, x)), rtol=1e-9)


def test_gradient_of_the_monte_carlo_statistic_against_finite_differences():
    # The budget's gradient of its Monte Carlo statistic (its contributions ∂stat/∂T_i · T_i, on
    # common random numbers) against float64 central differences of that statistic, recomputed
    # from plain Monte Carlo studies on the same samples.
    p = two_source_problem()
    t = {"a": 6.0, "b": 3.0}
    c = contributions(p, t, key=2, n_samples=3000)
    eps = 1e-5
    for n in p.names:
        up = float(statistic(p, te_samples(p, t | {n: t[n] + eps}, 2, 3000)))
        down = float(statistic(p, te_samples(p, t | {n: t[n] - eps}, 2, 3000)))
        np.testing.assert_allclose(c[n] / t[n], (up - down) / (2 * eps), atol=1e-10, rtol=1e-4, err_msg=n)


def test_single_source_budget_matches_the_closed_form():
    # One Rayleigh source (scale T/2, truncated at T), one frequency: peak TE = g·T·u exactly, so
    # the 99 % yield at spec needs T = spec / (g · q₀.₉₉(u)), with u's quantile known in closed form.
    d = ExplicitDrive([ExplicitTerm("a", 1)], gain=GAIN)
    model = gearte.ErrorModel({"a": gearte.ErrorSource(gearte.Rayleigh(5.0, truncate_at=10.0), gearte.UniformPhase())}, d.error_sources)
    p = budget_problem(
        d, model, costs={"a": gearte.Reciprocal(0.0, 1.0)}, nominal={"a": 10.0}, spec=20 * GAIN, statistic=gearte.Yield(0.99)
    )
    r = optimise_budget(p, key=0, n_samples=2000, n_check=40_000)
    assert r.result == gearte.RESULTS.successful and r.converged
    cdf1 = sps.rayleigh(scale=0.5).cdf(1.0)
    q = sps.rayleigh(scale=0.5).ppf(0.99 * cdf1)  # quantile of u = magnitude / T
    assert r.tolerances["a"] == pytest.approx(20.0 / q, rel=0.01)
    assert r.verified_yield >= 0.99


def test_the_binding_constraint_of_several_sets_the_scale_in_closed_form():
    """Two constraints on one Rayleigh source (peak TE = g·T·u, as above): 99 % within 20 g and 50 % within 5 g. Each
    alone needs T = spec / (g q(u)); together the smaller, the median's here, and the other is then met with room."""
    d = ExplicitDrive([ExplicitTerm("a", 1)], gain=GAIN)
    model = gearte.ErrorModel({"a": gearte.ErrorSource(gearte.Rayleigh(5.0, truncate_at=10.0), gearte.UniformPhase())}, d.error_sources)
    peak = gearte.Peak()
    constraints = [gearte.Constraint(peak, 20 * GAIN, gearte.Yield(0.99)), gearte.Constraint(peak, 5 * GAIN, gearte.Yield(0.5))]
    p = budget_problem(d, model, costs={"a": gearte.Reciprocal(0.0, 1.0)}, nominal={"a": 10.0}, constraints=constraints)
    law = sps.rayleigh(scale=0.5)
    u = lambda level: law.ppf(level * law.cdf(1.0))  # quantile of u = magnitude / T, truncated at 1
    alone = {0.99: 20.0 / u(0.99), 0.5: 5.0 / u(0.5)}
    assert alone[0.5] < 0.8 * alone[0.99]
    b = uniform_scaling(p, key=5, n_check=40_000)
    assert b.tolerances["a"] == pytest.approx(alone[0.5], rel=0.02)
    se = lambda q: 3 * math.sqrt(q * (1 - q) / 40_000)
    assert b.verified_yields[1] >= 0.5 - se(0.5) and b.verified_yields[0] >= 0.999
    # Each constraint's statistic on the fresh sample: the median at its spec (less the calibration's margin), the
    # P99 well inside its own.
    assert len(b.verified_statistics) == 2 and b.verified_statistics[0] == b.verified_statistic
    assert b.verified_statistics[1] == pytest.approx(5 * GAIN, rel=0.05) and b.verified_statistics[0] < 20 * GAIN


def _one_rayleigh_source(constraints, *, held=False):
    """One Rayleigh source a (scale T/2, truncated at T, nominal 10 µm) on one frequency, peak TE = g·T·u exactly, under
    `constraints`; with `held`, a second source c of magnitude 0 that the budget leaves out (so the problem is not
    homogeneous: the scale is the root search's, not spec / statistic)."""
    names = ("a", "c") if held else ("a",)
    d = ExplicitDrive([ExplicitTerm(n, f) for n, f in zip(names, (1, 2))], gain=GAIN)
    src = {"a": gearte.ErrorSource(gearte.Rayleigh(5.0, truncate_at=10.0), gearte.UniformPhase())}
    if held:
        src["c"] = gearte.ErrorSource(gearte.Fixed(0.0), gearte.FixedPhase(0.0))
    model = gearte.ErrorModel(src, d.error_sources)
    return budget_problem(d, model, costs={"a": gearte.Reciprocal(0.0, 1.0)}, nominal={"a": 10.0}, constraints=constraints)


def _rayleigh_u(level):
    """The `level`-quantile of u = magnitude / T for the Rayleigh law of scale T/2 truncated at T."""
    law = sps.rayleigh(scale=0.5)
    return law.ppf(level * law.cdf(1.0))


#: Three yield constraints on the peak: (spec in units of g, target); each alone needs T = spec / (g q(u)): 20.3, 9.40
#: and 17.3 µm. The middle one binds: neither the first, nor the last, nor the loosest.
THREE = ((20.0, 0.99), (5.0, 0.5), (15.0, 0.9))


@pytest.mark.parametrize("held", [False, True], ids=["homogeneous", "root_search"])
def test_the_optimisers_scale_is_set_by_the_binding_constraint_of_several(held):
    """The analogue of the test above for the optimiser's own scale (`_scale`): along any direction the tight
    tolerance is the smallest of the per-constraint ones (on 4,000 common samples, to a few standard errors of the
    median), whichever constraint that is."""
    peak = gearte.Peak()
    p = _one_rayleigh_source([gearte.Constraint(peak, spec * GAIN, gearte.Yield(t)) for spec, t in THREE], held=held)
    assert p.homogeneous == (not held)
    alone = [spec / _rayleigh_u(t) for spec, t in THREE]
    assert alone[1] < 0.6 * min(alone[0], alone[2])
    draws = common_draws(p, jax.random.PRNGKey(4), 4000)
    # The median of u on 4,000 samples: a standard error of 1 % (density 1.36 at the median); 4 % is four of them.
    for y in (math.log(10.0), math.log(0.7)):  # any direction: a single source's tight tolerance does not depend on it
        tight = float(_tight_tolerances_jit(p, jnp.asarray([y]), draws)["a"])
        assert tight == pytest.approx(alone[1], rel=0.04), y


def test_optimised_budget_of_several_constraints_is_set_by_the_binding_one():
    """`optimise_budget` end to end on the three constraints above: the tolerance is the binding (middle) one's, less
    the calibration's margin (its median clears 0.5 by four standard errors on 20,000 samples: u(0.514) / u(0.5) is
    1.3 % up), and each constraint's verified yield meets its target."""
    peak = gearte.Peak()
    p = _one_rayleigh_source([gearte.Constraint(peak, spec * GAIN, gearte.Yield(t)) for spec, t in THREE])
    r = optimise_budget(p, key=6, n_samples=2000, n_check=20_000)
    assert r.result == gearte.RESULTS.successful and r.converged
    assert r.tolerances["a"] == pytest.approx(5.0 / _rayleigh_u(0.5 + 4 * math.sqrt(0.25 / 20_000)), rel=0.03)
    se = lambda q: 3 * math.sqrt(q * (1 - q) / 20_000)
    assert r.verified_yields[1] >= 0.5 - se(0.5)
    assert r.verified_yields[0] == r.verified_yields[2] == 1.0  # u ≤ 1 (truncated): their specs exceed g·T itself
    assert r.cost == pytest.approx(1.0 / r.tolerances["a"], rel=1e-12)  # Reciprocal(0, 1)


def test_optimised_budget_is_cheaper_and_meets_the_yield_on_a_fresh_seed():
    p = two_source_problem()
    r = optimise_budget(p, key=3, n_samples=2000, n_check=40_000)
    b = uniform_scaling(p, key=3, n_check=40_000)
    assert r.verified_yield >= 0.99 and b.verified_yield >= 0.99
    assert r.verified_samples == 40_000
    assert r.cost < 0.97 * b.cost
    assert r.tolerances["a"] < r.tolerances["b"]  # the cheaper source is tightened
    # Fresh seed, independent of everything above: a plain Monte Carlo study at the found tolerances.
    x = te_samples(p, r.tolerances, 99, 40_000)
    assert np.mean(x <= float(p.constraints[0].spec)) >= 0.99 - 3 * math.sqrt(0.99 * 0.01 / 40_000)


def test_sources_keep_their_order_inside_compiled_functions():
    """The optimiser's y is built outside `jit` in `p.names` order and read inside; a dict comes back from `jit` with
    its keys sorted, so the order must not come from one. With the sources given as (b, a) and unequal nominal
    tolerances, the tight tolerances along y = log(nominal) are the nominal ones scaled alike."""
    q = two_source_problem()
    costs = {"b": gearte.Reciprocal(0.0, 40.0), "a": gearte.Reciprocal(0.0, 10.0)}
    p = budget_problem(q.drive, q.model, costs=costs, nominal={"b": 10.0, "a": 2.0}, spec=20 * GAIN, statistic=gearte.Yield(0.99))
    assert p.names == ["b", "a"] and eqx.filter_jit(lambda p: jnp.asarray([len(n) for n in p.names]))(p).shape == (2,)
    draws = common_draws(p, jax.random.PRNGKey(0), 256)
    tight = _tight_tolerances_jit(p, jnp.log(jnp.asarray([10.0, 2.0])), draws)
    assert float(tight["b"]) / 10.0 == pytest.approx(float(tight["a"]) / 2.0, rel=1e-12)


def test_bad_budget_inputs():
    with pytest.raises(ValueError, match="spec"):
        two_source_problem(spec=-1.0)
    with pytest.raises(ValueError, match="yield"):
        two_source_problem(target=1.2)
    with pytest.raises(ValueError, match="nominal"):
        budget_problem(
            two_source_problem().drive,
            two_source_problem().model,
            costs=two_source_problem().costs,
            nominal={"a": 10.0, "b": 0.0},
            spec=1e-4,
        )
    # A budget may cover some of the sources now (the others keep their laws); a cost model must name a source.
    q = two_source_problem()
    with pytest.raises(ValueError, match="costs"):
        budget_problem(
            q.drive, q.model, costs={"a": gearte.Reciprocal(0, 1), "z": gearte.Reciprocal(0, 1)}, nominal={"a": 1, "z": 1}, spec=1e-4
        )
    with pytest.raises(ValueError, match="costs"):
        budget_problem(q.drive, q.model, costs={}, nominal={}, spec=1e-4)
    with pytest.raises(ValueError, match="nominal"):
        budget_problem(q.drive, q.model, costs={"a": gearte.Reciprocal(0, 1)}, nominal={"a": 1, "b": 1}, spec=1e-4)
    assert budget_problem(q.drive, q.model, costs={"a": gearte.Reciprocal(0, 1)}, nominal={"a": 1}, spec=1e-4).names == ["a"]
    with pytest.raises(ValueError, match="minimum"):
        two_source_problem(minimum={"a": -1.0})
    # An infeasible spec is a solve's result (RESULTS.infeasible): raised by default, reported with throw=False.
    tight = two_source_problem(spec=1 * GAIN, minimum={"a": 5.0, "b": 5.0})
    with pytest.raises(RuntimeError, match="cannot be met"):
        optimise_budget(tight, key=0, n_samples=500, n_check=2000)
    r = optimise_budget(tight, key=0, n_samples=500, n_check=2000, throw=False)
    assert r.result == gearte.RESULTS.infeasible and math.isnan(r.cost)
    with pytest.raises(ValueError, match="> 0"):
        gearte.Reciprocal(0.0, 1.0)(jnp.asarray(-1.0))


def test_budget_example_through_gearte_run(tmp_path):
    text = (ROOT / "examples" / "planetary_wang2013_budget.toml").read_text()
    text = (
        text.replace("samples = 4096 ", "samples = 256 ")
        .replace("check_samples = 50000", "check_samples = 5000")
        .replace("pareto_specs = [90.0, 105.0, 120.0, 140.0, 160.0]", "pareto_specs = [110.0, 140.0]")
    )
    cfg = tmp_path / "b.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    assert cli.main(["run", str(cfg), "--out", str(out), "--samples", "3000"]) == 0
    s = json.loads((out / "summary.json").read_text())
    b = s["budget"]
    for k in ("tolerances_um", "grades", "cost", "baseline_cost", "spec_arcsec", "target_yield", "verified_yield", "verified_samples"):
        assert k in b, k
    assert b["spec_arcsec"] == 120.0 and b["verified_samples"] == 5000
    assert b["cost"] < b["baseline_cost"]
    assert set(b["grades"]) == {"sun_manufacturing", "planet_manufacturing", "ring_manufacturing"}
    # The Table 3 rule cancels the planet assembly error, so its tolerance may go to the cap.
    assert b["tolerances_um"]["planet_assembly"] == pytest.approx(80.0)
    assert b["random_assembly"]["tolerances_um"]["planet_assembly"] < 8.0
    assert len(b["pareto"]) == 2
    # Every budget reported says whether it meets its spec on its fresh samples (these do: a verified yield ≥ target).
    assert all(r["meets_spec"] == (r["verified_yield"] >= 0.9973) for r in b["pareto"])
    assert b["random_assembly"]["meets_spec"] and b["random_assembly"]["baseline_meets_spec"]
    assert b["baseline_meets_spec"] and all(r["baseline_meets_spec"] for r in b["pareto"])
    assert "| meets the spec |" in (out / "report.md").read_text()
    # The further Monte Carlo at the optimised tolerances (the study's seed, 3000 samples): its P99.73 is NumPy's
    # linear-interpolation quantile of the per-sample values the run wrote (same values, same rule: to rounding),
    # and it meets the spec, as the budget's verification on its own fresh samples claims (yield ≥ 0.9973 at 120″).
    te = np.load(out / "samples.npz")["te"]
    assert te.shape == (3000,)
    np.testing.assert_allclose(s["te"]["percentiles"]["99.73"], np.percentile(te, 99.73), rtol=1e-12)
    assert b["verified_yield"] >= b["target_yield"]
    assert s["te"]["percentiles"]["99.73"] <= b["spec_arcsec"]
    assert b["verified_statistic_arcsec"] <= b["spec_arcsec"]
    for f in ("pareto.png", "contributions.png"):
        assert (out / f).exists()


@pytest.mark.parametrize(
    "edit,match",
    [
        (lambda t: t.replace("spec = 120.0 ", "spec = -5.0 "), r"\[budget\] spec: must be > 0"),
        (lambda t: t.replace("target = 0.9973", "target = 1.5"), "a yield in"),
        (lambda t: t.replace('cost_model = "reciprocal"', 'cost_model = "linear"'), "cost_model: must be one of"),
        (
            lambda t: t.replace("tolerance_um = 13", "tolerance_um = 0"),
            r"\[errors.sun_manufacturing.magnitude\] scale_fraction: × tolerance_um 0 µm gives a Rayleigh scale of 0",
        ),
        (
            lambda t: t.replace(
                'tolerance_um = 13\nmagnitude = { law = "rayleigh", scale_fraction = 0.5,',
                'tolerance_um = 0\nmagnitude = { law = "rayleigh", scale_um = 6.5,',
            ),
            r"\[errors.sun_manufacturing.magnitude\] truncate_at_tolerance: the tolerance is 0",
        ),
        (lambda t: t.replace("maximum_factor = 10.0", "maximum_factor = 0.5"), "maximum_factor"),
        (lambda t: t.replace("maximum_factor = 10.0", "maximum_factor = 1e12"), r"\[budget\] maximum_factor: 1e\+12 is more than 1000"),
        (
            lambda t: t.replace("[budget]\n", '[budget]\nsources = ["sun_manufacturing", "sun_manufacturing"]\n', 1),
            r"\[budget\] sources: \['sun_manufacturing'\] named more than once",
        ),
        (  # a cost exponent whose normalisation overflows: a traceback from `gearte check` before
            lambda t: t.replace(
                "[budget.grades.sun_manufacturing]",
                '[budget.costs.sun_manufacturing]\nmodel = "power"\nexponent = 300\n\n[budget.grades.sun_manufacturing]',
                1,
            ),
            r"\[budget.costs.sun_manufacturing\]: Power.normalised: T_ref\^k = 13\^300 overflows",
        ),
        (
            lambda t: t.replace("pareto_specs = [90.0, 105.0", "pareto_specs = [90.0, inf", 1),
            r"\[budget\] pareto_specs: expected a list of positive numbers",
        ),
        (
            lambda t: t.replace('quantity = "F_r"', 'quantity = "F_beta"', 1),
            r"\[budget.grades.sun_manufacturing\]: quantity F_beta \(total helix\) needs face_width_mm",
        ),
        (  # coefficients whose cost at the nominal tolerance is 0 (13^-1e300 underflows) or inf: reported as results before
            lambda t: t.replace(
                "[budget.grades.sun_manufacturing]",
                '[budget.costs.sun_manufacturing]\nmodel = "power"\na = 1e300\nk = 1e300\n\n[budget.grades.sun_manufacturing]',
                1,
            ),
            r"\[budget.costs.sun_manufacturing\]: the cost at the nominal tolerance \(13\) is 0;",
        ),
        # The grades' ISO ranges, checked when the file is read (the run had reported "none" for every grade).
        (
            lambda t: t.replace("module_mm = 1.0", "module_mm = 100", 1),
            r"\[budget.grades.sun_manufacturing\] module_mm: module = 100 mm is outside the range of ISO 1328-1:2013",
        ),
        (lambda t: t.replace("diameter_mm = 12.0", "diameter_mm = 1e9", 1), r"diameter_mm: diameter = 1e\+09 mm is outside"),
    ],
)
def test_bad_budget_configs(edit, match, tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(edit((ROOT / "examples" / "planetary_wang2013_budget.toml").read_text()))
    with pytest.raises(ConfigError, match=match):
        load_study(cfg)


@functools.cache
def _root_search():
    from gearte.optimise.root_search import bracketed_root

    def run(root, lo, hi):
        def g(x):
            # Increasing, far from linear over the bracket (a regula falsi without the Illinois step stalls on it).
            return jnp.expm1(x - root) + 0.1 * jnp.tanh(5 * (x - root))

        return bracketed_root(g, lo, hi)

    return jax.jit(run, static_argnums=(1, 2))


@pytest.mark.parametrize("root", [0.0, 0.3, -0.2, 2.5, -5.0, 4.0])
def test_scale_root_search_finds_the_root_from_log_s_zero(root):
    # The non-homogeneous budget's scale search: bracketed outwards from log s = 0, then Illinois to 1e-12 in log s.
    found = float(_root_search()(root, math.log(1e-3), math.log(1e2)))
    assert found <= root + 1e-12  # the feasible end of the bracket
    assert found == pytest.approx(root, abs=1e-11)


def test_scale_root_search_returns_the_end_of_the_bracket_that_is_the_answer():
    lo, hi = math.log(1e-3), math.log(1e2)
    assert float(_root_search()(10.0, lo, hi)) == hi  # feasible everywhere: the largest scale
    assert float(_root_search()(-10.0, lo, hi)) == lo  # infeasible everywhere: the smallest


def _counted_root_search(g):
    """`bracketed_root` of a Python function g over gearte's bracket, and the points it evaluated g at; a value of
    `_NO_STATE` (1e3) is where the model has no valid state, as `_scale` counts a NaN."""
    from gearte.optimise.budget import _NO_STATE
    from gearte.optimise.root_search import bracketed_root

    calls = []

    def host(v):
        calls.append(float(v))
        return np.asarray(g(float(v)), dtype=np.float64)

    def traced(x):
        return jax.pure_callback(host, jax.ShapeDtypeStruct((), jnp.float64), x)

    found = float(jax.jit(lambda: bracketed_root(traced, math.log(1e-3), math.log(1e2), bisect_above=_NO_STATE))())
    return found, calls


def test_scale_root_search_spends_few_passes():
    # Each evaluation is a pass over the common samples (for a contact drive, thousands of equilibrium solves): count.
    found, calls = _counted_root_search(lambda x: math.expm1(x - 1.7) + 0.1 * math.tanh(5 * (x - 1.7)))
    assert found == pytest.approx(1.7, abs=1e-11)
    assert len(calls) <= 12, calls  # a fixed bisection of the whole bracket then regula falsi took 28
    # Concave: regula falsi stalls at the feasible end instead (halving its value, Illinois, unsticks it: 14 passes
    # against 45 without).
    found, calls = _counted_root_search(lambda x: -math.expm1(-3 * (x - 1.7)))
    assert found == pytest.approx(1.7, abs=1e-11)
    assert len(calls) <= 16, calls
    # Feasible everywhere, or infeasible everywhere: the search stops at the end of the bracket.
    found, calls = _counted_root_search(lambda x: x - 10.0)
    assert found == math.log(1e2) and len(calls) <= 4, calls
    found, calls = _counted_root_search(lambda x: x + 10.0)
    assert found == math.log(1e-3) and len(calls) <= 5, calls


def test_scale_root_search_bisects_a_lopsided_bracket():
    # A violation of 1e-9 on the feasible side against 1e3 on the other (a model's NaN is counted as 1e3): regula
    # falsi alone creeps from the small end and stopped 15 % below the root; bisecting while the infeasible end has no
    # valid state finds it (a jump: about as many evaluations as plain bisection).
    found, calls = _counted_root_search(lambda x: 1e-9 * (x - 1.0) if x <= 1.0 else 1e3)
    assert found == pytest.approx(1.0, abs=1e-10) and found <= 1.0
    assert len(calls) <= 45, len(calls)
    # A continuous violation with the NaN region just beyond the root: found as tightly as a smooth root.
    found, calls = _counted_root_search(lambda x: 1e-4 * (x - 1.0) if x <= 1.02 else 1e3)
    assert found == pytest.approx(1.0, abs=1e-10) and found <= 1.0 + 1e-12
    assert len(calls) <= 12, len(calls)


def test_budget_progress_bar_counts_the_optimiser_evaluations_and_changes_nothing(capsys):
    # The single-source problem (cheap): the bar's host callback must not change the result.
    d = ExplicitDrive([ExplicitTerm("a", 1)], gain=GAIN)
    model = gearte.ErrorModel({"a": gearte.ErrorSource(gearte.Rayleigh(5.0, truncate_at=10.0), gearte.UniformPhase())}, d.error_sources)
    p = budget_problem(
        d, model, costs={"a": gearte.Reciprocal(0.0, 1.0)}, nominal={"a": 10.0}, spec=20 * GAIN, statistic=gearte.Yield(0.99)
    )
    quiet = optimise_budget(p, key=0, n_samples=2000, n_check=40_000, progress=False)
    assert "budget: BFGS" not in capsys.readouterr().err
    shown = optimise_budget(p, key=0, n_samples=2000, n_check=40_000, progress=True)
    err = capsys.readouterr().err
    assert "budget: BFGS on the smoothed cost" in err
    assert "budget: calibrating and verifying (optimised) on 40,000 fresh samples" in err
    # tqdm redraws at most every 0.1 s: the evaluations it shows are the first ones, each with the cost it had.
    costs = [float(m) for m in re.findall(r"cost ([0-9.e+-]+)\]", err)]
    assert costs and all(c > 0.9 * quiet.cost for c in costs)  # the smoothed cost of tight tolerances, never below the optimum by much
    assert shown.tolerances == quiet.tolerances and shown.cost == quiet.cost


def _budget_entry(*, tolerances: dict, nominal: dict, baseline: dict) -> dict:
    """A budget's summary entry as `gearte run` writes it (`budget_kind`), for its report: one yield constraint of 1′ at
    99.73 %, verified on 1,000 samples, each source's maximum 10 × nominal."""
    names = list(tolerances)
    return {
        "constraint": "yield",
        "spec_arcmin": 1.0,
        "target_yield": 0.9973,
        "optimisation_samples": 64,
        "verified_samples": 1000,
        "solver_converged": True,
        "solver_result": "successful",
        "tolerances_um": tolerances,
        "nominal_tolerances_um": nominal,
        "maximum_tolerances_um": {n: 10 * t for n, t in nominal.items()},
        "baseline_tolerances_um": baseline,
        "grades": {},
        "cost_models": {n: gearte.Reciprocal(0.0, 1.0).describe() for n in names},
        "contributions_arcmin": {n: 0.1 for n in names},
        "cost": 2.0,
        "baseline_cost": 2.1,
        "baseline_scale": 1.1,
        "verified_yield": 0.998,
        "baseline_verified_yield": 0.998,
    }


def test_budget_report_gives_angular_tolerances_in_arcseconds():
    # The RV budget example budgets the disc indexing error (rad inside): its report row must read in ″, not "0.00".
    from gearte.cli.budget_kind import _report

    study = load_study(ROOT / "examples" / "rv_robot_joint_budget.toml")
    rad = math.radians(12.0 / 3600)  # 12″
    b = _budget_entry(
        tolerances={"pin_radius": 1.2, "disc_indexing": rad},
        nominal={"pin_radius": 1.0, "disc_indexing": math.radians(10.0 / 3600)},
        baseline={"pin_radius": 1.1, "disc_indexing": 1.1 * math.radians(10.0 / 3600)},
    )
    text = "\n".join(_report(study, {"budget": b}))
    row = next(line for line in text.splitlines() if line.startswith("| disc_indexing |"))
    assert "| 10″ | 12″ | 11″ |" in row and "T in rad" in row
    assert "| pin_radius | 1 | 1.20 | 1.10 |" in text and "T in µm" in text
    assert "± 0.00164, one binomial standard error at a yield of 0.9973 on 1,000 fresh samples" in text  # √(0.9973 · 0.0027 / 1000)
    assert "Below its target" not in text and "At their maximum" not in text
    # A tolerance at its maximum (the constraints do not limit it) is marked and said so.
    capped = "\n".join(_report(study, {"budget": b | {"tolerances_um": {"pin_radius": 10.0, "disc_indexing": rad}}}))
    assert (
        "| pin_radius | 1 | 10.00 (maximum) | 1.10 |" in capped
        and "**At their maximum:** pin_radius: the constraints do not limit it" in capped
    )
    # A verified yield under the target is said so, with how many standard errors that is.
    low = "\n".join(_report(study, {"budget": b | {"verified_yield": 0.995}}))
    assert "**Below its target on the fresh sample:** the yield of the metric is 0.9950 against 0.9973, 1.4 binomial" in low


def test_a_budget_of_several_constraints_reports_each_as_verified():
    """A yield by its yield, a mean − kσ by its value against the spec (it has no yield), each said met or not."""
    from gearte.cli.budget_kind import _report

    study = load_study(ROOT / "examples" / "cycloid_yao2001_budget.toml")
    b = _budget_entry(tolerances={"pin_radius": 1.0}, nominal={"pin_radius": 1.0}, baseline={"pin_radius": 1.0}) | {
        "spec_arcmin": 27.5,
        "constraints": [
            {"metric": "lost_motion", "spec": 27.5, "spec_unit": "arcmin", "constraint": "yield", "target": 0.9973},
            {"metric": "loaded_pairs", "spec": 4.04, "spec_unit": "pairs", "constraint": "mean_k_sigma", "target": 3.0},
        ],
        "verified_yields": [0.999, 1.0],
        "verified_statistics": [21.3, 4.01],
    }
    text = "\n".join(_report(study, {"budget": b}))
    assert "| yield of lost_motion ≥ 0.9973 | ≤ 27.5′ | yield 0.99900 | yes |" in text
    assert "| mean − 3σ of loaded_pairs | ≥ 4.04 pairs | 4.01 pairs | **no** |" in text
