"""Sobol' indices: closed forms, an independent NumPy pick-freeze estimate, per-planet inputs,
per-source aggregation, reproducibility, the side-by-side table, bad inputs."""

import json
import math
from pathlib import Path

import jax
import numpy as np
import pytest
from scipy import stats as sps
from trace_count import traces

import gearte
from gearte import budget_problem, contributions, sensitivity_table, sobol_indices
from gearte.cli.config import load_study
from gearte.drives import ExplicitDrive, ExplicitTerm, Planetary2KH
from gearte.studies.sensitivity_pathwise import gradient_rows

ROOT = Path(__file__).resolve().parents[1]
GAIN = 1e-5  # rad/µm


def study(terms, sources, *, metric=gearte.Peak()):
    d = ExplicitDrive([ExplicitTerm(s, f, offset=o) for s, f, o in terms], gain=GAIN)
    return gearte.TEStudy(d, gearte.ErrorModel(sources, d.error_sources), metric=metric)


def test_single_source_at_one_frequency_the_magnitude_explains_everything():
    # Peak of g·X sin(θ + φ) is g·X whatever φ: S = S_T = 1 for the magnitude, exactly 0 for the phase.
    st = study([("a", 1, 0.0)], {"a": gearte.ErrorSource(gearte.Rayleigh(5.0, truncate_at=10.0), gearte.UniformPhase())})
    r = sobol_indices(st, key=0, n=1024)
    assert r.inputs == ("a.magnitude", "a.phase")
    assert r.input_kind == ("magnitude", "phase") and r.input_source == ("a", "a")
    np.testing.assert_allclose(r.first_order[0], 1.0, atol=0.02)
    np.testing.assert_allclose(r.total_order[0], 1.0, atol=0.02)
    np.testing.assert_allclose(r.first_order[1], 0.0, atol=1e-9)
    np.testing.assert_allclose(r.total_order[1], 0.0, atol=1e-9)
    np.testing.assert_allclose(r.source_closed_first_order["a"], 1.0, atol=0.02)
    np.testing.assert_allclose(r.source_total_order["a"], 1.0, atol=0.02)
    np.testing.assert_allclose(r.source_first_order_sum["a"], r.first_order.sum(), rtol=1e-12)
    # Mean of the truncated Rayleigh (σ = 5, T = 10), in closed form, times the gain.
    law = sps.rayleigh(scale=5.0)
    mean = law.expect(lambda x: x, lb=0, ub=10.0) / law.cdf(10.0)
    np.testing.assert_allclose(r.mean, GAIN * mean, rtol=2e-3)


def test_additive_case_matches_the_closed_form():
    # Crests aligned at θ = π/2: sin θ and sin(3θ + π) both reach +1 there (and −1 at 3π/2), so the
    # exact peak is g (X_a + X_b): additive. X_a ~ U(0, 10), X_b ~ U(5, 25): variances 100/12 and 400/12,
    # so S_a = S_Ta = 0.2 and S_b = S_Tb = 0.8.
    st = study(
        [("a", 1, 0.0), ("b", 3, math.pi)],
        {
            "a": gearte.ErrorSource(gearte.Uniform(0.0, 10.0), gearte.FixedPhase(0.0)),
            "b": gearte.ErrorSource(gearte.Uniform(5.0, 25.0), gearte.FixedPhase(0.0)),
        },
    )
    r = sobol_indices(st, key=3, n=2048)
    assert r.inputs == ("a.magnitude", "b.magnitude")  # fixed phases are not inputs
    np.testing.assert_allclose(r.first_order, [0.2, 0.8], atol=0.01)
    np.testing.assert_allclose(r.total_order, [0.2, 0.8], atol=0.01)
    np.testing.assert_allclose(r.variance, GAIN**2 * (100 + 400) / 12, rtol=0.01)
    np.testing.assert_allclose(r.mean, GAIN * (5 + 15), rtol=1e-3)


