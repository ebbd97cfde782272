"""RV (K-H-V) reducer (Hidaka et al. 1994): the equilibrium model against independent references.

References: zero errors; the cycloid-pin geometric model (Yao & Liang 2001) for one disc on one
central crank; linearity at a fixed contact state; the rigid limit's independence of load and
stiffness; invariance to turning the whole drive by a pin pitch; the closed-form lost motion
c (1/max l⁺ + 1/max |l⁻|) of a uniform normal clearance c with the lever arms
l = a z_c sin φ / S of the cycloid's lines of action; gradients against float64 central differences.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gearte.core.solution import RESULTS
from gearte.drives.cycloid_pin import CycloidErrors, CycloidModification, CycloidPin, sweep
from gearte.drives.protocol import Eccentricity
from gearte.drives.rv_khv import RVKHV
from gearte.drives.rv_khv_contacts import rv_system, single_disc_system
from gearte.drives.rv_khv_equilibrium import ContactSystem, _active, _line_search, gradient, hessian, potential, solve

ZP, R, RPIN, A = 20, 50.0, 2.5, 1.5
POINTS = 24  # output angles of the shared grid


def make(**kw) -> RVKHV:
    base: dict[str, Any] = dict(
        pin_circle_radius=R, pin_radius=RPIN, eccentricity=A, z_sun=12, z_planet=24, crank_circle_radius=30.0, points=POINTS
    )
    base.update(kw)
    return RVKHV(ZP, **base)


@pytest.fixture(scope="module")
def drive():
    return make()


def arms(theta_T: np.ndarray) -> np.ndarray:
    """Lever arms a z_c sin φ / S of the pins at input position θ_T (rows), the pin's angle φ from the crank."""
    K = A * ZP / R
    phi = np.mod(theta_T[:, None] + 2 * np.pi * np.arange(ZP)[None, :] / ZP + np.pi, 2 * np.pi) - np.pi
    return A * (ZP - 1) * np.sin(phi) / np.sqrt(1 + K * K - 2 * K * np.cos(phi))


def test_zero_errors_give_zero_te_and_lost_motion(drive):
    r = drive.response(None)
    assert bool(np.all(np.asarray(r.result == RESULTS.successful)))
    # `solved` (what a budget's exact checks read): true here, false as soon as one solve of the response failed.
    assert bool(drive.solved(r))
    pick = jnp.arange(r.te.size).reshape(r.te.shape) == 5
    one_failed = jax.vmap(jax.vmap(lambda b: RESULTS.where(b, RESULTS.nonlinear_max_steps_reached, RESULTS.successful)))(pick)
    assert not bool(drive.solved(eqx.tree_at(lambda x: x.result, r, one_failed)))
    np.testing.assert_allclose(np.asarray(r.te), 0.0, atol=1e-13)
    # Under the small load itself the TE is the elastic deflection only: of the order of deflection_mm / R.
    assert np.max(np.abs(np.asarray(r.te_loaded))) < 10 * float(drive.deflection_mm) / R


@eqx.filter_jit
def _single_disc(stage, err, thetas, clearance):
    def one(t, s):
        eq = solve(single_disc_system(stage, err, t, clearance_mm=clearance, load_sign=s))
        return eq.q_rigid[2] / stage.pin_circle_radius, eq.result

    return jax.vmap(lambda s: jax.vmap(lambda t: one(t, s))(thetas))(jnp.asarray([1.0, -1.0]))


STAGE = CycloidPin(ZP, pin_circle_radius=R, pin_radius=RPIN, eccentricity=A)
# One shape for every single-disc solve (one compiled program): 12 input positions over a pin pitch.
PITCH_THETAS = np.arange(12) * (2 * np.pi / ZP / 12)


def test_one_crank_one_disc_reproduces_the_cycloid_model():
    """Hidaka's illustration (one disc on one central crank, rigid) against the cycloid-pin geometric model: the
    equilibrium of the contact system (its equivalent errors −l Δθ taken from the cycloid module's rotations to
    contact) against the geometric model's extreme rotation over the pins. This checks the contact system and its
    solve; the rotations to contact themselves are checked against an independent pin-by-pin root search (SciPy's
    brentq on the flank written out in NumPy) in tests/test_cycloid.py."""
    rng = np.random.default_rng(3)
    err = CycloidErrors(
        pin_radius=-30.0,
        pin_circle_radius=6.0,
        pin_tangential=rng.uniform(-8, 8, ZP),
        pin_radial=rng.uniform(-4, 4, ZP),
        indexing=rng.uniform(-20, 20, ZP - 1) / 206265,
        infeed=rng.uniform(-5, 5, ZP - 1),
        setup_eccentricity=9.0,
        setup_phase=0.7,
        dressing_x=2.0,
        disc_offset=15.0,
        disc_offset_phase=1.1,
    )
    thetas = jnp.asarray(np.arange(12) * (2 * np.pi / 12) + 0.013)  # over a turn of the crank
    te, res = _single_disc(STAGE, err, thetas, 0.0)
    assert bool(np.all(np.asarray(res == RESULTS.successful)))
    ref = sweep(STAGE, err, thetas, normal=False)
    te = np.asarray(te)
    # Where the rigid disc fits between the pins (lost motion > 0; elsewhere it interferes and the springs decide).
    fits = np.asarray(ref.lost_motion) > 0
    assert fits.all()
    np.testing.assert_allclose(te[0], np.asarray(ref.rotation_error), rtol=1e-6, atol=0)
    np.testing.assert_allclose(te[1], np.asarray(ref.reverse_rotation_error), rtol=1e-6, atol=0)
    np.testing.assert_allclose(te[0] - te[1], np.asarray(ref.lost_motion), rtol=1e-6, atol=0)


def test_uniform_profile_clearance_gives_the_backlash_formula():
    """A uniform normal clearance c (an equidistant modification of the profile): lost motion, max over a pitch,
    against max over the pitch of c (1/max l⁺ + 1/max |l⁻|), within 0.2 %."""
    c = 0.010
    stage = CycloidPin(ZP, pin_circle_radius=R, pin_radius=RPIN, eccentricity=A, modification=CycloidModification(0.0, c, 0.0))
    te, _ = _single_disc(stage, CycloidErrors(), jnp.asarray(PITCH_THETAS), 0.0)
    lm = np.max(np.asarray(te[0] - te[1]))
    lev = arms(PITCH_THETAS)
    ref = np.max(c * (1 / np.max(np.where(lev > 0, lev, 0), axis=1) + 1 / np.max(np.where(lev < 0, -lev, 0), axis=1)))
    assert lm == pytest.approx(ref, rel=2e-3)


