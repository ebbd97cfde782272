"""One contract for every registered drive, and for a drive added the way a user adds one.

Every drive in `gearte.drives.DRIVES` must come with an example study file and pass the same
checks through the protocol alone: the study file loads and `gearte check` accepts it; zero
errors give a TE without variation (zero for a linear drive); `vmap` over samples equals a
Python loop; Monte Carlo values are bit-identical for any chunk size; gradients of a Monte
Carlo mean with respect to every law parameter are finite and not all zero (and match float64 finite
differences for the toy drive); and a short `gearte run` writes every output.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import toy_drive
from conftest import CONTRACT_SAMPLES, CONTRACT_SEED
from jax.flatten_util import ravel_pytree

import gearte
from gearte import cli
from gearte.cli.config import build_study, load_study
from gearte.drives import DRIVES

ROOT = Path(__file__).resolve().parents[1]


def _examples_by_type() -> dict[str, Path]:
    import tomllib

    ranked: dict[str, tuple[int, str, Path]] = {}
    for p in sorted((ROOT / "examples").glob("*.toml")):
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
        t = raw.get("drive", {}).get("type")
        # Prefer a plain Monte Carlo study of each drive; the study kinds have their own tests.
        rank = (len({"allocation", "budget", "modification", "sensitivity", "doe"} & set(raw)), p.name, p)
        if t is not None and (t not in ranked or rank[:2] < ranked[t][:2]):
            ranked[t] = rank
    return {t: r[2] for t, r in ranked.items()} | {t: ROOT / "examples" / f for t, f in RUN_IN_FULL.items()}


#: Examples that a drive's own tests run end to end, study kinds included (tests/test_cycloid.py): the contract
#: takes them for their drive and reads the same run (conftest.example_run).
RUN_IN_FULL = {"cycloid_pin": "cycloid_yao2001_modified.toml"}
EXAMPLES = _examples_by_type()


def _all_examples_by_type() -> dict[str, list[Path]]:
    import tomllib

    out: dict[str, list[Path]] = {}
    for p in sorted((ROOT / "examples").glob("*.toml")):
        t = tomllib.loads(p.read_text(encoding="utf-8")).get("drive", {}).get("type")
        out.setdefault(t, []).append(p)
    return out


ALL_EXAMPLES = _all_examples_by_type()


#: Agreement of a Monte Carlo mean's gradient with its central difference, where a drive's is not 1e-6 (see the test).
FD_REL: dict[str, float] = {"cycloid_pin": 1e-5}  # its contact solves: 1.7e-6 measured
#: Drives whose trace is the TE under load: without errors, the static deflection (a constant), not zero.
LOADED_TE = {"helical_planetary"}


@pytest.fixture(scope="module", params=sorted(DRIVES) + ["toy"])
def case(request):
    """(study, name) for every registered drive's example, and for the toy drive of tests/toy_drive.py."""
    if request.param == "toy":
        with pytest.MonkeyPatch.context() as mp:
            mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)  # the one registry line
            import tomllib

            study = build_study(tomllib.loads(toy_drive.STUDY), "toy.toml")
        return study, "toy"
    assert request.param in EXAMPLES, f"drive {request.param!r} has no example study file in examples/"
    return load_study(EXAMPLES[request.param]), request.param


def test_every_registered_drive_has_an_example():
    assert set(DRIVES) <= set(EXAMPLES), sorted(set(DRIVES) - set(EXAMPLES))


def test_declares_sources_and_metrics(case):
    study, _ = case
    drive = study.drive
    specs = drive.error_sources
    assert specs and all(isinstance(s, gearte.SourceSpec) and s.name == n for n, s in specs.items())
    assert drive.metrics and all(isinstance(m, gearte.AbstractMetric) and m.name == n for n, m in drive.metrics.items())
    assert drive.accuracy()
    assert isinstance(drive, (gearte.AbstractSinusoidalDrive, gearte.AbstractGridDrive))
    # The class variables a drive and its metrics must set (class-level declarations of the protocol).
    assert isinstance(type(drive).type_name, str) and isinstance(type(drive).linear, bool)
    for m in drive.metrics.values():
        assert isinstance(m.label, str) and m.quantity in ("angle", "count") and isinstance(m.higher_is_better, bool)


