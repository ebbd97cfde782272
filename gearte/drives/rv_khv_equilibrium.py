"""Equilibrium of rigid bodies on unilateral springs and clearance bearings: the contact potential's minimum.

Hidaka et al. (1994) model every part of a K-H-V (RV) reducer as a rigid body in the plane and
every contact as a spring along its line of action carrying an *equivalent error*. gearte
writes each contact as a linear function of the parts' small displacements q (mm; rotations
as arcs at a reference length L, so every coordinate is a length):

- a **unilateral contact** (a tooth pair, a pin on its flank) has penetration p = g·q + e, with
  e its equivalent error (mm, > 0: interference, < 0: a gap) and force k·max(0, p);
- a **bearing** with radial clearance c has a relative displacement r = B q + e_b (a plane vector,
  mm). Without clearance (c = 0) it is a plain spring, force k r. With a clearance its dead zone is
  the regular polygon of `BEARING_FACES` faces tangent to the circle of radius c: each face f (unit
  outward normal n_f) is a unilateral contact of penetration n_f·r − c and stiffness k. The
  polygon lies outside the circle by at most c (sec(π/M) − 1) (1.2e-3 c for M = 64: 6 nm for a
  5 µm clearance) and makes the whole potential piecewise quadratic.

With a generalised load f (a small torque on the output) the equilibrium is the minimum of the
convex potential

    Φ(q) = Σ ½ k max(0, g·q + e)² + Σ_bearings Σ_f ½ k_b max(0, n_f·(B q + e_b) − c)² + ½ μ |q|² − f·q

(½ k_b |B q + e_b|² for a bearing without clearance), where the tiny μ makes the minimiser
unique: a part left floating inside its clearances, held by no contact, stays at its nominal
position (μ moves nothing that a contact holds: it adds μ|q| ≈ 1e-14 of the stiffness × mm to the
forces). `solve` minimises Φ by Newton's method with an exact line search (a safeguarded Newton
iteration on the monotone directional derivative). As Φ is piecewise quadratic, the iteration ends
in finitely many steps: once the set of closed contacts is found the full Newton step lands on the
minimum, and the iteration stops when the force residual is at rounding level relative to the
largest force in the system (the load, or the contact forces where the errors preload the parts).
The result code is reported per solve.

**Rigid limit.** For a fixed set of closed contacts the minimiser is affine in the load,
q(f) = q₀ + H⁻¹ f (H the Hessian there), so the rigid-body position is q₀ = q − H⁻¹ f: one more
back-substitution with the Hessian already factorised, exactly independent of the load and of a
common scale of the stiffnesses while the set of closed contacts stays the same (tested to 1e-9).
Where several load paths share the torque (hyperstatic), the ratios of the stiffnesses decide the
sharing: they are inputs of the model.

**Gradients** are those of the implicit-function theorem: the iteration runs on stopped
gradients, and one Newton step from the solution with the Hessian held carries the derivative
−H⁻¹ ∂(∇Φ)/∂θ (no iteration is differentiated).

Units: mm (forces in units of the stiffness, which is normalised), rad inside the callers.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.solution import RESULTS

#: Faces of the polygon that stands for a bearing's clearance circle.
BEARING_FACES = 64
#: Largest number of Newton iterations; a solve that needs more reports `RESULTS.nonlinear_max_steps_reached`.
MAX_STEPS = 200
#: A force residual below this many machine epsilons of the largest term it is computed from is at rounding level.
ROUNDING_FACTOR = 64.0
#: Sufficient decrease (Armijo) for taking the full Newton step without a line search.
ARMIJO = 1e-4
#: Largest number of safeguarded Newton iterations of the exact line search along each Newton direction.
LINE_SEARCH_STEPS = 40
#: The line search stops when the directional derivative has fallen below this fraction of its value at the start.
LINE_SEARCH_RTOL = 1e-9

_ANGLES = 2 * math.pi * np.arange(BEARING_FACES) / BEARING_FACES
#: Unit outward normals of the faces (M × 2).
FACE_NORMALS = np.stack([np.cos(_ANGLES), np.sin(_ANGLES)], axis=1)


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
    - `bearing_force`: magnitude of the force in every bearing.
    - `result`: a `RESULTS` item; `steps`: Newton iterations.
    """

    q: Float[Array, " n"]
    q_rigid: Float[Array, " n"]
    force: Float[Array, " m"]
    bearing_force: Float[Array, " b"]
    result: RESULTS
    steps: Array


def _normals(dtype):
    return jnp.asarray(FACE_NORMALS, dtype=dtype)


