"""Checks at the public boundary: each refuses an invalid argument with a message naming it, and still accepts a valid one."""

import math
import tomllib
import types
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte import budget_problem, contributions, extrema, pareto_front, smooth_quantile
from gearte.core.twoscale import extrema_two_scale
from gearte.drives import ExplicitDrive, ExplicitTerm
from gearte.identification import MeasuredRecord, RecordError, reassemble
from gearte.identification import assembly as assembly_mod

ROOT = Path(__file__).resolve().parents[1]

GAIN = 1e-5


def explicit_drive():
    return ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 3)], gain=GAIN)


def small_problem(**kw):
    d = explicit_drive()
    law = lambda t: gearte.Rayleigh(t / 2, truncate_at=t)
    model = gearte.ErrorModel(
        {"a": gearte.ErrorSource(law(10.0), gearte.UniformPhase()), "b": gearte.ErrorSource(law(10.0), gearte.UniformPhase())},
        d.error_sources,
    )
    costs = {"a": gearte.Reciprocal(0.0, 10.0), "b": gearte.Reciprocal(0.0, 40.0)}
    return budget_problem(d, model, costs=costs, nominal={"a": 10.0, "b": 10.0}, spec=20 * GAIN, statistic=gearte.Yield(0.99), **kw)


# 1. MeasuredRecord


def test_measured_record_refuses_mismatched_lengths_and_non_finite_values():
    theta = np.linspace(0.0, 2 * math.pi, 32, endpoint=False)
    te = 1e-5 * np.sin(theta)
    with pytest.raises(RecordError, match=r"bench\.csv: theta has 32 samples but te has 31: give one TE value per input angle"):
        MeasuredRecord(theta, te[:-1], source="bench.csv")
    bad = te.copy()
    bad[4] = np.nan
    with pytest.raises(RecordError, match=r"record: te, data row 5: not a finite number"):
        MeasuredRecord(theta, bad)
    with pytest.raises(RecordError, match=r"theta, data row 1: not a finite number"):
        MeasuredRecord(np.where(theta == 0.0, np.inf, theta), te)
    with pytest.raises(RecordError, match=r"te must be 1-D .* got shape \(32, 1\)"):
        MeasuredRecord(theta, te[:, None])
    # The grid its step, samples per revolution and span are read from: increasing, uniform, two samples at least.
    uneven = np.concatenate([theta[:3], theta[3:] + 0.05])
    with pytest.raises(RecordError, match=r"theta, sample 4: the input angles must be a uniform grid"):
        MeasuredRecord(uneven, te)
    with pytest.raises(RecordError, match=r"theta, sample 2: input angles must increase"):
        MeasuredRecord(theta[::-1], te)
    with pytest.raises(RecordError, match=r"at least 2 samples, got 1"):
        MeasuredRecord(theta[:1], te[:1])
    # A long computed grid (1,000 revolutions at 4,096 samples each) is uniform to its rounding.
    long = np.arange(4_096_000) * (2 * math.pi / 4096)
    assert MeasuredRecord(long, np.zeros(long.size)).revolutions == pytest.approx(1000.0, rel=1e-12)
    r = MeasuredRecord(theta, te, input_rpm=60.0)
    assert r.points_per_rev == pytest.approx(32.0)
    # Under jit the fields are traced and pass unchecked.
    out = jax.jit(lambda t, v: MeasuredRecord(t, v).te * 2)(jnp.asarray(theta), jnp.asarray(te))
    np.testing.assert_allclose(out, 2 * te)


# 2. contributions


def test_contributions_checks_n_samples_and_tolerances():
    p = small_problem()
    t = {"a": 4.0, "b": 7.0}
    with pytest.raises(ValueError, match=r"n_samples: must be ≥ 1, got 0"):
        contributions(p, t, key=1, n_samples=0)
    with pytest.raises(ValueError, match=r"n_samples: must be ≥ 1, got -5"):
        contributions(p, t, key=1, n_samples=-5)
    with pytest.raises(ValueError, match=r"tolerances\['a'\]: a tolerance must be finite and > 0 µm, got -4\.0"):
        contributions(p, {"a": -4.0, "b": 7.0}, key=1, n_samples=64)
    with pytest.raises(ValueError, match=r"tolerances: give one tolerance \(µm\) per error source \['a', 'b'\]; missing \['b'\]"):
        contributions(p, {"a": 4.0}, key=1, n_samples=64)
    c = contributions(p, t, key=1, n_samples=64)
    assert set(c) == {"a", "b"} and all(math.isfinite(v) and v > 0 for v in c.values())