def _numpy_pick_freeze(f, sample, n, groups, rng):
    """Plain NumPy estimates, independent of gearte and scipy: Saltelli (2010) first-order and
    Jansen (1999) total indices of each column group, from random (not quasi-random) A and B."""
    A, B = sample(rng, n), sample(rng, n)
    fA, fB = f(A), f(B)
    var = np.var(np.concatenate([fA, fB]))
    out = []
    for cols in groups:
        AB = A.copy()
        AB[:, cols] = B[:, cols]
        fAB = f(AB)
        out.append((np.mean(fB * (fAB - fA)) / var, 0.5 * np.mean((fA - fAB) ** 2) / var))
    return np.array(out)


def test_interacting_inputs_against_an_independent_numpy_estimate():
    # a sin θ + b sin(θ + φ) has peak |a + b e^{iφ}|: the magnitudes and b's phase interact.
    st = study(
        [("a", 1, 0.0), ("b", 1, 0.0)],
        {
            "a": gearte.ErrorSource(gearte.Uniform(2.0, 6.0), gearte.FixedPhase(0.0)),
            "b": gearte.ErrorSource(gearte.Rayleigh(2.0, truncate_at=5.0), gearte.UniformPhase()),
        },
    )
    r = sobol_indices(st, key=11, n=4096)
    assert r.inputs == ("a.magnitude", "b.magnitude", "b.phase")

    ray = sps.rayleigh(scale=2.0)

    def sample(rng, n):
        u = rng.uniform(size=(n, 3))
        return np.stack([2.0 + 4.0 * u[:, 0], ray.ppf(u[:, 1] * ray.cdf(5.0)), 2 * math.pi * u[:, 2]], axis=1)

    f = lambda x: np.abs(x[:, 0] + x[:, 1] * np.exp(1j * x[:, 2]))
    ref = _numpy_pick_freeze(f, sample, 400_000, [[0], [1], [2], [1, 2]], np.random.default_rng(7))
    np.testing.assert_allclose(r.first_order, ref[:3, 0], atol=0.03)
    np.testing.assert_allclose(r.total_order, ref[:3, 1], atol=0.03)
    np.testing.assert_allclose(r.source_closed_first_order["b"], ref[3, 0], atol=0.03)
    np.testing.assert_allclose(r.source_total_order["b"], ref[3, 1], atol=0.03)
    # Interactions are real here: the phase matters only together with the magnitudes.
    assert r.total_order[2] > r.first_order[2] + 0.1
    # One-input sources: the source's indices are its input's.
    np.testing.assert_allclose(r.source_closed_first_order["a"], r.first_order[0], rtol=1e-12)
    np.testing.assert_allclose(r.source_total_order["a"], r.total_order[0], rtol=1e-12)
    # Σ S_i over b's inputs bounds its closed first-order index from below.
    assert r.source_first_order_sum["b"] <= r.source_closed_first_order["b"] + 0.01


@pytest.mark.parametrize("coupling", [gearte.SinglePath(), gearte.LoadSharing()], ids=["single_path", "load_sharing"])
def test_per_planet_sources_give_one_magnitude_and_one_phase_input_per_planet(coupling):
    d = Planetary2KH(12, 36, 84, module=1.0, pressure_angle=math.pi / 9, n_planets=3, coupling=coupling)
    law = lambda t: gearte.Rayleigh(t / 2, truncate_at=t)
    tol = {
        "sun_manufacturing": 13,
        "planet_manufacturing": 16,
        "ring_manufacturing": 21,
        "sun_assembly": 12,
        "planet_assembly": 8,
        "carrier_assembly": 15,
    }
    model = gearte.ErrorModel({k: gearte.ErrorSource(law(v), gearte.UniformPhase()) for k, v in tol.items()}, d.error_sources)
    r = sobol_indices(gearte.TEStudy(d, model), key=5, n=256)
    # 4 single sources × 2 inputs + 2 per-planet sources × (3 + 3) inputs.
    assert len(r.inputs) == 4 * 2 + 2 * 6
    for i in range(3):
        assert f"planet_manufacturing.magnitude[{i}]" in r.inputs and f"planet_assembly.phase[{i}]" in r.inputs
    others = [j for j, lab in enumerate(r.inputs) if lab.startswith("planet_") and not lab.endswith("[0]")]
    if isinstance(coupling, gearte.SinglePath):
        # Planet 1's path alone sets the output: the other planets' errors change nothing at all.
        assert np.all(r.total_order[others] == 0) and np.all(r.first_order[others] == 0)
    else:
        assert np.all(r.total_order[others] > 0.001)