def test_zero_errors_give_zero_te(case):
    """Zero errors give zero TE: for a linear drive in every example; for a grid drive whose design may add its own
    nominal motion (a cycloid's profile modification gives a backlash and a small TE within each pitch), in at least
    one example of the drive (an unmodified design)."""
    study, name = case
    drive = study.drive
    tr = drive.trace(drive.zero_errors())
    assert np.all(np.isfinite(tr.te))
    if drive.linear:
        np.testing.assert_allclose(tr.te, 0.0, atol=1e-15)
        for m in drive.metrics.values():
            assert float(m(drive, drive.response(drive.zero_errors()))) == pytest.approx(0.0, abs=1e-15)
        return
    designs = [load_study(p).drive for p in ALL_EXAMPLES.get(name, [])] or [drive]
    traces = [np.asarray(d.trace(d.zero_errors()).te) for d in designs]
    spans = [float(np.ptp(te)) for te in traces]
    assert min(spans) <= 1e-9, spans  # rad
    if name not in LOADED_TE:
        sizes = [float(np.max(np.abs(te))) for te in traces]
        assert min(sizes) <= 1e-9, sizes  # rad: zero, not only flat, in the unmodified design


def test_bad_error_values_are_refused_naming_the_source(case):
    """A NaN, a string or an eccentricity where a deviation is due (a number where an eccentricity is due) is refused
    before anything is computed, naming the source: no drive answers inf or NaN for it."""
    study, _ = case
    drive = study.drive
    for n, spec in drive.error_sources.items():
        bad = [math.nan, "x", gearte.Eccentricity(1.0, 0.0)] if spec.kind == "deviation" else [1.0]
        for value in bad:
            errors = dict(drive.zero_errors()) | {n: value}
            with pytest.raises(ValueError, match=re.escape(n)):
                drive.response(errors)


def test_vmap_equals_a_loop(case):
    study, _ = case
    fn = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(7), i))(jnp.arange(3))
    batched = np.asarray(jax.jit(lambda k: jax.vmap(fn)(k))(keys))
    looped = np.asarray([eqx.filter_jit(fn)(k) for k in keys])
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=1e-300)
    assert np.all(np.isfinite(batched))


def test_results_do_not_depend_on_the_chunk_size(case):
    study, _ = case
    fn = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
    a = gearte.monte_carlo(fn, key=3, n_samples=20, block_size=4, chunk_size=8).values
    b = gearte.monte_carlo(fn, key=3, n_samples=20, block_size=4, chunk_size=12).values
    np.testing.assert_array_equal(a, b)