def test_budget_arguments_are_checked_before_any_sample_is_drawn():
    """A misspelt source in `maximum` or `minimum` is refused (it had been ignored, the default bound used instead);
    counts below one, a model of another drive, a bare constraint or spec are refused naming the argument."""
    with pytest.raises(ValueError, match=r"maximum: \['c'\] are not budgeted sources; use some of \['a', 'b'\]"):
        small_problem(maximum={"c": 5.0})
    with pytest.raises(ValueError, match=r"minimum: \['A'\] are not budgeted sources"):
        small_problem(minimum={"A": 1.0})
    with pytest.raises(ValueError, match=r"maximum\['a'\]: must be a finite number, got nan"):
        small_problem(maximum={"a": math.nan})
    with pytest.raises(ValueError, match=r"nominal\['a'\]: expected a number, got 'x'"):
        budget_problem(explicit_drive(), small_problem().model, costs=small_problem().costs, nominal={"a": "x", "b": 1.0}, spec=1e-4)
    other = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("c", 2)], gain=GAIN)
    with pytest.raises(ValueError, match=r"model: the error model's sources \['a', 'b'\] do not match the drive's \['a', 'c'\]"):
        budget_problem(other, small_problem().model, costs={"a": gearte.Reciprocal(0.0, 1.0)}, nominal={"a": 1.0}, spec=1e-4)
    q = small_problem()
    with pytest.raises(ValueError, match=r"constraints: a list of gearte.Constraint objects"):
        budget_problem(q.drive, q.model, costs=q.costs, nominal={"a": 1.0, "b": 1.0}, constraints=q.constraints[0])  # pyright: ignore[reportArgumentType]
    p = small_problem()
    for call, match in (
        (lambda: gearte.optimise_budget(p, key=0, n_samples=0), "optimise_budget: n_samples: must be ≥ 1, got 0"),
        (lambda: gearte.optimise_budget(p, key=0, n_check=0), "optimise_budget: n_check: must be ≥ 1, got 0"),
        (lambda: gearte.uniform_scaling(p, key=0, n_check=0), "uniform_scaling: n_check: must be ≥ 1, got 0"),
        (lambda: pareto_front(p, 2e-4, key=0), "pareto_front: specs: a list of specs"),
    ):
        with pytest.raises(ValueError, match=match):
            call()


# 3. pareto_front


def test_pareto_front_checks_each_spec_and_throws_when_asked():
    p = small_problem()
    with pytest.raises(ValueError, match=r"pareto_front: specs\[1\]: Constraint\.spec: the specification of peak must be > 0, got -1\.0"):
        pareto_front(p, [20 * GAIN, -1.0], key=0, n_samples=64, n_check=1000)
    with pytest.raises(ValueError, match=r"pareto_front: specs\[0\]: .*got nan"):
        pareto_front(p, [math.nan], key=0, n_samples=64, n_check=1000)
    # A spec the minimum tolerances cannot meet: reported by default (the current behaviour), raised with throw=True.
    tight = small_problem(minimum={"a": 5.0, "b": 5.0})
    (r,) = pareto_front(tight, [1 * GAIN], key=0, n_samples=256, n_check=1000)
    assert r.result == gearte.RESULTS.infeasible and math.isnan(r.cost)
    with pytest.raises(RuntimeError, match=r"optimise_budget: even at the tolerances .*cannot be met.*pass throw=False"):
        pareto_front(tight, [1 * GAIN], key=0, n_samples=256, n_check=1000, throw=True)


# 4. reassemble


def test_reassemble_passes_throw_to_allocate_measured(monkeypatch):
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 1)], gain=GAIN)  # two lines at one frequency: they cancel
    errs = {"a": gearte.Eccentricity(5.0, 0.3), "b": gearte.Eccentricity(3.0, 0.3)}
    sol = types.SimpleNamespace(groups=(), errors=errs)
    r = reassemble(d, sol, adjust={"b": None}, key=0, starts=2)  # pyright: ignore[reportArgumentType]
    np.testing.assert_allclose(float(r.te), 2.0 * GAIN, rtol=1e-6)  # |A1 − A2|
    seen = []
    real = assembly_mod.allocate_measured
    monkeypatch.setattr(assembly_mod, "allocate_measured", lambda *a, **kw: seen.append(kw["throw"]) or real(*a, **kw))
    reassemble(d, sol, adjust={"b": None}, key=0, starts=2)  # pyright: ignore[reportArgumentType]
    reassemble(d, sol, adjust={"b": None}, key=0, starts=2, throw=False)  # pyright: ignore[reportArgumentType]
    assert seen == [True, False]