def test_rule_bound_phases_are_not_inputs_and_follow_their_datum():
    s = load_study(ROOT / "examples" / "planetary_wang2013_budget.toml")
    r = sobol_indices(gearte.TEStudy(s.drive, s.errors), key=1, n=256)
    # Table 3: γ_s = β_r + 7π/9, γ_c = β_r + 8π/9, γ_p = 0 — no phase inputs for the assembly errors.
    assert not [lab for lab in r.inputs if lab.startswith(("sun_assembly.phase", "carrier_assembly.phase", "planet_assembly.phase"))]
    assert "ring_manufacturing.phase" in r.inputs
    # With the planet pin-hole phases at 0 the two constant terms cancel exactly: no influence at all.
    assert r.source_total_order["planet_assembly"] == pytest.approx(0.0, abs=1e-12)
    assert set(r.sources) == set(s.drive.error_sources)


def test_a_row_of_uniforms_becomes_the_errors_the_rules_and_the_budget_say():
    """The map from a row of uniforms to errors, by hand: a phase input u is 2π u; a relative rule adds its offset to
    its datum's phase; a band (a deviation's uniform law about a centre) scaled by a budget keeps its centre."""
    from gearte.studies.sensitivity import _plan

    st = study(
        [("a", 1, 0.0), ("b", 1, 0.0)],
        {"a": gearte.ErrorSource(2.0, gearte.UniformPhase()), "b": gearte.ErrorSource(1.0, gearte.RelativePhase("a", 0.4))},
    )
    labels, _, _, plan = _plan(st.drive, st.errors, {"a": 1.0, "b": 1.0}, gearte.Peak())
    assert labels == ("a.phase",)
    e = plan.errors(jax.numpy.asarray([0.25]))
    np.testing.assert_allclose(np.ravel(e["a"].phase), math.pi / 2, rtol=1e-15)
    np.testing.assert_allclose(np.ravel(e["b"].phase), math.pi / 2 + 0.4, rtol=1e-15)
    drive = load_study(ROOT / "examples" / "cycloid_yao2001_modified.toml").drive
    low, high = -58.5, -25.0  # µm, the example's pin-radius range, here as a band about its middle
    band = gearte.Uniform.centred((high - low) / 2, (low + high) / 2)
    sources = {n: gearte.ErrorSource(band if n == "pin_radius" else 0.0) for n in drive.error_sources}
    model = gearte.ErrorModel(sources, drive.error_sources)
    labels, _, _, plan = _plan(drive, model, {n: 0.5 if n == "pin_radius" else 1.0 for n in model.specs}, gearte.LostMotion())
    u = np.full(len(labels), 0.5)
    u[labels.index("pin_radius.value")] = 0.9
    value = float(np.ravel(plan.errors(jax.numpy.asarray(u))["pin_radius"])[0])
    centre = (low + high) / 2
    assert value == pytest.approx(centre + 0.5 * (low + 0.9 * (high - low) - centre), rel=1e-12)


def test_reproducible_from_the_seed():
    st = study(
        [("a", 1, 0.0), ("b", 2, 0.0)],
        {
            "a": gearte.ErrorSource(gearte.Rayleigh(2.0), gearte.UniformPhase()),
            "b": gearte.ErrorSource(gearte.Normal(5.0, 1.0), gearte.UniformPhase()),
        },
    )
    r1, r2 = sobol_indices(st, key=42, n=128), sobol_indices(st, key=42, n=128)
    np.testing.assert_array_equal(r1.first_order, r2.first_order)
    np.testing.assert_array_equal(r1.total_order, r2.total_order)
    assert r1.source_total_order == r2.source_total_order
    r3 = sobol_indices(st, key=43, n=128)
    assert not np.array_equal(r1.first_order, r3.first_order)
    k = jax.random.key(9)
    np.testing.assert_array_equal(sobol_indices(st, key=k, n=64).total_order, sobol_indices(st, key=k, n=64).total_order)
    # The block size changes how samples are batched, not which.
    np.testing.assert_allclose(sobol_indices(st, key=42, n=128, block_size=100).total_order, r1.total_order, rtol=1e-10, atol=1e-12)