def test_every_drive_runs_on_two_devices_with_the_values_of_one(tmp_path):
    """The `gearte` command shards the Monte Carlo over one CPU device per core: every registered drive's example must
    run there and give the values of one device to the bit (8 samples, two blocks of 4, in a fresh interpreter with
    two forced host devices, against this process's one). The helical drive's example failed there, with the drive's
    arrays closed over in the per-device program, where one device passed."""
    names = sorted(DRIVES)
    one = {}
    for name in names:
        study = load_study(EXAMPLES[name])
        fn = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
        r = gearte.monte_carlo(fn, key=3, n_samples=8, block_size=4, chunk_size=8, progress=False)
        assert r.devices == 1
        one[name] = r.values
    script = textwrap.dedent(
        f"""
        import os
        import jax, numpy as np
        jax.config.update("jax_enable_x64", True)
        import gearte
        from gearte.cli.config import load_study
        from gearte.core.cache import enable_compilation_cache
        enable_compilation_cache(os.environ["GEARTE_CACHE_DIR"], programs=False)  # the suite's JAX cache (conftest)
        out = {{}}
        for name, path in {[(n, str(EXAMPLES[n])) for n in names]!r}:
            study = load_study(path)
            fn = gearte.TEStudy(study.drive, study.errors, metric=study.metric)
            r = gearte.monte_carlo(fn, key=3, n_samples=8, block_size=4, chunk_size=8, progress=False)
            assert r.devices == 2, r.devices
            out[name] = r.values
        np.savez({str(tmp_path / "two.npz")!r}, **out)
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    two = np.load(tmp_path / "two.npz")
    for name in names:
        np.testing.assert_array_equal(two[name], one[name], err_msg=name)
        assert np.all(np.isfinite(one[name])), name


def test_gradients_of_a_monte_carlo_mean_are_finite_and_match_central_differences(case):
    study, name = case
    params, static = eqx.partition(study.errors, eqx.is_inexact_array)
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(11), i))(jnp.arange(2))

    def mean_metric(p):
        fn = gearte.TEStudy(study.drive, eqx.combine(p, static), metric=study.metric)
        return jnp.mean(jax.vmap(lambda k: study.metric.smooth(study.drive, fn.response(k)))(keys))

    value, g = eqx.filter_jit(jax.value_and_grad(mean_metric))(params)
    leaves = jax.tree.leaves(g)
    assert leaves and all(bool(jnp.all(jnp.isfinite(x))) for x in leaves)
    # The law parameters (every inexact leaf of the error model is one of a magnitude law's) move the mean: not all
    # zero, nor round-off (1e-21 where a parameter does not enter); the largest elasticity |p ∂mean/∂p| / |mean| is
    # over 0.05 in every example, well above 1e-3.
    flat, unflatten = ravel_pytree(params)
    grad = ravel_pytree(g)[0]
    assert float(jnp.max(jnp.abs(grad * flat))) > 1e-3 * abs(float(value)), g
    # Along a random direction of the law parameters, against a float64 central difference with the same keys
    # (common random numbers: the draws move with the parameters only), relative step 1e-5 of each parameter; the
    # values come from the program that computed the gradient (no second compilation).
    d = jnp.asarray(np.random.default_rng(0).standard_normal(flat.shape)) * jnp.abs(flat)
    h = 1e-5
    vg = eqx.filter_jit(jax.value_and_grad(mean_metric))
    fd = (float(vg(unflatten(flat + h * d))[0]) - float(vg(unflatten(flat - h * d))[0])) / (2 * h)
    directional = float(grad @ d)
    assert directional != 0.0
    assert directional == pytest.approx(fd, rel=FD_REL.get(name, 1e-6)), (directional, fd)


def test_a_short_run_writes_every_output(case, tmp_path, monkeypatch, capsys, example_run):
    study, name = case
    if name == "toy":
        monkeypatch.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        cfg = tmp_path / "toy.toml"
        cfg.write_text(toy_drive.STUDY)
    else:
        cfg = EXAMPLES[name]
    assert cli.main(["check", str(cfg)]) == 0
    if name == "toy":
        out = tmp_path / "out"
        assert cli.main(["run", str(cfg), "--out", str(out), "--samples", "40", "--seed", "2"]) == 0
    else:
        # The drive's own outputs only where the example has study kinds (budgets, optimisers): they have their own
        # tests. The run is shared with the drive's tests that read this example's results (conftest.example_run).
        drive_only = bool(study.kinds) and name not in RUN_IN_FULL
        out = example_run(cfg, samples=CONTRACT_SAMPLES, seed=CONTRACT_SEED, drive_only=drive_only).out
    for f in ("summary.json", "report.md", "samples.npz", "histogram.png", "trace.png"):
        assert (out / f).exists(), f
    s = json.loads((out / "summary.json").read_text())
    assert s["te"]["n"] == 40 and s["te"]["metric"] == study.metric.name
    # The typical unit's trace spans the drive's hyper-period only for a sinusoidal drive; a grid drive's is its window.
    typical = s["typical_sample"]
    assert ("hyper_period_input_revs" in typical) == isinstance(study.drive, gearte.AbstractSinusoidalDrive)
    assert typical["trace_input_revs"] == typical.get("hyper_period_input_revs", typical["trace_input_revs"])
    for figure in (out / "report.md").read_text().split("](")[1:]:
        assert (out / figure.split(")")[0]).exists(), figure.split(")")[0]


def test_toy_drive_gradient_matches_finite_differences():
    import tomllib

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        study = build_study(tomllib.loads(toy_drive.STUDY), "toy.toml")
    drive = study.drive
    errs = {
        "pinion": gearte.Eccentricity(7.0, 0.4),
        "gear": gearte.Eccentricity(11.0, 2.0),
        "backlash": jnp.asarray(55.0),
        "spacing": jnp.zeros(20),
        "index": jnp.asarray(0.0),
    }

    def lm(m1):
        e = dict(errs, pinion=gearte.Eccentricity(m1, jnp.asarray(0.4)))
        return study.metric(drive, drive.response(e))

    g = float(jax.grad(lm)(jnp.asarray(7.0)))
    h = 1e-6
    fd = (float(lm(jnp.asarray(7.0 + h))) - float(lm(jnp.asarray(7.0 - h)))) / (2 * h)
    assert g == pytest.approx(fd, rel=1e-6)
    # Lost motion = backlash + p-p: its derivative in the backlash is 1/r_b (rad per µm).
    gb = float(jax.grad(lambda b: study.metric(drive, drive.response(dict(errs, backlash=b))))(jnp.asarray(55.0)))
    assert gb == pytest.approx(1e-3 / 28.2, rel=1e-12)


def test_toy_drive_budget_through_the_generic_pipeline():
    """A budget on a non-homogeneous metric (a backlash band about its nominal), solved by the scale search."""
    import tomllib

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        study = build_study(tomllib.loads(toy_drive.STUDY), "toy.toml")
    spec = 8.0 / gearte.units.ARCMIN_PER_RAD  # 8′
    p = gearte.budget_problem(
        study.drive,
        study.errors,
        costs={n: gearte.Reciprocal.normalised(t) for n, t in (("pinion", 10.0), ("gear", 16.0), ("backlash", 20.0))},
        nominal={"pinion": 10.0, "gear": 16.0, "backlash": 20.0},
        spec=spec,
        metric=toy_drive.LostMotion(),
        statistic=gearte.Yield(0.95),
    )
    assert not p.homogeneous
    r = gearte.optimise_budget(p, key=1, n_samples=256, n_check=2000)
    assert r.result == gearte.RESULTS.successful
    assert r.verified_yield >= 0.95
    assert r.cost < gearte.uniform_scaling(p, key=1, n_check=2000).cost * (1 + 1e-9)


def test_scale_search_meets_the_constraint_and_its_gradient_matches_finite_differences():
    """Non-homogeneous budget: the tolerances along a direction are scaled until the smooth statistic equals the
    spec (regula falsi), and their gradient comes from the implicit-function theorem: checked against float64
    central differences of the same computation."""
    import tomllib

    from gearte.optimise import budget as gb

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        study = build_study(tomllib.loads(toy_drive.STUDY), "toy.toml")
    nominal = {"pinion": 10.0, "gear": 16.0, "backlash": 20.0}
    spec = 8.0 / gearte.units.ARCMIN_PER_RAD
    p = gearte.budget_problem(
        study.drive,
        study.errors,
        costs={n: gearte.Reciprocal.normalised(t) for n, t in nominal.items()},
        nominal=nominal,
        spec=spec,
        metric=toy_drive.LostMotion(),
        statistic=gearte.Yield(0.95),
    )
    draws = gb.common_draws(p, jax.random.key(4), 128)
    y = jnp.log(jnp.asarray([12.0, 9.0, 25.0]))
    tol = eqx.filter_jit(gb.tight_tolerances)(p, y, draws)
    stat = gb.statistic(p, gb.metric_samples(p, tol, draws)[0])
    assert float(stat) == pytest.approx(spec, rel=1e-9)

    def cost(yy):
        return gb.total_cost(p, gb.tight_tolerances(p, yy, draws), throw=False)

    g = np.asarray(eqx.filter_jit(jax.grad(cost))(y))
    h = 1e-5
    for i in range(3):
        e = jnp.zeros(3).at[i].set(h)
        fd = (float(eqx.filter_jit(cost)(y + e)) - float(eqx.filter_jit(cost)(y - e))) / (2 * h)
        assert g[i] == pytest.approx(fd, rel=1e-4, abs=1e-8)


def test_a_budget_scales_each_law_as_its_draws_are_scaled():
    """The study at a budget's tolerances (each law `scaled`, as `gearte run` continues with it) draws exactly what
    the budget's common random numbers gave at those tolerances: a band about its centre, a magnitude and a
    sinusoidal pattern about 0."""
    import tomllib

    from gearte.optimise import budget as gb

    text = toy_drive.STUDY + (
        '\n[errors.spacing]\ntolerance_um = 5\nvalue = { law = "sinusoid", amplitude = { law = "uniform", low_um = 0, '
        'high_um = 5 }, phase = "uniform" }\n'
    )
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        study = build_study(tomllib.loads(text), "toy.toml")
    nominal = {"pinion": 10.0, "gear": 16.0, "backlash": 20.0, "spacing": 5.0}
    p = gearte.budget_problem(
        study.drive,
        study.errors,
        costs={n: gearte.Reciprocal.normalised(t) for n, t in nominal.items()},
        nominal=nominal,
        spec=1e-3,
        metric=toy_drive.LostMotion(),
    )
    factors = {"pinion": 0.5, "gear": 1.7, "backlash": 0.3, "spacing": 0.6}
    key, n = jax.random.key(8), 64
    budget_values = np.asarray(
        gb.metric_samples(p, {k: jnp.asarray(nominal[k] * f) for k, f in factors.items()}, gb.common_draws(p, key, n), exact=True)[0]
    )
    scaled = study.errors.replace(
        **{
            k: gearte.ErrorSource(
                study.errors.sources[k].magnitude.scaled(f, about_centre=study.errors.specs[k].kind == "deviation"),
                study.errors.sources[k].phase,
            )
            for k, f in factors.items()
        }
    )
    fn = gearte.TEStudy(study.drive, scaled, metric=toy_drive.LostMotion())
    study_values = np.asarray(jax.vmap(fn)(gearte.sample_keys(key, 0, n)))
    np.testing.assert_allclose(study_values, budget_values, rtol=1e-12)


class _ToyThatFails(toy_drive.ToyGearPair):
    """The toy drive, said to have failed its solve wherever the gear's eccentricity points within 0.2 rad of +x
    (about 3 % of random phases, whatever the tolerances)."""

    def solved(self, response):
        return jnp.cos(response["gear_phase"]) < math.cos(0.2)

    def response(self, errors):
        return super().response(errors) | {"gear_phase": self.checked(errors)["gear"].phase[0]}


def test_a_budget_counts_samples_with_failed_solves_as_missing_every_spec():
    """A drive that solves says where a solve failed (`AbstractDrive.solved`); the budget's exact checks (calibration,
    verification) must not take such a sample's metric at face value: it misses every spec, and the verification
    counts it. The smooth statistics the optimiser steers by are left as they are."""
    import tomllib

    from gearte.optimise import budget as gb

    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        study = build_study(tomllib.loads(toy_drive.STUDY), "toy.toml")
    drive = _ToyThatFails(study.drive.z1, study.drive.z2, base_radius=study.drive.base_radius, points=study.drive.points)
    nominal = {"pinion": 10.0, "gear": 16.0, "backlash": 20.0}
    p = gearte.budget_problem(
        drive,
        study.errors,
        costs={n: gearte.Reciprocal.normalised(t) for n, t in nominal.items()},
        nominal=nominal,
        spec=8.0 / gearte.units.ARCMIN_PER_RAD,
        metric=toy_drive.LostMotion(),
        statistic=gearte.Yield(0.95),
    )
    draws = gb.common_draws(p, jax.random.key(3), 200)
    tol = {n: jnp.asarray(v) for n, v in nominal.items()}
    exact = np.asarray(gb.metric_samples(p, tol, draws, exact=True))[0]
    smooth = np.asarray(gb.metric_samples(p, tol, draws))[0]
    failed = np.cos(np.asarray(draws.errors["gear"].phase).ravel()) >= math.cos(0.2)
    assert 0 < failed.sum() < failed.size
    assert np.all(exact[failed] > 100 * float(p.constraints[0].spec))  # counted as far out of spec
    plain = study.drive  # the same drive without the failure: the other samples keep their exact metric
    q = eqx.tree_at(lambda t: t.drive, p, plain)
    np.testing.assert_array_equal(exact[~failed], np.asarray(gb.metric_samples(q, tol, draws, exact=True))[0][~failed])
    np.testing.assert_array_equal(smooth, np.asarray(gb.metric_samples(q, tol, draws))[0])
    # The verification reports how many of its samples failed.
    r = gb._calibrate_and_verify(
        p,
        {n: float(v) for n, v in nominal.items()},
        set(),
        key=jax.random.key(4),
        n_check=500,
        label="t",
        result=gearte.RESULTS.successful,
        converged=True,
    )
    assert 3 <= r.failed_solves <= 40  # about 3 % of 500
    assert r.verified_yield <= 1 - r.failed_solves / 500
    assert int(np.sum(np.isnan(r.verified_values))) == r.failed_solves  # NaN, not a made-up metric, where they failed
    assert np.isfinite(r.verified_statistic) and r.verified_statistic < 10 * float(p.constraints[0].spec)
    # A mean + kσ has no value to average for a failed sample: it is taken over the samples that solved.
    c = gb.Constraint(toy_drive.LostMotion(), float(p.constraints[0].spec), gearte.MeanKSigma(3.0))
    x = np.where(failed, float(gb._missed(c)), exact)
    assert gb._exact_stat(c, x) == pytest.approx(np.mean(exact[~failed]) + 3 * np.std(exact[~failed], ddof=1), rel=1e-12)