def test_allocate_measured_checks_its_width_and_starts(monkeypatch):
    d = ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 1)], gain=GAIN)
    errs = {"a": gearte.Eccentricity(5.0, 0.3), "b": gearte.Eccentricity(3.0, 0.3)}
    for width in (0.0, -1e-3, math.nan, math.inf, "wide", True):
        with pytest.raises(ValueError, match="width"):
            gearte.allocate_measured(d, errs, adjust={"b": None}, key=0, starts=2, width=width)  # pyright: ignore[reportArgumentType]
    for starts in (0, -1, 1.5):
        with pytest.raises(ValueError, match="starts"):
            gearte.allocate_measured(d, errs, adjust={"b": None}, key=0, starts=starts)  # pyright: ignore[reportArgumentType]
    # A width given is the one the optimiser gets (None: 0, its default of 0.2 % of the metric as delivered); both
    # find the optimum |A1 − A2| and report the metric as delivered, |A1 + A2| (both phases at 0.3).
    from gearte.optimise import allocation_measured

    widths = []
    real = allocation_measured._optimise
    monkeypatch.setattr(allocation_measured, "_optimise", lambda *a: widths.append(float(a[6])) or real(*a))
    for width in (1e-7, None):
        r = gearte.allocate_measured(d, errs, adjust={"b": None}, key=0, starts=2, width=width)
        np.testing.assert_allclose(float(r.te), 2.0 * GAIN, rtol=1e-6)
        np.testing.assert_allclose(float(r.te_before), 8.0 * GAIN, rtol=1e-12)
    assert widths == [1e-7, 0.0]


# 5. pathwise_sensitivities


def test_pathwise_sensitivities_refuses_a_chunk_below_one():
    d = explicit_drive()
    model = gearte.ErrorModel(
        {
            "a": gearte.ErrorSource(gearte.Rayleigh(5.0), gearte.UniformPhase()),
            "b": gearte.ErrorSource(gearte.Rayleigh(5.0), gearte.UniformPhase()),
        },
        d.error_sources,
    )
    for bad in (0, -3):
        with pytest.raises(ValueError, match=rf"chunk: must be ≥ 1, got {bad}"):
            gearte.pathwise_sensitivities(d, model, gearte.Peak(), key=0, n_samples=2, chunk=bad)
    out = gearte.pathwise_sensitivities(d, model, gearte.Peak(), key=0, n_samples=2, chunk=1)
    assert math.isfinite(out["peak"].mean) and out["peak"].n_samples == 2


# 6. smooth_quantile


def test_smooth_quantile_checks_level_width_and_shape():
    x = jnp.linspace(1.0, 2.0, 101)
    for level in (2.0, 0.0, 1.0, -0.1):
        with pytest.raises(ValueError, match=r"smooth_quantile: level must be in \(0, 1\)"):
            smooth_quantile(x, level, 0.01)
    for width in (-0.01, 0.0, math.inf):
        with pytest.raises(ValueError, match=r"smooth_quantile: width must be finite and > 0"):
            smooth_quantile(x, 0.9, width)
    with pytest.raises(ValueError, match=r"smooth_quantile: x must be 1-D .* got shape \(101, 1\)"):
        smooth_quantile(x[:, None], 0.9, 0.01)
    q = float(smooth_quantile(x, 0.9, 1e-4))
    assert q == pytest.approx(1.9, abs=2e-2)
    # Traced level and width pass unchecked (no concretisation error), and give the same value.
    traced = jax.jit(lambda v, lv, w: smooth_quantile(v, lv, w))(x, 0.9, 1e-4)
    np.testing.assert_allclose(float(traced), q, rtol=1e-12)


# 7. Eccentricity


