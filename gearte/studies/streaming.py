"""Streaming statistics: the summary of a study too large to hold, fed chunk by chunk, in bounded memory.

`StreamingStatistics` takes per-sample values (one or several metrics per sample) in chunks of any
size, in sample order, and gives the same `Statistics` as `gearte.studies.montecarlo.statistics`
would on all the values at once:

- **n, min, max** exactly.
- **mean, std** (sample, ddof = 1) from the count, mean and sum of squared deviations (M2) of
  fixed blocks of `block` consecutive samples (the 1st to the `block`-th sample, and so on; each block
  summed by NumPy, M2 in two passes about the block's mean), merged by Chan, Golub and LeVeque's
  (1979) update ``M2 = M2_a + M2_b + δ² n_a n_b / n`` in a fixed pairwise tree over the blocks. The
  blocks and the tree depend only on the sample sequence, so the result is bit for bit the same
  for any chunking of the input, and for any split of the study into consecutive parts on block
  boundaries merged in order (`merge`). The block summaries are kept (five numbers per block and
  metric: 2.4 MiB for 10⁹ samples of one metric in blocks of 2¹⁶), plus at most one partial block.
- **percentiles** from a histogram on the values' floating-point representation: a value's bin is
  its sign, exponent and the top `bits` bits of its mantissa, so every bin spans at most a relative
  width of 2^-bits, whatever the range of the values (no range to choose beforehand), and
  histograms merge by adding counts. The rank of each order statistic gives its bin exactly; the
  percentile (linear interpolation between order statistics, as `numpy.percentile`) is taken at
  the centre of the interval the bins allow, and its error bound is half that interval: at most
  2^-(bits+1) of the largest magnitude in the bins involved (about 3·10⁻⁵ relative for the default
  14 bits). `quantile_errors` gives each percentile's bound.
- **a histogram for plotting** (`histogram`) from the same bins, rebinned on uniform edges.

Non-finite values are refused (a failed sample must not be summarised away). Everything is NumPy
float64 on the CPU; the accumulator changes no global state.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .montecarlo import Statistics

#: Percentiles reported (the same as `gearte.studies.montecarlo.PERCENTILES`; a test keeps them equal).
PERCENTILES = (1.0, 5.0, 50.0, 95.0, 99.0, 99.73)
DEFAULT_BLOCK = 2**16
DEFAULT_BITS = 14

_SIGN = np.uint64(1 << 63)


def _ordered(x: np.ndarray) -> np.ndarray:
    """float64 → uint64 with the same order (negative values below positive ones, -0 just below +0)."""
    u = np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)
    return np.where(u & _SIGN, ~u, u | _SIGN)


def _unordered(o: np.ndarray) -> np.ndarray:
    """The inverse of `_ordered`."""
    o = np.asarray(o, dtype=np.uint64)
    return np.where(o & _SIGN, o & ~_SIGN, ~o).view(np.float64)


@dataclasses.dataclass(frozen=True)
class _Blocks:
    """Summaries of consecutive blocks, one row per block, one column per metric."""

    count: np.ndarray  # (k,) int64
    mean: np.ndarray  # (k, m)
    m2: np.ndarray  # (k, m)


def _bin_chunk(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The distinct bins of a chunk (sorted), the count and the first index of each: by counting over the
    chunk's key range when it is narrow (a few binades: linear time), else by sorting (`np.unique`)."""
    lo, hi = int(keys.min()), int(keys.max())
    span = hi - lo + 1
    if span > 4 * len(keys) + 65_536:
        u, first, counts = np.unique(keys, return_index=True, return_counts=True)
        return u, counts, first
    rel = (keys - np.uint64(lo)).astype(np.int64)
    counts = np.bincount(rel, minlength=span)
    first = np.full(span, np.iinfo(np.int64).max)
    np.minimum.at(first, rel, np.arange(len(rel)))
    hit = np.nonzero(counts)[0]
    return hit.astype(np.uint64) + np.uint64(lo), counts[hit], first[hit]


