"""Tooth micro-modifications of a helical planetary stage, as a displacement excitation along the contact normal.

Zhang, Chen & Wang turn the profile and lead modifications into the component h of the flank's
departure from the involute helicoid along the line of action, and subtract it from the mesh
deflection (their eqs. 6-8, 11): δ̃ = δ − h. Here h is evaluated per tooth pair in contact and per
slice across the face width (`gearte.drives.helical_stiffness`), so that crowning shifts the load
between slices (a load distribution), and profile relief unloads a pair as it enters and leaves
contact:

- lead crowning, parabolic about mid face: h = C_β (2 z / b)², z from mid face;
- profile tip relief from `length` before the tip to the tip: h = C_a ((u − u_start)/L)^e, linear
  (e = 1) or parabolic (e = 2), u the position along the path of contact; by default L is the
  length from the single/double-contact boundary to the tip, g_α − p_bt (the paper's choice);
- root relief alike, at the other end of the path.

Amounts are in µm along the contact normal (ISO 21771 transverse values × cos β_b), lengths in mm
along the transverse path of contact.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ..core.validate import check_array_values

SHAPES = {"linear": 1, "parabolic": 2}


def _amount(name: str, value) -> Array:
    check_array_values(name, value, nonnegative=False, unit="µm")
    return jnp.asarray(value, dtype=float)


def _length(name: str, value) -> Array:
    if value is None:
        return jnp.asarray(jnp.nan)
    check_array_values(name, value, nonnegative=True, unit="mm")
    if not isinstance(value, jnp.ndarray) and not float(value) > 0:
        raise ValueError(f"{name}: a relief length must be > 0 mm (or None for the single/double-contact boundary), got {value!r}")
    return jnp.asarray(value, dtype=float)


class ToothModification(eqx.Module):
    """The modification of one flank of one gear.

    **Arguments:**

    - `tip_relief`: C_a, µm at the tip; `tip_relief_length`: mm along the path of contact (None: from
      the single/double-contact boundary to the tip, g_α − p_bt of the mesh).
    - `root_relief`, `root_relief_length`: the same at the root.
    - `crowning`: lead crowning C_β, µm at each end of the face (parabolic about mid face).
    - `shape`: "linear" or "parabolic" profile relief.
    """

    tip_relief: Float[Array, ""]
    tip_relief_length: Float[Array, ""]
    root_relief: Float[Array, ""]
    root_relief_length: Float[Array, ""]
    crowning: Float[Array, ""]
    exponent: int = eqx.field(static=True)

    def __init__(
        self,
        tip_relief: ArrayLike = 0.0,
        *,
        tip_relief_length: float | None = None,
        root_relief: ArrayLike = 0.0,
        root_relief_length: float | None = None,
        crowning: ArrayLike = 0.0,
        shape: str = "linear",
    ):
        if shape not in SHAPES:
            raise ValueError(f"ToothModification.shape: one of {sorted(SHAPES)}, got {shape!r}")
        self.tip_relief = _amount("ToothModification.tip_relief", tip_relief)
        self.root_relief = _amount("ToothModification.root_relief", root_relief)
        self.crowning = _amount("ToothModification.crowning", crowning)
        self.tip_relief_length = _length("ToothModification.tip_relief_length", tip_relief_length)
        self.root_relief_length = _length("ToothModification.root_relief_length", root_relief_length)
        self.exponent = SHAPES[shape]


class StageModifications(eqx.Module):
    """Modifications of every gear flank of the stage: `sun`, the planet's flank facing the sun
    (`planet_sun_flank`) and facing the ring (`planet_ring_flank`), and the `ring`. Every planet
    carries the same modification."""

    sun: ToothModification
    planet_sun_flank: ToothModification
    planet_ring_flank: ToothModification
    ring: ToothModification

    def __init__(
        self,
        *,
        sun: ToothModification | None = None,
        planet_sun_flank: ToothModification | None = None,
        planet_ring_flank: ToothModification | None = None,
        ring: ToothModification | None = None,
    ):
        given = {"sun": sun, "planet_sun_flank": planet_sun_flank, "planet_ring_flank": planet_ring_flank, "ring": ring}
        for name, m in given.items():
            if m is not None and not isinstance(m, ToothModification):
                raise ValueError(
                    f"StageModifications.{name}: expected a ToothModification (e.g. ToothModification(tip_relief=10.0, "
                    f"crowning=5.0), µm) or None for none, got {m!r}"
                )
        self.sun = sun if sun is not None else ToothModification()
        self.planet_sun_flank = planet_sun_flank if planet_sun_flank is not None else ToothModification()
        self.planet_ring_flank = planet_ring_flank if planet_ring_flank is not None else ToothModification()
        self.ring = ring if ring is not None else ToothModification()


def modifications_from_amounts(amounts: Float[Array, " 4"], *, shape: str = "linear") -> StageModifications:
    """The modifications of Zhang, Chen & Wang's study from the design variables x = (x₁, x₂, x₃, x₄), µm:
    sun tip relief x₁ and crowning x₂, planet tip relief x₃ and crowning x₄ (on both planet flanks);
    relief from the single/double-contact boundary to the tip. Traceable (for `jax.grad` and `jax.vmap`)."""
    x = jnp.asarray(amounts, dtype=float)
    if x.shape != (4,):
        raise ValueError(
            f"modifications_from_amounts: amounts must have shape (4,) (sun profile, sun lead, planet profile, planet lead, µm), got {x.shape}"
        )
    sun = ToothModification(x[0], crowning=x[1], shape=shape)
    planet = ToothModification(x[2], crowning=x[3], shape=shape)
    return StageModifications(sun=sun, planet_sun_flank=planet, planet_ring_flank=planet)


def flank_pair_relief(first: ToothModification, last: ToothModification, u, path_length, base_pitch):
    """Profile modification (µm) of a tooth pair at position `u` (mm) on a path of contact of length
    `path_length` that starts at the tip of gear `first` and ends at the tip of gear `last` (`PathRelief` of one mesh)."""
    u = jnp.asarray(u, dtype=float)
    return PathRelief([(first, last)], jnp.reshape(jnp.asarray(path_length, dtype=float), (1,)), base_pitch)(u[None], path_length)[0]


class PathRelief(eqx.Module):
    """The four profile reliefs of the pairs of each of M meshes (`flank_pair_relief`) as arrays, for evaluating all
    meshes at once: term t of mesh m removes `amount[m, t]` µm at its end of the path, falling over `length[m, t]` mm
    as ((L − d)/L)^e, e = 1 + `square[m, t]`; terms 0 and 1 (the first gear's tip, the last gear's root) are measured
    from the start of the path, terms 2 and 3 (the last gear's tip, the first gear's root) from its end."""

    amount: Float[Array, "m 4"]
    length: Float[Array, "m 4"]
    inverse_length: Float[Array, "m 4"]
    square: Float[Array, "m 4"]

    def __init__(self, flanks, path_length, base_pitch):
        """`flanks`: a (first, last) pair of `ToothModification`s per mesh; `path_length` (M,), mm; `base_pitch`, mm."""
        amount, length, square = [], [], []
        for (first, last), g in zip(flanks, path_length, strict=True):
            default = jnp.maximum(g - base_pitch, 1e-3 * base_pitch)
            terms = (
                (first.tip_relief, first.tip_relief_length, first.exponent),
                (last.root_relief, last.root_relief_length, last.exponent),
                (last.tip_relief, last.tip_relief_length, last.exponent),
                (first.root_relief, first.root_relief_length, first.exponent),
            )
            amount.append(jnp.stack([jnp.asarray(a, dtype=float) for a, _, _ in terms]))
            length.append(jnp.stack([jnp.where(jnp.isnan(n), default, n) for _, n, _ in terms]))
            square.append(jnp.asarray([float(e - 1) for _, _, e in terms]))
        self.amount, self.length, self.square = jnp.stack(amount), jnp.stack(length), jnp.stack(square)
        self.inverse_length = 1.0 / self.length

    def __call__(self, u, path_length) -> Float[Array, "m ..."]:
        """Relief (µm) of pairs at positions `u` (M, …) mm on paths of contact of length `path_length` (M,)."""
        shape = (u.shape[0],) + (1,) * (u.ndim - 1)
        path_length = jnp.broadcast_to(jnp.asarray(path_length, dtype=float), (u.shape[0],))
        g = jnp.reshape(path_length, shape)
        forms, amounts = [], []
        for term, d in enumerate((u, u, g - u, g - u)):
            col = [jnp.reshape(a[:, term], shape) for a in (self.amount, self.length, self.inverse_length, self.square)]
            amount, length, inverse, square = col
            t = jnp.maximum(length - d, 0.0) * inverse
            forms.append(t * (1.0 + square * (t - 1.0)))
            amounts.append(amount)
        # Kept once computed: in a gradient through an ODE solve, XLA otherwise recomputes these shapes (from τ through
        # the pair positions) inside every fused kernel that sums the amounts' gradient (docs/helical.md).
        forms = jax.lax.optimization_barrier(forms)
        out = jnp.zeros_like(u)
        for a, f in zip(amounts, forms, strict=True):
            out = out + a * f
        return out


def crowning(first: ToothModification, last: ToothModification, z, face_width):
    """Lead crowning (µm) of the pair at axial position `z` (mm from mid face) for face width `face_width` (mm)."""
    return (first.crowning + last.crowning) * (2.0 * z / face_width) ** 2


def recommended_tip_relief(*, mesh_stiffness: float, face_width: float, tangential_force: float, lead_mismatch: float = 0.0) -> float:
    """A starting value for the tip relief, µm: the mesh deflection under load plus the lead mismatch,
    C_a ≈ F_m/(c_γ b) + F_βy (Niemann's rule, the form of Zhang, Chen & Wang's eq. 19).

    **Arguments:** `mesh_stiffness` c_γ, N/(mm·µm); `face_width` b, mm; `tangential_force` F_m, N;
    `lead_mismatch` F_βy, µm.
    """
    for n, v in (("mesh_stiffness", mesh_stiffness), ("face_width", face_width), ("tangential_force", tangential_force)):
        if not (math.isfinite(v) and v > 0):
            raise ValueError(f"recommended_tip_relief: {n} must be > 0, got {v!r}")
    return tangential_force / (mesh_stiffness * face_width) + lead_mismatch
