"""Monte Carlo engine: reproducibility, chunk-size independence, statistics, recompilation."""

import math

import equinox as eqx
import hypothesis.strategies as st
import jax
import numpy as np
import pytest
from hypothesis import given, settings
from scipy import stats as sps

import gearte
from gearte.cli.config import load_study
from gearte.drives import wang2013

ARCSEC = 180 * 3600 / math.pi


@pytest.fixture(scope="module")
def random_study():
    s = load_study("examples/planetary_wang2013_random.toml")
    return gearte.TEStudy(s.drive, s.errors, metric=gearte.Peak())


@settings(max_examples=8, deadline=None)
@given(st.integers(1, 700))
def test_results_do_not_depend_on_chunk_size(random_study, chunk):
    # Blocks of 64: progress every block or every many blocks, against one chunk for everything.
    a = gearte.monte_carlo(random_study, key=7, n_samples=1000, chunk_size=chunk, block_size=64).values
    b = gearte.monte_carlo(random_study, key=7, n_samples=1000, chunk_size=1024, block_size=64).values
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("chunk", [1, 64, 65, 128, 1000])
def test_one_block_and_many_blocks_per_call_agree_bitwise(random_study, chunk):
    a = gearte.monte_carlo(random_study, key=11, n_samples=600, chunk_size=chunk, block_size=64).values
    b = gearte.monte_carlo(random_study, key=11, n_samples=600, chunk_size=640, block_size=64).values
    np.testing.assert_array_equal(a, b)


def test_progress_bar_shows_on_request_and_changes_nothing(random_study, capsys):
    # The progress bar (tqdm, on stderr) is shown when asked for, never when stderr is not a terminal
    # by default, and it changes no value. (Blocks of 64: the program compiled above.)
    kw = dict(key=7, n_samples=300, chunk_size=128, block_size=64)
    quiet = gearte.monte_carlo(random_study, **kw).values
    assert "samples" not in capsys.readouterr().err
    shown = gearte.monte_carlo(random_study, progress=True, desc="planetary study", **kw).values
    err = capsys.readouterr().err
    assert "planetary study" in err and "300" in err and "samples" in err
    np.testing.assert_array_equal(quiet, shown)


def test_prefix_property_and_seeds(random_study):
    a = gearte.monte_carlo(random_study, key=7, n_samples=300).values
    b = gearte.monte_carlo(random_study, key=7, n_samples=1000).values
    np.testing.assert_array_equal(a, b[:300])  # sample i depends on (seed, i) only
    c = gearte.monte_carlo(random_study, key=8, n_samples=300).values
    assert not np.allclose(a, c)
    d = gearte.monte_carlo(random_study, key=jax.random.key(7), n_samples=300).values
    np.testing.assert_array_equal(a, d)


def test_half_tolerances_halve_every_sample():
    # Same seed, same phases, magnitudes halved: the peak TE halves exactly, sample by sample.
    full = load_study("examples/planetary_wang2013_random.toml")
    half = load_study("examples/planetary_wang2013_half.toml")
    a = gearte.monte_carlo(gearte.TEStudy(full.drive, full.errors), key=5, n_samples=2000).values
    b = gearte.monte_carlo(gearte.TEStudy(half.drive, half.errors), key=5, n_samples=2000).values
    np.testing.assert_allclose(b, a / 2, rtol=1e-12)


def test_single_rayleigh_source_gives_a_rayleigh_te():
    # Only the sun eccentricity, Rayleigh magnitude, random phase: peak TE = gain · E exactly,
    # so the whole pipeline (draws → components → exact peak) must give a Rayleigh law.
    d = wang2013.table1_drive()
    zero = gearte.ErrorSource(gearte.Fixed(0.0), gearte.UniformPhase())
    src = {k: zero for k in d.error_sources}
    src["sun_manufacturing"] = gearte.ErrorSource(gearte.Rayleigh(6.5), gearte.UniformPhase())
    study = gearte.TEStudy(d, gearte.ErrorModel(src, d.error_sources))
    v = gearte.monte_carlo(study, key=1, n_samples=20_000).values
    gain = 1 / (48000 * math.cos(math.pi / 9))  # rad/µm, eq. (9)
    assert sps.kstest(v, sps.rayleigh(scale=6.5 * gain).cdf).pvalue > 0.01


