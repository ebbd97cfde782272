"""Periodic steady state of a `MeshedSystem` with diffrax, and the dynamic transmission error (DTE) it gives.

Solver: Tsit5 (explicit Runge-Kutta, 5th order, Tsitouras 2011) with a constant step of
T_m/`steps_per_period`. Constant steps because (i) the step must stay below the stability limit
of the stiffest support mode anyway, which also makes it accurate for the mesh-frequency response;
(ii) under `jax.vmap` every member of a batch takes the same steps, with no wasted
masked iterations; (iii) the discrete solution is then a smooth function of the parameters, so
its reverse-mode gradient (diffrax's `RecursiveCheckpointAdjoint`, discretise-then-optimise)
matches finite differences of the same computation. Zhang, Chen & Wang used a variable-step 4th-order
Runge-Kutta method; `steps_per_period` is checked by convergence (tests: the error falls at the
5th order of Tsit5).

Steady state: start from the quasi-static solution at τ = 0 (every mesh loaded, so only the
mesh-stiffness and error excitation is left to decay), integrate `n_periods` mesh periods, and
keep the last one. Why not shooting for the periodic orbit (optimistix root find of the period map):
each Newton step needs the 2D × 2D monodromy matrix (2D = 12(3 + N) tangents through one period),
more than the ~10 periods the damping needs to settle. The period-to-period change of the state
is returned (`periodicity`, µm) so a caller can check the transient has gone.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.validate import as_int
from .helical_equations import MeshedSystem


class PeriodicSolver(eqx.Module):
    """How to integrate to periodic steady state (module docstring).

    **Arguments:**

    - `n_periods`: mesh periods integrated, the last one kept (≥ 2).
    - `steps_per_period`: constant Tsit5 steps per mesh period.
    - `samples_per_period`: output samples over the kept period.
    - `record_periods`: periods kept at the end (1 for a mesh-periodic excitation; the hyper-period
      of the eccentricity errors, in mesh periods, to see their whole effect).
    """

    n_periods: int = eqx.field(static=True)
    steps_per_period: int = eqx.field(static=True)
    samples_per_period: int = eqx.field(static=True)
    record_periods: int = eqx.field(static=True)

    def __init__(self, n_periods: int = 12, *, steps_per_period: int = 256, samples_per_period: int = 128, record_periods: int = 1):
        self.n_periods = as_int("n_periods", n_periods, minimum=2)
        self.steps_per_period = as_int("steps_per_period", steps_per_period, minimum=4)
        self.samples_per_period = as_int("samples_per_period", samples_per_period, minimum=4)
        self.record_periods = as_int("record_periods", record_periods, minimum=1)
        if self.record_periods >= self.n_periods:
            raise ValueError(f"record_periods ({record_periods}) must be < n_periods ({n_periods}): the first periods settle the transient")


class PeriodicSolution(eqx.Module):
    """States over the kept window: `tau` (S,) mesh periods from its start, `q` (S, D) µm, `v` (S, D)
    µm per mesh period, and `periodicity`: max |q(end) − q(start)| of the window, µm."""

    tau: Float[Array, " s"]
    q: Float[Array, "s d"]
    v: Float[Array, "s d"]
    periodicity: Float[Array, ""]


def solve_periodic(system: MeshedSystem, solver: PeriodicSolver, *, y0: Float[Array, " n"] | None = None) -> PeriodicSolution:
    """Integrate `system` from `y0` (default: quasi-static at τ = 0, at rest) to periodic steady state."""
    d = system.mass.shape[0]
    if y0 is None:
        y0 = jnp.concatenate([system.static(jnp.asarray(0.0)), jnp.zeros(d)])
    n, rec, s = solver.n_periods, solver.record_periods, solver.samples_per_period
    t_start = float(n - rec)
    steps = solver.steps_per_period

    # Two solves, the transient then the kept window with its dense (Tsit5) interpolant, sampled at the save
    # times; the same steps and interpolant as one solve saving at those times, without diffrax's run-time
    # checks of save times and of the result (host callbacks, which JAX's persistent compilation cache does
    # not store: every new process would compile the solve again). Constant steps with max_steps above their
    # number cannot fail; a non-finite state shows as NaN in `periodicity`.
    def integrate(t0: float, t1: float, y: Float[Array, " n"], saveat: diffrax.SaveAt) -> diffrax.Solution:
        n_steps = round((t1 - t0) * steps) + 16
        return diffrax.diffeqsolve(
            diffrax.ODETerm(system.vector_field),
            diffrax.Tsit5(),
            t0=t0,
            t1=t1,
            dt0=1.0 / steps,
            y0=y,
            saveat=saveat,
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=n_steps,
            adjoint=diffrax.RecursiveCheckpointAdjoint(checkpoints=n_steps),
            throw=False,
        )

    settle = integrate(0.0, t_start, y0, diffrax.SaveAt(t1=True))
    assert settle.ys is not None
    window = integrate(t_start, float(n), settle.ys[-1], diffrax.SaveAt(dense=True))
    ts = t_start + np.arange(rec * s + 1, dtype=float) / s
    ys = jax.vmap(window.evaluate)(jnp.asarray(ts))
    ok = (settle.result == diffrax.RESULTS.successful) & (window.result == diffrax.RESULTS.successful)
    q, v = ys[:, :d], ys[:, d:]
    periodicity = jnp.where(ok, jnp.max(jnp.abs(q[-1] - q[0])), jnp.nan)
    return PeriodicSolution(jnp.asarray(ts[:-1] - t_start), q[:-1], v[:-1], periodicity)


def peak_to_peak(x: Float[Array, "*b s"], axis: int = -1) -> Float[Array, "*b"]:
    """max − min along `axis` (of samples)."""
    return jnp.max(x, axis=axis) - jnp.min(x, axis=axis)


def smooth_peak_to_peak(x: Float[Array, "*b s"], width: float, axis: int = -1) -> Float[Array, "*b"]:
    """Smooth peak-to-peak for optimisers: w·logΣe^{x/w} + w·logΣe^{−x/w}, ≥ the sampled peak-to-peak and
    at most 2 w log S above it (S samples); infinitely differentiable."""
    return width * (jax.nn.logsumexp(x / width, axis=axis) + jax.nn.logsumexp(-x / width, axis=axis))


def harmonics(x: Float[Array, "*b s"], n: int) -> Float[Array, "*b n"]:
    """Amplitudes of harmonics 0 … n−1 of samples over one period (0 = mean; k: amplitude of the k-th harmonic)."""
    s = x.shape[-1]
    c = jnp.fft.rfft(x, axis=-1)[..., :n] / s
    return jnp.abs(c) * jnp.where(jnp.arange(n) == 0, 1.0, 2.0)