def test_bootstrap_intervals():
    # The additive case above (S_a = 0.2, S_b = 0.8) and a source c of zero magnitude whose random
    # phase therefore changes nothing: its indices are 0 in every resample, a degenerate interval.
    st = study(
        [("a", 1, 0.0), ("b", 3, math.pi), ("c", 2, 0.0)],
        {
            "a": gearte.ErrorSource(gearte.Uniform(0.0, 10.0), gearte.FixedPhase(0.0)),
            "b": gearte.ErrorSource(gearte.Uniform(5.0, 25.0), gearte.FixedPhase(0.0)),
            "c": gearte.ErrorSource(0.0, gearte.UniformPhase()),
        },
    )
    r = sobol_indices(st, key=2, n=256, confidence_level=0.9, n_resamples=200)
    assert r.inputs == ("a.magnitude", "b.magnitude", "c.phase")
    assert r.first_order_ci.shape == (3, 2) and r.total_order_ci.shape == (3, 2)
    assert np.all(r.first_order_ci[:, 0] <= r.first_order_ci[:, 1])
    assert r.first_order_ci[0, 0] < 0.2 < r.first_order_ci[0, 1]
    assert r.total_order_ci[1, 0] < 0.8 < r.total_order_ci[1, 1]
    np.testing.assert_allclose(r.total_order_ci[2], [0.0, 0.0], atol=1e-12)
    again = sobol_indices(st, key=2, n=256, confidence_level=0.9, n_resamples=200)
    np.testing.assert_array_equal(r.first_order_ci, again.first_order_ci)
    d = r.to_dict()
    assert d["inputs"]["a.magnitude"]["first_order_ci"] == [float(x) for x in r.first_order_ci[0]]


def two_source_problem():
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 3)], gain=GAIN)
    law = lambda t: gearte.Rayleigh(t / 2, truncate_at=t)
    model = gearte.ErrorModel(
        {"a": gearte.ErrorSource(law(10.0), gearte.UniformPhase()), "b": gearte.ErrorSource(law(20.0), gearte.UniformPhase())},
        d.error_sources,
    )
    return budget_problem(
        d,
        model,
        costs={"a": gearte.Reciprocal(0.0, 1.0), "b": gearte.Reciprocal(0.0, 1.0)},
        nominal={"a": 10.0, "b": 20.0},
        spec=20 * GAIN,
        statistic=gearte.Yield(0.99),
    )


def budget_study(p):
    """The per-sample study of a budget problem: its drive, its laws at the nominal tolerances, its metric."""
    return gearte.TEStudy(p.drive, p.model, metric=p.constraints[0].metric)


def tolerance_scale(p, tolerances):
    """Sobol' `scale` factors for these tolerances: T / T_nominal per source."""
    return {n: tolerances[n] / float(p.nominal[n]) for n in p.names}


