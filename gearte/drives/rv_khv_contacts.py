"""RV (K-H-V) reducer: the contacts of every part at one input angle, as a `ContactSystem`.

The model and its conventions are set out in `gearte.drives.rv_khv`. This module writes each
contact's line of action and equivalent error (Hidaka et al. 1994, sec. 3) in the fixed frame
centred on the pin ring (x, y; angles CCW from +x), with the 20 coordinates (for 3 cranks and 2
discs) of sun (x, y), cranks (x, y, θ), discs (x, y, θ) and carrier (x, y, θ); rotations are
carried as arcs at the pin-circle radius R so that every coordinate is a length (mm).

**Disc–pin contacts** come from the cycloid-pin geometry (`gearte.drives.cycloid_pin`): in
that model's converted frame (the disc's eccentric along +y) the clearance analysis gives, for
every pin j, the exact disc rotation Δθ_j from its theoretical position at which the pin touches
its own flank with the disc centre on the eccentric. The pin's line of action passes through the
pin centre c_j and the pitch point P = (0, z_c a) (Hidaka et al. 1994, sec. 2.1); with N_j the
unit vector from P to c_j (the disc's outward normal at the contact) and l_j = c_j × N_j its
lever arm about the disc centre, a small disc displacement (u, θ) gives the penetration

    p_j = N_j · u + l_j (θ − Δθ_j),

so the equivalent error is −l_j Δθ_j: exact for a disc that turns about its centre (the cycloid
model's contact), linearised only in the disc's translation. Where the lever arm is short the
contact is not linear in the disc's rotation: near the line of centres a pin meets the flank at a
rotation of second order in its gap (so l_j Δθ_j → 0 at the tooth root however large the gap),
and a pin facing a lobe tip never meets its own flank by turning (Δθ_j = ±∞). Those pins are met
when the disc translates; for them (|l_j| < `SHORT_LEVER` × the largest |l| of the disc, or
Δθ_j infinite) the equivalent error is minus the normal clearance n_j with the disc at its
theoretical position (`normal_clearance`), the gap along the line of action. For the other pins
n_j and l_j Δθ_j agree to first order (within 0.04 µm on the robot-joint example's driving pins).
Only a pin whose normal clearance is not finite is left out.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..core.units import MM_PER_UM
from .cycloid_pin_contact import contact_geometry
from .cycloid_pin_geometry import CycloidErrors
from .rv_khv_equilibrium import ContactSystem

if TYPE_CHECKING:
    from .cycloid_pin import CycloidPin
    from .rv_khv import RVKHV


#: The small load's default elastic deflection scale (mm): the middle of the window where the rigid limit does not depend
#: on it (docs/rv.md, "Size of the small load": on 400 units of the tolerance example, no lost motion below −0.01″ and
#: no failed solve at 1e-10 mm; at 1e-9 mm units whose weak modes the load moves across a change of contact state).
DEFLECTION_MM = 1e-10
#: The default regularisation μ / k_pin per mm of `deflection_mm`: its force μ |q − q₀| is then 1e-3 × |q − q₀| / mm times
#: the load's, whatever the load.
REGULARISATION_PER_MM = 1e-3
#: The small load's deflection scales accepted (mm): the rigid limit holds between about 1e-11 and 1e-8 mm on the
#: examples (docs/rv.md, "Size of the small load"); beyond this range the results are the loaded TE or rounding.
DEFLECTION_RANGE_MM = (1e-13, 1e-5)


def check_deflection(value: float) -> float:
    """`value` (mm) inside `DEFLECTION_RANGE_MM`; ValueError naming ``deflection_mm`` otherwise."""
    lo, hi = DEFLECTION_RANGE_MM
    if not lo <= value <= hi:
        raise ValueError(
            f"deflection_mm: {value:g} mm is outside {lo:g} … {hi:g} mm; the rigid limit needs a small load (default "
            f"{DEFLECTION_MM:g} mm, docs/rv.md, 'Size of the small load')"
        )
    return value


UM = MM_PER_UM
#: Pins with a lever arm shorter than this fraction of the disc's longest take their normal clearance as the gap.
SHORT_LEVER = 0.1


def _dir(angle):
    return jnp.stack([jnp.cos(angle), jnp.sin(angle)], axis=-1)


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def pin_contacts(stage: CycloidPin, errors: CycloidErrors, theta_T) -> tuple[Array, Array, Array, Array]:
    """The pins of one disc in the cycloid model's converted frame at input position θ_T (rad).

    **Returns:** (N (z_p × 2, the disc's outward normals at the contacts), l (z_p, lever arms about the disc centre,
    mm; > 0 on driving flanks), e (z_p, equivalent errors −l Δθ, or minus the normal clearance for a pin on a short
    lever, mm), mask (z_p, 1.0 for a pin that can touch)).
    """
    # One traced program for every disc and every call with the same shapes (a jitted function is traced once
    # and called, where a plain one is traced again at each call: the contact solve is most of an RV unit's
    # program). θ_T as an array: a float would be a static value, one program per angle.
    return _pin_contacts(stage, errors, jnp.asarray(theta_T, dtype=float))


@eqx.filter_jit
def _pin_contacts(stage: CycloidPin, errors: CycloidErrors, theta_T) -> tuple[Array, Array, Array, Array]:
    lay, rotation_to_contact, gap = contact_geometry(stage, errors, theta_T)
    c = lay.centre
    P = jnp.stack([jnp.zeros(()), stage.z_lobes * stage.eccentricity])
    d = c - P
    N = d / jnp.sqrt(jnp.sum(d * d, axis=-1, keepdims=True))
    lever = _cross(c, N)
    turning = jnp.isfinite(rotation_to_contact) & (jnp.abs(lever) >= SHORT_LEVER * jnp.max(jnp.abs(lever)))
    dth = jnp.where(turning, rotation_to_contact, 0.0)
    e = jnp.where(turning, -lever * dth, -gap)
    touch = jnp.isfinite(e)
    return N, lever, jnp.where(touch, e, -1.0), touch.astype(c.dtype)


def single_disc_system(
    stage: CycloidPin, errors: CycloidErrors, theta_T, *, clearance_mm=0.0, deflection_mm=1e-9, load_sign=1.0, mu=1e-12
) -> ContactSystem:
    """Hidaka et al.'s (1994) small illustration: one disc (x, y, θ) on one central crank (a bearing of radial
    clearance `clearance_mm`), against the fixed pins, in the converted frame, under a torque of sign `load_sign`
    (+1: the disc turned CCW, onto the driving flanks). Coordinates: disc x, y (mm) and R θ (mm)."""
    N, lever, e, mask = pin_contacts(stage, errors, theta_T)
    L = stage.pin_circle_radius
    G = jnp.concatenate([N, (lever / L)[:, None]], axis=1)
    B = jnp.asarray([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    return ContactSystem(
        G=G,
        e=e,
        k=mask,
        B=B,
        eb=jnp.zeros((1, 2)),
        c=jnp.reshape(jnp.asarray(clearance_mm, dtype=float), (1,)),
        kb=jnp.ones(1),
        f=jnp.asarray([0.0, 0.0, 1.0]) * (load_sign * deflection_mm),
        mu=jnp.asarray(mu, dtype=float),
    )


def cycloid_errors(drive: RVKHV, err: dict, d: int) -> CycloidErrors:
    """The cycloid-pin errors of disc `d` (its profile, the shared pins) from the RV errors (protocol mapping, checked)."""
    zc = drive.z_pins - 1
    sl = slice(d * zc, (d + 1) * zc)
    pe = err["pin_circle_eccentricity"]
    return CycloidErrors(
        dressing_x=err["disc_dressing_x"][d],
        dressing_y=err["disc_dressing_y"][d],
        infeed=err["disc_infeed"][sl],
        indexing=err["disc_indexing"][sl],
        setup_eccentricity=err["disc_setup"].magnitude[d],
        setup_phase=err["disc_setup"].phase[d],
        mandrel_runout=err["disc_mandrel"].magnitude[d],
        mandrel_phase=err["disc_mandrel"].phase[d],
        pin_circle_radius=err["pin_circle_radius"],
        pin_radius=err["pin_radius"],
        pin_tangential=err["pin_tangential"],
        pin_radial=err["pin_radial"],
        pin_circle_eccentricity=pe.magnitude[0],
        pin_circle_eccentricity_phase=pe.phase[0],
    )


def dof_count(cranks: int, discs: int) -> int:
    """Coordinates of the model: sun 2, cranks 3 each, discs 3 each, carrier 3 (20 for 3 cranks and 2 discs)."""
    return 5 + 3 * (cranks + discs)


def translations(cranks: int, discs: int) -> np.ndarray:
    """The coordinates of every body's translation x (its y is the next one): sun, cranks, discs, carrier."""
    return np.asarray([0] + [2 + 3 * b for b in range(cranks + discs)] + [2 + 3 * (cranks + discs)])


