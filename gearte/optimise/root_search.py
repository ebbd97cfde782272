"""The root of an increasing function of a scale, in log scale: a bracket grown outwards from 0, then Illinois.

A tolerance budget scales a direction of tolerances until its constraints hold exactly (`gearte.optimise.budget`);
each evaluation is a pass over the Monte Carlo samples, thousands of equilibrium solves for a contact drive, so the
search spends as few as it can and stays away from the far ends of its bracket.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array

#: Width in log s at which the root search stops (the constraint's root is then known to ~1e-12 relative in s).
ROOT_TOL = 1e-12
#: Most evaluations of the root search after the bracket is found (Illinois converges superlinearly; ~6-10 are used).
ROOT_STEPS = 60


def bracketed_root(g, lo: float, hi: float, *, bisect_above: float = math.inf) -> Array:
    """The root of g (increasing: ≤ 0 feasible, > 0 infeasible; finite: the caller maps a NaN to a violation) in
    [lo, hi] (log s, lo < 0 < hi), or the end of the bracket that is the answer: lo where even lo is infeasible, hi
    where even hi is feasible.

    The search brackets the root outwards from log s = 0 (the direction as given: the optimiser starts at the nominal
    tolerances and moves the direction by factors, not orders of magnitude), doubling the step from log 4, so it seldom
    visits the far ends of the bracket (near-perfect parts, where a contact drive's solves are slowest); then the
    Illinois variant of regula falsi (a bracket kept at every step, superlinear convergence) until the bracket is
    `ROOT_TOL` wide, bisecting while the infeasible end's value is at least `bisect_above` (where the caller counts a
    model without a valid state). Each evaluation is one pass over the common samples: about 8-12 passes for a smooth
    constraint, where a fixed bisection of the whole bracket needed 26."""
    zero = jnp.zeros(())
    g0 = g(zero)
    up = g0 <= 0  # feasible at s = 1: the root lies above

    def widen_cond(state):
        x, gx, _, _, _, k = state
        outside = jnp.where(up, gx <= 0, gx > 0)
        at_end = jnp.where(up, x >= hi, x <= lo)
        return outside & ~at_end & (k < 8)

    def widen(state):
        x, gx, _, _, step, k = state
        nx = jnp.clip(jnp.where(up, x + step, x - step), lo, hi)
        return nx, g(nx), x, gx, 2.0 * step, k + 1

    start = (zero, g0, zero, g0, jnp.asarray(math.log(4.0)), jnp.asarray(0))
    x, gx, prev, g_prev, _, _ = jax.lax.while_loop(widen_cond, widen, start)
    # Feasible end a (g ≤ 0) and infeasible end b (g > 0): the last point and the one before it.
    a = jnp.where(up, prev, x)
    b = jnp.where(up, x, prev)
    ga = jnp.where(up, g_prev, gx)
    gb = jnp.where(up, gx, g_prev)
    bracketed = (ga <= 0) & (gb > 0)

    def cond(state):
        a, b, ga, _, _, _, k = state
        return bracketed & (b - a > ROOT_TOL) & (ga < 0) & (k < ROOT_STEPS)

    def body(state):
        a, b, ga, gb, no_state, side, k = state
        c = jnp.clip((a * gb - b * ga) / jnp.where(gb != ga, gb - ga, 1.0), a, b)
        # Bisect while the infeasible end is where the model has no valid state (its value, before any Illinois
        # halving, at least `bisect_above`): regula falsi would creep from the feasible end towards that jump.
        c = jnp.where((c <= a) | (c >= b) | no_state, 0.5 * (a + b), c)
        gc = g(c)
        feasible = gc <= 0
        # Halve the function value at the end that stays twice in a row (Illinois), to avoid one-sided stalls.
        ga_new = jnp.where(feasible, gc, jnp.where(side == -1, 0.5 * ga, ga))
        gb_new = jnp.where(feasible, jnp.where(side == 1, 0.5 * gb, gb), gc)
        no_state_new = jnp.where(feasible, no_state, gc >= bisect_above)
        return jnp.where(feasible, c, a), jnp.where(feasible, b, c), ga_new, gb_new, no_state_new, jnp.where(feasible, 1, -1), k + 1

    start = (a, b, ga, gb, gb >= bisect_above, jnp.asarray(0), jnp.asarray(0))
    a, *_ = jax.lax.while_loop(cond, body, start)
    # Not bracketed: the search stopped at an end of the bracket, which is the answer.
    return jnp.where(bracketed, a, jnp.where(up, hi, lo))
