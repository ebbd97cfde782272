"""Monte Carlo engine: chunked `vmap` over samples, bounded memory, chunk-size independent.

Sample i uses the key ``fold_in(key, i)``: its draws depend only on the study key and
its index, never on the chunk it falls in, the chunk size or the device count.

Bit-for-bit identical results for any chunk size: XLA may round differently in the last
bit for different batch shapes, so samples are always computed in *blocks* of one fixed
shape (set by the study's memory need, not by the chunk size) inside `lax.map`; the
chunk size only says how many blocks one compiled call runs. Memory is bounded by the
block, whatever the number of samples.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray
from tqdm import tqdm

from ..core.metrics import AbstractMetric, check_offered
from ..core.precision import require_x64
from ..core.programs import kept_program
from ..core.schema import MAX_SAMPLES
from ..core.validate import as_key, is_traced
from ..drives.protocol import AbstractDrive, AbstractSinusoidalDrive
from .errors import ErrorModel, check_drive_model

PERCENTILES = (1.0, 5.0, 50.0, 95.0, 99.0, 99.73)
DEFAULT_SAMPLES = 50_000


class TEStudy(eqx.Module):
    """One Monte Carlo sample of any drive: draw errors, take the drive's response, take metrics.

    Callable as ``study(key) -> value``: one metric gives a scalar (rad for angles), a tuple of
    metrics a vector in that order.

    **Arguments:**

    - `drive`: the drive model (any `AbstractDrive`).
    - `errors`: how every error source is drawn (an `ErrorModel` over ``drive.error_sources``).
    - `metric`: a metric object the drive offers (`gearte.Peak()`, `gearte.PeakToPeak()`,
      `gearte.LostMotion()`, …), or a tuple of them. Default: the drive's first metric.
    """

    drive: AbstractDrive
    errors: ErrorModel
    metric: AbstractMetric | tuple[AbstractMetric, ...]

    def __init__(self, drive: AbstractDrive, errors: ErrorModel, *, metric: AbstractMetric | tuple[AbstractMetric, ...] | None = None):
        if not isinstance(drive, AbstractDrive):
            raise ValueError(f"drive: expected a gearte drive, got {type(drive).__name__}")
        check_drive_model(drive, errors, name="errors")
        offered = drive.metrics
        if metric is None:
            metric = next(iter(offered.values()))
        if isinstance(metric, tuple) and not metric:
            raise ValueError(f"metric: give a metric of the drive or a tuple of them, e.g. {next(iter(offered.values()))!r}; got ()")
        for m in metric if isinstance(metric, tuple) else (metric,):
            check_offered(m, drive)
        self.drive, self.errors, self.metric = drive, errors, metric

    def response(self, key: PRNGKeyArray):
        """The drive's response (e.g. the TE signal) of the sample drawn with `key`."""
        return self.drive.response(self.errors.sample(key))

    def signal(self, key: PRNGKeyArray):
        """Alias of `response` for sinusoidal drives: the TE signal of the sample drawn with `key`."""
        return self.response(key)

    def __call__(self, key: PRNGKeyArray) -> Float[Array, ...]:
        r = self.response(key)
        if isinstance(self.metric, tuple):
            return jnp.stack([m(self.drive, r) for m in self.metric])
        return self.metric(self.drive, r)

    def batch(self, keys: PRNGKeyArray) -> Float[Array, ...]:
        """The values of the samples drawn with `keys` (leading axis), equal to ``jax.vmap(self)(keys)``.

        A sinusoidal drive's responses are drawn under `vmap` and its metrics (which take any
        batch shape) run on the whole batch at once: the exact extrema search then works on dense
        arrays rather than through `vmap`'s batching of gathers and loops.
        """
        if not isinstance(self.drive, AbstractSinusoidalDrive):
            return jax.vmap(self)(keys)
        r = jax.vmap(self.response)(keys)
        if isinstance(self.metric, tuple):
            return jnp.stack([m(self.drive, r) for m in self.metric], axis=-1)
        return self.metric(self.drive, r)

    def bytes_per_sample(self) -> int:
        """Rough peak working memory per sample (bytes), to size blocks."""
        return self.drive.bytes_per_sample()