def _bearing_local(s: ContactSystem, r):
    """Energy (b,), force vector (b × 2) and stiffness (b × 2 × 2) of every bearing at relative displacement r."""
    N = _normals(r.dtype)
    P = r @ N.T - s.c[:, None]  # face penetrations (b × M)
    pos = jnp.maximum(P, 0.0)
    poly = s.c > 0
    energy = 0.5 * s.kb * jnp.where(poly, jnp.sum(pos * pos, axis=-1), jnp.sum(r * r, axis=-1))
    force = s.kb[:, None] * jnp.where(poly[:, None], pos @ N, r)
    act = (P > 0).astype(r.dtype)
    K_poly = jnp.einsum("bf,fi,fj->bij", act, N, N)
    K = s.kb[:, None, None] * jnp.where(poly[:, None, None], K_poly, jnp.eye(2, dtype=r.dtype))
    return energy, force, K


def _relative(s: ContactSystem, q):
    return jnp.einsum("bin,n->bi", s.B, q) + s.eb


def potential(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, ""]:
    """Φ(q) (module notes)."""
    p = jnp.maximum(s.G @ q + s.e, 0.0)
    energy, _, _ = _bearing_local(s, _relative(s, q))
    return 0.5 * jnp.sum(s.k * p * p) + jnp.sum(energy) + 0.5 * s.mu * jnp.dot(q, q) - jnp.dot(s.f, q)


def gradient(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, " n"]:
    """∇Φ(q): generalised-force residual."""
    p = jnp.maximum(s.G @ q + s.e, 0.0)
    _, force, _ = _bearing_local(s, _relative(s, q))
    return s.G.T @ (s.k * p) + jnp.einsum("bin,bi->n", s.B, force) + s.mu * q - s.f


def hessian(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, "n n"]:
    """The (generalised) Hessian of Φ at q: closed contacts only (right derivative on a contact's boundary)."""
    n = q.shape[0]
    active = (s.G @ q + s.e > 0.0).astype(q.dtype)
    H = (s.G.T * (s.k * active)) @ s.G
    _, _, K = _bearing_local(s, _relative(s, q))
    H = H + jnp.einsum("bim,bij,bjn->mn", s.B, K, s.B)
    return H + s.mu * jnp.eye(n, dtype=q.dtype)


def _line_derivatives(s: ContactSystem, q, dq):
    """φ(t) = Φ(q + t dq): a function of t giving (φ′(t), φ″(t)) (φ″ the right derivative), each in O(m + b M)."""
    N = _normals(q.dtype)
    a, b = s.G @ q + s.e, s.G @ dq
    r0, rb = _relative(s, q), jnp.einsum("bin,n->bi", s.B, dq)
    fa, fb = r0 @ N.T - s.c[:, None], rb @ N.T  # face penetrations along the line: fa + t fb
    poly = s.c > 0
    kp = jnp.where(poly, s.kb, 0.0)[:, None]
    ks = jnp.where(poly, 0.0, s.kb)
    r0rb, rb2 = jnp.sum(r0 * rb, axis=-1), jnp.sum(rb * rb, axis=-1)
    lin0 = s.mu * jnp.dot(q, dq) - jnp.dot(s.f, dq) + jnp.sum(ks * r0rb)
    lin1 = s.mu * jnp.dot(dq, dq) + jnp.sum(ks * rb2)

    def derivatives(t):
        p = a + t * b
        pf = fa + t * fb
        d1 = jnp.sum(s.k * jnp.maximum(p, 0.0) * b) + jnp.sum(kp * jnp.maximum(pf, 0.0) * fb) + lin0 + t * lin1
        d2 = jnp.sum(jnp.where(p > 0, s.k * b * b, 0.0)) + jnp.sum(jnp.where(pf > 0, kp * fb * fb, 0.0)) + lin1
        return d1, d2

    return derivatives


def _line_search(s: ContactSystem, q, dq):
    """The step t > 0 that minimises Φ(q + t dq): safeguarded Newton on the monotone, piecewise-linear φ′(t), from
    t = 1 (the Newton step, exact where no contact changes state), bisecting where a step leaves the bracket."""
    derivatives = _line_derivatives(s, q, dq)
    d0, _ = derivatives(jnp.zeros((), dtype=q.dtype))
    tol = LINE_SEARCH_RTOL * jnp.abs(d0)
    one = jnp.ones((), dtype=q.dtype)

    def cond(state):
        _, _, _, k, done = state
        return (~done) & (k < LINE_SEARCH_STEPS)

    def body(state):
        t, lo, hi, k, _ = state
        d1, d2 = derivatives(t)
        done = jnp.abs(d1) <= tol
        lo = jnp.where(d1 < 0, t, lo)
        hi = jnp.where(d1 >= 0, t, hi)
        tn = t - d1 / d2
        tn = jnp.where((tn > lo) & (tn < hi), tn, jnp.where(jnp.isfinite(hi), 0.5 * (lo + hi), 2.0 * t))
        return jnp.where(done, t, tn), lo, hi, k + 1, done

    state = (one, 0.0 * one, jnp.inf * one, jnp.asarray(0), jnp.asarray(False))
    t, lo, _, _, done = jax.lax.while_loop(cond, body, state)
    # Out of iterations: the last point known to lie before the minimum (φ decreases up to it).
    return jnp.where(done | (lo <= 0), t, lo)


