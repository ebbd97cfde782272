"""Equilibrium of rigid bodies on unilateral springs and clearance bearings: the contact potential's minimum.

Hidaka et al. (1994) model every part of a K-H-V (RV) reducer as a rigid body in the plane and
every contact as a spring along its line of action carrying an *equivalent error*. gearte
writes each contact as a linear function of the parts' small displacements q (mm; rotations
as arcs at a reference length L, so every coordinate is a length):

- a **unilateral contact** (a tooth pair, a pin on its flank) has penetration p = g·q + e, with
  e its equivalent error (mm, > 0: interference, < 0: a gap) and force k·max(0, p);
- a **bearing** with radial clearance c has a relative displacement r = B q + e_b (a plane vector,
  mm). Without clearance (c = 0) it is a plain spring, force k r. With a clearance its dead zone is
  the regular polygon of M = `ContactSystem.faces` faces (default `BEARING_FACES`, 64) tangent to the
  circle of radius c: each face f (unit outward normal n_f) is a unilateral contact of penetration
  n_f·r − c and stiffness k. The
  polygon lies outside the circle by at most c (sec(π/M) − 1) (1.2e-3 c for M = 64: 6 nm for a
  5 µm clearance) and makes the whole potential piecewise quadratic. Its faces are fixed in the frame
  of r (for the RV reducer, the housing).

With a generalised load f (a small torque on the output) the equilibrium is the minimum of the
convex potential

    Φ(q) = Σ ½ k max(0, g·q + e)² + Σ_bearings Σ_f ½ k_b max(0, n_f·(B q + e_b) − c)² + ½ μ |q|² − f·q

(½ k_b |B q + e_b|² for a bearing without clearance), where the tiny μ makes the minimiser
unique. `solve` takes it proximal to the starting point, ½ μ |q − q₀|², so a part left floating
inside its clearances, held by no contact, stays where the start put it (the neighbouring solution
along the grid) instead of being pulled back to nominal across every contact in its way; μ moves
nothing that a contact holds (for the RV reducer, μ = 1e-3 k × deflection_mm / mm and |q − q₀| of µm: μ|q − q₀| is
about 1e-6 of the small load).
`solve` minimises Φ by Newton's method with an exact line search: φ′(t) along a Newton direction is
piecewise linear and increasing, so the search walks from kink to kink (a contact or a bearing face
that opens or closes) to the piece that holds its root. As Φ is piecewise quadratic, the iteration ends
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
−H⁻¹ ∂(∇Φ)/∂θ (no iteration is differentiated). That step's value and the rigid limit are computed where
the iteration ends, one solve at a time (`_settled`); their derivative is a custom JVP rule (`_held`).

Units: mm (forces in units of the stiffness, which is normalised), rad inside the callers.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core import linalg
from ..core.solution import RESULTS

#: Faces of the polygon that stands for a bearing's clearance circle, by default (`ContactSystem.faces`).
BEARING_FACES = 64
#: Most faces of a clearance polygon a drive accepts (1,024 is the accuracy benchmark's reference).
MAX_BEARING_FACES = 4096
#: Largest number of Newton iterations; a solve that needs more reports `RESULTS.nonlinear_max_steps_reached`. Units
#: with errors far below their clearances are the slow ones: their contacts close one per iteration, 130-260
#: iterations on 64 units of the budget example at 1e-3 to 1e-1 of its nominal tolerances (77 and 42 of their 1,152
#: solves needed more than 200, the earlier limit, and a solve cut short gives a wrong TE).
MAX_STEPS = 1000
#: A force residual below this many machine epsilons of the largest term it is computed from is at rounding level.
ROUNDING_FACTOR = 64.0
#: A solve whose steps no longer move it (by at most 4 machine epsilons of its largest coordinate: the iteration creeps
#: where a contact's state flips at rounding level) has converged once its force residual is within this many rounding
#: floors (`ROUNDING_FACTOR`). The solves of the tolerance study that ran to `MAX_STEPS` that way sat at 2-3 floors.
STALLED_FLOORS = 16.0
#: Sufficient decrease (Armijo) for taking the full Newton step without a line search.
ARMIJO = 1e-4
#: Largest number of kinks the exact line search crosses along one Newton direction.
LINE_SEARCH_STEPS = 64


def face_normals(faces: int = BEARING_FACES) -> np.ndarray:
    """Unit outward normals of a clearance polygon's faces (M × 2), the first along +x."""
    angles = 2 * math.pi * np.arange(faces) / faces
    return np.stack([np.cos(angles), np.sin(angles)], axis=1)