@pytest.mark.parametrize("towards", [1.0, -1.0], ids=["root-pin", "tip-pin"])
def test_a_disc_pushed_along_the_line_of_centres_moves_by_the_normal_clearance(towards):
    """Pins ground δ undersize leave a normal clearance δ at every pin, so a disc free to translate (a loose bearing)
    and pushed along the line of centres moves by exactly δ before the pin on that line stops it (the pin at the tooth
    root for +y, the one facing a lobe tip for −y). Both have zero lever arm: turning the disc cannot close them."""
    delta = 4.0
    err = CycloidErrors(pin_radius=-delta)
    s = single_disc_system(STAGE, err, 0.0, clearance_mm=1.0)
    s = eqx.tree_at(lambda t: t.f, s, jnp.asarray([0.0, towards * 1e-7, 0.0]))
    eq = solve(s)
    assert eq.result == RESULTS.successful
    np.testing.assert_allclose(np.asarray(eq.q_rigid), [0.0, towards * delta * 1e-3, 0.0], atol=1e-12)


def test_pin_radius_error_gives_the_closed_form_lost_motion(drive):
    """The whole drive (3 cranks, 2 discs, rigid bearings, no backlash) with undersize pins, Δr′ = −c.

    With the input held, an output rotation θ_o turns the discs by θ_o and rolls each planet on the sun, turning the
    cranks by θ_o r_c / r_g, which moves the discs by a θ_o r_c / r_g across the eccentric. As the disc's conjugate
    motion leaves every pin gap unchanged, that translation changes pin j's gap as a disc rotation l_j/z_c per unit
    crank turn would: the gap closes at the rate l_j (1 + r_c / (z_c r_g)). So the lost motion at each angle is
    c (1/max l⁺ + 1/max |l⁻|) / (1 + r_c / (z_c r_g)) over both discs' pins."""
    c_um = 6.0
    r = drive.response({"pin_radius": -c_um})
    lm = np.asarray(r.te[0] - r.te[1])
    th_o = np.asarray(r.output_angle)
    lev = np.concatenate([arms((ZP - 1) * th_o), arms((ZP - 1) * th_o - np.pi)], axis=1)
    rc, rg = 30.0, 30.0 * 24 / 36  # crank circle; planet pitch radius r_c z_g / (z_s + z_g)
    ref = 1e-3 * c_um * (1 / np.max(np.where(lev > 0, lev, 0), axis=1) + 1 / np.max(np.where(lev < 0, -lev, 0), axis=1))
    np.testing.assert_allclose(lm, ref / (1 + rc / ((ZP - 1) * rg)), rtol=2e-3)


ERRS = {
    "carrier_hole": Eccentricity(np.asarray([4.0, 2.0, 3.0]), np.asarray([0.3, 2.0, 4.0])),
    "disc_hole": Eccentricity(np.asarray([3.0, 1.0, 2.0, 2.5, 1.5, 0.5]), np.asarray([0.1, 1.0, 2.0, 3.0, 4.0, 5.0])),
    "crank_eccentricity": jnp.asarray([3.0, -2.0, 1.0]),
    "crank_phase": jnp.asarray([1e-4, -2e-4, 0.5e-4]),
    "planet_eccentricity": Eccentricity(np.asarray([5.0, 3.0, 4.0]), np.asarray([0.0, 2.0, 4.0])),
    "sun_eccentricity": Eccentricity(6.0, 1.0),
    "backlash": 8.0,
}


def _scaled(s):
    out = {}
    for k, v in ERRS.items():
        out[k] = Eccentricity(np.asarray(v.magnitude) * s, v.phase) if isinstance(v, Eccentricity) else jnp.asarray(v) * s
    return out


def test_te_is_linear_in_small_errors_at_a_fixed_contact_state(drive):
    """Doubling every (bearing, crank, gear) error doubles the rigid TE wherever the same contacts carry load."""
    r1, r2 = drive.response(_scaled(1.0)), drive.response(_scaled(2.0))
    same = np.all((np.asarray(r1.force) > 0) == (np.asarray(r2.force) > 0), axis=-1)
    assert same.mean() > 0.5
    te1, te2 = np.asarray(r1.te), np.asarray(r2.te)
    np.testing.assert_allclose(te2[same], 2 * te1[same], rtol=1e-8, atol=1e-15)
    assert np.max(np.abs(te1)) > 1e-5  # the errors move the output by arc seconds


def test_rigid_limit_does_not_depend_on_load_or_stiffness(drive):
    """With a backlash and pin clearances (unilateral contacts), the rigid-limit TE is the same for any small load and
    any common scale of the stiffnesses; the loaded TE converges to it linearly in the load."""
    drive = eqx.tree_at(lambda d: d.backlash_mm, drive, jnp.asarray(0.02, dtype=float))
    base = drive.response(_scaled(1.0))
    errs = dict(_scaled(1.0), pin_radius=jnp.asarray(-8.0))
    base = drive.response(errs)
    for kw in (dict(deflection_mm=1e-8), dict(deflection_mm=1e-6), dict(pin_stiffness=30.0, mesh_stiffness=30.0, bearing_stiffness=30.0)):
        other = eqx.tree_at(lambda d, kw=kw: [getattr(d, k) for k in kw], drive, [jnp.asarray(v, dtype=float) for v in kw.values()])
        r = other.response(errs)
        np.testing.assert_allclose(np.asarray(r.te), np.asarray(base.te), rtol=1e-9, atol=1e-14)
    # The loaded TE converges to the rigid one linearly in the load: 10× less load, 10× less deflection.
    devs = []
    for defl in (1e-6, 1e-7):
        r = eqx.tree_at(lambda d: d.deflection_mm, drive, jnp.asarray(defl, dtype=float)).response(errs)
        devs.append(np.max(np.abs(np.asarray(r.te_loaded - r.te))))
    assert devs[0] / devs[1] == pytest.approx(10.0, rel=1e-3)