def test_allocation_beats_random_assembly():
    alloc = load_study("examples/planetary_wang2013_rayleigh_allocated.toml")
    rand = load_study("examples/planetary_wang2013_rayleigh_random.toml")
    a = gearte.monte_carlo(gearte.TEStudy(alloc.drive, alloc.errors), key=3, n_samples=5000).values * ARCSEC
    r = gearte.monte_carlo(gearte.TEStudy(rand.drive, rand.errors), key=3, n_samples=5000).values * ARCSEC
    assert a.mean() < 0.8 * r.mean()
    assert a.max() < r.max()


def test_statistics_against_numpy():
    x = np.random.default_rng(0).gamma(3.0, 2.0, 1001)
    s = gearte.statistics(x, unit="arcsec")
    assert s.n == 1001 and s.min == x.min() and s.max == x.max()
    np.testing.assert_allclose([s.mean, s.std], [np.mean(x), np.std(x, ddof=1)], rtol=1e-14)
    for p in ("1", "5", "50", "95", "99", "99.73"):
        np.testing.assert_allclose(s.percentiles[p], np.percentile(x, float(p)), rtol=1e-14)
    assert set(s.to_dict()) == {"unit", "n", "min", "max", "mean", "std", "percentiles"}
    with pytest.raises(ValueError, match=r"2 non-finite values \(the first is nan at sample 1\)"):
        gearte.statistics([1.0, float("nan"), 2.0, float("inf")])


def test_statistics_of_values_whose_squares_overflow_stay_finite():
    """A drive outside its model's range can give finite values past 1e154 whose squares overflow: the std is then
    taken on the values scaled by their largest magnitude (the report stays valid JSON, no `Infinity`)."""
    x = np.array([1.0, 2.0, 3.0, 4.0]) * 1e300
    s = gearte.statistics(x)
    assert math.isfinite(s.std)
    assert s.std == pytest.approx(np.std([1.0, 2.0, 3.0, 4.0], ddof=1) * 1e300, rel=1e-15)
    t = gearte.statistics([1e308, 1.5e308])  # their sum overflows too
    assert t.mean == pytest.approx(1.25e308, rel=1e-15) and math.isfinite(t.std)


class _CountingResponse(gearte.TEStudy):
    traces: list = eqx.field(static=True)

    def __init__(self, drive, errors, traces):
        super().__init__(drive, errors)
        self.traces = traces

    def response(self, key):
        self.traces.append(1)  # runs only while tracing
        return super().response(key)


class _CountingCall(_CountingResponse):
    def __call__(self, key):
        return super().__call__(key)


@pytest.mark.parametrize("kind", [_CountingResponse, _CountingCall])
def test_one_compilation_for_repeated_runs(kind):
    # A sinusoidal drive's study runs batch-wise (`TEStudy.batch`); a subclass with its own `__call__`
    # runs under vmap. Either way one compiled block serves every run.
    traces: list = []
    s = load_study("examples/planetary_wang2013_random.toml")
    study = kind(s.drive, s.errors, traces)
    gearte.monte_carlo(study, key=1, n_samples=500, chunk_size=128)
    gearte.monte_carlo(study, key=2, n_samples=1000, chunk_size=128)
    # Other sample counts and chunk sizes (one block, or many blocks between progress updates): still the
    # one compiled block.
    gearte.monte_carlo(study, key=3, n_samples=37, chunk_size=4096)
    gearte.monte_carlo(study, key=4, n_samples=20_000)
    assert len(traces) == 1


def test_batched_and_vmapped_samples_agree(random_study):
    keys = gearte.studies.montecarlo.sample_keys(jax.random.key(5), 0, 256)
    a = np.asarray(jax.jit(lambda k: random_study.batch(k))(keys))
    b = np.asarray(jax.jit(lambda k: jax.vmap(random_study)(k))(keys))
    np.testing.assert_allclose(a, b, rtol=1e-13, atol=0)


def test_bad_arguments(random_study):
    for kw, match in (
        (dict(n_samples=0), "n_samples"),
        (dict(n_samples=2.5), "n_samples"),
        (dict(chunk_size=0), "chunk_size"),
        (dict(key=-1), "seed"),
        (dict(key="x"), "key"),
    ):
        args = dict(key=1, n_samples=10) | kw
        with pytest.raises(ValueError, match=match):
            gearte.monte_carlo(random_study, **args)
    with pytest.raises(ValueError, match="metric"):
        gearte.TEStudy(random_study.drive, random_study.errors, metric="max")