def sample_keys(key: PRNGKeyArray, start, size: int) -> PRNGKeyArray:
    """Keys of samples ``start … start + size − 1``."""
    idx = start + jnp.arange(size, dtype=jnp.uint32)
    return jax.vmap(lambda i: jax.random.fold_in(key, i))(idx)


def _block(fn, key, start, block: int):
    """Samples ``start … start + block − 1``, vectorised: the one program every device runs."""
    keys = sample_keys(key, start, block)
    batch = getattr(fn, "batch", None)
    return batch(keys) if callable(batch) else jax.vmap(fn)(keys)


def sample_mesh() -> jax.sharding.Mesh:
    """A one-axis mesh (``"samples"``) of every device of every process (`jax.devices()`)."""
    return jax.sharding.Mesh(np.asarray(jax.devices()), ("samples",))


def _step(fn_and_key, starts, block: int, mesh: jax.sharding.Mesh):
    """One block per device: device d computes the block starting at ``starts[d]`` with the same program,
    whatever the number of devices (`shard_map`), so results do not depend on the device count."""
    spec = jax.sharding.PartitionSpec("samples")
    # The drive's and the errors' arrays enter the mapped function as its replicated arguments, not closed over: a
    # closed-over array keeps its placement on the whole mesh, and JAX refuses to index it (a gather, as
    # `stage.mass[kind]` in the helical drive) inside the per-device program.
    arrays, static = eqx.partition(fn_and_key, eqx.is_array)

    def per_device(local, start):
        fn, key = eqx.combine(local, static)
        return jax.tree.map(lambda x: x[None], _block(fn, key, start[0], block))

    # check_vma=False: drives loop with carries built from constants (no per-device type annotations needed).
    replicated = jax.sharding.PartitionSpec()
    return jax.shard_map(per_device, mesh=mesh, in_specs=(replicated, spec), out_specs=spec, check_vma=False)(arrays, starts)


_run_step = eqx.filter_jit(_step)


def _on_every_device(tree, mesh: jax.sharding.Mesh):
    """`tree` with its arrays copied once to every device of `mesh` (replicated), as every step takes them:
    passed as they are, each step would copy them anew (a tenth of a 500,000-sample planetary run on two
    devices). Only where this process holds every device of the mesh; the values do not change."""
    if mesh.size == 1 or mesh.is_multi_process:
        return tree
    replicated = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec())
    concrete = lambda x: eqx.is_array(x) and not is_traced(x)
    dynamic, fixed = eqx.partition(tree, concrete)
    return eqx.combine(jax.device_put(dynamic, replicated), fixed)


def _step_program(fn, key, starts, block: int, mesh: jax.sharding.Mesh):
    """The compiled step as a function of the step's starts: from the program store when one is in use
    (`gearte.core.programs`: a repeat run neither traces nor lowers it), else `_run_step`."""
    body = functools.partial(_step, block=block, mesh=mesh)
    fallback = lambda tree, s: _run_step(tree, s, block, mesh)
    tree = _on_every_device((fn, key), mesh)  # one tree for every step: the kept program takes its arrays once
    kept = kept_program("monte_carlo_step", body, tree, starts, static=(block, mesh), fallback=fallback)
    return lambda s: kept(tree, s)