def test_lost_motion_is_never_negative_on_random_units(drive):
    """The output's rotation grows with the torque on it (the minimiser of a convex potential moves monotonically with
    its load), so TE(+) ≥ TE(−) at every angle: lost motion ≥ 0, within the rigid limit's resolution, for random
    units with bearing clearances, hole positions, crank errors and undersize pins (parts floating and preloaded)."""
    from gearte.drives.rv_khv_outputs import resolution

    loose = eqx.tree_at(lambda d: d.crank_disc_clearance_mm, drive, jnp.asarray(0.005))
    rng = np.random.default_rng(11)
    worst = []
    for _ in range(3):
        u = rng.uniform
        errs = {
            "carrier_hole": Eccentricity(u(0, 5, 3), u(0, 2 * np.pi, 3)),
            "disc_hole": Eccentricity(u(0, 5, 6), u(0, 2 * np.pi, 6)),
            "crank_eccentricity": jnp.asarray(u(-3, 3, 3)),
            "crank_phase": jnp.asarray(u(-2e-4, 2e-4, 3)),
            "pin_radius": jnp.asarray(u(-6, -2)),
            "pin_tangential": jnp.asarray(u(-3, 3, ZP)),
            "crank_disc_clearance": jnp.asarray(u(-3, 3)),
        }
        r = loose.response(errs)
        assert bool(np.all(np.asarray(r.result == RESULTS.successful)))
        te = np.asarray(r.te)
        worst.append(np.min(te[0] - te[1]))
    assert min(worst) >= -resolution(loose)
    assert max(worst) > 1e-5  # most of these units have lost motion at every angle: the check is not vacuous


def test_near_perfect_units_converge_well_inside_the_iteration_limit(drive):
    """Errors a thousandth of the clearances leave many contacts at nearly equal gaps; they close one per Newton
    iteration (100-150 iterations on this 20-pin drive, 130-260 on the 40-pin example's). Every solve must end at its
    exact minimum, with a margin of 4 under `MAX_STEPS`, and the TE stays of the order of the errors."""
    from gearte.drives.rv_khv_equilibrium import MAX_STEPS

    loose = eqx.tree_at(lambda d: d.crank_disc_clearance_mm, drive, jnp.asarray(0.005))
    rng = np.random.default_rng(5)
    u, s = rng.uniform, 1e-3
    errs = {
        "carrier_hole": Eccentricity(s * u(0, 5, 3), u(0, 2 * np.pi, 3)),
        "disc_hole": Eccentricity(s * u(0, 5, 6), u(0, 2 * np.pi, 6)),
        "crank_eccentricity": jnp.asarray(s * u(-3, 3, 3)),
        "crank_phase": jnp.asarray(s * u(-2e-4, 2e-4, 3)),
        "pin_radius": jnp.asarray(-1.5 + s * u(-1, 1)),
        "pin_tangential": jnp.asarray(s * u(-3, 3, ZP)),
        "crank_disc_clearance": jnp.asarray(s * u(-3, 3)),
    }
    r = loose.response(errs)
    assert bool(np.all(np.asarray(r.result == RESULTS.successful)))
    assert int(np.max(np.asarray(r.steps))) <= MAX_STEPS // 4
    assert np.max(np.ptp(np.asarray(r.te), axis=1)) < 1e-5  # rad (2″): errors of nm, a 1.5 µm profile clearance


def test_turning_the_whole_drive_by_a_pin_pitch_gives_the_same_te(drive):
    """Pins are at fixed angles, so the drive can be turned onto itself by k pin pitches γ: the per-pin errors move k
    places, housing-fixed phases turn by γ, the sun's by γ − i γ (it turns i γ as the carrier turns γ)."""
    k = 3
    gamma = 2 * np.pi * k / ZP
    errs = dict(_scaled(1.0))
    rng = np.random.default_rng(1)
    errs["pin_tangential"] = jnp.asarray(rng.uniform(-5, 5, ZP))
    errs["pin_circle_eccentricity"] = Eccentricity(4.0, 0.4)
    turned = dict(errs)
    turned["pin_tangential"] = jnp.roll(errs["pin_tangential"], k)
    turned["pin_circle_eccentricity"] = Eccentricity(4.0, 0.4 + gamma)
    se = errs["sun_eccentricity"]
    turned["sun_eccentricity"] = Eccentricity(se.magnitude, se.phase + gamma - drive.ratio * gamma)
    th = np.asarray(drive.output_angles())
    a = drive.solve_at(errs, th)
    b = drive.solve_at(turned, th + gamma)
    np.testing.assert_allclose(np.asarray(b.te), np.asarray(a.te), rtol=1e-9, atol=1e-13)
    # Not vacuous: the pins' errors matter, and only turned with the drive do they give its TE again (a drive that
    # ignored them, or took pin j's error at another pin, would pass the check above without these).
    for wrong in (
        dict(turned, pin_tangential=errs["pin_tangential"]),
        dict(turned, pin_circle_eccentricity=errs["pin_circle_eccentricity"]),
    ):
        c = drive.solve_at(wrong, th + gamma)
        assert np.max(np.abs(np.asarray(c.te) - np.asarray(a.te))) > 1e-7  # rad (0.02″), 1e6 × the tolerance above