def test_eccentricity_refuses_shapes_that_do_not_broadcast():
    with pytest.raises(ValueError, match=r"Eccentricity: magnitude of shape \(2,\) and phase of shape \(3,\) do not broadcast"):
        gearte.Eccentricity([1.0, 2.0], [0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match=r"do not broadcast"):
        jax.jit(lambda m, p: gearte.Eccentricity(m, p).magnitude)(jnp.ones(2), jnp.zeros(3))
    e = gearte.Eccentricity([1.0, 2.0], [0.0, 1.0])
    assert e.magnitude.shape == e.phase.shape == (2,)
    assert gearte.Eccentricity([1.0, 2.0], 0.5).phase.shape == ()
    assert gearte.Eccentricity(1.0, [0.0, 1.0, 2.0]).phase.shape == (3,)


# 8. extrema


def test_extrema_refuses_negative_newton_steps():
    d = explicit_drive()
    sig = d.signal({"a": gearte.Eccentricity(5.0, 0.3), "b": gearte.Eccentricity(3.0, 1.0)})
    with pytest.raises(ValueError, match=r"extrema: newton_steps: must be ≥ 0, got -1"):
        extrema(sig, newton_steps=-1)
    with pytest.raises(ValueError, match=r"extrema_two_scale: newton_steps: must be ≥ 0, got -2"):
        extrema_two_scale(sig, newton_steps=-2)
    e0, e1 = extrema(sig, newton_steps=0), extrema(sig, newton_steps=1)
    assert float(e0.max) <= float(e1.max) + 1e-15
    assert float(extrema_two_scale(sig, newton_steps=0).max) <= float(e1.max) + 1e-15


# 9. Optimised


def test_optimised_checks_to_as_relative_phase_does():
    for bad in (1, ""):
        with pytest.raises(ValueError, match=r"RelativePhase\.to: name the error source"):
            gearte.RelativePhase(bad)  # pyright: ignore[reportArgumentType]
        with pytest.raises(ValueError, match=r"Optimised\.to: name the error source whose phase this one follows"):
            gearte.Optimised(bad)  # pyright: ignore[reportArgumentType]
    assert gearte.Optimised().to is None and gearte.Optimised(None).reference is None
    assert gearte.Optimised("sun").reference == "sun"


def _public_callables():
    """(name, signature) of every public function and class constructor of gearte and of the subpackages whose names
    it does not re-export (`gearte.optimise` and `gearte.studies` have none of their own)."""
    import importlib
    import inspect

    found = {}
    for modname in ("gearte", "gearte.drives", "gearte.drives.harmonic", "gearte.identification"):
        module = importlib.import_module(modname)
        for name in getattr(module, "__all__", None) or [n for n in dir(module) if not n.startswith("_")]:
            obj = getattr(module, name, None)
            target = obj.__init__ if inspect.isclass(obj) else obj
            if not callable(target):
                continue
            try:
                found[f"{modname}.{name}"] = inspect.signature(target)
            except (TypeError, ValueError):
                continue
    return found


def test_every_random_result_takes_an_explicit_key_or_seed():
    # PRNG keys are always explicit: a public function or model that draws anything at random takes its `key` or
    # `seed` keyword-only and without a default (a hidden seed 0 would make every unseeded call the same "random"
    # draw). Exempt: the key utilities, whose key is their data, an unscrambled Sobol' sequence, which draws
    # nothing (its constructor refuses scrambling without a seed: test_doe's bad-input cases), and the study-file
    # reader, whose `seed` overrides the file's own (a required key of [study], checked below) as --seed does, and
    # its `Study`, whose seed is its data.
    exempt = {"gearte.as_key", "gearte.sample_keys", "gearte.SobolSequence", "gearte.load_study", "gearte.build_study", "gearte.Study"}
    checked, wrong = [], []
    for name, sig in _public_callables().items():
        for p in sig.parameters.values():
            if p.name in ("key", "seed") and name not in exempt:
                checked.append(name)
                if p.kind is not p.KEYWORD_ONLY or p.default is not p.empty:
                    wrong.append(f"{name}({p.name}{'' if p.default is p.empty else '=' + repr(p.default)})")
    assert len(checked) >= 15, checked  # the survey reached the API (identify, monte_carlo, allocate_*, designs, …)
    assert not wrong, wrong
    assert gearte.SobolSequence(16, scramble=False).points(2).shape == (16, 2)
    with pytest.raises(ValueError, match=r"\[study\]: missing required key `seed`"):
        gearte.build_study({"study": {"name": "s"}, "drive": {"type": "planetary_2kh"}}, "s.toml")


@pytest.mark.parametrize(
    "freqs, shown",
    [
        ((1, "7/2400001"), "makes 2400001 periods"),  # a long hyper-period: 2,400,001 input revolutions
        ((1, 1e20), "makes 1e+20 periods"),  # a huge frequency
        ((1, "0.29166666666666666666666"), "5e+22 input revolutions"),  # a decimal string read exactly
    ],
)
def test_explicit_frequencies_whose_exact_extrema_would_not_fit_are_refused(freqs, shown):
    """The exact extrema sample every period of the fastest term over the hyper-period (16 points each): frequencies
    that make that grid billions of points are refused when the drive is built, not when it runs out of memory."""
    with pytest.raises(ValueError, match="more than 8,388,608") as e:
        ExplicitDrive([ExplicitTerm("a", freqs[0]), ExplicitTerm("b", freqs[1])], gain=GAIN)
    assert shown in str(e.value)
    # At the bound itself the drive is built: two orders, 262,144 periods, 2 × 16 × 262,144 = 2²³ entries.
    ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 262_144)], gain=GAIN)
    with pytest.raises(ValueError, match="makes 262145 periods"):
        ExplicitDrive([ExplicitTerm("a", 1), ExplicitTerm("b", 262_145)], gain=GAIN)