def test_budget_problem_tolerances_scale_the_laws():
    p = two_source_problem()
    st = budget_study(p)
    base = sobol_indices(st, key=4, n=512)
    # TE is homogeneous of degree 1 in the tolerances: scaling them all leaves every index unchanged.
    both = sobol_indices(st, key=4, n=512, scale=tolerance_scale(p, {"a": 30.0, "b": 60.0}))
    np.testing.assert_allclose(both.first_order, base.first_order, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(both.mean, 3 * base.mean, rtol=1e-12)
    # Loosening a alone moves the variance towards a.
    a_loose = sobol_indices(st, key=4, n=512, scale=tolerance_scale(p, {"a": 40.0, "b": 20.0}))
    assert a_loose.source_total_order["a"] > base.source_total_order["a"] + 0.2


def test_sensitivity_table_puts_contributions_and_sobol_side_by_side():
    p = two_source_problem()
    tol = {"a": 10.0, "b": 20.0}
    t = sensitivity_table(p, tol, key=6, n_sobol=256, n_samples=1024)
    assert t.sources == ["a", "b"]
    k_grad, k_sobol = jax.random.split(jax.random.key(6))
    assert t.contribution == contributions(p, tol, key=k_grad, n_samples=1024)
    np.testing.assert_array_equal(
        t.sobol.total_order, sobol_indices(budget_study(p), key=k_sobol, n=256, scale=tolerance_scale(p, tol)).total_order
    )
    np.testing.assert_allclose(sum(r["contribution_rad"] for r in t.rows()), t.statistic, rtol=1e-12)
    np.testing.assert_allclose(sum(r["share"] for r in t.rows()), 1.0, rtol=1e-12)
    assert {r["source"]: r["sobol_total_order"] for r in t.rows()} == t.sobol.source_total_order
    # b (twice the tolerance) owns more of both.
    rows = {r["source"]: r for r in t.rows()}
    assert rows["b"]["share"] > rows["a"]["share"] and rows["b"]["sobol_total_order"] > rows["a"]["sobol_total_order"]
    json.dumps(t.to_dict())
    text = t.format(unit="arcsec")
    assert "″" in text and "a" in text.splitlines()[2]
    with pytest.raises(ValueError, match="unit"):
        t.format(unit="furlong")


class NoInverse(gearte.AbstractLaw):
    def sample(self, key, shape):
        return jax.random.uniform(key, shape, dtype=float)

    def describe(self, unit="µm"):
        return "no inverse CDF"


def test_bad_inputs():
    good = study([("a", 1, 0.0)], {"a": gearte.ErrorSource(gearte.Rayleigh(1.0), gearte.UniformPhase())})
    for n in (1000, 8, True, 64.0):
        with pytest.raises(ValueError, match="power of 2"):
            sobol_indices(good, key=0, n=n)
    # Tolerances scale the laws through `scale` (a factor per source, > 0, of a source of the model).
    with pytest.raises(ValueError, match="not an error source"):
        sobol_indices(good, key=0, n=64, scale={"z": 1.0})
    for bad in (0.0, -2.0, float("nan")):
        with pytest.raises(ValueError, match="factor > 0"):
            sobol_indices(good, key=0, n=64, scale={"a": bad})
    with pytest.raises(ValueError, match="TEStudy"):
        sobol_indices(good.drive, key=0, n=64)
    with pytest.raises(ValueError, match="seed"):
        sobol_indices(good, key="zero", n=64)
    with pytest.raises(ValueError, match="confidence_level"):
        sobol_indices(good, key=0, n=64, confidence_level=95)
    with pytest.raises(ValueError, match="block_size"):
        sobol_indices(good, key=0, n=64, block_size=0)
    # A budget problem's tolerances (the side-by-side table of a budget) are checked where they are given.
    p = two_source_problem()
    with pytest.raises(ValueError, match="missing"):
        sensitivity_table(p, {"a": 1.0}, key=0)
    with pytest.raises(ValueError, match="unknown"):
        sensitivity_table(p, {"a": 1.0, "b": 1.0, "c": 1.0}, key=0)
    with pytest.raises(ValueError, match="> 0 µm"):
        sensitivity_table(p, {"a": 1.0, "b": -2.0}, key=0)
    with pytest.raises(ValueError, match="TEStudy"):
        sobol_indices(p, key=0, n=64)
    with pytest.raises(ValueError, match="> 0 µm"):
        sensitivity_table(p, {"a": 1.0, "b": float("nan")}, key=0)
    with pytest.raises(ValueError, match="budget problem"):
        sensitivity_table(good, key=0)
    constant = study([("a", 1, 0.0)], {"a": gearte.ErrorSource(gearte.Uniform(3.0, 3.0), gearte.FixedPhase(0.1))})
    with pytest.raises(ValueError, match="no random input"):
        sobol_indices(constant, key=0, n=64)
    with pytest.raises(ValueError, match="inverse CDF"):
        sobol_indices(study([("a", 1, 0.0)], {"a": gearte.ErrorSource(NoInverse(), gearte.UniformPhase())}), key=0, n=64)
    s = load_study(ROOT / "examples" / "planetary_wang2013_allocate.toml")
    with pytest.raises(ValueError, match="allocation optimiser"):
        sobol_indices(gearte.TEStudy(s.drive, s.errors), key=0, n=64)


def test_a_second_pathwise_study_of_the_same_drive_traces_nothing():
    """`pathwise_sensitivities` twice on one drive with other law scales and seed: the second call traces nothing (a
    chunk's values and gradients are jitted once at module level, the laws' parameters and the key being data), and
    its mean is that of its own samples, drawn and measured one by one; the peak of a linear drive is homogeneous of
    degree 1 in the errors, so Σ scale·∂mean/∂scale = mean (Euler)."""
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 3)], gain=GAIN)

    def model(sa, sb):
        laws = {"a": gearte.Rayleigh(sa), "b": gearte.Rayleigh(sb)}
        return gearte.ErrorModel({n: gearte.ErrorSource(law, gearte.UniformPhase()) for n, law in laws.items()}, d.error_sources)

    gearte.pathwise_sensitivities(d, model(5.0, 2.0), gearte.Peak(), key=0, n_samples=3, chunk=2)
    m = model(7.0, 3.0)
    with traces() as seen:
        out = gearte.pathwise_sensitivities(d, m, gearte.Peak(), key=1, n_samples=3, chunk=2)["peak"]
    assert not seen, dict(seen)
    key = jax.random.key(1)
    mean = np.mean([float(gearte.Peak()(d, d.response(m.sample(jax.random.fold_in(key, i))))) for i in range(3)])
    assert out.mean == pytest.approx(mean, rel=1e-12)
    rows = {r.label: r.value for r in gradient_rows(out, m)}
    assert 7.0 * rows["a.scale"] + 3.0 * rows["b.scale"] == pytest.approx(mean, rel=1e-9)


