"""Equilibrium of rigid bodies on unilateral springs and clearance bearings: the contact potential's minimum.

Hidaka et al. (1994) model every part of a K-H-V (RV) reducer as a rigid body in the plane and
every contact as a spring along its line of action carrying an *equivalent error*. gearte
writes each contact as a linear function of the parts' small displacements q (mm; rotations
as arcs at a reference length L, so every coordinate is a length):

- a **unilateral contact** (a tooth pair, a pin on its flank) has penetration p = g·q + e, with
  e its equivalent error (mm, > 0: interference, < 0: a gap) and force k·max(0, p);
- a **bearing** with radial clearance c ≥ 0 has a relative displacement r = B q + e_b (a plane
  vector, mm) and force k·max(0, |r| − c) along r (a dead zone of radius c).

With a generalised load f (a small torque on the output) the equilibrium is the minimum of the
convex potential

    Φ(q) = Σ ½ k max(0, g·q + e)² + Σ ½ k_b max(0, |B q + e_b| − c)² + ½ μ |q|² − f·q,

where the tiny μ picks, among the positions of a part left floating inside its clearances, the
one nearest to nominal (it moves nothing that a contact holds). `solve` minimises Φ by Newton's
method with a backtracking (Armijo) line search: Φ is piecewise quadratic in the unilateral
contacts, so once the set of closed contacts is found the full Newton step lands on the minimum
and the iteration stops at a gradient at rounding level. The result code is reported per solve.

**Rigid limit.** For a fixed set of closed unilateral contacts and bearings without clearance the
minimiser is affine in the load, q(f) = q₀ + H⁻¹ f (H the Hessian there), so the rigid-body
position is q₀ = q − H⁻¹ f: one more back-substitution with the Hessian already factorised,
independent of the load and of a common scale of the stiffnesses while the set of closed contacts
stays the same (tested to 1e-9). A bearing in contact at its clearance is not affine in the load
(its tangential stiffness k (1 − c/|r|) grows with the load): there the correction is first order
and the floating parts' rigid-limit positions are approached as the load decreases, not reached
exactly. Where several load paths share the torque (hyperstatic), the ratios of the stiffnesses
decide the sharing: they are inputs of the model.

**Gradients** are those of the implicit-function theorem: the iteration runs on stopped
gradients, and one Newton step from the solution with the Hessian held carries the derivative
−H⁻¹ ∂(∇Φ)/∂θ (no iteration is differentiated).

Units: mm (forces in units of the stiffness, which is normalised), rad inside the callers.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..core.solution import RESULTS

#: Largest number of Newton iterations; a solve that needs more reports `RESULTS.nonlinear_max_steps_reached`.
MAX_STEPS = 60
#: Converged when the largest generalised-force residual is below this fraction of the load.
GRADIENT_RTOL = 1e-9
#: Trial step lengths of the line search: 1, ½, ¼, … (the first that satisfies Armijo's condition is taken).
LINE_SEARCH_STEPS = 24


class ContactSystem(eqx.Module):
    """The contacts of one configuration (one input angle), linear in the small displacements q (n coordinates, mm).

    - `G`, `e`, `k`: unilateral contacts: penetration `G @ q + e` (m × n, mm), stiffness (m,; 0 leaves a contact out).
    - `B`, `eb`, `c`, `kb`: bearings: relative displacement `B @ q + eb` (b × 2 × n, mm), clearance (b,, mm ≥ 0),
      stiffness (b,).
    - `f`: the generalised load (n,), in units of stiffness × mm.
    - `mu`: the regularisation of floating parts (units of stiffness).
    """

    G: Float[Array, "m n"]
    e: Float[Array, " m"]
    k: Float[Array, " m"]
    B: Float[Array, "b 2 n"]
    eb: Float[Array, "b 2"]
    c: Float[Array, " b"]
    kb: Float[Array, " b"]
    f: Float[Array, " n"]
    mu: Float[Array, ""]


class Equilibrium(eqx.Module):
    """The minimum of the contact potential.

    - `q`: the displacements under the load (mm); `q_rigid`: the rigid-limit displacements (mm).
    - `force`: force in every unilateral contact (units of stiffness × mm; > 0: closed, carrying load).
    - `bearing_force`: force in every bearing.
    - `result`: a `RESULTS` item; `steps`: Newton iterations.
    """

    q: Float[Array, " n"]
    q_rigid: Float[Array, " n"]
    force: Float[Array, " m"]
    bearing_force: Float[Array, " b"]
    result: RESULTS
    steps: Array


def _bearing_terms(s: ContactSystem, q):
    r = jnp.einsum("bin,n->bi", s.B, q) + s.eb
    nr2 = jnp.sum(r * r, axis=-1)
    nr = jnp.sqrt(jnp.where(nr2 > 0, nr2, 1.0))
    nr = jnp.where(nr2 > 0, nr, 0.0)
    over = (nr > s.c) | (s.c <= 0.0)  # a bearing without clearance is a plain spring
    safe = jnp.where(nr > 0, nr, 1.0)
    rhat = r / safe[:, None]
    # r − c r̂ (= r when c = 0, smooth through r = 0)
    stretch = jnp.where(over[:, None], r - s.c[:, None] * rhat, 0.0)
    return r, nr, over, rhat, stretch


def potential(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, ""]:
    """Φ(q) (module notes)."""
    p = jnp.maximum(s.G @ q + s.e, 0.0)
    _, _, _, _, stretch = _bearing_terms(s, q)
    return (
        0.5 * jnp.sum(s.k * p * p)
        + 0.5 * jnp.sum(s.kb * jnp.sum(stretch * stretch, axis=-1))
        + 0.5 * s.mu * jnp.dot(q, q)
        - jnp.dot(s.f, q)
    )


def gradient(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, " n"]:
    """∇Φ(q): generalised-force residual."""
    p = jnp.maximum(s.G @ q + s.e, 0.0)
    _, _, _, _, stretch = _bearing_terms(s, q)
    return s.G.T @ (s.k * p) + jnp.einsum("bin,bi->n", s.B, s.kb[:, None] * stretch) + s.mu * q - s.f


def hessian(s: ContactSystem, q: Float[Array, " n"], *, radial: bool = False) -> Float[Array, "n n"]:
    """The (generalised) Hessian of Φ at q: closed contacts only.

    With `radial=True`, a bearing in contact keeps only its stiffness along r̂ (the stiffness of its penetration; its
    tangential stiffness k (1 − c/|r|) vanishes with the load): the compliance of the rigid-limit correction."""
    n = q.shape[0]
    active = (s.G @ q + s.e > 0.0).astype(q.dtype)
    H = (s.G.T * (s.k * active)) @ s.G
    _, nr, over, rhat, _ = _bearing_terms(s, q)
    ratio = jnp.where(over, s.c / jnp.where(nr > 0, nr, 1.0), 0.0)
    if radial:
        ratio = jnp.where(s.c > 0, 1.0, 0.0)
    eye = jnp.eye(2, dtype=q.dtype)
    local = (1.0 - ratio)[:, None, None] * eye + ratio[:, None, None] * (rhat[:, :, None] * rhat[:, None, :])
    local = local * (s.kb * over.astype(q.dtype))[:, None, None]
    H = H + jnp.einsum("bim,bij,bjn->mn", s.B, local, s.B)
    return H + s.mu * jnp.eye(n, dtype=q.dtype)


def _newton(s: ContactSystem):
    n = s.f.shape[0]
    scale = jnp.max(jnp.abs(s.f))
    tol = GRADIENT_RTOL * jnp.where(scale > 0, scale, 1.0)
    ts = 0.5 ** jnp.arange(LINE_SEARCH_STEPS, dtype=s.f.dtype)

    def cond(state):
        _, g, i = state
        return (jnp.max(jnp.abs(g)) > tol) & (i < MAX_STEPS)

    def body(state):
        q, g, i = state
        H = hessian(s, q)
        dq = -jnp.linalg.solve(H, g)
        phi0 = potential(s, q)
        slope = jnp.dot(g, dq)
        trial = jax.vmap(lambda t: potential(s, q + t * dq))(ts)
        ok = trial <= phi0 + 1e-4 * ts * slope
        t = jnp.where(jnp.any(ok), ts[jnp.argmax(ok)], ts[-1])
        qn = q + t * dq
        return qn, gradient(s, qn), i + 1

    q0 = jnp.zeros(n, dtype=s.f.dtype)
    q, g, steps = jax.lax.while_loop(cond, body, (q0, gradient(s, q0), jnp.asarray(0)))
    return q, jnp.max(jnp.abs(g)) <= tol, steps


def solve(s: ContactSystem) -> Equilibrium:
    """Minimise the contact potential of `s` (see the module notes); differentiable by the implicit-function theorem.

    **Returns:** an `Equilibrium` (its `result` is `RESULTS.successful` or `RESULTS.nonlinear_max_steps_reached`).
    """
    ss = jax.tree.map(jax.lax.stop_gradient, s)
    q_star, ok, steps = _newton(ss)
    H = jax.lax.stop_gradient(hessian(ss, q_star))
    # One Newton step with the Hessian held: the value stays, the derivative is the implicit one.
    q = q_star - jnp.linalg.solve(H, gradient(s, q_star))
    # The rigid limit: remove the part of q proportional to the load for the closed contacts.
    q_rigid = q - jnp.linalg.solve(H, s.f)
    force = s.k * jnp.maximum(s.G @ q + s.e, 0.0)
    _, _, _, _, stretch = _bearing_terms(s, q)
    s2 = jnp.sum(stretch * stretch, axis=-1)
    bforce = s.kb * jnp.where(s2 > 0, jnp.sqrt(jnp.where(s2 > 0, s2, 1.0)), 0.0)
    result = RESULTS.where(ok, RESULTS.successful, RESULTS.nonlinear_max_steps_reached)  # pyright: ignore[reportArgumentType]
    return Equilibrium(q, q_rigid, force, bforce, result, steps)


__all__ = ("ContactSystem", "Equilibrium", "gradient", "hessian", "potential", "solve")