def test_each_discs_profile_errors_enter_its_own_pin_contacts_and_the_pins_errors_both():
    """The contact system's first z_p unilateral rows are disc 1's pins, the next z_p disc 2's. A disc's profile
    errors (dressing, infeed, indexing, set-up, mandrel) change the equivalent errors of its own pins only; the pins'
    errors change both discs'; and the discs' eccentrics being 180° apart, swapping their profile errors moves the
    TE."""
    zero = {
        k: (Eccentricity(0 * np.asarray(v.magnitude), v.phase) if isinstance(v, Eccentricity) else 0 * jnp.asarray(v))
        for k, v in _scaled(1.0).items()
    }
    zc = ZP - 1
    rng = np.random.default_rng(3)
    disc2 = dict(
        zero,
        disc_dressing_x=jnp.asarray([0.0, 2.0]),
        disc_infeed=jnp.asarray(np.r_[np.zeros(zc), rng.uniform(-2, 2, zc)]),
        disc_indexing=jnp.asarray(np.r_[np.zeros(zc), rng.uniform(-5e-5, 5e-5, zc)]),  # rad (±10″)
        disc_setup=Eccentricity(jnp.asarray([0.0, 3.0]), jnp.asarray([0.0, 0.7])),
    )
    pins = dict(zero, pin_tangential=jnp.asarray(rng.uniform(-3, 3, ZP)), pin_radial=jnp.asarray(rng.uniform(-3, 3, ZP)))
    theta = 0.37

    def offsets(errs):
        s = rv_system(drive_, drive_.errors(errs), theta, 1.0)
        e, k = np.asarray(s.e), np.asarray(s.k)
        return [np.where(k[i * ZP : (i + 1) * ZP] > 0, e[i * ZP : (i + 1) * ZP], 0.0) for i in (0, 1)]

    drive_ = make()
    e0, e2, ep = offsets(zero), offsets(disc2), offsets(pins)
    np.testing.assert_array_equal(e2[0], e0[0])  # disc 1 untouched by disc 2's profile
    assert np.max(np.abs(e2[1] - e0[1])) > 1e-4  # mm: disc 2's pins see µm
    assert min(np.max(np.abs(ep[i] - e0[i])) for i in (0, 1)) > 1e-4  # the pins' errors reach both discs
    swapped = {
        k: (Eccentricity(v.magnitude[::-1], v.phase[::-1]) if isinstance(v, Eccentricity) else v[::-1])
        for k, v in disc2.items()
        if k.startswith("disc_")
    }
    swapped["disc_infeed"] = jnp.roll(disc2["disc_infeed"], zc)
    swapped["disc_indexing"] = jnp.roll(disc2["disc_indexing"], zc)
    a, b = drive_.response(disc2), drive_.response(dict(disc2, **swapped))
    np.testing.assert_array_equal(offsets(dict(disc2, **swapped))[1], e0[1])  # now disc 2 is the perfect one
    assert np.max(np.abs(np.asarray(a.te) - np.asarray(b.te))) > 1e-6  # rad


def test_warm_started_orders_give_the_te_of_each_angle_solved_alone():
    """Each solve starts from the one before it in `solve_order` (docs/rv.md): on a grid of 38 angles with z_c = 19 a
    walk two angles at a time (the pins' phase, 20 θ_o, steps by 2π/19, the eccentrics' phase not at all); with one
    angle moved off the grid, the eccentrics' phase order in the 19 sectors that gcd(19, 38) makes. The TE must be that
    of each angle solved alone from the nominal position, under both loads."""
    from gearte.drives.rv_khv import solve_order

    wide = make(points=2 * (ZP - 1))
    assert math.gcd(ZP - 1, wide.points) == ZP - 1  # the sectors of the order off the grid are in use
    errs = dict(_scaled(1.0))
    r = wide.response(errs)
    assert bool(np.all(np.asarray(r.result == RESULTS.successful)))
    th = np.asarray(wide.output_angles())
    alone = np.stack([np.asarray(wide.solve_at(errs, th[j : j + 1]).te)[:, 0] for j in range(th.size)], axis=1)
    np.testing.assert_allclose(np.asarray(r.te), alone, rtol=1e-9, atol=1e-13)
    assert np.max(np.abs(alone)) > 1e-5  # rad: the errors move the output by arc seconds
    moved = th.copy()
    moved[5] += 1e-6
    on_grid, off_grid = (np.asarray(solve_order(ZP - 1, jnp.asarray(t))) for t in (th, moved))
    assert not np.array_equal(on_grid, off_grid)
    alone[:, 5] = np.asarray(wide.solve_at(errs, moved[5:6]).te)[:, 0]
    np.testing.assert_allclose(np.asarray(wide.solve_at(errs, moved).te), alone, rtol=1e-9, atol=1e-13)


def test_the_solve_order_walks_a_grid_by_the_pins_phase_and_other_angles_by_the_eccentrics_phase():
    """Warm starts go from each angle to its neighbour in `solve_order`. On the example's 97 angles (prime) the order
    of the eccentrics' phase; on 360 angles with z_c = 39 a walk of one pin pitch (9 angles) at a time, where the
    pins' phase z_p θ_o stays and the eccentrics' phase moves by 9° (in the phase's order, taken in the three
    sectors of 120°, the pins' phase moved by 40° and the output by 37°: 42 Newton iterations per solve against
    22, docs/rv.md). Angles that are not a uniform grid keep the phase's order, in g = gcd(z_c, p) sectors so that
    no neighbour is a sector away."""
    from gearte.drives.rv_khv import grid_walk, solve_order

    for p in (97, 360):
        th = 2 * np.pi * np.arange(p) / p
        order = np.asarray(solve_order(39, jnp.asarray(th)))
        np.testing.assert_array_equal(order, grid_walk(39, p))
        assert sorted(order.tolist()) == list(range(p))
        phase = np.mod(39 * th, 2 * np.pi)
        if p == 97:
            np.testing.assert_array_equal(order, np.argsort(phase, kind="stable"))
        else:
            step = np.mod(np.diff(order), p)
            assert np.sum((step == 9) | (step == p - 9)) == p - 9  # a pin pitch, but where a cycle of 40 ends
            pins = np.diff(40 * th[order])  # the pins' phase from each angle to the next, wrapped to ±π
            assert np.sum(np.abs(np.mod(pins + np.pi, 2 * np.pi) - np.pi) < 1e-9) == p - 9
        # Off the grid (one angle moved by 1e-6 rad): the phase's order in sectors.
        moved = th.copy()
        moved[1] += 1e-6
        off = np.asarray(solve_order(39, jnp.asarray(moved)))
        g = math.gcd(39, p)
        sector = np.floor(moved[off] / (2 * np.pi / g) + 1e-9)
        assert np.all(np.diff(sector) >= 0)  # sector after sector
        for k in range(g):
            assert np.all(np.diff(np.mod(39 * moved, 2 * np.pi)[off][sector == k]) > 0)  # each in the phase's order
        if g > 1:
            plain = np.abs(np.diff(moved[np.argsort(np.mod(39 * moved, 2 * np.pi), kind="stable")]))
            assert np.max(np.abs(np.diff(moved[off]))[np.diff(sector) == 0]) < 2 * np.pi / g
            assert np.mean(plain > 2 * np.pi / g - 1e-5) > 0.6