def _rounding_floor(s: ContactSystem, q):
    """The rounding level of the force residual at q: eps × the largest magnitude it is computed from (the load, the
    contact terms k (|G||q| + |e|), the bearing terms)."""
    aq = jnp.abs(q)
    unilateral = jnp.max(s.k * (jnp.abs(s.G) @ aq + jnp.abs(s.e)), initial=0.0)
    bearing = jnp.max(s.kb * jnp.max(jnp.einsum("bin,n->bi", jnp.abs(s.B), aq) + jnp.abs(s.eb), axis=-1) + s.kb * s.c, initial=0.0)
    scale = jnp.maximum(jnp.max(jnp.abs(s.f)), jnp.maximum(unilateral, bearing))
    return ROUNDING_FACTOR * jnp.finfo(q.dtype).eps * scale


def _active(s: ContactSystem, q):
    """Which unilateral contacts and bearing faces are closed at q."""
    N = _normals(q.dtype)
    faces = (_relative(s, q) @ N.T - s.c[:, None] > 0.0) & (s.c > 0)[:, None]  # a bearing without clearance has none
    return s.G @ q + s.e > 0.0, faces


def _newton(s: ContactSystem, q0):
    """Newton iterations from q0. Stops when the full Newton step was taken and no contact changed state on it (the
    quadratic model was exact there: the step landed on the minimum), or when the residual is at rounding level."""

    def cond(state):
        _, _, _, i, done = state
        return (~done) & (i < MAX_STEPS)

    def body(state):
        q, g, act, i, _ = state
        L = jnp.linalg.cholesky(hessian(s, q))
        dq = -jax.scipy.linalg.cho_solve((L, True), g)
        # The full step where it decreases Φ enough (Armijo): the whole set of closed contacts may change at once.
        full = potential(s, q + dq) <= potential(s, q) + ARMIJO * jnp.dot(g, dq)
        t = jax.lax.cond(full, lambda: jnp.ones((), dtype=q.dtype), lambda: _line_search(s, q, dq))
        qn = q + t * dq
        gn = gradient(s, qn)
        actn = _active(s, qn)
        same = jnp.all(act[0] == actn[0]) & jnp.all(act[1] == actn[1])
        done = ((t == 1.0) & same) | (jnp.max(jnp.abs(gn)) <= _rounding_floor(s, qn))
        return qn, gn, actn, i + 1, done

    g0 = gradient(s, q0)
    done0 = jnp.max(jnp.abs(g0)) <= _rounding_floor(s, q0)
    q, _, _, steps, ok = jax.lax.while_loop(cond, body, (q0, g0, _active(s, q0), jnp.asarray(0), done0))
    return q, ok, steps


def solve(s: ContactSystem, q0: Float[Array, " n"] | None = None) -> Equilibrium:
    """Minimise the contact potential of `s` (see the module notes); differentiable by the implicit-function theorem.

    `q0`: the starting point (default: the nominal position, zero); a neighbouring solution makes a good one.

    **Returns:** an `Equilibrium` (its `result` is `RESULTS.successful` or `RESULTS.nonlinear_max_steps_reached`).
    """
    ss = jax.tree.map(jax.lax.stop_gradient, s)
    start = jnp.zeros_like(ss.f) if q0 is None else jax.lax.stop_gradient(q0)
    q_star, ok, steps = _newton(ss, start)
    cho = (jax.lax.stop_gradient(jnp.linalg.cholesky(hessian(ss, q_star))), True)
    # One Newton step with the Hessian held: the value stays, the derivative is the implicit one.
    q = q_star - jax.scipy.linalg.cho_solve(cho, gradient(s, q_star))
    # The rigid limit: remove the part of q proportional to the load for the closed contacts.
    q_rigid = q - jax.scipy.linalg.cho_solve(cho, s.f)
    force = s.k * jnp.maximum(s.G @ q + s.e, 0.0)
    _, bf, _ = _bearing_local(s, _relative(s, q))
    b2 = jnp.sum(bf * bf, axis=-1)
    bforce = jnp.where(b2 > 0, jnp.sqrt(jnp.where(b2 > 0, b2, 1.0)), 0.0)
    result = RESULTS.where(ok, RESULTS.successful, RESULTS.nonlinear_max_steps_reached)  # pyright: ignore[reportArgumentType]
    return Equilibrium(q, q_rigid, force, bforce, result, steps)


__all__ = ("BEARING_FACES", "ContactSystem", "Equilibrium", "gradient", "hessian", "potential", "solve")
