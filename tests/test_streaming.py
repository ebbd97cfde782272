"""Streaming statistics against the exact ones on samples that fit in memory."""

import hypothesis.strategies as st
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

from gearte.studies import montecarlo
from gearte.studies.streaming import PERCENTILES, StreamingStatistics

RNG = np.random.default_rng(20240611)
# Skewed, with a negative tail and values spanning several octaves (and zero crossings): a TE peak's
# Rayleigh-like shape plus noise.
VALUES = RNG.rayleigh(40.0, size=(20_011, 2)) + RNG.normal(0.0, 3.0, size=(20_011, 2)) - 5.0


def feed(values, cuts, **kw) -> StreamingStatistics:
    """An accumulator fed `values` cut at the positions `cuts`."""
    acc = StreamingStatistics(None if values.ndim == 1 else values.shape[1], **kw)
    edges = [0, *sorted(cuts), len(values)]
    for a, b in zip(edges[:-1], edges[1:]):
        acc.update(values[a:b])
    return acc


def test_percentiles_are_the_reported_ones():
    assert PERCENTILES == montecarlo.PERCENTILES


@pytest.mark.parametrize("block", [2, 7, 1000, 2**16])
def test_exact_moments_and_extremes_match_numpy(block):
    acc = feed(VALUES, [3, 5000, 5001, 17_000], block=block)
    for j in range(2):
        x = VALUES[:, j]
        n, mean, std = acc.moments(j)
        assert n == len(x)
        assert mean == pytest.approx(np.mean(x), rel=1e-13)
        assert std == pytest.approx(np.std(x, ddof=1), rel=1e-12)
        s = acc.statistics(j, unit="arcsec")
        assert (s.n, s.min, s.max, s.unit) == (len(x), x.min(), x.max(), "arcsec")


def test_moments_of_a_shifted_sample_keep_their_digits():
    # A large offset: the naive sum of squares would lose the variance entirely; Chan's update does not.
    x = 1e9 + RNG.normal(0.0, 1e-3, 30_000)
    acc = feed(x, [12_345], block=4096)
    _, mean, std = acc.moments()
    assert mean == pytest.approx(np.mean(x), rel=1e-15)
    assert std == pytest.approx(np.std(x, ddof=1), rel=1e-6)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cuts=st.lists(st.integers(0, 4000), max_size=12), block=st.sampled_from([5, 64, 1000, 4096]))
def test_results_are_bit_identical_for_any_chunking(cuts, block):
    x = VALUES[:4000]
    one = feed(x, [], block=block, bits=10)
    many = feed(x, cuts, block=block, bits=10)
    for j in range(2):
        assert many.moments(j) == one.moments(j)
        assert many.statistics(j) == one.statistics(j)
        assert all(np.array_equal(a, b) for a, b in zip(many.histogram(40, j), one.histogram(40, j)))


@settings(max_examples=25, deadline=None)
@given(parts=st.lists(st.integers(0, 6), min_size=1, max_size=5), tail=st.integers(0, 99), cuts=st.lists(st.integers(0, 10**6), max_size=4))
def test_block_aligned_parts_merged_in_order_give_the_one_stream_result(parts, tail, cuts):
    block = 100
    sizes = [k * block for k in parts] + [tail]
    x = VALUES[: sum(sizes), 0]
    accs, start = [], 0
    for size in sizes:
        part = x[start : start + size]
        accs.append(feed(part, [c % (size + 1) for c in cuts], block=block))
        start += size
    if len(x) == 0:
        return
    left = accs[0]
    for a in accs[1:]:
        left = left.merge(a)
    one = feed(x, [], block=block)
    assert left.n == one.n == len(x)
    assert left.moments() == one.moments()
    assert left.statistics() == one.statistics()
    # Associativity in the canonical order: (a·b)·c = a·(b·c).
    if len(accs) >= 3 and sum(sizes[:3]):
        right = accs[0].merge(accs[1].merge(accs[2]))
        assert right.moments() == accs[0].merge(accs[1]).merge(accs[2]).moments()


def test_merging_after_a_partial_block_is_refused():
    a, b = feed(VALUES[:150, 0], [], block=100), feed(VALUES[150:300, 0], [], block=100)
    with pytest.raises(ValueError, match="not a multiple of block = 100"):
        a.merge(b)


@pytest.mark.parametrize("bits", [6, 10, 14])
def test_percentiles_within_their_stated_bound(bits):
    acc = feed(VALUES, [777, 9000], bits=bits)
    for j in range(2):
        x = VALUES[:, j]
        exact = np.percentile(x, PERCENTILES)
        est, bound = acc.quantiles(PERCENTILES, j)
        assert np.all(np.abs(est - exact) <= bound), (est - exact, bound)
        # The bound itself: half a bin, at most 2^-(bits+1) of the largest magnitude involved (plus rounding).
        assert np.all(bound <= 2.0 ** -(bits + 1) * np.maximum(np.abs(exact), np.abs(est)) * (1 + 2.0**-bits) + 1e-12)
        assert acc.quantile_errors(j) == {f"{p:g}": float(b) for p, b in zip(PERCENTILES, bound)}
    # Percentiles of every kind (ends, ties) on a small sample with repeated values.
    small = np.repeat(np.array([-3.0, 0.0, 0.5, 2.0, 1e-300, 7.25]), [3, 1, 5, 2, 1, 4])
    acc = feed(small, [4, 9], bits=bits)
    p = np.linspace(0, 100, 41)
    est, bound = acc.quantiles(p)
    assert np.all(np.abs(est - np.percentile(small, p)) <= bound)
    assert est[0] == small.min() and est[-1] == small.max()


