"""Cycloid-pin reducer: the disc floating in its turning-arm bearing, at the minimum of the contact potential.

Yao & Liang (2001) hold the disc centre at a fixed offset Δ_1 at α_1 from the eccentric (the turning-arm
bearing's clearance) and the pin-wheel centre at Δ_2 at α_2; `gearte.drives.cycloid_pin` follows them, and over
part of a revolution that rigid, fixed-offset disc interferes (negative lost motion). A real disc is free within
its bearing clearance and settles where the pins let it. This module solves that floating disc with the
equilibrium model of the RV reducer (`gearte.drives.rv_khv_equilibrium`, Hidaka et al. 1994): one disc (x, y, θ)
on the eccentric through a bearing of radial clearance c (a dead zone, the 64-gon tangent to the circle of radius
c), every pin a unilateral spring on its own flank (`gearte.drives.rv_khv_contacts.single_disc_system`), under a
small torque in one direction and then the other, in the rigid limit (the elastic part removed exactly for the
closed contacts, so nothing depends on the load or the stiffnesses while the disc fits between the pins).

**The errors.** The pin contacts (`pin_contacts`) come from the cycloid model's pin layout and clearance analysis
and so carry every error of the disc's grinding and of the reducer: the pin-circle and pin radii, the per-pin
positions, the crank eccentricity ΔA′, the pin-circle eccentricity, and the pin-wheel offset Δ_2 at α_2, which
`pin_layout` adds to the pin-wheel centre: the pin wheel stays where the fixed-offset model puts it (its input
shaft bearings are not part of this model). The disc offset Δ_1 at α_1 is *replaced* by the free disc centre: the
contacts are written with Δ_1 = 0 (the disc's nominal centre on the eccentric) and the centre may move anywhere
within the clearance circle, of radius `clearance_um` (default: the given Δ_1, as `floating_disc` searches). The
fixed-offset disc is then one of the positions the floating disc may take.

**What the floating disc can do that the fixed one cannot.** Under a forward torque the rigid-limit disc turns as
far forward as the pins and the bearing let it: its rotation is θ_F = max over the centres u in the clearance of
the forward rotation at u (among the positions where the disc fits between the pins), and under a reverse torque
θ_R = min over u of the reverse rotation. For any single centre u where the disc fits, the fixed-offset lost
motion LM(u) = θ_fwd(u) − θ_rev(u) ≥ 0 and θ_F ≥ θ_fwd(u), θ_R ≤ θ_rev(u), so

    LM_floating = θ_F − θ_R ≥ max over u of LM(u),

the bound `floating_disc`'s search over a finite set of centres gives wherever it finds one that fits (its value
is a lower bound of the floating disc's lost motion; the two centres of the floating disc, forward and reverse,
may differ). Where no centre fits, the disc is jammed: the contacts stay closed at zero load, the rigid limit
is the elastic compromise of the preloaded contacts (it depends on the stiffnesses), the two directions meet
(LM = 0) and `preloaded` marks it.

**Accuracy.** The contacts are exact in the disc's rotation and linear in its translation (each pin's normal taken
through the pitch point, `gearte.drives.rv_khv_contacts`); the 64-gon lies outside the circle by at most
1.2e-3 c. A pin at the bottom of a tooth space has no lever arm, and its equivalent error −l Δθ would lose its gap:
there (|l| < `LEVER_FLOOR`, or l of the sign of the other flank) the gap is the pin's normal clearance at the
disc's theoretical position. Against the exact optimum over centres (the cycloid model's contacts with the disc
held at 8 rings × 180 directions of centres within the clearance, every fourth angle of the examples' grid), the
floating rotations of Yao & Liang's reducers (clearance 57.5 µm, modified and unmodified) are within 7.3e-6 rad
(1.5″) of it, against lost motions of 3–28′. The torque is a pure couple on the disc: the output mechanism (pins in
the disc's holes) is not modelled.

Loaded pairs are the pins that carry force under the small load (force above `FORCE_FLOOR` of the load's scale):
pins in contact in the rigid limit, with no deformation budget (unlike the cycloid model's loaded pairs, which
count the pins within 0.2 mm of contact).

Units: µm for the clearance and the centre, rad for the rotations; mm inside the solve.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.solution import RESULTS
from ..core.units import MM_PER_UM, TWO_PI
from ..core.validate import as_float
from .cycloid_pin_contact import normal_clearance, pin_layout
from .cycloid_pin_geometry import CycloidErrors, checked_errors
from .rv_khv_contacts import single_disc_system
from .rv_khv_equilibrium import solve

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin

#: A pin whose lever arm about the disc centre is below this sits at the bottom of its tooth space, mm.
LEVER_FLOOR = 1.0
#: The small load of every solve: the disc's rotation it would cause on one pin at the pin circle, mm.
DEFLECTION_MM = 1e-7
#: A pin carries load where its force exceeds this fraction of the load (stiffness × `DEFLECTION_MM`).
FORCE_FLOOR = 1e-6
#: A contact that still penetrates by more than this in the rigid limit is preloaded: the disc is jammed, mm.
PRELOAD_MM = 1e-9


class FloatingEquilibrium(eqx.Module):
    """The floating disc at every input angle of a grid, under a forward and a reverse load (first axis: [+, −]).

    - `input_angle`: θ_T (p,), rad.
    - `rotation_error`: the disc's rotation from its theoretical position (2 × p), rad, in the rigid limit.
    - `lost_motion`: forward − reverse (p,), rad (≥ 0).
    - `centre`: the disc centre from the eccentric, in the converted frame (2 × p × 2), µm, rigid limit.
    - `force`: every pin's force under the small load (2 × p × z_b; units of stiffness × mm).
    - `loaded_pairs`: pins carrying load (2 × p).
    - `preloaded`: a contact still penetrates in the rigid limit: no centre within the clearance lets the disc
      fit between the pins (2 × p).
    - `result`: the solve's `RESULTS` (2 × p); `steps`: its Newton iterations (2 × p).
    - `clearance`: the radial clearance of the disc's bearing, µm.
    """

    input_angle: Float[Array, " p"]
    rotation_error: Float[Array, "2 p"]
    lost_motion: Float[Array, " p"]
    centre: Float[Array, "2 p 2"]
    force: Float[Array, "2 p zb"]
    loaded_pairs: Int[Array, "2 p"]
    preloaded: Bool[Array, "2 p"]
    result: RESULTS
    steps: Int[Array, "2 p"]
    clearance: Float[Array, ""]


def _system(drive: CycloidPin, err: CycloidErrors, theta, clearance_mm, sign):
    """`single_disc_system`, with the gap of a pin at the bottom of a tooth space taken along its normal.

    There the lever arm l vanishes (and its sign, from the pin's actual position, may disagree with the flank the
    cycloid model pairs the pin with), so the equivalent error −l Δθ loses the gap; `normal_clearance` at the disc's
    theoretical position gives it: e = −gap for pins with |l| < `LEVER_FLOOR` or l of the wrong sign."""
    s = single_disc_system(drive, err, theta, clearance_mm=clearance_mm, deflection_mm=DEFLECTION_MM, load_sign=sign)
    lever = s.G[:, 2] * drive.pin_circle_radius
    bottom = (s.k > 0) & ((jnp.abs(lever) < LEVER_FLOOR) | (lever * pin_layout(drive, err, theta).side < 0))
    gap = normal_clearance(drive, err, theta)
    return eqx.tree_at(lambda s: s.e, s, jnp.where(bottom, -gap, s.e))


def _floating(drive: CycloidPin, err: CycloidErrors, thetas, clearance_mm) -> FloatingEquilibrium:
    L = drive.pin_circle_radius
    # The free centre replaces the fixed disc offset; everything else stays in the pin layout.
    zero = jnp.zeros((), dtype=thetas.dtype)
    err0 = eqx.tree_at(lambda e: (e.disc_offset, e.disc_offset_phase), err, (zero, zero))
    # Warm start along the angles in order over the revolution, where the contact states of neighbours are alike.
    order = jnp.argsort(jnp.mod(thetas, TWO_PI))
    back = jnp.argsort(order)

    def direction(sign):
        def step(q0, theta):
            s = _system(drive, err0, theta, clearance_mm, sign)
            eq = solve(s, q0)
            pen = jnp.max(jnp.where(s.k > 0, s.G @ eq.q_rigid + s.e, -jnp.inf))
            return eq.q, (eq.q_rigid, eq.force, pen > PRELOAD_MM, eq.result, eq.steps)

        _, out = jax.lax.scan(step, jnp.zeros(3, dtype=thetas.dtype), thetas[order])
        return jax.tree.map(lambda x: x[back], out)

    q, force, pre, result, steps = jax.vmap(direction)(jnp.asarray([1.0, -1.0]))
    te = q[..., 2] / L
    return FloatingEquilibrium(
        input_angle=thetas,
        rotation_error=te,
        lost_motion=te[0] - te[1],
        centre=q[..., :2] / MM_PER_UM,
        force=force,
        loaded_pairs=jnp.sum(force > FORCE_FLOOR * DEFLECTION_MM, axis=-1),
        preloaded=pre,
        result=result,
        steps=steps,
        clearance=clearance_mm / MM_PER_UM,
    )


@kept_jit
def _floating_jit(drive, err, thetas, clearance_mm):
    return _floating(drive, err, thetas, clearance_mm)


def floating_equilibrium(
    drive: CycloidPin,
    errors: CycloidErrors | Mapping[str, Any] | None = None,
    *,
    clearance_um: ArrayLike | None = None,
    positions: ArrayLike | None = None,
) -> FloatingEquilibrium:
    """The disc floating within its turning-arm bearing's clearance at every input angle, under both loads.

    **Arguments:**

    - `drive`, `errors`: the stage and the reducer's errors (a `CycloidErrors`, a mapping of its fields, or None).
    - `clearance_um`: the radial clearance the disc centre floats in around the eccentric, µm ≥ 0 (default: the
      given disc offset Δ_1, the radius `floating_disc` searches). The fixed offset Δ_1 at α_1 itself is dropped.
    - `positions`: input angles θ_T, rad (default the drive's grid, `drive.input_angles()`).

    One compiled program per drive and grid size: new errors, clearances and angles do not recompile.

    **Returns:** a `FloatingEquilibrium` (see the module notes for the model and what it is exact in).
    """
    require_x64()
    err = checked_errors(drive, errors)
    p = drive.input_angles() if positions is None else jnp.asarray(positions, dtype=float)
    if p.ndim != 1 or p.size == 0:
        raise ValueError(f"positions: give a 1-D array of input angles (rad), got shape {p.shape}")
    if clearance_um is None:
        c = float(jnp.asarray(err.disc_offset))
        if c < 0:
            raise ValueError(f"clearance_um: the default is the disc offset Δ_1 = {c:g} µm, which is negative; give clearance_um ≥ 0")
    else:
        c = as_float("clearance_um", clearance_um, nonnegative=True, hint="the bearing's radial clearance is a length ≥ 0 µm")
    return _floating_jit(drive, err, p, jnp.asarray(c * MM_PER_UM, dtype=float))


__all__ = ("DEFLECTION_MM", "FORCE_FLOOR", "PRELOAD_MM", "FloatingEquilibrium", "floating_equilibrium")