def test_a_hyper_period_whose_exact_extrema_would_not_fit_is_refused_by_every_drive_and_metric():
    """Coprime tooth counts (301/299/899: the fastest mesh makes 270,599 periods over 358,800 input revolutions; three
    orders, 13 million table entries) and a signal of 300,000 periods are refused before their tables are built, also
    at 4 times the points per period where 16 would fit; 212/199/610 (64,660 periods, 3.1 million entries) is
    computed, and so is a harmonic drive whose tooth line is fast (614/616: 12 million entries for the plain grid, but
    its own two-scale search grids the slow orders only). Two orders reach 2²³ / 32 = 262,144 periods."""
    from fractions import Fraction

    from gearte.core.grid import MAX_GRID_ENTRIES, grid_entries

    assert MAX_GRID_ENTRIES == 2**23
    d = gearte.Planetary2KH(z_sun=301, z_planet=299, z_ring=899, n_planets=3, module=1.0)
    with pytest.raises(ValueError, match=r"3 orders up to 270,599 .* need 12,988,752 table entries at 16 points per period"):
        jax.eval_shape(lambda: d.extrema(d.signal(d.zero_errors())))
    d = gearte.Planetary2KH(z_sun=212, z_planet=199, z_ring=610, n_planets=3, module=1.0)
    orders = jax.eval_shape(lambda: d.signal(d.zero_errors())).orders
    assert max(orders) == 64660 and grid_entries(orders) == 3 * 16 * 64660
    jax.eval_shape(lambda: d.extrema(d.signal(d.zero_errors())))
    raw = tomllib.loads((ROOT / "examples" / "harmonic_liu.toml").read_text())
    raw["drive"] |= {"z_flexspline": 614, "z_circular_spline": 616}
    for table in ("record", "assembly"):
        raw["drive"].pop(table, None)
    h = gearte.build_study(raw, str(ROOT / "examples" / "harmonic_614.toml")).drive  # the file's check passes too
    sig = jax.eval_shape(lambda: h.signal(h.zero_errors()))
    assert grid_entries(sig.orders) > MAX_GRID_ENTRIES
    jax.eval_shape(lambda: h.extrema(h.signal(h.zero_errors())))
    with pytest.raises(ValueError, match="more than 8,388,608"):
        jax.eval_shape(lambda: extrema(h.signal(h.zero_errors())))
    for freq, refused in (([1, 262_145], True), ([1, 262_144], False)):
        two = gearte.to_signal(gearte.Components(amplitude=[1.0, 1.0], phase=[0.0, 0.0], freq=freq))
        if refused:
            with pytest.raises(ValueError, match="more than 8,388,608"):
                jax.eval_shape(extrema, two)
        else:
            jax.eval_shape(extrema, two)
    with pytest.raises(ValueError, match="more than 8,388,608"):  # 2 orders × 64 × 65,537 points
        jax.eval_shape(lambda s: extrema(s, oversample=64), gearte.to_signal(gearte.Components([1.0, 1.0], [0.0, 0.0], [1, 65_537])))
    long = gearte.TESignal(offset=jnp.zeros(()), cos_coef=jnp.ones(2), sin_coef=jnp.zeros(2), orders=(1, 300_000), fundamental=Fraction(1))
    for fn in (lambda s: extrema(s), lambda s: gearte.smooth_peak(s, width=1e-6)):
        with pytest.raises(ValueError, match=r"2 orders up to 300,000 .* need 9,600,000 table entries"):
            fn(long)