def _face_outer(faces: int) -> np.ndarray:
    """Each face's n nᵀ as (xx, xy, yy) (M × 3): a bearing's stiffness over its closed faces is one product with them."""
    n = face_normals(faces)
    return np.stack([n[:, 0] ** 2, n[:, 0] * n[:, 1], n[:, 1] ** 2], axis=1)


#: XLA's CPU compiler rewrites a reduction over an axis longer than this into a windowed reduction (a pairwise-like
#: summation), an operation of its own that fuses with nothing around it and costs about half a microsecond to launch,
#: more than it computes here. Reductions over axes of at most this length stay inside the fusion of what they reduce
#: (`_reduce`).
_FUSED_AXIS = 32
_COMBINE = {jnp.sum: jnp.add, jnp.min: jnp.minimum, jnp.max: jnp.maximum, jnp.all: jnp.logical_and}


def _reduce(op, x, fill):
    """`op` (``jnp.sum``, ``jnp.min``, ``jnp.max`` or ``jnp.all``) over the last axis of x: its slices of
    `_FUSED_AXIS` combined elementwise (the axis padded with `fill`, the identity of `op`), then one reduction over
    `_FUSED_AXIS`. Written as a reshape and a reduction over two axes instead, XLA folds it back into one long one."""
    n = x.shape[-1]
    if n <= _FUSED_AXIS:
        return op(x, axis=-1)
    m = -(-n // _FUSED_AXIS)
    pad = m * _FUSED_AXIS - n
    if pad:
        x = jnp.concatenate([x, jnp.full((*x.shape[:-1], pad), fill, dtype=x.dtype)], axis=-1)
    combine = _COMBINE[op]
    acc = x[..., :_FUSED_AXIS]
    for i in range(1, m):
        acc = combine(acc, x[..., i * _FUSED_AXIS : (i + 1) * _FUSED_AXIS])
    return op(acc, axis=-1)


def _sum(x):
    """Σ over the last axis (`_reduce`)."""
    return _reduce(jnp.sum, x, 0)


class ContactSystem(eqx.Module):
    """The contacts of one configuration (one input angle), linear in the small displacements q (n coordinates, mm).

    - `G`, `e`, `k`: unilateral contacts: penetration `G @ q + e` (m × n, mm), stiffness (m,; 0 leaves a contact out).
    - `B`, `eb`, `c`, `kb`: bearings: relative displacement `B @ q + eb` (b × 2 × n, mm), clearance (b,, mm ≥ 0),
      stiffness (b,).
    - `f`: the generalised load (n,), in units of stiffness × mm.
    - `mu`: the regularisation of floating parts (units of stiffness).
    - `faces`: faces of every bearing's clearance polygon (static; default `BEARING_FACES`).
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
    faces: int = eqx.field(static=True, default=BEARING_FACES)


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


def _normals(dtype, faces: int):
    return jnp.asarray(face_normals(faces), dtype=dtype)


def _along_normals(r, faces: int):
    """n_f · r for every face f of every bearing (… × M) from plane vectors r (… × 2): written as a product and a
    sum rather than a matrix product with the normals, so that XLA fuses it with what uses it (on the CPU a separate
    small matrix product costs more to launch than its arithmetic)."""
    N = _normals(r.dtype, faces)
    return r[..., 0:1] * N[:, 0] + r[..., 1:2] * N[:, 1]


def _bearing_local(s: ContactSystem, r):
    """Energy (b,) and force vector (b × 2) of every bearing at relative displacement r (its stiffness: `_hessian`)."""
    N = _normals(r.dtype, s.faces)
    P = _along_normals(r, s.faces) - s.c[:, None]  # face penetrations (b × M)
    pos = jnp.maximum(P, 0.0)
    poly = s.c > 0
    energy = 0.5 * s.kb * jnp.where(poly, _sum(pos * pos), jnp.sum(r * r, axis=-1))
    summed = jnp.stack([_sum(pos * N[:, 0]), _sum(pos * N[:, 1])], axis=-1)  # Σ_f pos_f n_f
    force = s.kb[:, None] * jnp.where(poly[:, None], summed, r)
    return energy, force


def _rows(s: ContactSystem) -> Float[Array, "r n"]:
    """Every row of the system ((m + 2b) × n): the unilateral contacts, then every bearing's x row, then its y row."""
    return jnp.concatenate([s.G, s.B[:, 0, :], s.B[:, 1, :]])


def _values(s: ContactSystem, q, rows=None):
    """The value of every row at q, rows q + offsets (m + 2b): the contacts' penetrations, then the bearings' relative
    displacements, x then y. The Newton iteration carries them from one iteration to the next (computed from q)."""
    rows = _rows(s) if rows is None else rows
    return rows @ q + _offsets(s)


def _offsets(s: ContactSystem):
    """Every row's offset (m + 2b): the contacts' equivalent errors, then the bearings' x and y errors."""
    return jnp.concatenate([s.e, s.eb[:, 0], s.eb[:, 1]])


def _split(s: ContactSystem, v):
    """Row values `v` (`_values`) as the contacts' penetrations (m,) and the bearings' displacements (b × 2)."""
    m, b = s.e.shape[0], s.c.shape[0]
    return v[:m], jnp.stack([v[m : m + b], v[m + b :]], axis=-1)


def _energy(s: ContactSystem, v):
    """The contacts' and bearings' energy at row values `v` (Φ without the regularisation and the load)."""
    p, r = _split(s, v)
    pos = jnp.maximum(p, 0.0)
    energy, _ = _bearing_local(s, r)
    return 0.5 * _sum(s.k * pos * pos) + jnp.sum(energy)


def _row_forces(s: ContactSystem, v):
    """The force along every row at row values `v` (`_gradient`)."""
    p, r = _split(s, v)
    _, force = _bearing_local(s, r)
    return jnp.concatenate([s.k * jnp.maximum(p, 0.0), force[:, 0], force[:, 1]])


def _gradient(s: ContactSystem, q, v, rows_t):
    """∇Φ = rowsᵀ (row forces) + μ q − f at q, its row values `v` (`_values`) and the rows transposed `rows_t`."""
    return rows_t @ _row_forces(s, v) + s.mu * q - s.f


def potential(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, ""]:
    """Φ(q) (module notes)."""
    return _energy(s, _values(s, q)) + 0.5 * s.mu * jnp.dot(q, q) - jnp.dot(s.f, q)


def gradient(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, " n"]:
    """∇Φ(q): generalised-force residual."""
    rows = _rows(s)
    return _gradient(s, q, _values(s, q, rows), rows.T)


def hessian(s: ContactSystem, q: Float[Array, " n"]) -> Float[Array, "n n"]:
    """The (generalised) Hessian of Φ at q: closed contacts only (right derivative on a contact's boundary)."""
    return _hessian(s, _active(s, q), q.dtype)


def _hessian(s: ContactSystem, active: tuple[Array, Array], dtype, rows_t=None) -> Float[Array, "n n"]:
    """The Hessian for the closed contacts and bearing faces `active` (`_active`): every row of the contacts and the
    bearings with its stiffness applied, in one product, ``rowsᵀ (K rows)`` (a bearing's 2 × 2 stiffness written out;
    ``Σ_f n_f n_fᵀ`` over its closed faces summed with `_face_outer`). `rows_t`: `_rows` transposed, if already built."""
    closed, faces = active
    n = s.G.shape[1]
    poly = s.c > 0
    outer = jnp.asarray(_face_outer(s.faces), dtype=dtype)
    closed_faces = faces.astype(dtype)
    kxx = s.kb * jnp.where(poly, _sum(closed_faces * outer[:, 0]), 1.0)
    kxy = s.kb * jnp.where(poly, _sum(closed_faces * outer[:, 1]), 0.0)
    kyy = s.kb * jnp.where(poly, _sum(closed_faces * outer[:, 2]), 1.0)
    bx, by = s.B[:, 0, :], s.B[:, 1, :]
    if rows_t is None:
        rows_t = _rows(s).T
    stiff = jnp.concatenate(
        [(s.k * closed.astype(dtype))[:, None] * s.G, kxx[:, None] * bx + kxy[:, None] * by, kxy[:, None] * bx + kyy[:, None] * by]
    )
    return rows_t @ stiff + s.mu * jnp.eye(n, dtype=dtype)


def _line_search(s: ContactSystem, q, dq):
    """The step t > 0 that minimises Φ(q + t dq) (`_search`)."""
    rows = _rows(s)
    return _search(s, q, dq, _values(s, q, rows), rows @ dq)


def _search(s: ContactSystem, q, dq, v, u):
    """The step t > 0 that minimises Φ(q + t dq), exactly, from the row values at q, `v`, and their change along dq,
    `u` (`_values`): φ′(t) is piecewise linear and increasing, with a kink wherever a unilateral contact or a bearing
    face opens or closes. From its start (see below) the walk takes the root of φ′ on the piece it stands on if that
    root lies before the next kink, or moves to that kink; each step crosses one kink (a contact that closes usually
    stops the walk at once). Out of steps: the last kink reached (φ decreases up to it)."""
    N = _normals(q.dtype, s.faces)
    poly = s.c > 0
    kb = jnp.where(poly, s.kb, 0.0)
    ks = jnp.where(poly, 0.0, s.kb)
    (p0, r0), (pb, rb) = _split(s, v), _split(s, u)
    # Every row as one piece a + t b with stiffness w: the unilateral contacts, then the faces of every bearing.
    a = jnp.concatenate([p0, jnp.ravel(_along_normals(r0, s.faces) - s.c[:, None])])
    b = jnp.concatenate([pb, jnp.ravel(_along_normals(rb, s.faces))])
    w = jnp.concatenate([s.k, jnp.ravel(jnp.broadcast_to(kb[:, None], (kb.shape[0], N.shape[0])))])
    # The smooth part: regularisation, load and the bearings without clearance (plain springs).
    lin0 = s.mu * jnp.dot(q, dq) - jnp.dot(s.f, dq) + jnp.sum(ks * jnp.sum(r0 * rb, axis=-1))
    lin1 = s.mu * jnp.dot(dq, dq) + jnp.sum(ks * jnp.sum(rb * rb, axis=-1))
    crossing = (w > 0) & (b != 0)
    kink = jnp.where(crossing, -a / jnp.where(b != 0, b, 1.0), jnp.inf)
    zero = jnp.zeros((), dtype=q.dtype)

    def walk(start):
        def cond(state):
            _, k, done, _ = state
            return (~done) & (k < LINE_SEARCH_STEPS)

        def body(state):
            t, k, _, _ = state
            nxt = _reduce(jnp.min, jnp.where(kink > t, kink, jnp.inf), jnp.inf)
            mid = jnp.where(jnp.isfinite(nxt), 0.5 * (t + nxt), t + 1.0)
            p = a + t * b
            d1 = _sum(w * jnp.maximum(p, 0.0) * b) + lin0 + t * lin1
            slope = _sum(jnp.where(a + mid * b > 0, w * b * b, 0.0)) + lin1
            root = t - d1 / slope
            done = root <= nxt
            behind = (k == 0) & (t > 0) & (d1 > 0)  # φ already rises at the start: the root lies before it
            return jnp.where(done, root, nxt), k + 1, done, behind

        t, _, _, behind = jax.lax.while_loop(cond, body, (start, jnp.asarray(0), jnp.asarray(False), jnp.asarray(False)))
        return t, behind  # out of steps: t is the last kink reached, where φ is still decreasing

    # The search runs where the full step failed: a contact changes state before t = 1, and the Newton direction is
    # the minimum of the piece before it. So the walk starts at the first kink (or 1): the same root as from t = 0,
    # one step sooner (0.7 µs of 6 per search); where φ′ > 0 there already (the start's own contact state differs
    # from the Hessian's), it walks again from 0.
    t, behind = walk(jnp.minimum(_reduce(jnp.min, jnp.where(kink > 0, kink, jnp.inf), jnp.inf), 1.0))
    return jax.lax.cond(behind, lambda: walk(zero)[0], lambda: t)


def _rounding_floor(s: ContactSystem, q, abs_rows=None):
    """The rounding level of the force residual at q: eps × the largest magnitude it is computed from (the load, the
    contact terms k (|G||q| + |e|), the bearing terms). `abs_rows`: |`_rows`|, if already built."""
    abs_rows = jnp.abs(_rows(s)) if abs_rows is None else abs_rows
    p, r = _split(s, abs_rows @ jnp.abs(q) + jnp.abs(_offsets(s)))
    unilateral = jnp.maximum(_reduce(jnp.max, s.k * p, 0.0), 0.0)
    bearing = jnp.max(s.kb * jnp.max(r, axis=-1) + s.kb * s.c, initial=0.0)
    scale = jnp.maximum(jnp.max(jnp.abs(s.f)), jnp.maximum(unilateral, bearing))
    return ROUNDING_FACTOR * jnp.finfo(q.dtype).eps * scale


def _active(s: ContactSystem, q):
    """Which unilateral contacts and bearing faces are closed at q."""
    return _closed(s, _values(s, q))


def _closed(s: ContactSystem, v):
    """Which unilateral contacts and bearing faces are closed at row values `v` (`_values`)."""
    p, r = _split(s, v)
    faces = (_along_normals(r, s.faces) - s.c[:, None] > 0.0) & (s.c > 0)[:, None]  # a bearing without clearance has none
    return p > 0.0, faces


def _newton(s: ContactSystem, q0):
    """Newton iterations from q0. Stops when the full Newton step was taken and no contact changed state on it (the
    quadratic model was exact there: the step landed on the minimum), or when the residual is at rounding level, or
    within `STALLED_FLOORS` of it where the step moved q by rounding only.

    **Returns:** the solution q, whether it converged, the iterations, ∇Φ(q), and the lower Cholesky factor of the
    Hessian at q (that of the last iteration where the closed contacts did not change on its step, as they usually
    do not on the last one; else factored again)."""

    def cond(state):
        i, done = state[5], state[8]
        return (~done) & (i < MAX_STEPS)

    # The rows, once per solve, and transposed. Left to `_hessian`, XLA hoists the rows out of the loop untransposed
    # and its product with them was the slowest operation of an iteration in a profile; this way the 16 units at 360
    # angles of docs/rv.md take 0.164 s per unit instead of 0.177.
    rows = _rows(s)
    rows_t, abs_rows = rows.T, jnp.abs(rows)

    def energy(q, v):
        return _energy(s, v) + 0.5 * s.mu * jnp.dot(q, q) - jnp.dot(s.f, q)

    def body(state):
        q, v, phi, g, act, i, _, _, _ = state
        L = jnp.linalg.cholesky(_hessian(s, act, q.dtype, rows_t))
        dq = -jax.scipy.linalg.cho_solve((L, True), g)
        u = rows @ dq  # every row's change along the step (the rows are linear in q)
        # The full step where it decreases Φ enough (Armijo): the whole set of closed contacts may change at once.
        phi_full = energy(q + dq, v + u)
        full = phi_full <= phi + ARMIJO * jnp.dot(g, dq)

        def searched():
            t = _search(s, q, dq, v, u)
            return t, energy(q + t * dq, v + t * u)

        t, phin = jax.lax.cond(full, lambda: (jnp.ones((), dtype=q.dtype), phi_full), searched)
        qn = q + t * dq
        # The rows' values at the new point from q itself, not moved by t u: carried along the steps they drift from
        # rows q + offsets by rounding, and the residual computed from them can then stall above its rounding floor
        # (a unit of the tolerance study ran its 1,000 iterations at 3× the floor; from q it ends in 22).
        vn = _values(s, qn, rows)
        gn = _gradient(s, qn, vn, rows_t)
        actn = _closed(s, vn)
        same = _reduce(jnp.all, act[0] == actn[0], True) & jnp.all(_reduce(jnp.all, act[1] == actn[1], True))
        residual, floor = jnp.max(jnp.abs(gn)), _rounding_floor(s, qn, abs_rows)
        creeping = jnp.max(jnp.abs(qn - q)) <= 4 * jnp.finfo(q.dtype).eps * jnp.max(jnp.abs(qn))
        done = ((t == 1.0) & same) | (residual <= floor) | (creeping & (residual <= STALLED_FLOORS * floor))
        return qn, vn, phin, gn, actn, i + 1, L, same, done

    # Carried from one iteration to the next: q and the values of the rows there, Φ, ∇Φ and the closed contacts at q
    # (the Hessian is theirs), and the last factor with whether it is the Hessian's at q.
    v0 = _values(s, q0, rows)
    g0 = _gradient(s, q0, v0, rows_t)
    done0 = jnp.max(jnp.abs(g0)) <= _rounding_floor(s, q0, abs_rows)
    n = q0.shape[0]
    no_factor = jnp.zeros((n, n), dtype=q0.dtype)
    state = (q0, v0, energy(q0, v0), g0, _closed(s, v0), jnp.asarray(0), no_factor, jnp.asarray(False), done0)
    q, _, _, g, act, steps, L, fresh, ok = jax.lax.while_loop(cond, body, state)
    L = jax.lax.cond(fresh, lambda: L, lambda: jnp.linalg.cholesky(_hessian(s, act, q.dtype, rows_t)))
    return q, ok, steps, g, L


def _settled(s: ContactSystem, q0):
    """`_newton` from q0, then what the solution needs from its Hessian H (for the contacts closed there), one matrix
    at a time with LAPACK: the lower Cholesky factor of H; one Newton step with H held, q = q* − H⁻¹ ∇Φ(q*) (the
    value of the implicit-function step of `solve`); and the rigid limit q − H⁻¹ f_load, f_load = f − μ q0 (the load
    without the regularisation's pull to the start)."""
    q_star, ok, steps, g, low = _newton(s, q0)
    q = q_star - jax.scipy.linalg.cho_solve((low, True), g)
    q_rigid = q - jax.scipy.linalg.cho_solve((low, True), s.f - s.mu * q0)
    return q_star, q, q_rigid, low, ok, steps


#: `_settled`, one solve after another under `vmap` (`jax.custom_batching.sequential_vmap`): a batched while loop
#: would run every solve of a batch for as many iterations as its slowest one, and one matrix at a time LAPACK is
#: safe (see `gearte.core.linalg`). Its inputs carry no derivative (`_held` gives the implicit one), so it needs no
#: derivative rule of its own. Jitted: the batching rule and the shape evaluation call it again, and a jitted
#: function is traced once.
_settled_each = jax.custom_batching.sequential_vmap(eqx.filter_jit(_settled))


@jax.custom_jvp
def _held(s: ContactSystem, q_star, low, start, value, rigid):
    """`value` and `rigid` (the solve's q and rigid limit, computed by `_settled`) as functions of the system `s`:
    their derivatives are those of one Newton step from q* with the Hessian held (the implicit-function theorem),
    −H⁻¹ ∂(∇Φ)/∂s, and for the rigid limit also −H⁻¹ ∂f_load/∂s."""
    del s, q_star, low, start
    return value, rigid


@_held.defjvp
def _held_jvp(primals, tangents):
    s, q_star, low, start, value, rigid = primals
    ds = tangents[0]
    _, dg = jax.jvp(lambda t: gradient(t, q_star), (s,), (ds,))
    # Batched over samples and angles under `vmap`: gearte.core.linalg, not LAPACK, whose batched kernels can hang
    # a run on several CPU devices (see that module).
    dq = -linalg.cho_solve(low, dg[:, None])[:, 0]
    dr = dq - linalg.cho_solve(low, (ds.f - ds.mu * start)[:, None])[:, 0]
    return (value, rigid), (dq, dr)


def solve(s: ContactSystem, q0: Float[Array, " n"] | None = None) -> Equilibrium:
    """Minimise the contact potential of `s` (see the module notes); differentiable by the implicit-function theorem.

    `q0`: the starting point (default: the nominal position, zero); a neighbouring solution makes a good one.

    **Returns:** an `Equilibrium` (its `result` is `RESULTS.successful` or `RESULTS.nonlinear_max_steps_reached`).
    """
    start = jnp.zeros_like(s.f) if q0 is None else jax.lax.stop_gradient(q0)
    # The regularisation is proximal to the start: ½ μ |q − q0|² (a load μ q0 added), so a part that floats keeps its
    # position instead of being sent back to nominal across every contact in its way.
    s = eqx.tree_at(lambda t: t.f, s, s.f + s.mu * start)
    q_star, q, q_rigid, low, ok, steps = _settled_each(jax.tree.map(jax.lax.stop_gradient, s), start)
    # One Newton step with the Hessian held: the value stays, the derivative is the implicit one.
    q, q_rigid = _held(s, q_star, low, start, q, q_rigid)
    p, r = _split(s, _values(s, q))
    force = s.k * jnp.maximum(p, 0.0)
    _, bf = _bearing_local(s, r)
    b2 = jnp.sum(bf * bf, axis=-1)
    bforce = jnp.where(b2 > 0, jnp.sqrt(jnp.where(b2 > 0, b2, 1.0)), 0.0)
    result = RESULTS.where(ok, RESULTS.successful, RESULTS.nonlinear_max_steps_reached)  # pyright: ignore[reportArgumentType]
    return Equilibrium(q, q_rigid, force, bforce, result, steps)


__all__ = (
    "BEARING_FACES",
    "MAX_BEARING_FACES",
    "ContactSystem",
    "Equilibrium",
    "face_normals",
    "gradient",
    "hessian",
    "potential",
    "solve",
)
