"""Small dense symmetric positive definite systems, solved with jax.numpy operations only.

`cholesky` and `cho_solve` give what `jnp.linalg.cholesky` and `jax.scipy.linalg.cho_solve` give, for any batch
of small matrices (a drive's stiffness matrices: tens of unknowns), written as loops over the columns of vector
operations on the whole batch rather than as calls of LAPACK.

Why not LAPACK: on a CPU, jaxlib 0.10's batched LAPACK kernels (potrf, getrf, trsm) split a batch into tasks on
XLA's intra-op thread pool and block until these finish. When the Monte Carlo engine runs one program per CPU
device (`gearte run` makes one device per core) and every device's program reaches such a kernel at once, every
thread of the pool waits for tasks that no thread is left to run: the run hangs (reproduced with two host devices
and a batch of 32 Cholesky factorisations of 36 × 36). Vector operations have no such wait, and on a batch they
vectorise across its matrices, where LAPACK factors one matrix at a time.

Accuracy: the column (Crout) Cholesky and substitution are LAPACK's unblocked algorithms: the same backward
stability; tests/test_linalg.py compares them with LAPACK's to 1e-13 relative and checks their gradients.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def cholesky(a: Float[Array, "*b n n"]) -> Float[Array, "*b n n"]:
    """Lower Cholesky factor L (a = L Lᵀ) of every symmetric positive definite matrix of the batch; only the lower
    triangle of `a` is read. A matrix that is not positive definite gives NaN (as `jnp.linalg.cholesky`)."""
    n = a.shape[-1]
    rows = jnp.arange(n)

    def column(j, lower):
        # Column j of L from the columns before it: L[:, j] = (a[:, j] − L[:, :j] L[j, :j]) / L[j, j], rows ≥ j.
        # (Row j of `lower` holds L[j, :j] and zeros after, so the product runs over the filled columns only.)
        c = jnp.take(a, j, axis=-1) - jnp.einsum("...ik,...k->...i", lower, jnp.take(lower, j, axis=-2))
        d = jnp.sqrt(jnp.take(c, j, axis=-1))
        new = jnp.where(rows >= j, c / d[..., None], 0.0)
        return jax.lax.dynamic_update_index_in_dim(lower, new[..., None], j, axis=-1)

    return jax.lax.fori_loop(0, n, column, jnp.zeros_like(a))


def solve_lower(lower: Float[Array, "*b n n"], b: Float[Array, "*b n r"]) -> Float[Array, "*b n r"]:
    """x with L x = b (forward substitution; L lower triangular)."""
    n = lower.shape[-1]

    def row(i, x):
        li = jnp.take(lower, i, axis=-2)  # (…, n): L[i, :], used for the columns already solved (x is 0 after)
        xi = (jnp.take(b, i, axis=-2) - jnp.einsum("...k,...kr->...r", li, x)) / jnp.take(li, i, axis=-1)[..., None]
        return jax.lax.dynamic_update_index_in_dim(x, xi[..., None, :], i, axis=-2)

    return jax.lax.fori_loop(0, n, row, jnp.zeros(jnp.broadcast_shapes(lower.shape[:-1] + (1,), b.shape), b.dtype))


def solve_lower_transposed(lower: Float[Array, "*b n n"], y: Float[Array, "*b n r"]) -> Float[Array, "*b n r"]:
    """x with Lᵀ x = y (backward substitution; L lower triangular)."""
    n = lower.shape[-1]

    def row(k, x):
        i = n - 1 - k
        li = jnp.take(lower, i, axis=-1)  # (…, n): column i of L = row i of Lᵀ, used for the rows already solved
        xi = (jnp.take(y, i, axis=-2) - jnp.einsum("...k,...kr->...r", li, x)) / jnp.take(li, i, axis=-1)[..., None]
        return jax.lax.dynamic_update_index_in_dim(x, xi[..., None, :], i, axis=-2)

    return jax.lax.fori_loop(0, n, row, jnp.zeros(jnp.broadcast_shapes(lower.shape[:-1] + (1,), y.shape), y.dtype))


def cho_solve(lower: Float[Array, "*b n n"], b: Float[Array, "*b n r"]) -> Float[Array, "*b n r"]:
    """x with (L Lᵀ) x = b, from the factor of `cholesky`."""
    return solve_lower_transposed(lower, solve_lower(lower, b))


def solve_spd(a: Float[Array, "*b n n"], b: Float[Array, "*b n r"]) -> Float[Array, "*b n r"]:
    """x with a x = b for symmetric positive definite `a` (a Cholesky factorisation and two substitutions)."""
    return cho_solve(cholesky(a), b)


__all__ = ("cho_solve", "cholesky", "solve_lower", "solve_lower_transposed", "solve_spd")