def test_each_start_is_turned_with_the_drive_so_a_pin_pitch_is_one_newton_step():
    """On a grid of z_p angles `grid_walk` goes a pin pitch at a time, and without errors the drive turned by a pin
    pitch is the same drive. Each solve starts from the one before with every body's translation turned with the
    output (`_response_jit`): that start is the solution but for rounding, so one Newton step ends each solve after
    the first. (From the solution before as it stands, unturned, each takes two or three.)"""
    from gearte.drives.rv_khv import grid_walk

    walk = grid_walk(ZP - 1, ZP)
    assert set(np.mod(np.diff(walk), ZP).tolist()) <= {1, ZP - 1}  # a pin pitch each step
    r = make(points=ZP).response(None)
    steps = np.asarray(r.steps)[:, walk]
    assert np.all(steps[:, 1:] == 1), steps


def test_gradients_match_finite_differences(drive):
    """d(lost motion)/d(tolerance) by the implicit-function theorem against float64 central differences."""

    def lm(x):
        e = dict(_scaled(1.0))
        e["carrier_hole"] = Eccentricity(jnp.asarray([4.0, 2.0, 3.0]) * x[0], e["carrier_hole"].phase)
        e["pin_radius"] = -3.0 * x[1]
        e["crank_eccentricity"] = jnp.asarray([3.0, -2.0, 1.0]) * x[2]
        r = drive.response(e)  # the grid's program, shared with the other tests
        return jnp.sum(r.te[0] - r.te[1]) + jnp.sum(r.te[0])

    x0 = jnp.asarray([1.0, 1.0, 1.0])
    g = np.asarray(jax.jacfwd(lm)(x0))  # forward mode through the implicit step: a smaller program to compile than reverse
    h = 1e-5
    for i in range(3):
        e = jnp.zeros(3).at[i].set(h)
        fd = (float(lm(x0 + e)) - float(lm(x0 - e))) / (2 * h)
        assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-12), i
    assert np.all(np.isfinite(g)) and np.any(np.abs(g) > 0)


def test_newton_uses_the_derivatives_of_the_potential(drive):
    """`gradient` and `hessian` (written out for speed: every row with its stiffness in one product, a bearing's
    closed faces summed by one product) against JAX's own derivatives of `potential`, at points around a loose
    unit's equilibrium where pins, both gear flanks and several faces of every bearing polygon are closed and others
    open (no contact exactly on its boundary, where Φ has no second derivative)."""
    loose = eqx.tree_at(
        lambda d: (d.crank_disc_clearance_mm, d.crank_carrier_clearance_mm), drive, (jnp.asarray(0.004), jnp.asarray(0.003))
    )
    s = jax.jit(lambda e: rv_system(loose, loose.errors(e), 0.37, 1.0))(_scaled(1.0))
    q0 = eqx.filter_jit(solve)(s).q
    rng = np.random.default_rng(5)
    for _ in range(4):
        q = q0 + jnp.asarray(rng.normal(scale=2e-3, size=q0.shape))
        closed, faces = (np.asarray(a) for a in _active(s, q))
        assert 0 < closed.sum() < closed.size  # pins and flanks closed and open
        assert (faces.sum(axis=1) > 1).sum() >= 3 and faces.sum(axis=1).max() < faces.shape[1]  # several faces closed
        h, h_ref = jax.jit(hessian)(s, q), jax.jit(jax.hessian(lambda y: potential(s, y)))(q)
        np.testing.assert_allclose(np.asarray(h), np.asarray(h_ref), rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(h_ref))))
        g, g_ref = jax.jit(gradient)(s, q), jax.jit(jax.grad(lambda y: potential(s, y)))(q)
        np.testing.assert_allclose(np.asarray(g), np.asarray(g_ref), rtol=0, atol=1e-12 * float(jnp.max(jnp.abs(g_ref))))


