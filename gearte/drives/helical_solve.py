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

The settling periods take diffrax's own Tsit5 tableau through `UnrolledExplicitRK(diffrax.Tsit5)`, a
diffrax solver whose stages are unrolled when traced, where diffrax's generic Runge-Kutta step loops
over the tableau's rows: on the wind-turbine example a solve takes 0.075-0.080 s instead of 0.09 s
and its reverse-mode gradient 0.45 s instead of 0.57 s (2 cores). Same tableau, same steps: the two
agree to rounding (tested). The kept window uses `diffrax.Tsit5` itself for its 5th-order dense interpolant.

Steady state: start from the quasi-static solution at τ = 0 (every mesh loaded, so only the
mesh-stiffness and error excitation is left to decay), integrate `n_periods` mesh periods, and
keep the last one. Why not shooting for the periodic orbit (optimistix root find of the period map):
each Newton step needs the 2D × 2D monodromy matrix (2D = 12(3 + N) tangents through one period),
more than the ~10 periods the damping needs to settle. The period-to-period change of the state
is returned (`periodicity`, µm) so a caller can check the transient has gone.
"""

from __future__ import annotations

from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.solution import RESULTS
from ..core.validate import as_int
from .helical_equations import MeshedSystem


class UnrolledExplicitRK(diffrax.AbstractSolver):
    """The Butcher tableau of a diffrax explicit Runge-Kutta solver, its stages unrolled when traced.

    For constant steps (`diffrax.ConstantStepSize`; no error estimate, linear dense output between steps) on an
    `ODETerm`. A first-same-as-last method (Tsit5, Dopri5) carries the last stage's vector field to the next step, so
    a step costs one evaluation fewer than it has stages.

    **Arguments:**

    - `method`: the diffrax solver class whose `tableau` and `order` are taken (a subclass of `diffrax.AbstractERK`;
      default `diffrax.Tsit5`).
    """

    method: type[diffrax.AbstractERK] = eqx.field(static=True, default=diffrax.Tsit5)
    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = diffrax.LocalLinearInterpolation

    def __check_init__(self):
        if not (isinstance(self.method, type) and issubclass(self.method, diffrax.AbstractERK)):
            raise ValueError(
                f"UnrolledExplicitRK: method must be an explicit Runge-Kutta solver class of diffrax (a diffrax.AbstractERK), got {self.method!r}"
            )
        tab = self.method.tableau
        if not isinstance(tab, diffrax.ButcherTableau):
            raise ValueError(f"UnrolledExplicitRK: {self.method.__name__} has no single Butcher tableau")
        if tab.fsal and not tab.ssal:
            raise ValueError("UnrolledExplicitRK: a first-same-as-last tableau must have its last stage at the solution")

    @property
    def tableau(self) -> diffrax.ButcherTableau:
        tab = self.method.tableau
        assert isinstance(tab, diffrax.ButcherTableau)  # __check_init__
        return tab

    def order(self, terms):
        return self.method().order(terms)

    def init(self, terms, t0, t1, y0, args):
        del t1
        return terms.vf(t0, y0, args) if self.tableau.fsal else None

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        tab = self.tableau
        h = terms.contr(t0, t1)
        if tab.fsal and made_jump is False:
            k0 = solver_state
        elif tab.fsal:
            k0 = jax.lax.cond(made_jump, lambda: terms.vf(t0, y0, args), lambda: solver_state)
        else:
            k0 = terms.vf(t0, y0, args)
        ks = [k0]

        def combine(weights):
            incr = [(float(w), k) for w, k in zip(weights, ks, strict=False) if float(w) != 0.0]
            return jax.tree.map(lambda y, *kk: y + h * sum(w * k for (w, _), k in zip(incr, kk, strict=True)), y0, *[k for _, k in incr])

        # Stages 2…s; where the last stage is the solution itself (`ssal`: its row is b_sol), it is not evaluated here
        # (a first-same-as-last tableau evaluates it below, as the next step's first stage).
        rows = list(zip(tab.c, tab.a_lower, strict=True))
        for ci, row in rows[:-1] if tab.ssal else rows:
            ks.append(terms.vf(t0 + float(ci) * h, combine(row), args))
        y1 = combine(tab.a_lower[-1] if tab.ssal else tab.b_sol)
        state = terms.vf(t1, y1, args) if tab.fsal else None
        return y1, None, dict(y0=y0, y1=y1), state, diffrax.RESULTS.successful


#: A periodic solution whose displacements pass this many times the larger of the quasi-static deflection it started
#: from and 1 µm has diverged (`solve_periodic`): a dynamic response of a damped stage stays within tens of times its static one.
DIVERGED = 1e3


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
    µm per mesh period, `periodicity`: max |q(end) − q(start)| of the window, µm (NaN where the solve failed), and
    `result`: `RESULTS.successful`, `RESULTS.max_steps_reached` (diffrax stopped) or `RESULTS.nonfinite` (the state
    became NaN or infinite, or diverged beyond `DIVERGED` times its quasi-static deflection: too few steps per mesh
    period for the stage's stiffness)."""

    tau: Float[Array, " s"]
    q: Float[Array, "s d"]
    v: Float[Array, "s d"]
    periodicity: Float[Array, ""]
    result: RESULTS


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
    def integrate(t0: float, t1: float, y: Float[Array, " n"], saveat: diffrax.SaveAt, method: diffrax.AbstractSolver) -> diffrax.Solution:
        n_steps = round((t1 - t0) * steps) + 16
        return diffrax.diffeqsolve(
            diffrax.ODETerm(system.vector_field),
            method,
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

    settle = integrate(0.0, t_start, y0, diffrax.SaveAt(t1=True), UnrolledExplicitRK(diffrax.Tsit5))
    assert settle.ys is not None
    window = integrate(t_start, float(n), settle.ys[-1], diffrax.SaveAt(dense=True), diffrax.Tsit5())
    ts = t_start + np.arange(rec * s + 1, dtype=float) / s
    ys = jax.vmap(window.evaluate)(jnp.asarray(ts))
    ok = (settle.result == diffrax.RESULTS.successful) & (window.result == diffrax.RESULTS.successful)
    q, v = ys[:, :d], ys[:, d:]
    # An explicit step beyond the stability limit of the stage's stiffest mode grows the state by orders of magnitude
    # every period, to astronomical but finite values (1e62 µm at 128 steps per mesh period in the wind-turbine
    # stage): a window that leaves `DIVERGED` times the start's quasi-static deflection (and at least 1 mm) has diverged.
    bound = DIVERGED * jnp.maximum(jnp.max(jnp.abs(y0[:d])), 1.0)
    finite = jnp.all(jnp.isfinite(ys)) & (jnp.max(jnp.abs(q)) <= bound)
    periodicity = jnp.where(ok & finite, jnp.max(jnp.abs(q[-1] - q[0])), jnp.nan)
    result = RESULTS.where(ok, RESULTS.where(finite, RESULTS.successful, RESULTS.nonfinite), RESULTS.max_steps_reached)  # pyright: ignore[reportArgumentType]
    return PeriodicSolution(jnp.asarray(ts[:-1] - t_start), q[:-1], v[:-1], periodicity, result)


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
