"""gearte.core.linalg: small SPD solves without LAPACK, against LAPACK (NumPy), by finite differences, and on
several CPU devices at once (where jaxlib's batched LAPACK kernels can hang)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gearte.core import linalg

ROOT = Path(__file__).resolve().parents[1]


def _spd(rng, batch, n, cond=1e-2):
    a = rng.normal(size=(*batch, n, n))
    return a @ np.swapaxes(a, -1, -2) + cond * n * np.eye(n)


# Three shapes (each compiles once), any values: a batch of two, a single matrix, a batch of 2 × 3.
SHAPES = [((2,), 6, 3), ((), 1, 1), ((2, 3), 12, 2)]


@settings(max_examples=15, deadline=None)
@given(shape=st.sampled_from(SHAPES), seed=st.integers(0, 2**16))
def test_factor_and_solves_are_lapacks(shape, seed):
    batch, n, r = shape
    rng = np.random.default_rng(seed)
    k, b = _spd(rng, batch, n), rng.normal(size=(*batch, n, r))
    ref = np.linalg.cholesky(k)
    low, x, xl, xu = (np.asarray(v) for v in _all(jnp.asarray(k), jnp.asarray(b), jnp.asarray(ref)))
    np.testing.assert_allclose(low, ref, rtol=0, atol=1e-13 * np.max(np.abs(ref)))
    assert np.all(np.triu(low, 1) == 0.0)  # a lower factor: nothing above the diagonal
    xr = np.linalg.solve(k, b)
    # the solves' rounding grows with the condition number: compare with the residual's scale
    np.testing.assert_allclose(x, xr, rtol=0, atol=1e-12 * np.linalg.cond(k).max() * np.max(np.abs(xr)))
    np.testing.assert_allclose(xl, np.linalg.solve(ref, b), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(xu, np.linalg.solve(np.swapaxes(ref, -1, -2), b), rtol=1e-10, atol=1e-12)


@jax.jit
def _all(k, b, ref):
    return linalg.cholesky(k), linalg.solve_spd(k, b), linalg.solve_lower(ref, b), linalg.solve_lower_transposed(ref, b)


def test_not_positive_definite_gives_nan():
    low = linalg.cholesky(jnp.asarray([[1.0, 2.0], [2.0, 1.0]]))
    assert bool(jnp.isnan(low[1, 1]))


def test_gradient_matches_central_differences():
    rng = np.random.default_rng(4)
    k0, b = _spd(rng, (), 6), rng.normal(size=(6, 2))
    d = rng.normal(size=(6, 6))
    d = d + d.T  # a symmetric direction

    def f(t):
        return jnp.sum(linalg.solve_spd(jnp.asarray(k0) + t * d, jnp.asarray(b)) ** 2)

    g = float(jax.grad(f)(0.0))
    h = 1e-6
    fd = (float(f(h)) - float(f(-h))) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-7)


def test_no_hang_on_several_cpu_devices():
    # Two host devices each factor a batch at once (one program per device, as the Monte Carlo engine runs them):
    # jaxlib's batched LAPACK kernels can wait there forever for pool threads that are all waiting too (reproduced
    # with jnp.linalg.cholesky on a batch of 32 matrices 36 × 36). gearte's must finish.
    script = textwrap.dedent(
        """
        import jax, jax.numpy as jnp, numpy as np
        jax.config.update("jax_enable_x64", True)
        from gearte.core import linalg
        mesh = jax.sharding.Mesh(np.asarray(jax.devices()), ("s",))
        spec = jax.sharding.PartitionSpec("s")
        a = np.random.default_rng(0).normal(size=(64, 36, 36))
        k = a @ a.transpose(0, 2, 1) + 36 * np.eye(36)
        def per(x):
            kk = jnp.asarray(k) + (1 + x[0]) * jnp.eye(36)
            return jnp.sum(linalg.solve_spd(kk, kk[..., :3]))[None]
        f = jax.jit(jax.shard_map(per, mesh=mesh, in_specs=spec, out_specs=spec, check_vma=False))  # as the engine
        for _ in range(20):
            f(jnp.arange(2.0)).block_until_ready()
        assert len(jax.devices()) == 2
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, timeout=120, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