def test_an_eccentricity_magnitude_is_drawn_by_a_value_law_that_stays_positive():
    """A magnitude law that can draw below 0 within its bounds, a pattern over teeth (Sinusoid) or a phase law where a
    magnitude is due are refused naming the source; an unbounded Normal is allowed (a negative draw is the phase + π)."""
    d = explicit_drive()
    for law, match in (
        (gearte.Uniform(-1.0, 5.0), r"error source 'a': its magnitude law .* can draw negative values"),
        (gearte.Sinusoid(5.0, 0.0), r"error source 'a': the magnitude of an eccentricity is drawn by a value law .* not Sinusoid"),
        (gearte.UniformPhase(), r"error source 'a': the magnitude of an eccentricity is drawn by a value law .* not UniformPhase"),
    ):
        with pytest.raises(ValueError, match=match):
            gearte.ErrorModel(
                {"a": gearte.ErrorSource(law, gearte.UniformPhase()), "b": gearte.ErrorSource(1.0, gearte.UniformPhase())},  # pyright: ignore[reportArgumentType]
                d.error_sources,
            )
    gearte.ErrorModel(
        {"a": gearte.ErrorSource(gearte.Normal(0.0, 5.0), gearte.UniformPhase()), "b": gearte.ErrorSource(1.0, gearte.UniformPhase())},
        d.error_sources,
    )


def test_counts_and_options_of_the_library_functions_are_checked():
    """Counts, sizes and options that had passed into the computation (a JAX shape error, a float rounded down, a
    sum over nothing) are refused naming the argument."""
    d = explicit_drive()
    model = gearte.ErrorModel({n: gearte.ErrorSource(1.0, gearte.UniformPhase()) for n in "ab"}, d.error_sources)
    sig = d.signal(d.zero_errors() | {"a": gearte.Eccentricity(1.0, 0.0)})
    for call, match in (
        (lambda: gearte.TEStudy(d, model, metric=()), r"metric: give a metric of the drive or a tuple of them"),
        (lambda: gearte.monte_carlo(d, key=0, n_samples=4), r"fn: one sample as a function of its key"),  # pyright: ignore[reportArgumentType]
        (lambda: gearte.monte_carlo(gearte.TEStudy(d, model), key=0, n_samples=4, block_size=2**40), r"block_size: at most"),
        (lambda: gearte.monte_carlo(gearte.TEStudy(d, model), key=0, n_samples=4, on_chunk=1), r"on_chunk: a function"),  # pyright: ignore[reportArgumentType]
        (lambda: extrema(sig, oversample=8.5), r"extrema: oversample: must be a whole number, got 8.5"),  # pyright: ignore[reportArgumentType]
        (lambda: extrema(sig, candidates=1.5), r"extrema: candidates: must be a whole number"),  # pyright: ignore[reportArgumentType]
        (lambda: extrema_two_scale(sig, candidates=0), r"extrema_two_scale: candidates: must be ≥ 1, got 0"),
        (lambda: gearte.smooth_peak(sig, width=math.inf), r"smooth_peak: width: must be a finite number"),
        (lambda: gearte.smooth_peak(sig, width=1e-6, oversample=0), r"smooth_peak: oversample: must be ≥ 2"),
        (lambda: gearte.synthetic_record(d, {}, key=0, revolutions=2, points_per_rev=64.9), r"points_per_rev: must be a whole number"),  # pyright: ignore[reportArgumentType]
        (lambda: gearte.synthetic_record(d, {}, key=0, revolutions=2, points_per_rev=64, counts_per_rev=2.7), r"counts_per_rev: must be"),  # pyright: ignore[reportArgumentType]
        (lambda: gearte.synthetic_record(d, {}, key=0, revolutions=2, points_per_rev=64, noise=-1e-5), r"noise: must be ≥ 0"),
        (lambda: gearte.synthetic_record(d, {}, key=0, revolutions=math.nan, points_per_rev=64), r"revolutions: must be a finite number"),
    ):
        with pytest.raises(ValueError, match=match):
            call()


def test_explicit_terms_read_as_written_in_the_report():
    """A negative offset reads "− 0.349066 rad", not "+ -0.349066"; no offset, no term."""
    d = ExplicitDrive(
        [ExplicitTerm("a", "1/8", phase_sign=-1, offset=-0.349066), ExplicitTerm("b", 2, offset=0.5), ExplicitTerm("c", 3)], gain=GAIN
    )
    rows = dict(d.describe()[2:])
    assert rows == {
        "term a": "1·E sin(1/8·θ − φ − 0.349066 rad)",
        "term b": "1·E sin(2·θ + φ + 0.5 rad)",
        "term c": "1·E sin(3·θ + φ)",
    }