def test_the_pathwise_summary_is_in_the_report_units_by_hand():
    """Two fixed phasors of one frequency, 2 µm at phase 0 and 1 µm at phase β = 1 rad: the peak is g |2 + e^{iβ}|,
    so d peak/d(magnitude of a) = g (2 + cos β)/|·| (rad per µm, reported in ″ per µm) and d peak/dβ =
    −2 g sin β/|·| (rad per rad: the same number in ″ per ″). The smooth peak the derivatives are taken of is within
    its width of the exact one."""
    from gearte.core.units import ARCSEC_PER_RAD
    from gearte.studies.sensitivity_pathwise import pathwise_summary

    st = study(
        [("a", 1, 0.0), ("b", 1, 0.0)],
        {"a": gearte.ErrorSource(2.0, gearte.FixedPhase(0.0)), "b": gearte.ErrorSource(1.0, gearte.FixedPhase(1.0))},
    )
    peak = gearte.Peak()
    out = gearte.pathwise_sensitivities(st.drive, st.errors, peak, key=0, n_samples=2, chunk=2)
    entry = pathwise_summary(out, st.errors, {"peak": peak}, unit="arcsec")["peak"]
    r = abs(2 + np.exp(1j))
    assert entry["unit"] == "arcsec" and entry["mean"] == pytest.approx(GAIN * r * ARCSEC_PER_RAD, rel=1e-3)
    rows = entry["derivatives"]
    assert rows["a.value"]["per"] == "µm" and rows["b.phase.value"]["per"] == "″"
    assert rows["a.value"]["value"] == pytest.approx(GAIN * (2 + math.cos(1.0)) / r * ARCSEC_PER_RAD, rel=1e-3)
    assert rows["b.phase.value"]["value"] == pytest.approx(-2 * GAIN * math.sin(1.0) / r, rel=1e-3)
    # A law with one parameter at zero (a magnitude uniform from 0) is a source like any other, not one left out.
    st = study([("a", 1, 0.0)], {"a": gearte.ErrorSource(gearte.Uniform(0.0, 10.0), gearte.UniformPhase())})
    out = gearte.pathwise_sensitivities(st.drive, st.errors, peak, key=0, n_samples=2, chunk=2)
    assert {"a.low", "a.high"} <= set(pathwise_summary(out, st.errors, {"peak": peak})["peak"]["derivatives"])