def test_histogram_matches_numpy_up_to_the_fine_bins():
    acc = feed(VALUES, [5000], bits=14)
    edges, counts = acc.histogram(50, 0)
    x = VALUES[:, 0]
    assert edges[0] == x.min() and edges[-1] == x.max() and counts.sum() == len(x)
    exact, _ = np.histogram(x, bins=edges)
    # Only samples within a fine bin (relative width 2^-14) of an inner edge can move across it.
    near = sum(np.count_nonzero(np.abs(x - e) <= 2.0**-14 * abs(e)) for e in edges[1:-1])
    assert np.abs(counts - exact).sum() <= 2 * near
    const = feed(np.full(10, 2.5), [])
    assert const.histogram(4)[1].tolist() == np.histogram(np.full(10, 2.5), bins=4)[0].tolist()


def test_statistics_of_one_sample_and_of_a_unit_scale():
    acc = feed(np.array([4.0]), [])
    s = acc.statistics()
    assert (s.n, s.min, s.max, s.mean, s.std, s.percentiles["50"]) == (1, 4.0, 4.0, 4.0, 0.0, 4.0)
    acc = feed(VALUES[:, 0], [])
    ref = montecarlo.statistics(VALUES[:, 0] * 2.0, unit="arcsec")
    got = acc.statistics(unit="arcsec", unit_scale=2.0)
    assert got.mean == pytest.approx(ref.mean, rel=1e-13) and got.std == pytest.approx(ref.std, rel=1e-12)
    errors = acc.quantile_errors(unit_scale=2.0)
    assert all(abs(got.percentiles[k] - ref.percentiles[k]) <= errors[k] for k in ref.percentiles)


def test_bad_input_is_refused_with_a_clear_message():
    acc = StreamingStatistics(2)
    bad = VALUES[:10].copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match=r"1 non-finite values \(the first is nan at sample 7, metric 1\)"):
        acc.update(bad)
    assert acc.n == 0  # nothing of the refused chunk was taken
    with pytest.raises(ValueError, match=r"expected shape \(n, 2\)"):
        acc.update(VALUES[:10, 0])
    with pytest.raises(ValueError, match="no values"):
        acc.statistics(0)
    with pytest.raises(ValueError, match="metric: expected an index in"):
        feed(VALUES, []).moments(2)
    with pytest.raises(ValueError, match="block"):
        StreamingStatistics(block=0)
    with pytest.raises(ValueError, match="bits"):
        StreamingStatistics(bits=60)
    one = StreamingStatistics()
    with pytest.raises(ValueError, match=r"non-finite values \(the first is inf at sample 1\)"):
        one.update([1.0, np.inf])


def test_sample_near_is_the_first_sample_of_the_nearest_occupied_bin():
    """`bits = 0`: a bin is a sign and a binade, [2^e, 2^(e+1)) (or its negative), so every answer is read off by
    hand. Two metrics whose binades hold other samples, fed in two chunks so that the first index of some bins
    comes from the second chunk (stream order, not chunk order)."""
    #                  index:  0      1    2    3    4      5    6
    m0 = np.array([5.0, 1.5, 3.0, 6.0, 100.0, 2.5, -3.0])  # binades 2, 0, 1, 2, 6, 1, −(1)
    m1 = np.array([100.0, 3.0, 1.5, 2.5, 6.0, 5.0, -3.0])  # binades 6, 1, 0, 1, 2, 2, −(1)
    acc = feed(np.stack([m0, m1], axis=1), [3], bits=0)
    expected = {
        # value: (metric 0, metric 1)
        7.0: (0, 4),  # binade 2 holds 0 and 3 (6.0 is nearer 7 in value; the first in the bin is the answer)
        2.1: (2, 1),  # binade 1: 2 then 5 for metric 0; 1 then 3 for metric 1
        1.2: (1, 2),  # binade 0
        40.0: (4, 0),  # binade 5 is empty: binade 6 (one away) is nearer than binade 2 (three away)
        12.0: (0, 4),  # binade 3 is empty: binade 2 (one away) is nearer than binade 6 (three away)
        0.3: (1, 2),  # below every positive sample: the lowest positive binade, 0
        1e9: (4, 0),  # above every sample: the highest binade, 6
        -2.5: (6, 6),  # the negative binade of −3.0
        -1000.0: (6, 6),  # the only negative bin is nearer than any positive one
    }
    for value, (i0, i1) in expected.items():
        assert acc.sample_near(value, 0) == i0, (value, 0)
        assert acc.sample_near(value, metric=1) == i1, (value, 1)
    # Equidistant bins (binade 4: binades 2 and 6 both two away): the lower one, as `min` over (distance, bin) picks.
    assert acc.sample_near(24.0, 0) == 0
    # One metric per sample: `metric` None or 0 reads the only column; another index is refused, as it is past the
    # columns of a two-metric accumulator.
    one = feed(m1, [3], bits=0)
    assert [one.sample_near(v) for v in (7.0, 2.1, 40.0)] == [4, 1, 0] == [one.sample_near(v, 0) for v in (7.0, 2.1, 40.0)]
    with pytest.raises(ValueError, match="one value per sample"):
        one.sample_near(7.0, 1)
    with pytest.raises(ValueError, match=r"metric: expected an index in \[0, 2\)"):
        acc.sample_near(7.0, 2)
    with pytest.raises(ValueError, match="no values"):
        StreamingStatistics().sample_near(1.0)