def test_reverse_and_forward_derivatives_of_a_solve_match_finite_differences():
    """The solve's derivatives (the implicit step's JVP rule, and its transpose in reverse mode) against float64
    central differences: of the displacement and of the rigid limit, in the errors and in the load. The rigid limit
    does not move with the load (the contact set stays), the displacement does."""

    def out(x):
        err = CycloidErrors(pin_radius=-5.0 * x[0], pin_tangential=jnp.linspace(-3.0, 3.0, ZP) * x[1])
        s = single_disc_system(STAGE, err, 0.1, load_sign=1.0)
        eq = solve(eqx.tree_at(lambda t: t.f, s, s.f * x[2]))
        return jnp.concatenate([eq.q, eq.q_rigid])

    x0 = jnp.asarray([1.0, 1.0, 1.0])
    fwd = np.asarray(jax.jit(jax.jacfwd(out))(x0))
    rev = np.asarray(jax.jit(jax.jacrev(out))(x0))
    h = 1e-6
    fd = np.stack([(np.asarray(out(x0.at[i].add(h))) - np.asarray(out(x0.at[i].add(-h)))) / (2 * h) for i in range(3)], axis=1)
    scale = np.max(np.abs(fd))
    np.testing.assert_allclose(fwd, fd, rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(rev, fwd, rtol=0, atol=1e-12 * scale)
    # In the load, by the rigid limit's definition (q affine in the load for the closed contacts): the displacement
    # moves by its compliant part q − q_rigid, the rigid limit not at all.
    n = fd.shape[0] // 2
    v = np.asarray(out(x0))
    compliant = v[:n] - v[n:]
    assert np.max(np.abs(compliant)) > 0
    np.testing.assert_allclose(rev[:n, 2], compliant, rtol=0, atol=1e-9 * np.max(np.abs(compliant)))
    np.testing.assert_allclose(rev[n:, 2], 0.0, atol=1e-9 * np.max(np.abs(compliant)))


def test_the_line_search_finds_the_minimum_along_any_descent_direction(drive):
    """`_line_search` against the root of φ′(t) = ∇Φ(q + t dq)·dq found by bisection, along random descent directions
    from points around a loose unit's equilibrium (pins, flanks and bearing faces opening and closing on the way)."""
    loose = eqx.tree_at(
        lambda d: (d.crank_disc_clearance_mm, d.crank_carrier_clearance_mm), drive, (jnp.asarray(0.004), jnp.asarray(0.003))
    )
    s = jax.jit(lambda e: rv_system(loose, loose.errors(e), 0.37, 1.0))(_scaled(1.0))
    q0 = np.asarray(eqx.filter_jit(solve)(s).q)
    search = jax.jit(_line_search)
    slope = jax.jit(lambda q, dq, t: jnp.dot(gradient(s, q + t * dq), dq))
    rng = np.random.default_rng(11)
    for _ in range(12):
        q = jnp.asarray(q0 + rng.normal(scale=1e-3, size=q0.shape))
        dq = jnp.asarray(rng.normal(scale=1e-3, size=q0.shape))
        if float(slope(q, dq, 0.0)) > 0:
            dq = -dq
        lo, hi = 0.0, 1e-3
        while float(slope(q, dq, hi)) <= 0:
            lo, hi = hi, 2 * hi
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if float(slope(q, dq, mid)) <= 0 else (lo, mid)
        assert float(search(s, q, dq)) == pytest.approx(0.5 * (lo + hi), rel=1e-9, abs=0)


@pytest.mark.parametrize("step, t_min", [(-1.0, 0.5), (-4.0, 0.125)])
def test_the_line_search_finds_a_minimum_that_lies_before_the_first_kink(step, t_min):
    """Two opposed contacts on one coordinate, p = 1 ± q, both closed at q = 0.5: Φ = ½(1 + q)² + ½(1 − q)² is least at
    q = 0, before the first kink (q = −1) along dq = −1 or −4; the walk, which starts at the first kink (or t = 1),
    must come back."""
    s = ContactSystem(
        G=jnp.asarray([[1.0], [-1.0]]),
        e=jnp.asarray([1.0, 1.0]),
        k=jnp.asarray([1.0, 1.0]),
        B=jnp.zeros((1, 2, 1)),
        eb=jnp.zeros((1, 2)),
        c=jnp.zeros(1),
        kb=jnp.zeros(1),
        f=jnp.zeros(1),
        mu=jnp.asarray(1e-12),
    )
    t = float(jax.jit(_line_search)(s, jnp.asarray([0.5]), jnp.asarray([step])))
    assert t == pytest.approx(t_min, rel=1e-12, abs=0)  # μ q vanishes at q = 0


def test_the_rigid_limit_of_the_solver_is_exact_for_the_closed_contacts():
    """The rigid-limit position satisfies the closed contacts with zero penetration (to rounding)."""
    err = CycloidErrors(pin_radius=-5.0, pin_tangential=np.linspace(-3, 3, ZP))
    s = single_disc_system(STAGE, err, 0.1, load_sign=1.0)
    eq = eqx.filter_jit(solve)(s)
    closed = np.asarray(eq.force) > 0
    p = np.asarray(s.G @ eq.q_rigid + s.e)
    assert closed.any()
    np.testing.assert_allclose(p[closed], 0.0, atol=1e-13)
    assert math.isfinite(float(eq.q_rigid[2]))


def test_best_planet_assembly_is_a_coordinate_optimum_of_the_units_te():
    """The search's positions: no single planet's other position gives a smaller TE p-p (each checked through the
    drive's own response, not the search's batched one), the value is that of the drive at those positions, and
    it is not above the start's."""
    from gearte.drives.rv_khv import RVPeakToPeak
    from gearte.optimise.rv_assembly import best_planet_assembly

    d = make(z_sun=12, z_planet=12, points=16)
    run_out = Eccentricity(jnp.asarray([12.0, 8.0, 10.0]), jnp.asarray([0.3, 2.0, 4.1]))
    errors = {"planet_eccentricity": run_out, "sun_eccentricity": Eccentricity(jnp.asarray([6.0]), jnp.asarray([1.0]))}
    with pytest.raises(ValueError, match=r"metric: give a metric object such as gearte\.RVLostMotion\(\)"):
        best_planet_assembly(d, errors, metric="peak_to_peak")  # type: ignore[arg-type]
    out = best_planet_assembly(d, errors, metric=RVPeakToPeak())
    assert bool(out.result == RESULTS.successful)
    teeth = np.asarray(out.teeth)
    metric = d.metrics["peak_to_peak"]

    def pp(k):
        return float(metric(d, d.response(dict(errors, planet_assembly=2 * np.pi * np.asarray(k, dtype=float) / d.z_planet))))

    assert float(out.value) == pytest.approx(pp(teeth), rel=1e-9)
    assert float(out.value) <= float(out.start) + 1e-15
    assert float(out.start) == pytest.approx(pp([0, 0, 0]), rel=1e-9)
    for i in range(d.cranks):
        for k in range(d.z_planet):
            other = teeth.copy()
            other[i] = k
            assert pp(other) >= float(out.value) * (1 - 1e-9), (i, k)


def test_best_planet_assembly_never_takes_a_failed_solve_and_says_where_one_failed(monkeypatch):
    """A position whose equilibrium solves failed is never chosen, however small its metric (a failed solve's TE is
    not the unit's); a failed solve at the start makes the result `contact_not_converged`; a start position that is
    not a whole tooth in 0 … z_g − 1 is refused. The solves are stood in for: planet 0's position 5 "fails" with the
    smallest value, position 3 succeeds with the next smallest."""
    from gearte.optimise import rv_assembly

    d = make(z_sun=12, z_planet=12, points=16)
    for bad in ([0, 0, d.z_planet], [0.7, 1.0, 0], [0, 0]):
        with pytest.raises(ValueError, match=r"start: give one whole-tooth position 0 … 11 per planet \(3\)"):
            rv_assembly.best_planet_assembly(d, {}, start=bad)
    start_ok = [True]

    def evaluate(drive, err, teeth, metric):
        return jnp.asarray(10.0 - float(np.asarray(teeth)[0] == 3)), jnp.asarray(start_ok[0] or bool(np.asarray(teeth)[0] == 3))

    def candidates(drive, err, planet, teeth, metric):
        values = np.full(drive.z_planet, 10.0)
        ok = np.ones(drive.z_planet, dtype=bool)
        if planet == 0:
            values[5], ok[5], values[3] = 1.0, False, 9.0
        return jnp.asarray(values), jnp.asarray(ok)

    monkeypatch.setattr(rv_assembly, "_evaluate", evaluate)
    monkeypatch.setattr(rv_assembly, "_candidates", candidates)
    out = rv_assembly.best_planet_assembly(d, {})
    assert list(np.asarray(out.teeth)) == [3, 0, 0] and bool(out.result == RESULTS.successful)
    start_ok[0] = False
    out = rv_assembly.best_planet_assembly(d, {}, throw=False)
    assert bool(out.result == RESULTS.contact_not_converged)


@pytest.mark.parametrize("op, fill", [(jnp.sum, 0.0), (jnp.min, np.inf), (jnp.max, -np.inf)])
@pytest.mark.parametrize("n", [1, 31, 32, 33, 64, 86, 726])
def test_reductions_written_in_slices_equal_the_plain_ones(op, fill, n):
    """`_reduce` (slices of 32 combined, then one reduction) against NumPy over the last axis, for lengths on both
    sides of the slice and with padding: min and max exactly, sums to rounding."""
    from gearte.drives.rv_khv_equilibrium import _reduce

    x = np.random.default_rng(n).normal(size=(3, n))
    got = np.asarray(jax.jit(lambda v: _reduce(op, v, fill))(jnp.asarray(x)))
    want = {jnp.sum: np.sum, jnp.min: np.min, jnp.max: np.max}[op](x, axis=-1)
    np.testing.assert_allclose(got, want, rtol=1e-14 if op is jnp.sum else 0, atol=0)
    flags = np.arange(n) != n // 2
    assert not bool(jax.jit(lambda v: _reduce(jnp.all, v, True))(jnp.asarray(flags)))
    assert bool(jax.jit(lambda v: _reduce(jnp.all, v, True))(jnp.ones(n, dtype=bool)))


def test_the_newton_iteration_compiles_without_windowed_reductions(drive):
    """XLA's CPU compiler turns a reduction over more than 32 elements into a windowed reduction, an operation of its
    own (about half a microsecond each on the CPU, a dozen per iteration before `_reduce`); the compiled Newton
    iteration of a drive with 20 pins per disc and 64-face bearings has none."""
    from gearte.drives.rv_khv_equilibrium import _newton

    s = jax.jit(lambda e: rv_system(drive, drive.errors(e), 0.37, 1.0))(_scaled(1.0))
    assert s.G.shape[0] > 32 and s.c.shape[0] * 64 > 32  # long axes: the rewrite would apply
    text = jax.jit(_newton).lower(s, jnp.zeros_like(s.f)).compile().as_text()
    assert "while" in text
    assert "reduce-window" not in text


@pytest.mark.parametrize("faces", [8, 64, 128])
def test_a_loaded_part_rests_on_the_vertex_of_its_clearance_polygon_nearest_the_load(faces):
    """One free part (x, y) in a bearing of clearance c, pushed in direction ψ: in the rigid limit it rests at the
    support point of the M-gon tangent to the circle, the vertex nearest ψ, at c / cos(π/M) (`ContactSystem.faces`)."""
    c, psi = 0.005, 0.3
    s = ContactSystem(
        G=jnp.asarray([[1.0, 0.0]]),
        e=jnp.asarray([-1.0]),
        k=jnp.asarray([0.0]),  # no unilateral contact
        B=jnp.eye(2)[None],
        eb=jnp.zeros((1, 2)),
        c=jnp.asarray([c]),
        kb=jnp.ones(1),
        f=1e-9 * jnp.asarray([math.cos(psi), math.sin(psi)]),
        mu=jnp.asarray(1e-12),
        faces=faces,
    )
    eq = eqx.filter_jit(solve)(s)
    pitch = 2 * math.pi / faces
    vertex = (math.floor(psi / pitch) + 0.5) * pitch
    want = c / math.cos(math.pi / faces) * np.asarray([math.cos(vertex), math.sin(vertex)])
    assert bool(eq.result == RESULTS.successful)
    np.testing.assert_allclose(np.asarray(eq.q_rigid), want, rtol=1e-9, atol=0)


def test_the_bearing_polygon_is_an_option_of_the_drive_and_its_study_file(tmp_path):
    """`RVKHV(bearing_faces=...)` and ``[drive.model] bearing_faces`` reach the contact system; fewer than 8 faces are
    refused, naming the key."""
    from gearte.cli.config import load_study

    drive = make(bearing_faces=16)
    s = jax.jit(lambda e: rv_system(drive, drive.errors(e), 0.37, 1.0))(_scaled(1.0))
    assert s.faces == 16 and make().bearing_faces == 64
    with pytest.raises(ValueError, match="bearing_faces"):
        make(bearing_faces=4)
    with pytest.raises(ValueError, match="bearing_faces: 100,000,000 faces, more than 4,096"):
        make(bearing_faces=100_000_000)  # took gigabytes before it was refused
    # A load outside the small-load window is refused, naming the key (10 mm gave a lost motion of 14.6′, silently).
    for bad in (10.0, 1e-300):
        with pytest.raises(ValueError, match=r"deflection_mm: .* is outside 1e-13 … 1e-05 mm"):
            make(deflection_mm=bad)
    text = (Path(__file__).resolve().parents[1] / "examples" / "rv_robot_joint.toml").read_text()
    head, sep, tail = text.partition("[drive.model]")
    assert sep
    path = tmp_path / "rv.toml"
    path.write_text(head + sep + tail.replace("\n", "\nbearing_faces = 128\n", 1))
    assert load_study(path).drive.bearing_faces == 128
    # In the study file the bounds are named with the file's table and key.
    from gearte.core.schema import ConfigError

    for new, message in (
        (head + sep + tail.replace("\n", "\nbearing_faces = 100000\n", 1), r"\[drive.model\] bearing_faces: must be ≤ 4096, got 100000"),
        (
            text.replace("deflection_mm = 1e-10 ", "deflection_mm = 10 ", 1),
            r"\[drive.model\] deflection_mm: 10 mm is outside 1e-13 … 1e-05 mm",
        ),
        (
            text.replace("pressure_angle_deg = 20.0 ", "pressure_angle_deg = 50 ", 1),
            r"\[drive\] pressure_angle_deg: 50° is not a gear pressure angle",
        ),
    ):
        assert new != text
        path.write_text(new)
        with pytest.raises(ConfigError, match=message):
            load_study(path)


def test_the_regularisation_follows_the_small_load_unless_given(tmp_path):
    """By default μ / k_pin = `REGULARISATION_PER_MM` × deflection_mm, so the regularisation's pull stays the same
    fraction of the load whatever its size, in the drive, its contact system and its study file; a value given wins."""
    from gearte.cli.config import load_study
    from gearte.drives.rv_khv_contacts import DEFLECTION_MM, REGULARISATION_PER_MM

    assert float(make().deflection_mm) == DEFLECTION_MM == 1e-10
    assert float(make().regularisation) == pytest.approx(1e-13, rel=1e-12, abs=0)
    light = make(deflection_mm=1e-12, pin_stiffness=3.0)
    assert float(light.regularisation) == pytest.approx(REGULARISATION_PER_MM * 1e-12, rel=1e-12, abs=0)
    s = jax.jit(lambda e: rv_system(light, light.errors(e), 0.37, 1.0))(_scaled(1.0))
    assert float(s.mu) == pytest.approx(3.0 * 1e-15, rel=1e-12, abs=0)  # μ = regularisation × k_pin
    assert float(make(deflection_mm=1e-12, regularisation=1e-12).regularisation) == 1e-12
    text = (Path(__file__).resolve().parents[1] / "examples" / "rv_robot_joint.toml").read_text()
    head, sep, tail = text.partition("[drive.model]")
    path = tmp_path / "rv.toml"
    path.write_text(head + sep + tail.replace("\ndeflection_mm = 1e-10", "\ndeflection_mm = 1e-9", 1))
    assert float(load_study(path).drive.regularisation) == pytest.approx(1e-12, rel=1e-12, abs=0)


def test_the_default_small_load_keeps_a_preloaded_units_lost_motion_positive():
    """Unit 239 of the tolerance example (seed 121) has preloaded parts whose weak modes a load of 1e-9 mm moves across a
    change of contact state: removing the elastic part there extrapolates too far and gives a lost motion of −0.06′,
    impossible at equilibrium. At the default load (1e-10 mm, μ following it) every angle's lost motion is ≥ 0 within
    the rigid limit's resolution, and the TE p-p agrees with the heavier load's (the defect is local)."""
    from gearte.cli.config import load_study
    from gearte.drives.rv_khv_outputs import resolution

    study = load_study(Path(__file__).resolve().parents[1] / "examples" / "rv_robot_joint_tolerances.toml")
    drive = study.drive
    errs = study.errors.sample(jax.random.fold_in(jax.random.key(study.seed), 239))
    heavy = eqx.tree_at(lambda d: (d.deflection_mm, d.regularisation), drive, (jnp.asarray(1e-9), jnp.asarray(1e-12)))
    lost = {}
    for name, d in (("default", drive), ("heavy", heavy)):
        r = d.response(errs)
        assert bool(d.solved(r))
        te = np.asarray(r.te)
        lost[name] = (float(np.min(te[0] - te[1])), float(np.ptp(te[0])))
    arcmin = 180 * 60 / math.pi
    assert lost["heavy"][0] * arcmin < -0.05  # the case this test is about: if it passes, choose another unit
    assert lost["default"][0] >= -resolution(drive)
    assert lost["default"][1] == pytest.approx(lost["heavy"][1], rel=1e-4)


def _stored_solve(name: str) -> tuple[ContactSystem, jax.Array]:
    """A contact system with its load and start, and the start, stored from a Monte Carlo run (`tests/data`)."""
    z = np.load(Path(__file__).resolve().parent / "data" / name)
    fields = ("G", "e", "k", "B", "eb", "c", "kb", "f", "mu")
    return ContactSystem(**{k: jnp.asarray(z[k]) for k in fields}, faces=int(z["faces"])), jnp.asarray(z["q0"])


def test_the_residual_is_taken_from_q_itself_so_a_solve_ends_below_its_rounding_floor():
    """One solve of unit 4055 of the tolerance study as the Monte Carlo met it (`tests/data/rv_drifting_solve.npz`):
    with the rows' values moved along the Newton steps (v + t u) instead of computed from q, their rounding drift
    held its residual at 3-4× its rounding floor (it ran to `MAX_STEPS`, or creeps there). Computed from q, it ends
    in 22 iterations with its residual below the floor."""
    from gearte.drives.rv_khv_equilibrium import _newton, _rounding_floor

    s, q0 = _stored_solve("rv_drifting_solve.npz")
    q, ok, steps, g, _ = jax.jit(_newton)(s, q0)
    assert bool(ok) and int(steps) < 50
    assert float(jnp.max(jnp.abs(g))) <= float(_rounding_floor(s, q))


def test_a_solve_that_creeps_at_its_rounding_floor_ends():
    """One solve of unit 2929 of the tolerance study as the Monte Carlo met it (its contact system with the load and
    the start, `tests/data/rv_creeping_solve.npz`): from its 16th iteration the steps move q by about 1e-19 mm while
    its residual stays at 2× the rounding floor, a contact's state flipping at rounding level; it ran to `MAX_STEPS`
    and failed. It ends, successful, once its steps move q by rounding only and its residual is within
    `STALLED_FLOORS` floors."""
    from gearte.drives.rv_khv_equilibrium import STALLED_FLOORS, _newton, _rounding_floor

    s, q0 = _stored_solve("rv_creeping_solve.npz")
    q, ok, steps, g, _ = jax.jit(_newton)(s, q0)
    floor = float(_rounding_floor(s, q))
    assert bool(ok) and int(steps) < 50
    assert floor < float(jnp.max(jnp.abs(g))) <= STALLED_FLOORS * floor  # the case this test is about