def default_block_size(bytes_per_sample: int, *, budget_bytes: int = 128 * 2**20) -> int:
    """Largest power of two ≤ 4096 whose block of samples fits in `budget_bytes` (larger blocks spread the
    per-call cost of a compiled program over more samples)."""
    c = max(1, min(4096, budget_bytes // max(1, bytes_per_sample)))
    return 1 << int(math.floor(math.log2(c)))


class MonteCarloResult(eqx.Module):
    """Per-sample values (rad for angles) of a Monte Carlo study, with how they were drawn.

    `values` is None when the run was asked not to keep them (``keep=False``: the values went to
    `on_chunk` only). `devices` is the number of devices (of every process) that computed them.
    """

    values: Any
    n_samples: int = eqx.field(static=True)
    chunk_size: int = eqx.field(static=True)
    block_size: int = eqx.field(static=True)
    seconds: float = eqx.field(static=True)
    devices: int = eqx.field(static=True, default=1)


def _to_host(out) -> Any:
    """A step's result (leading axes: device, sample) as NumPy arrays on every process, samples in order."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        out = multihost_utils.process_allgather(out, tiled=True)
    return jax.tree.map(lambda x: np.asarray(x).reshape((-1,) + np.shape(x)[2:]), out)


def monte_carlo(
    fn: Callable[[PRNGKeyArray], Any],
    *,
    key: int | PRNGKeyArray,
    n_samples: int = DEFAULT_SAMPLES,
    chunk_size: int | None = None,
    block_size: int | None = None,
    progress: bool | None = None,
    desc: str = "Monte Carlo",
    keep: bool = True,
    on_chunk: Callable[[int, Any], None] | None = None,
    mesh: jax.sharding.Mesh | None = None,
) -> MonteCarloResult:
    """Run ``fn(key_i)`` for ``n_samples`` samples, sharded over every device.

    **Arguments:**

    - `fn`: one sample, ``key → value`` (an `eqx.Module` such as `TEStudy`, so repeated
      runs reuse the compiled code).
    - `key`: integer seed or `jax.random` key; sample i uses ``fold_in(key, i)``.
    - `n_samples`: number of samples (default 50,000).
    - `chunk_size`: samples between progress-bar updates and `on_chunk` calls (rounded up to
      whole steps of one block per device; default 16 blocks). Never changes the results,
      nor what is compiled.
    - `block_size`: samples computed together in one vectorised block, the one compiled
      program of the study (compiled once, whatever `n_samples`); bounds memory.
      Default: from ``fn.bytes_per_sample()`` (128 MiB per block), else 256. Results are
      bit-identical for any chunk size, any number of devices or processes and any number
      of samples at a given block size (the first n samples of a longer run are those of an
      n-sample run); another block size may change them in the last bit.
    - `progress`: show a progress bar on stderr (default: when stderr is a terminal).
    - `keep`: hold every value and return them (default). With ``keep=False`` only
      `on_chunk` sees them, a chunk at a time: memory stays bounded whatever `n_samples`.
    - `on_chunk`: called as ``on_chunk(start, values)`` with the values of samples
      ``start, start + 1, …`` (NumPy; a pytree when `fn` returns one), chunk after chunk in
      sample order, on every process.
    - `mesh`: the devices to shard samples over (a one-axis `jax.sharding.Mesh`); default
      every device of every process (`sample_mesh`). Device d of a step computes block
      ``step · devices + d`` with the program a single device would run.

    **Returns:** a `MonteCarloResult` with the values as a NumPy array (a pytree of them when `fn`
    returns a pytree), or None with ``keep=False``.
    """
    require_x64()
    if not callable(fn):
        raise ValueError(f"fn: one sample as a function of its key, such as gearte.TEStudy(drive, errors); got {type(fn).__name__}")
    if on_chunk is not None and not callable(on_chunk):
        raise ValueError(f"on_chunk: a function on_chunk(start, values), got {on_chunk!r}")
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 1:
        raise ValueError(f"n_samples: must be a whole number ≥ 1, got {n_samples!r}")
    if n_samples > MAX_SAMPLES:
        raise ValueError(f"n_samples: at most 2³² − 1 samples per key, got {n_samples}")
    key = as_key(key)
    for name, v in (("chunk_size", chunk_size), ("block_size", block_size)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1):
            raise ValueError(f"{name}: must be a whole number ≥ 1, got {v!r}")
    if not keep and on_chunk is None:
        raise ValueError("keep=False: give on_chunk, or the values would be lost")
    if block_size is None:
        sizer = getattr(fn, "bytes_per_sample", None)
        per = int(sizer()) if callable(sizer) else 0  # pyright: ignore[reportArgumentType]
        block_size = default_block_size(per) if per else 256
    block = int(block_size)
    if block > MAX_SAMPLES:
        raise ValueError(f"block_size: at most 2³² − 1 samples, got {block}")
    mesh = sample_mesh() if mesh is None else mesh
    if mesh.axis_names != ("samples",):
        raise ValueError(f"mesh: expected one axis named 'samples', got {mesh.axis_names}")
    n_dev = mesh.size
    sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("samples"))
    # Every block is the same compiled program (one compilation per study, block size and mesh,
    # whatever the number of samples or the chunk size); a step runs one block on each device, and
    # the chunk only sets how often progress is shown and values are handed on.
    n_blocks = -(-n_samples // block)
    n_steps = -(-n_blocks // n_dev)
    steps_per_chunk = max(1, -(-int(chunk_size) // (block * n_dev))) if chunk_size is not None else max(1, 16 // n_dev)
    steps_per_chunk = min(steps_per_chunk, n_steps)
    chunk = steps_per_chunk * block * n_dev
    if progress is None:
        progress = n_steps > steps_per_chunk and sys.stderr.isatty()
    t0 = time.perf_counter()
    parts: list = []
    pending: list = []  # dispatched steps not yet handed on: (first sample, device result)

    def starts_of(step: int):
        starts = (np.arange(n_dev, dtype=np.uint32) + np.uint32(step * n_dev)) * np.uint32(block)
        return jax.make_array_from_callback((n_dev,), sharding, lambda idx: starts[idx])

    run_step = _step_program(fn, key, starts_of(0), block, mesh)

    def launch(step: int):
        return run_step(starts_of(step))

    def hand_on(first: int, out) -> int:
        vals = _to_host(out)
        n = min(n_samples - first, block * n_dev)  # samples past n_samples in the last step are dropped
        vals = jax.tree.map(lambda x: x[:n], vals)
        if keep:
            parts.append(vals)
        if on_chunk is not None:
            on_chunk(first, vals)
        return first + n

    done = 0
    with tqdm(total=n_samples, desc=desc, unit="samples", disable=not progress, leave=False) as bar:
        for step in range(n_steps):
            pending.append((step * block * n_dev, launch(step)))
            # Hand results on a chunk at a time, one step behind the dispatch so the devices keep busy;
            # without `on_chunk`, results stay on the devices until the end (as few host copies as possible).
            if (step + 1) % steps_per_chunk == 0 or step + 1 == n_steps:
                flush = pending if step + 1 == n_steps or on_chunk is None else pending[:-1]
                if on_chunk is not None or progress:
                    for first, out in flush:
                        done = hand_on(first, out)
                    pending = pending[len(flush) :]
                if progress:
                    bar.update(done - bar.n)
        for first, out in pending:
            done = hand_on(first, out)
        bar.update(done - bar.n)
    values = None
    if keep:
        # One array, or a pytree of them when `fn` returns several outputs per sample.
        values = jax.tree.map(lambda *xs: np.concatenate(xs), *parts) if len(parts) > 1 else parts[0]
    return MonteCarloResult(
        values=values, n_samples=int(n_samples), chunk_size=chunk, block_size=block, seconds=time.perf_counter() - t0, devices=n_dev
    )


class Statistics(eqx.Module):
    """Summary statistics of a sample (in the unit named by `unit`)."""

    n: int
    min: float
    max: float
    mean: float
    std: float
    percentiles: dict[str, float]
    unit: str

    def to_dict(self) -> dict:
        return {
            "unit": self.unit,
            "n": self.n,
            "min": self.min,
            "max": self.max,
            "mean": self.mean,
            "std": self.std,
            "percentiles": dict(self.percentiles),
        }


def _pct_key(p: float) -> str:
    return f"{p:g}"


def statistics(values, *, unit: str = "rad") -> Statistics:
    """n, min, max, mean, std (sample, ddof = 1) and percentiles 1/5/50/95/99/99.73 (linear interpolation)."""
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0:
        raise ValueError("statistics: no values")
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise ValueError(
            f"statistics: {bad.size} non-finite values (the first is {v[bad[0]]} at sample {int(bad[0])}); a sample whose "
            "metric cannot be computed cannot be summarised"
        )
    pct = np.percentile(v, PERCENTILES)
    with np.errstate(over="ignore", invalid="ignore"):
        std = float(v.std(ddof=1)) if v.size > 1 else 0.0
    with np.errstate(over="ignore"):
        mean = float(v.mean())
    if not (math.isfinite(std) and math.isfinite(mean)):  # sums beyond the float range: the same figures, scaled
        scale = float(np.max(np.abs(v)))
        mean = scale * float((v / scale).mean())
        std = scale * float((v / scale).std(ddof=1)) if v.size > 1 else 0.0
    return Statistics(
        n=int(v.size),
        min=float(v.min()),
        max=float(v.max()),
        mean=mean,
        std=std,
        percentiles={_pct_key(p): float(x) for p, x in zip(PERCENTILES, pct)},
        unit=unit,
    )