def _summarise(block: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and M2 of each column of one block (n, m), each from its own contiguous copy, so that a
    block's summary depends only on its values."""
    mean = np.empty(block.shape[1])
    m2 = np.empty(block.shape[1])
    for j in range(block.shape[1]):
        v = np.array(block[:, j], dtype=np.float64, order="C")
        mean[j] = np.sum(v) / v.size
        d = v - mean[j]
        m2[j] = np.sum(d * d)
    return mean, m2


def _chan(na, ma, sa, nb, mb, sb):
    """Merge (count, mean, M2) of two consecutive parts (Chan, Golub & LeVeque 1979)."""
    n = na + nb
    d = mb - ma
    return n, ma + d * (nb / n), sa + sb + d * d * (na * nb / n)


def _tree(count: np.ndarray, mean: np.ndarray, m2: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """Merge block summaries in a fixed pairwise tree: (0,1), (2,3), … then the pairs, and so on (an odd
    last one is carried up unchanged)."""
    c = count.astype(np.float64)[:, None]
    while len(c) > 1:
        k = len(c) // 2 * 2
        nc, nm, ns = _chan(c[0:k:2], mean[0:k:2], m2[0:k:2], c[1:k:2], mean[1:k:2], m2[1:k:2])
        c, mean, m2 = (np.concatenate([a, b[k:]]) for a, b in ((nc, c), (nm, mean), (ns, m2)))
    return int(round(c[0, 0])), mean[0], m2[0]


class StreamingStatistics:
    """Statistics of per-sample values fed in chunks, in bounded memory.

    **Arguments:**

    - `metrics`: None for one value per sample (chunks of shape (n,)), or the number m of values per
      sample (chunks of shape (n, m); each column is summarised on its own).
    - `block`: samples per block of the exact moments (results are bit-identical for any chunking;
      two accumulators merge exactly when the first ends on a block boundary).
    - `bits`: mantissa bits of the histogram's bins (relative bin width 2^-bits).
    """

    def __init__(self, metrics: int | None = None, *, block: int = DEFAULT_BLOCK, bits: int = DEFAULT_BITS):
        if metrics is not None and (isinstance(metrics, bool) or not isinstance(metrics, int) or metrics < 1):
            raise ValueError(f"metrics: expected None (one value per sample) or a whole number ≥ 1, got {metrics!r}")
        if isinstance(block, bool) or not isinstance(block, int) or block < 1:
            raise ValueError(f"block: expected a whole number of samples ≥ 1, got {block!r}")
        if isinstance(bits, bool) or not isinstance(bits, int) or not 0 <= bits <= 52:
            raise ValueError(f"bits: expected a whole number of mantissa bits in [0, 52], got {bits!r}")
        self.metrics, self.block, self.bits = metrics, block, bits
        m = 1 if metrics is None else metrics
        self._m = m
        self._shift = np.uint64(52 - bits)
        self._n = 0
        self._count: list[int] = []
        self._mean: list[np.ndarray] = []
        self._m2: list[np.ndarray] = []
        self._partial = np.empty((0, m))
        self._min = np.full(m, np.inf)
        self._max = np.full(m, -np.inf)
        self._keys = [np.empty(0, np.uint64) for _ in range(m)]
        self._counts = [np.empty(0, np.int64) for _ in range(m)]
        self._first = [np.empty(0, np.int64) for _ in range(m)]  # first sample index in each bin

    # ------------------------------------------------------------------ feeding

    @property
    def n(self) -> int:
        """Samples seen so far."""
        return self._n

    def _as_2d(self, values) -> np.ndarray:
        v = np.asarray(values, dtype=np.float64)
        if self.metrics is None:
            if v.ndim != 1:
                raise ValueError(f"values: expected one value per sample, shape (n,), got shape {v.shape}")
            v = v[:, None]
        elif v.ndim != 2 or v.shape[1] != self.metrics:
            raise ValueError(f"values: expected shape (n, {self.metrics}) ({self.metrics} metrics per sample), got shape {v.shape}")
        bad = ~np.isfinite(v)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise ValueError(
                f"values: {int(bad.sum())} non-finite values (the first is {v[i, j]} at sample {self.n + int(i)}"
                + (f", metric {int(j)}" if self.metrics is not None else "")
                + "); a sample whose metric cannot be computed cannot be summarised"
            )
        return v

    def update(self, values) -> None:
        """Add the next chunk of samples, in sample order: shape (n,) or (n, metrics)."""
        v = self._as_2d(values)
        if len(v) == 0:
            return
        np.minimum(self._min, v.min(axis=0), out=self._min)
        np.maximum(self._max, v.max(axis=0), out=self._max)
        for j in range(self._m):
            self._add_bins(j, *_bin_chunk(_ordered(v[:, j]) >> self._shift), offset=self._n)
        data = np.concatenate([self._partial, v]) if len(self._partial) else v
        full = len(data) // self.block * self.block
        for s in range(0, full, self.block):
            mean, m2 = _summarise(data[s : s + self.block])
            self._count.append(self.block)
            self._mean.append(mean)
            self._m2.append(m2)
        self._partial = np.array(data[full:])
        self._n += len(v)

    def _add_bins(self, j: int, keys: np.ndarray, counts: np.ndarray, first: np.ndarray, *, offset: int = 0) -> None:
        first = first + offset
        allk = np.concatenate([self._keys[j], keys])
        uk, inv = np.unique(allk, return_inverse=True)
        self._keys[j] = uk
        self._counts[j] = np.bincount(inv, weights=np.concatenate([self._counts[j], counts]), minlength=len(uk)).astype(np.int64)
        lowest = np.full(len(uk), np.iinfo(np.int64).max)
        np.minimum.at(lowest, inv, np.concatenate([self._first[j], first]))
        self._first[j] = lowest

    def bin_keys(self, values) -> np.ndarray:
        """The histogram bin of each value (sign, exponent and top `bits` mantissa bits, as an ordered integer)."""
        return _ordered(np.asarray(values, dtype=np.float64)) >> self._shift

    def sample_near(self, value: float, metric: int | None = None) -> int:
        """The index (in stream order) of the first sample in the bin of `value`, or of the nearest bin holding
        samples: a sample within one bin width (2^-bits relative) of `value` when its bin is not empty."""
        j = self._column(metric)
        self._require()
        key = self.bin_keys(np.asarray([value]))[0]
        keys = self._keys[j]
        i = int(np.searchsorted(keys, key))
        near = [c for c in (i - 1, i) if 0 <= c < len(keys)]
        best = min(near, key=lambda c: (abs(int(keys[c]) - int(key)), c))
        return int(self._first[j][best])

    def merge(self, other: StreamingStatistics) -> StreamingStatistics:
        """The accumulator of this one's samples followed by `other`'s (a new object; both unchanged).

        Bit-identical to one accumulator fed both streams in order when this one ends on a block
        boundary (its `n` a multiple of `block`), which is what an engine splitting a study into block-
        aligned parts gives; otherwise refused, since the blocks would no longer be the canonical ones.
        """
        if not isinstance(other, StreamingStatistics):
            raise ValueError(f"merge: expected a StreamingStatistics, got {type(other).__name__}")
        if (other.metrics, other.block, other.bits) != (self.metrics, self.block, self.bits):
            raise ValueError(
                f"merge: accumulators differ (metrics, block, bits) = {(self.metrics, self.block, self.bits)} and "
                f"{(other.metrics, other.block, other.bits)}"
            )
        if len(self._partial) and other.n:
            raise ValueError(
                f"merge: the first accumulator holds {self.n} samples, not a multiple of block = {self.block}; split a "
                "study on block boundaries so that the merged statistics are those of one stream"
            )
        out = StreamingStatistics(self.metrics, block=self.block, bits=self.bits)
        out._n = self._n + other._n
        out._count = self._count + other._count
        out._mean = self._mean + other._mean
        out._m2 = self._m2 + other._m2
        out._partial = np.array(other._partial if other.n else self._partial)
        out._min = np.minimum(self._min, other._min)
        out._max = np.maximum(self._max, other._max)
        for j in range(self._m):
            out._keys[j], out._counts[j], out._first[j] = self._keys[j], self._counts[j], self._first[j]
            out._add_bins(j, other._keys[j], other._counts[j], other._first[j], offset=self._n)
        return out

    # ------------------------------------------------------------------ results

    def _column(self, metric: int | None) -> int:
        if self.metrics is None:
            if metric not in (None, 0):
                raise ValueError(f"metric: this accumulator has one value per sample, got metric = {metric!r}")
            return 0
        if metric is None or isinstance(metric, bool) or not isinstance(metric, int) or not 0 <= metric < self.metrics:
            raise ValueError(f"metric: expected an index in [0, {self.metrics}), got {metric!r}")
        return metric

    def _require(self) -> None:
        if self.n == 0:
            raise ValueError("statistics: no values")

    def moments(self, metric: int | None = None) -> tuple[int, float, float]:
        """(n, mean, std with ddof = 1) of one metric (std 0 for one sample)."""
        j = self._column(metric)
        self._require()
        count, mean, m2 = list(self._count), [x[j : j + 1] for x in self._mean], [x[j : j + 1] for x in self._m2]
        if len(self._partial):
            pm, ps = _summarise(self._partial[:, j : j + 1])
            count.append(len(self._partial))
            mean.append(pm)
            m2.append(ps)
        n, mu, s = _tree(np.asarray(count, np.int64), np.stack(mean), np.stack(m2))
        std = math.sqrt(float(s[0]) / (n - 1)) if n > 1 else 0.0
        return n, float(mu[0]), std

    def _bin_ends(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Lowest and highest float of each occupied bin (clamped to the exact min and max), and the
        cumulative counts."""
        k = self._keys[j]
        lo = _unordered(k << self._shift)
        hi = _unordered(((k + np.uint64(1)) << self._shift) - np.uint64(1))
        lo = np.clip(lo, self._min[j], self._max[j])
        hi = np.clip(hi, self._min[j], self._max[j])
        return lo, hi, np.cumsum(self._counts[j])

    def quantiles(self, percentiles: Sequence[float] = PERCENTILES, metric: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Percentiles (linear interpolation between order statistics, as `numpy.percentile`) and, for
        each, a bound on its error: |estimate − exact| ≤ bound."""
        j = self._column(metric)
        self._require()
        p = np.asarray(percentiles, dtype=np.float64)
        if p.ndim != 1 or not np.all((p >= 0) & (p <= 100)):
            raise ValueError(f"percentiles: expected values in [0, 100], got {percentiles!r}")
        lo, hi, cum = self._bin_ends(j)
        n = int(cum[-1])
        h = (n - 1) * p / 100.0
        r = np.floor(h).astype(np.int64)
        f = h - r
        r2 = np.minimum(r + 1, n - 1)
        b1, b2 = np.searchsorted(cum, r, side="right"), np.searchsorted(cum, r2, side="right")
        low = (1 - f) * lo[b1] + f * lo[b2]
        high = (1 - f) * hi[b1] + f * hi[b2]
        est = 0.5 * (low + high)
        # Half the interval, and a few units in the last place for the rounding of this and of numpy's interpolation.
        bound = 0.5 * (high - low) + 4 * np.spacing(np.maximum(np.abs(low), np.abs(high)))
        return est, bound

    def quantile_errors(self, metric: int | None = None, *, unit_scale: float = 1.0) -> dict[str, float]:
        """The error bound of each reported percentile, keyed like `Statistics.percentiles`."""
        _, bound = self.quantiles(PERCENTILES, metric)
        return {f"{p:g}": float(b) * unit_scale for p, b in zip(PERCENTILES, bound)}

    def statistics(self, metric: int | None = None, *, unit: str = "rad", unit_scale: float = 1.0) -> Statistics:
        """The `Statistics` of one metric (values multiplied by `unit_scale`, labelled `unit`);
        `quantile_errors` gives the bounds of its percentiles."""
        from .montecarlo import Statistics

        n, mean, std = self.moments(metric)
        est, _ = self.quantiles(PERCENTILES, metric)
        j = self._column(metric)
        s = unit_scale
        return Statistics(
            n=n,
            min=float(self._min[j]) * s,
            max=float(self._max[j]) * s,
            mean=mean * s,
            std=std * abs(s),
            percentiles={f"{p:g}": float(x) * s for p, x in zip(PERCENTILES, est)},
            unit=unit,
        )

    def histogram(self, bins: int = 80, metric: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(edges, counts) on `bins` uniform bins over [min, max], for a histogram plot without the samples
        (``ax.stairs(counts, edges)``). Each fine bin is counted where its centre falls, so a count can be
        off by the samples of the fine bins straddling an edge (each at most 2^-bits relative wide)."""
        j = self._column(metric)
        self._require()
        if isinstance(bins, bool) or not isinstance(bins, int) or bins < 1:
            raise ValueError(f"bins: expected a whole number ≥ 1, got {bins!r}")
        lo, hi, _ = self._bin_ends(j)
        a, b = float(self._min[j]), float(self._max[j])
        if a == b:
            a, b = a - 0.5, b + 0.5  # as numpy.histogram does for a constant sample
        edges = np.linspace(a, b, bins + 1)
        counts, _ = np.histogram(0.5 * (lo + hi), bins=edges, weights=self._counts[j])
        return edges, counts.astype(np.int64)


__all__ = ["DEFAULT_BITS", "DEFAULT_BLOCK", "PERCENTILES", "StreamingStatistics"]