def rv_system(drive: RVKHV, err: dict, theta_out, load_sign) -> ContactSystem:
    """The contacts of the RV reducer at nominal output angle θ_o (rad; input angle i θ_o) under a torque on the
    carrier of sign `load_sign`. `err`: the checked protocol mapping of the drive's error sources."""
    Nc, D, zp = drive.cranks, drive.discs, drive.z_pins
    zc = zp - 1
    n = dof_count(Nc, D)
    L = drive.stage.pin_circle_radius
    a = drive.stage.eccentricity
    rc = drive.crank_circle_radius
    rs = rc * drive.z_sun / (drive.z_sun + drive.z_planet)
    rp = rc - rs
    alpha = drive.pressure_angle
    th_in = drive.ratio * theta_out
    planet_rot = -zc * theta_out
    i_car = 2 + 3 * (Nc + D)
    zeta = math.pi / 2 + theta_out + 2 * math.pi * jnp.arange(Nc, dtype=float) / Nc
    C = rc * _dir(zeta)  # crank centres
    zeros = jnp.zeros(n)

    def body_row(i0, direction, rho):
        return zeros.at[i0].set(direction[0]).at[i0 + 1].set(direction[1]).at[i0 + 2].set(_cross(rho, direction) / L)

    def body_block(i0, rho):
        b = jnp.zeros((2, n))
        return b.at[0, i0].set(1.0).at[1, i0 + 1].set(1.0).at[0, i0 + 2].set(-rho[1] / L).at[1, i0 + 2].set(rho[0] / L)

    rows, es, ks = [], [], []
    # Disc–pin contacts: every disc's in one batched call (disc d's eccentric at η_d = π/2 − z_c θ_o + π d, its input
    # position θ_T = π/2 − η_d). Batched, the cycloid contact solve (unrolled, most of the program) is compiled once
    # instead of once per disc: the example's Monte Carlo and trace programs compile in 13.9 s instead of 17.5 (the
    # same values to rounding).
    etas = [math.pi / 2 - zc * theta_out + math.pi * d for d in range(D)]
    disc_errors = jax.tree.map(lambda *x: jnp.stack(x), *[cycloid_errors(drive, err, d) for d in range(D)])
    theta_T = jnp.stack([math.pi / 2 - eta for eta in etas])
    pins = jax.vmap(lambda e_d, t_d: pin_contacts(drive.stage, e_d, t_d))(disc_errors, theta_T)
    for d, eta in enumerate(etas):
        N, lever, e, mask = (x[d] for x in pins)
        c, s = jnp.cos(eta - math.pi / 2), jnp.sin(eta - math.pi / 2)
        Nf = jnp.stack([c * N[:, 0] - s * N[:, 1], s * N[:, 0] + c * N[:, 1]], axis=-1)
        i0 = 2 + 3 * (Nc + d)
        G = jnp.zeros((zp, n)).at[:, i0].set(Nf[:, 0]).at[:, i0 + 1].set(Nf[:, 1]).at[:, i0 + 2].set(lever / L)
        rows.append(G)
        es.append(e)
        ks.append(drive.pin_stiffness * mask)
    # Sun–planet meshes, both flanks (the sun's rotation is the input, held).
    backlash = jnp.maximum(drive.backlash_mm + err["backlash"] * UM, 0.0)
    se, pe = err["sun_eccentricity"], err["planet_eccentricity"]
    E_sun = se.magnitude[0] * UM * _dir(se.phase[0] + th_in)
    for i in range(Nc):
        ch, th = _dir(zeta[i]), _dir(zeta[i] + math.pi / 2)
        E_pl = pe.magnitude[i] * UM * _dir(pe.phase[i] + err["planet_assembly"][i] + planet_rot)
        for flank in (1.0, -1.0):
            nvec = flank * jnp.cos(alpha) * th + jnp.sin(alpha) * ch
            row = zeros.at[0].set(nvec[0]).at[1].set(nvec[1]) - body_row(2 + 3 * i, nvec, -rp * ch)
            rows.append(row[None, :])
            es.append(jnp.reshape(-0.5 * backlash + jnp.dot(nvec, E_sun) - jnp.dot(nvec, E_pl), (1,)))
            ks.append(jnp.full((1,), drive.mesh_stiffness))
    G = jnp.concatenate(rows, axis=0)
    e = jnp.concatenate(es)
    k = jnp.concatenate(ks)

    # Bearings: crank–disc (each crank in each disc), crank–carrier, carrier main bearing.
    Bs, ebs, cs = [], [], []
    c_cd = jnp.maximum(drive.crank_disc_clearance_mm + err["crank_disc_clearance"] * UM, 0.0)
    c_cc = jnp.maximum(drive.crank_carrier_clearance_mm + err["crank_carrier_clearance"] * UM, 0.0)
    c_m = jnp.maximum(drive.main_bearing_clearance_mm + err["main_bearing_clearance"] * UM, 0.0)
    dh, ch_err = err["disc_hole"], err["carrier_hole"]
    for d in range(D):
        eta = math.pi / 2 - zc * theta_out + math.pi * d
        ed = _dir(eta)
        for i in range(Nc):
            rho_c = a * ed
            B = body_block(2 + 3 * i, rho_c) - body_block(2 + 3 * (Nc + d), C[i])
            j = d * Nc + i
            eb = (
                err["crank_eccentricity"][i] * UM * ed
                + a * err["crank_phase"][i] * _dir(eta + math.pi / 2)
                - dh.magnitude[j] * UM * _dir(dh.phase[j] + zeta[i])
            )
            Bs.append(B)
            ebs.append(eb)
            cs.append(c_cd)
    for i in range(Nc):
        B = body_block(2 + 3 * i, jnp.zeros(2)) - body_block(i_car, C[i])
        Bs.append(B)
        ebs.append(-ch_err.magnitude[i] * UM * _dir(ch_err.phase[i] + zeta[i]))
        cs.append(c_cc)
    Bs.append(body_block(i_car, jnp.zeros(2)))
    ebs.append(jnp.zeros(2))
    cs.append(c_m)
    f = zeros.at[i_car + 2].set(load_sign * drive.deflection_mm * drive.pin_stiffness)
    return ContactSystem(
        G=G,
        e=e,
        k=k,
        B=jnp.stack(Bs),
        eb=jnp.stack(ebs),
        c=jnp.stack(cs),
        kb=jnp.full((len(Bs),), drive.bearing_stiffness),
        f=f,
        mu=jnp.asarray(drive.regularisation * drive.pin_stiffness),
        faces=drive.bearing_faces,
    )


def output_index(drive: RVKHV) -> int:
    """The coordinate of the carrier's rotation (an arc at R, mm)."""
    return 2 + 3 * (drive.cranks + drive.discs) + 2


__all__ = (
    "DEFLECTION_MM",
    "DEFLECTION_RANGE_MM",
    "REGULARISATION_PER_MM",
    "SHORT_LEVER",
    "check_deflection",
    "cycloid_errors",
    "dof_count",
    "output_index",
    "pin_contacts",
    "rv_system",
    "single_disc_system",
    "translations",
)
