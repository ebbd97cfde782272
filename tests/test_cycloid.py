"""Cycloid-pin reducer (Yao & Liang 2001): geometry, clearances, the drive protocol, Monte Carlo, sensitivities,
the profile-modification optimiser, and `gearte run`."""

import json
import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import CONTRACT_SAMPLES, CONTRACT_SEED
from scipy.optimize import brentq, minimize_scalar
from trace_count import traces

import gearte
from gearte import cli
from gearte.drives import cycloid_pin as cp
from gearte.drives.cycloid_pin import (
    ERROR_FIELDS,
    CycloidAnalysis,
    CycloidErrors,
    CycloidModification,
    CycloidPin,
    LoadedPairs,
    LostMotion,
    LostMotionMin,
    RotationErrorPeakToPeak,
    clearances,
    first_order_clearance,
    loaded_pairs,
    normal_clearance,
    pitch_angles,
    revolution_angles,
    smooth_loaded_pairs,
    sweep,
    tooth_profile,
    unit_metrics,
)
from gearte.drives.cycloid_pin_outputs import sample_outputs
from gearte.studies.sensitivity_pathwise import gradient_rows

ROOT = Path(__file__).resolve().parents[1]
ARCSEC = 180 * 3600 / math.pi
ARCMIN = 180 * 60 / math.pi


def basic(**kw) -> CycloidPin:
    """The paper's stage: z_b = 26, R = 195 mm, r = 13.5 mm, a = 6 mm (K_1 = 0.8)."""
    return CycloidPin(26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, **kw)


def modified(**kw) -> CycloidPin:
    """The paper's stage with its modified profile (R_Z = 194.785, r_Z = 13.880 mm)."""
    return basic(wheel_pin_circle_radius=194.785, wheel_pin_radius=13.88, **kw)


def seed_errors(za: int = 25) -> CycloidErrors:
    """The error values of the paper's figures 3–8, in gearte's frame (J = 6: the paper's disc frame is gearte's
    turned 360°·6/25 clockwise, its tooth n is gearte's space 7 − n, turned the other way)."""
    J = 6
    return CycloidErrors(
        pin_circle_radius=14.0,
        pin_radius=-25.0,
        setup_eccentricity=31.5,
        setup_phase=math.radians(45) - 2 * math.pi * J / za,
        eccentricity=20.0,
        mandrel_runout=5.0,
        mandrel_phase=-2 * math.pi * J / za,
        dressing_x=2.0,
        dressing_y=2.0,
        disc_offset=57.5,
        disc_offset_phase=math.radians(40),
        pin_wheel_offset=17.3,
        pin_wheel_offset_phase=math.radians(10),
        indexing=-30 / ARCSEC * np.sin(2 * np.pi * (J + 1 - np.arange(za)) / za),
    )


def flank_parameter(drive, theta_T):
    """Each pin's angle from the crank direction, wrapped to [−π, π) (an independent restatement)."""
    psi = theta_T + 2 * np.pi * np.arange(drive.z_pins) / drive.z_pins
    return (psi + np.pi) % (2 * np.pi) - np.pi


# ---------------------------------------------------------------- the error-free profile


@pytest.mark.parametrize("z_pins, R, r, a", [(26, 195.0, 13.5, 6.0), (12, 80.0, 6.0, 3.0), (40, 150.0, 5.0, 2.5)])
@pytest.mark.parametrize("theta_T", [0.1, 0.77, 2.0])
def test_unmodified_error_free_profile_touches_every_pin(z_pins, R, r, a, theta_T):
    d = CycloidPin(z_pins, pin_circle_radius=R, pin_radius=r, eccentricity=a)
    c = clearances(d, None, theta_T)
    assert bool(jnp.all(c.converged))
    np.testing.assert_allclose(np.asarray(c.normal_clearance), 0.0, atol=1e-10)  # mm
    reach = np.asarray(c.reachable)
    np.testing.assert_allclose(np.asarray(c.rotation_to_contact)[reach], 0.0, atol=1e-13)  # rad
    # Half of the pins sit on driving flanks, and all of them carry (zero clearance).
    phi = flank_parameter(d, theta_T)
    assert int(jnp.sum(c.on_driving_flank)) == z_pins // 2 == int(np.sum(phi > 0))
    np.testing.assert_array_equal(np.asarray(c.on_driving_flank), phi > 0)
    assert int(loaded_pairs(c, budget_mm=1e-9)) == z_pins // 2
    assert abs(float(c.lost_motion)) < 1e-13 and abs(float(c.rotation_error)) < 1e-13


def test_rotation_error_is_zero_without_errors():
    d = basic()
    s = sweep(d, None, revolution_angles(d, 8), normal=False)
    assert bool(jnp.all(s.converged))
    np.testing.assert_allclose(np.asarray(s.rotation_error), 0.0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(s.lost_motion), 0.0, atol=1e-13)
    # A sweep is the single-position analysis, position by position.
    one = clearances(d, seed_errors(), float(revolution_angles(d, 8)[37]), normal=False)
    many = sweep(d, seed_errors(), revolution_angles(d, 8), normal=False)
    np.testing.assert_allclose(np.asarray(many.rotation_to_contact)[37], np.asarray(one.rotation_to_contact), rtol=1e-12, atol=1e-15)


def test_pin_radius_error_gives_a_uniform_normal_clearance():
    # Smaller pins on an exact wheel: every pin centre is still on the theoretical curve, at distance r from the
    # flank (parallel curves), so the normal clearance at the theoretical position is r − r′ for every pin.
    d = basic()
    for delta_um in (-7.0, -30.0):
        nc = np.asarray(normal_clearance(d, CycloidErrors(pin_radius=delta_um), 0.3))
        np.testing.assert_allclose(nc, -delta_um * 1e-3, atol=1e-12)
    # The errors may also be given as the protocol's mapping of source names (the others 0).
    np.testing.assert_array_equal(
        np.asarray(normal_clearance(d, {"pin_radius": -7.0}, 0.3)), np.asarray(normal_clearance(d, CycloidErrors(pin_radius=-7.0), 0.3))
    )


# ---------------------------------------------------------------- closed forms of the modifications


def lever(d, phi):
    """Lever arm of a contact about the disc centre, l = a z_a sin φ / S (derived in the module notes), mm."""
    K = float(d.K1)
    S = np.sqrt(1 + K * K - 2 * K * np.cos(phi))
    return float(d.eccentricity) * d.z_lobes * np.sin(phi) / S


@pytest.mark.parametrize("shift, equidistant", [(0.0, 0.002), (-0.002, 0.0), (-0.001, 0.0015)])
def test_small_modifications_match_the_first_order_closed_form(shift, equidistant):
    """First order: the flank moves along its normal by n(φ) = Δr_Z − ΔR_Z (1 − K_1 cos φ)/S (∂P/∂R = (sin φ/z_a,
    cos φ/z_a), projected on N); the disc must turn n/l to close it, l = a z_a sin φ / S."""
    d = basic(modification=CycloidModification(shift, equidistant))
    theta_T = 0.05
    c = clearances(d, None, theta_T)
    phi = flank_parameter(d, theta_T)
    K = float(d.K1)
    S = np.sqrt(1 + K * K - 2 * K * np.cos(phi))
    n = equidistant - shift * (1 - K * np.cos(phi)) / S
    expected = np.sign(phi) * n / lever(d, np.abs(phi))
    mid = (np.abs(phi) > 0.3) & (np.abs(phi) < 2.6)
    got = np.asarray(c.rotation_to_contact)[mid]
    np.testing.assert_allclose(got, expected[mid], rtol=2e-3)
    np.testing.assert_allclose(np.asarray(first_order_clearance(d, phi))[mid] * np.sign(phi[mid]), expected[mid], rtol=1e-9)
    # Normal clearance at the theoretical position: n(φ) itself (exactly Δr_Z for a pure equidistant).
    nc0 = np.asarray(normal_clearance(d, None, theta_T))
    np.testing.assert_allclose(nc0[mid], n[mid], atol=2e-3 * max(abs(shift), abs(equidistant)))
    if shift == 0.0:
        np.testing.assert_allclose(nc0, equidistant, atol=1e-12)
    # At the contacting configuration: n(φ) − (turn to contact) × l(φ).
    drv = np.asarray(c.on_driving_flank)
    te = float(c.rotation_error)
    nc = np.asarray(c.normal_clearance)
    sel = mid & drv
    np.testing.assert_allclose(nc[sel], n[sel] - te * lever(d, phi[sel]), atol=5e-3 * max(abs(shift), abs(equidistant)))
    # Lost motion ≈ twice the smallest n/l (symmetric flanks).
    assert float(c.lost_motion) == pytest.approx(2 * te, rel=1e-2)


def test_pure_equidistant_contact_at_the_largest_lever_arm():
    # n/l is smallest where l = a z_a sin φ / S is largest: cos φ = K_1, l = a z_a; so the contacting pair is the
    # pin nearest to φ = arccos K_1 and the lost motion of a pure equidistant Δ is ≈ 2Δ/(a z_a).
    d = basic(modification=CycloidModification(0.0, 0.001))
    s = sweep(d, None, pitch_angles(d, 16))
    for k in range(16):
        phi = flank_parameter(d, float(s.input_angle[k]))
        drv = phi > 0
        best = np.argmax(np.where(drv, lever(d, np.abs(phi)), -1))
        assert int(s.contact_pin[k]) == best
    # Lost motion = Δ/l at the driving contact + Δ/l at the reverse contact (first order): at least 2Δ/(a z_a).
    lm = np.asarray(s.lost_motion)
    for k in range(16):
        phi = flank_parameter(d, float(s.input_angle[k]))
        l_f, l_r = lever(d, abs(phi[int(s.contact_pin[k])])), lever(d, abs(phi[int(s.reverse_contact_pin[k])]))
        assert lm[k] == pytest.approx(0.001 / l_f + 0.001 / l_r, rel=1e-3)
    assert np.all(lm >= 2 * 0.001 / (6.0 * 25) * (1 - 1e-3))


def test_rotation_modification_gives_a_uniform_clearance():
    delta = 20 / ARCSEC
    d = basic(modification=CycloidModification(rotation=delta))
    c = clearances(d, None, 0.2)
    reach = np.asarray(c.reachable)
    drv = np.asarray(c.on_driving_flank)
    rot = np.asarray(c.rotation_to_contact)
    np.testing.assert_allclose(rot[reach & drv], delta, rtol=1e-9)
    np.testing.assert_allclose(rot[reach & ~drv], -delta, rtol=1e-9)
    assert int(loaded_pairs(c, budget_mm=1e-9)) == 13
    assert float(c.lost_motion) == pytest.approx(2 * delta, rel=1e-9)


# ---------------------------------------------------------------- an independent check of the contact solve


def test_rotation_to_contact_against_a_brute_force_search():
    """For a few pins: turn the disc (scipy brentq) until the smallest distance (scipy bounded search over the
    flank of `tooth_profile`) from the pin centre to the flank equals r′; check the sense of the constraint."""
    d = modified()
    err = seed_errors()
    theta_T = 0.37
    c = clearances(d, err, theta_T)
    pins = cp.pin_layout(d, err, theta_T)
    r1 = 13.5 - 0.025
    nominal = theta_T * 26 / 25
    profile = jax.jit(lambda p, s: tooth_profile(d, p, errors=err, space=s))
    for j in (0, 2, 5, 15, 20, 24):
        space, side = int(pins.space[j]), float(pins.side[j])
        cx, cy = (float(v) for v in pins.centre[j])
        lo, hi = (0.0, math.pi) if side > 0 else (-math.pi, 0.0)

        def gap(theta, cx=cx, cy=cy, lo=lo, hi=hi, space=space):
            x = math.cos(theta) * cx + math.sin(theta) * cy
            y = -math.sin(theta) * cx + math.cos(theta) * cy
            f = lambda p: float(np.hypot(*(np.asarray(profile(p, space)) - (x, y))))
            res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12})
            return res.fun - r1

        t0 = nominal + float(c.rotation_to_contact[j])
        root = brentq(gap, t0 - 2e-4, t0 + 2e-4, xtol=1e-14)
        assert root - nominal == pytest.approx(float(c.rotation_to_contact[j]), abs=2e-9)
        # Driving flanks bound the disc from above (θ ≤ θ_j), reverse flanks from below.
        assert (gap(root - 1e-5) > 0) == (side > 0)


# ---------------------------------------------------------------- gradients


def test_gradients_match_finite_differences():
    d = modified()
    err = cp.checked_errors(d, seed_errors())
    err = eqx.tree_at(
        lambda e: (e.infeed, e.pin_tangential, e.pin_circle_eccentricity),
        err,
        (jnp.linspace(-5, 5, 25), 8 * jnp.sin(jnp.arange(26.0)), jnp.asarray(6.0)),
    )
    theta_T = 0.41
    w = jnp.asarray(np.random.default_rng(0).normal(size=26))

    def f(diff):
        mod, e = diff
        dd = eqx.tree_at(lambda x: x.modification, d, mod)
        c = clearances(dd, e, theta_T, normal=True)
        rot = jnp.where(c.reachable, c.rotation_to_contact, 0.0)
        return (
            jnp.sum(w * rot) * 1e4
            + c.lost_motion * 1e3
            + jnp.sum(w * c.normal_clearance)
            + smooth_loaded_pairs(c, budget_mm=0.2, width_mm=0.02)
        )

    x = (d.modification, err)
    g = jax.grad(f)(x)
    rng = np.random.default_rng(1)
    h = 1e-3
    for _ in range(3):
        v = jax.tree.map(lambda a: jnp.asarray(rng.normal(size=np.shape(a))), x)
        # Angles get small steps, µm and mm their own scale.
        v = (
            jax.tree.map(lambda a: a * 1e-3, v[0]),
            eqx.tree_at(
                lambda e: (
                    e.index_offset,
                    e.indexing,
                    e.setup_phase,
                    e.mandrel_phase,
                    e.disc_offset_phase,
                    e.pin_wheel_offset_phase,
                    e.pin_circle_eccentricity_phase,
                ),
                v[1],
                replace_fn=lambda a: a * 1e-4,
            ),
        )
        plus = jax.tree.map(lambda a, b: a + h * b, x, v)
        minus = jax.tree.map(lambda a, b: a - h * b, x, v)
        fd = (float(f(plus)) - float(f(minus))) / (2 * h)
        ad = sum(float(jnp.sum(a * b)) for a, b in zip(jax.tree.leaves(g), jax.tree.leaves(v), strict=True))
        assert ad == pytest.approx(fd, rel=2e-5, abs=1e-9)


def test_gradients_have_no_nans_for_pins_that_never_touch():
    d = modified()
    metrics = (LostMotion(), RotationErrorPeakToPeak(), LoadedPairs())
    s = cp.sensitivities(d, seed_errors(), positions=pitch_angles(d, 4), metrics=metrics)
    for sens in s.values():
        for leaf in jax.tree.leaves((sens.errors, sens.modification)):
            assert np.all(np.isfinite(np.asarray(leaf)))
    # A rotation modification δ opens both flanks by δ: the lost motion grows by 2δ (exactly without errors; the
    # wheel is turned about the grinding axis, not the bore, so the errors here shift it by ~1e-4).
    assert float(s["lost_motion"].modification.rotation) == pytest.approx(2.0, rel=1e-3)
    exact = cp.sensitivities(d, None, positions=pitch_angles(d, 4))
    assert float(exact["lost_motion"].modification.rotation) == pytest.approx(2.0, rel=1e-9)


# ---------------------------------------------------------------- bad inputs


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(z_pins=26, z_lobes=24, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0), "z_lobes"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=7.5), "K1"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, K1=1.2), "K1"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=22.0, eccentricity=6.0), "undercut"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=24.0, eccentricity=6.0), "overlap"),
        (dict(z_pins=26, pin_circle_radius=-195.0, pin_radius=13.5, eccentricity=6.0), "pin_circle_radius"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=-13.5, eccentricity=6.0), "pin_radius"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=-6.0), "eccentricity"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5), "eccentricity / K1"),
        (dict(z_pins=26.5, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0), "z_pins"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_radius=23.0), "undercut"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_circle_radius=150.0), "K = a z_b / R_Z"),
        # A wheel far from the pin circle (R_Z 12 mm or more away: the teeth's depth 2a) would grind away every tooth.
        (
            dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_circle_radius=207.0),
            "shift: \\+12 mm is not below",
        ),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_circle_radius=1e9), "teeth's depth"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_radius=1.5), "equidistant: -12 mm"),
        (dict(z_pins=26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, analysis=CycloidAnalysis), "analysis"),
    ],
)
def test_bad_geometry_is_rejected(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CycloidPin(**kwargs)


def test_bad_error_shapes_and_laws_are_rejected():
    d = basic()
    with pytest.raises(ValueError, match=r"errors\.infeed: give a scalar or one value per tooth space"):
        clearances(d, CycloidErrors(infeed=np.zeros(26)), 0.1)
    with pytest.raises(ValueError, match=r"errors\.pin_tangential"):
        clearances(d, CycloidErrors(pin_tangential=np.zeros(25)), 0.1)
    with pytest.raises(ValueError, match="unknown error field"):
        clearances(d, {"eccentricty": 1.0}, 0.1)
    with pytest.raises(ValueError, match="Sinusoid"):
        model(d, eccentricity=gearte.Sinusoid(1.0)).sample(jax.random.key(0))
    with pytest.raises(ValueError, match="unknown error source"):
        model(d, eccentricty=gearte.Fixed(1.0))
    with pytest.raises(ValueError, match="half_width"):
        gearte.Uniform.centred(-1.0)
    with pytest.raises(ValueError, match="budget_mm"):
        CycloidAnalysis(budget_mm=-0.2)
    with pytest.raises(ValueError, match="width_mm"):
        CycloidAnalysis(budget_mm=0.0)


# ---------------------------------------------------------------- the drive protocol


def model(drive, **laws) -> gearte.ErrorModel:
    """An error model of the drive: the given laws, every other source fixed at 0."""
    sources = {n: gearte.ErrorSource(laws.pop(n, gearte.Fixed(0.0))) for n in drive.error_sources}
    return gearte.ErrorModel(sources | {n: gearte.ErrorSource(v) for n, v in laws.items()}, drive.error_sources)


def small_tolerances(drive) -> gearte.ErrorModel:
    u = gearte.Uniform.centred
    return model(
        drive,
        dressing_y=u(2.0),
        infeed=u(10.0),
        indexing=u(30 / ARCSEC),
        setup_eccentricity=gearte.Uniform(0.0, 31.5),
        setup_phase=gearte.UniformPhase(),
        pin_radius=u(16.75, -41.75),
        eccentricity=u(20.0),
        pin_tangential=gearte.Sinusoid(gearte.Uniform(0.0, 90.0), gearte.UniformPhase()),
        disc_offset=gearte.Uniform(40.0, 90.0),
        disc_offset_phase=gearte.UniformPhase(),
    )


def test_drive_declares_its_errors_as_deviation_sources():
    d = basic()
    specs = d.error_sources
    assert list(specs) == list(ERROR_FIELDS) and len(specs) == 20
    assert all(s.kind == "deviation" for s in specs.values())
    assert specs["infeed"].shape == (25,) and specs["pin_tangential"].shape == (26,) and specs["eccentricity"].shape == ()
    assert specs["indexing"].unit == "rad" and specs["setup_phase"].unit == "rad" and specs["pin_radius"].unit == "µm"
    assert d.type_name == "cycloid_pin" and not d.linear
    assert list(d.metrics) == ["lost_motion", "lost_motion_min", "peak_to_peak", "loaded_pairs", "loaded_pairs_min"]
    assert d.metrics["loaded_pairs"].quantity == "count" and d.metrics["loaded_pairs"].higher_is_better
    assert "grid of 52 input angles" in d.accuracy()


def test_error_model_draws_are_those_of_0_1():
    """`ErrorModel.sample` draws field i of `CycloidErrors` with fold_in(key, i), as gearte 0.1's cycloid
    tolerances did: check every field against the draw computed directly."""
    d = basic()
    m = small_tolerances(d)
    key = jax.random.fold_in(jax.random.key(3), 5)
    got = m.sample(key)
    for i, name in enumerate(ERROR_FIELDS):
        k = jax.random.fold_in(key, i)
        shape = d.error_sources[name].shape
        if name in ("dressing_y", "infeed", "indexing", "pin_radius", "eccentricity"):
            centre, half = {
                "dressing_y": (0, 2.0),
                "infeed": (0, 10.0),
                "indexing": (0, 30 / ARCSEC),
                "pin_radius": (-41.75, 16.75),
                "eccentricity": (0, 20.0),
            }[name]
            want = centre + half * jax.random.uniform(k, shape, dtype=float, minval=-1.0, maxval=1.0)
        elif name in ("setup_eccentricity", "disc_offset"):
            lo, hi = {"setup_eccentricity": (0.0, 31.5), "disc_offset": (40.0, 90.0)}[name]
            want = lo + (hi - lo) * jax.random.uniform(k, shape, dtype=float)
        elif name in ("setup_phase", "disc_offset_phase"):
            want = 2 * jnp.pi * jax.random.uniform(k, shape, dtype=float)
        elif name == "pin_tangential":
            ka, kp = jax.random.split(k)
            amp = 90.0 * jax.random.uniform(ka, (), dtype=float)
            ph = 2 * jnp.pi * jax.random.uniform(kp, (), dtype=float)
            want = amp * jnp.sin(2 * jnp.pi * jnp.arange(1, 27, dtype=float) / 26 + ph)
        else:
            want = jnp.zeros(shape)
        np.testing.assert_array_equal(np.asarray(got[name]), np.asarray(want), err_msg=name)


def test_response_is_the_sweep_over_the_grid_and_the_metrics_read_it():
    d = modified(analysis=CycloidAnalysis(positions_per_pitch=1))
    angles = np.asarray(d.input_angles())
    np.testing.assert_allclose(angles, revolution_angles(d, 1), rtol=0, atol=0)
    r = d.response(d.errors_dict(seed_errors()))
    s = sweep(d, seed_errors(), angles, normal=False)
    np.testing.assert_allclose(np.asarray(r.lost_motion), np.asarray(s.lost_motion), rtol=1e-12, atol=1e-15)
    u = unit_metrics(d, seed_errors())
    m = d.metrics
    assert float(m["lost_motion"](d, r)) == pytest.approx(float(u["lost_motion_max"]), rel=1e-12)
    assert float(m["lost_motion_min"](d, r)) == pytest.approx(float(u["lost_motion_min"]), rel=1e-12)
    assert float(m["peak_to_peak"](d, r)) == pytest.approx(float(u["rotation_error_p2p"]), rel=1e-12)
    assert float(m["loaded_pairs"](d, r)) == pytest.approx(float(u["loaded_pairs_mean"]), rel=1e-12)
    assert float(m["loaded_pairs"].smooth(d, r)) == pytest.approx(float(u["loaded_pairs_smooth"]), rel=1e-12)
    assert float(m["loaded_pairs_min"](d, r)) == float(u["loaded_pairs_min"])
    # The smooth count tends to the exact one as its width → 0.
    sharp = modified(analysis=CycloidAnalysis(positions_per_pitch=1, width_mm=1e-9))
    assert float(m["loaded_pairs"].smooth(sharp, r)) == pytest.approx(float(u["loaded_pairs_mean"]), abs=1e-6)
    # The trace of a unit for reports: its rotation error over the report's sweep (16 positions per pitch).
    tr = d.trace(seed_errors())
    te = np.asarray(sweep(d, seed_errors(), revolution_angles(d, 16), normal=False).rotation_error)
    np.testing.assert_allclose(tr.te, te, rtol=1e-12)
    assert (tr.max, tr.min, tr.span_revs) == (te.max(), te.min(), "1")


# ---------------------------------------------------------------- Monte Carlo and sensitivities


@pytest.fixture(scope="module")
def mc_drive():
    return modified()


def test_monte_carlo_is_reproducible_and_matches_the_single_reducer(mc_drive):
    d = mc_drive
    tol = small_tolerances(d)
    st = gearte.TEStudy(d, tol, metric=(LostMotion(), LostMotionMin(), RotationErrorPeakToPeak()))
    # Chunks of 2 and 3 blocks: bit-identical. (A chunk of a single block may differ in the last bits: XLA
    # simplifies a one-trip loop, which changes how the Newton iterations are fused.)
    a = gearte.monte_carlo(st, key=3, n_samples=24, block_size=4, chunk_size=8).values
    b = gearte.monte_carlo(st, key=3, n_samples=24, block_size=4, chunk_size=12).values
    np.testing.assert_array_equal(a, b)
    assert np.all(a[:, 0] >= a[:, 1])
    # Sample 5 by hand: draw its errors, analyse them.
    err = tol.sample(jax.random.fold_in(jax.random.key(3), 5))
    m = unit_metrics(d, err)
    assert a[5, 0] == pytest.approx(float(m["lost_motion_max"]), rel=1e-12)
    assert a[5, 2] == pytest.approx(float(m["rotation_error_p2p"]), rel=1e-12)
    # The per-pin outputs of a study (at half a pitch, with normal clearances).
    fn = sample_outputs(d, tol)
    u = fn.unpack(gearte.monte_carlo(fn, key=3, n_samples=8, block_size=4, chunk_size=8).values)
    assert np.all(u["not_converged"] == 0)
    assert u["lost_motion_max"][5] == pytest.approx(float(m["lost_motion_max"]), rel=1e-12)
    at = clearances(d, err, d.pitch / 2)
    assert u["loaded_pairs"][5] == int(loaded_pairs(at, budget_mm=0.2))
    np.testing.assert_allclose(u["normal_clearance"][5], np.asarray(at.normal_clearance), atol=1e-11)  # mm
    # The draws follow their laws (4000 draws: the mean of U(−58.5, −25) has a standard error of 0.15 µm).
    draws = jax.vmap(tol.sample)(jax.random.split(jax.random.key(0), 4000))
    pr = np.asarray(draws["pin_radius"])
    assert pr.min() >= -58.5 and pr.max() <= -25.0 and abs(pr.mean() + 41.75) < 0.5
    amp = np.max(np.abs(np.asarray(draws["pin_tangential"])), axis=1)
    assert amp.max() <= 90.0 and amp.mean() == pytest.approx(45.0, rel=0.05)


def test_tolerance_sensitivities_match_finite_differences_with_common_random_numbers():
    d = modified(analysis=CycloidAnalysis(positions_per_pitch=1))
    u = gearte.Uniform.centred
    tol = model(d, pin_radius=u(16.75, -41.75), eccentricity=u(20.0))
    out = gearte.pathwise_sensitivities(d, tol, LostMotion(), key=9, n_samples=16, chunk=8)
    s = out["lost_motion"]
    rows = {r.label: r.value for r in gradient_rows(s, tol)}
    assert set(rows) == {"pin_radius.centre", "pin_radius.half_width", "eccentricity.centre", "eccentricity.half_width"}
    h = 0.5

    def mean_lm(half, centre=-41.75):
        t = model(d, pin_radius=u(16.75, centre), eccentricity=u(half))
        vals = [float(unit_metrics(d, t.sample(jax.random.fold_in(jax.random.key(9), i)))["lost_motion_max"]) for i in range(16)]
        return np.mean(vals)

    assert s.mean == pytest.approx(mean_lm(20.0), rel=1e-12)
    fd = (mean_lm(20.0 + h) - mean_lm(20.0 - h)) / (2 * h)
    assert rows["eccentricity.half_width"] == pytest.approx(fd, rel=1e-3, abs=1e-10)
    # The pin radius's centre row, the same way (the same draws, the law's centre −41.75 µm moved by ±h): they
    # agree to ~1e-9 here.
    fd = (mean_lm(20.0, -41.75 + h) - mean_lm(20.0, -41.75 - h)) / (2 * h)
    assert rows["pin_radius.centre"] == pytest.approx(fd, rel=1e-6)


# ---------------------------------------------------------------- the optimiser


@pytest.mark.slow
def test_optimiser_keeps_the_lost_motion_within_spec_and_gains_pairs():
    d = modified()
    am = 1 / ARCMIN
    res = gearte.optimise_modification(
        d, None, lost_motion_max=20 * am, radial_clearance_min=0.2, positions=pitch_angles(d, 4), max_steps=60
    )
    assert res.feasible and res.result == gearte.RESULTS.successful
    assert res.lost_motion_max <= 20 * am and res.radial_clearance >= 0.2 - 1e-12
    assert not res.initial.feasible  # the paper's design has ~23′ of lost motion without errors
    assert res.loaded_pairs_mean >= res.initial.loaded_pairs_mean
    # The reported counts are the exact ones at the reported modification.
    m = unit_metrics(res.drive, None, positions=pitch_angles(d, 4))
    assert float(m["loaded_pairs_mean"]) == pytest.approx(res.loaded_pairs_mean)
    assert all(r in ("successful", "max_steps_reached", "nonlinear_max_steps_reached") for s in res.starts for r in s.results)


def test_optimiser_of_another_reducer_traces_nothing():
    # One stage, each reducer's measured errors: the solve is compiled for the stage's structure and shapes (those of
    # the test above: run after it, nothing is compiled here); another reducer traces nothing, and its answer is its own.
    d = modified()
    pos = pitch_angles(d, 4)
    units = [{"eccentricity": 5.0, "pin_radius": -10.0}, {"eccentricity": 12.0, "pin_radius": 4.0}]
    kw = dict(lost_motion_max=20 / ARCMIN, radial_clearance_min=0.2, positions=pos, starts=[(-0.1, 0.3)], max_steps=60, throw=False)
    first = gearte.optimise_modification(d, units[0], **kw)
    with traces() as seen:
        second = gearte.optimise_modification(d, units[1], **kw)
    assert not seen, dict(seen)  # neither the solve (`_solve_penalised`) nor anything else
    assert second.starts[0].end != first.starts[0].end
    # Its counts are the exact ones of its own errors at its modification.
    m = unit_metrics(second.drive, units[1], positions=pos)
    assert float(m["lost_motion_max"]) == pytest.approx(second.lost_motion_max, rel=1e-12)
    assert float(m["loaded_pairs_mean"]) == pytest.approx(second.loaded_pairs_mean, rel=1e-12)
    # The first reducer again: exactly its own path (nothing of the second kept in the compiled solve).
    again = gearte.optimise_modification(d, units[0], **kw)
    assert [(s.end, s.results, s.steps) for s in again.starts] == [(s.end, s.results, s.steps) for s in first.starts]


def test_optimiser_checks_its_arguments():
    d = modified()
    with pytest.raises(ValueError, match="lost_motion_max"):
        gearte.optimise_modification(d, None, lost_motion_max=-1.0)
    with pytest.raises(ValueError, match="must exceed lost_motion_min"):
        gearte.optimise_modification(d, None, lost_motion_max=1e-3, lost_motion_min=2e-3)
    with pytest.raises(ValueError, match="CycloidPin"):
        gearte.optimise_modification(gearte.Planetary2KH(12, 36, 84, module=1.0, n_planets=3), None, lost_motion_max=1e-3)


# ---------------------------------------------------------------- gearte run


def run(*args):
    return cli.main([str(a) for a in args])


@pytest.mark.slow
def test_example_runs_and_writes_every_output(example_run):
    # The contract's short run of this example (tests/test_contract.py), shared: one `gearte run` per worker.
    out, printed = example_run(ROOT / "examples" / "cycloid_yao2001_modified.toml", samples=CONTRACT_SAMPLES, seed=CONTRACT_SEED)
    assert sorted(p.name for p in out.iterdir()) == [
        "clearance_per_pin.png",
        "clearance_vs_input.png",
        "curves.npz",
        "histogram.png",
        "monte_carlo.png",
        "report.md",
        "rotation_error.png",
        "samples.npz",
        "summary.json",
        "trace.png",
    ]
    s = json.loads((out / "summary.json").read_text())
    for key in (
        "te",
        "pairs",
        "contact_pair",
        "loaded_pairs",
        "deformation_budget_mm",
        "lost_motion_arcmin",
        "rotation_error_p2p_arcsec",
        "monte_carlo",
        "sensitivities",
        "tolerance_sensitivities",
        "optimised_modification",
    ):
        assert key in s, key
    assert len(s["pairs"]) == 26 and s["deformation_budget_mm"] == 0.2 and s["loaded_pairs_out_of"] == 13
    contact = s["contact_pair"]["pin"]
    row = s["pairs"][contact - 1]
    assert row["on_driving_flank"] and row["tangential_clearance_mm"] == pytest.approx(0.0, abs=1e-12)
    assert abs(row["normal_clearance_mm"]) < 1e-9
    assert s["loaded_pairs"] == sum(p["loaded"] for p in s["pairs"])
    assert sum(p["on_driving_flank"] for p in s["pairs"]) == 13
    assert s["sweep"]["all_solves_converged"]
    # The numbers agree with the library called directly.
    d = modified()
    c = clearances(d, seed_errors(), d.pitch / 2)
    assert contact == int(c.contact_pin) + 1
    assert s["lost_motion_at_input_angle_arcmin"] == pytest.approx(float(c.lost_motion) * ARCMIN, rel=1e-12)
    opt = s["optimised_modification"]
    assert opt["best"]["feasible"]
    # Every row's wheel is the pin circle and pin modified (R_z = 195, r_z = 13.5 mm); a feasible row meets the
    # constraints as the summary states them; the best is the feasible row with the most loaded pairs.
    c = opt["constraints"]
    for r in [opt["best"], opt["initial"], *opt["starts"]]:
        assert r["wheel_pin_circle_radius_mm"] == pytest.approx(195.0 + r["shift_mm"], rel=1e-14)
        assert r["wheel_pin_radius_mm"] == pytest.approx(13.5 + r["equidistant_mm"], rel=1e-14)
        assert r["radial_clearance_mm"] == pytest.approx(r["equidistant_mm"] - r["shift_mm"], rel=1e-12)
        if r["feasible"]:
            assert c["lost_motion_min_arcmin"] - 1e-9 <= r["lost_motion_min_arcmin"]
            assert r["lost_motion_max_arcmin"] <= c["lost_motion_max_arcmin"] * (1 + 1e-9)
            assert r["radial_clearance_mm"] >= c["radial_clearance_min_mm"] - 1e-12
    feasible = [r for r in opt["starts"] if r["feasible"]]
    assert feasible and opt["best"]["loaded_pairs_mean"] >= max(r["loaded_pairs_mean"] for r in feasible) - 1e-9
    # The study metric's statistics are those of the Monte Carlo's lost motion.
    assert s["te"]["metric"] == "lost_motion" and s["te"]["mean"] == pytest.approx(
        s["monte_carlo"]["lost_motion_max_arcmin"]["mean"], rel=1e-12
    )
    with np.load(out / "curves.npz") as z:  # the reference reducer's curves
        assert z["pitch_tangential_clearance_mm"].shape == (64, 26) and z["lost_motion_arcmin"].ndim == 1
    report = (out / "report.md").read_text()
    for needed in ("contacting pair", "loaded pairs", "lost motion", "Monte Carlo", "float64"):
        assert needed in report, needed
    assert "lost_motion" in printed


@pytest.mark.slow
def test_unmodified_example_has_more_loaded_pairs(tmp_path):
    mod = _summary(tmp_path, "cycloid_yao2001_modified.toml")
    unmod = _summary(tmp_path, "cycloid_yao2001_unmodified.toml")
    # The paper's reducer with the unmodified profile interferes at θ_T when its disc centre is held at the paper's
    # fixed offset, so its rigid loaded-pair count is that of an interfering disc; a disc floating within that
    # offset (its bearing clearance) clears it and then carries more pairs than the modified one.
    assert unmod["lost_motion_at_input_angle_arcmin"] < 0 < mod["lost_motion_at_input_angle_arcmin"]
    floating = unmod["disc_centre"]["loaded_pairs_floating"]
    assert floating["positions"] > 0 and floating["min"] > mod["loaded_pairs"]
    assert unmod["lost_motion_arcmin"] < mod["lost_motion_arcmin"]
    # Beside the headline, a warning says which share of the batch interferes (every unit here: the errors are the
    # reducer analysed's); the modified reducer has none.
    share = unmod["monte_carlo"]["interference_fraction"]
    assert share == 1.0 and unmod["warnings"][0].startswith("100.00 % of the reducers interfere somewhere on the grid")
    assert mod["monte_carlo"]["interference_fraction"] == 0.0 and "warnings" not in mod


def _summary(tmp_path, name):
    text = (ROOT / "examples" / name).read_text()
    text = text.split("# Monte Carlo:")[0]  # the reducer analysed only (every error law left out): fast
    p = tmp_path / name
    p.write_text(text)
    out = tmp_path / (name + ".out")
    assert run("run", p, "--out", out, "--samples", 8) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.parametrize(
    "edit, match",
    [
        (("z_lobes = 25", "z_lobes = 24"), "z_lobes"),
        (("eccentricity_mm = 6.0", "eccentricity_mm = 8.0"), "K1"),
        (("pin_radius_mm = 13.880", "pin_radius_mm = 25.0"), "undercut"),
        (("pin_radius_mm = 13.5 ", "pin_radius_mm = -13.5 "), "pin_radius_mm"),
        (("deformation_budget_mm = 0.2", "deformation_budget_mm = -0.2"), "deformation_budget_mm"),
        (("disc_offset_um = 57.5", "disc_ofset_um = 57.5"), "disc_ofset_um"),
        (("disc_offset_um = 57.5", "disc_offset_mm = 0.0575"), "disc_offset_um"),
        (("infeed_um = 0 ", "infeed_um = [1, 2] "), "infeed_um"),
        (
            ('value = { law = "uniform", low_um = -58.5, high_um = -25 }', 'value = { law = "uniform", low_um = -25, high_um = -58.5 }'),
            "pin_radius.value] high",
        ),
        (
            (
                '[errors.eccentricity]\nvalue = { law = "uniform", half_width_um = 20 }',
                '[errors.eccentricity]\nvalue = { law = "sinusoid", amplitude_um = 20 }',
            ),
            "sinusoid",
        ),
        (("lost_motion_max_arcmin = 25", "lost_motion_max_arcmin = -1"), "lost_motion_max_arcmin"),
        (("positions_per_pitch = 2 ", "positions_per_pitch = 0 "), "positions_per_pitch"),
        (('metric = "lost_motion"', 'metric = "lost_motoin"'), "lost_motion"),
    ],
)
def test_bad_config_exits_2_naming_the_field(tmp_path, capsys, edit, match):
    text = (ROOT / "examples" / "cycloid_yao2001_modified.toml").read_text()
    old, new = edit
    assert old in text, old
    p = tmp_path / "bad.toml"
    p.write_text(text.replace(old, new, 1))
    out = tmp_path / "never"
    assert run("run", p, "--out", out) == 2
    err = capsys.readouterr().err
    assert match in err, err
    assert not out.exists()
    assert run("check", p) == 2


def test_check_accepts_the_examples(capsys):
    for name in ("cycloid_yao2001_modified.toml", "cycloid_yao2001_unmodified.toml"):
        assert run("check", ROOT / "examples" / name) == 0
    assert "OK" in capsys.readouterr().out


def test_new_error_values_and_modifications_do_not_recompile():
    @eqx.filter_jit
    @eqx.debug.assert_max_traces(max_traces=1)
    def lost_motion(drive, errors):
        return LostMotion()(drive, drive.response(errors))

    grid = CycloidAnalysis(positions_per_pitch=1)
    for k, mod in enumerate((CycloidModification(), CycloidModification(-0.2, 0.4), CycloidModification(0.1, 0.3, 1e-4))):
        d = basic(modification=mod, analysis=grid)
        e = d.errors_dict(CycloidErrors(pin_radius=-5.0 * k, indexing=np.full(25, 1e-5 * k), disc_offset=3.0 * k))
        lost_motion(d, e)


def _reference_rotations(drive, err, theta_T):
    """Rotation to contact of every pin, pin by pin with a bracketing root search (SciPy's brentq) on the placed
    flank of Yao & Liang's eqs. 1–2 written out in NumPy (an independent restatement of the model's notes):
    (rotation, reachable, interference) per pin; rotation NaN where the pin cannot touch."""
    zb, za = drive.z_pins, drive.z_lobes
    um = 1e-3
    R, a, r = float(drive.pin_circle_radius), float(drive.eccentricity), float(drive.pin_radius)
    RZ, rZ = float(drive.wheel_pin_circle_radius), float(drive.wheel_pin_radius)
    m = float(drive.modification.rotation)
    e = {k: np.asarray(getattr(err, k), dtype=float) for k in ERROR_FIELDS}
    R1, r1 = R + e["pin_circle_radius"] * um, r + e["pin_radius"] * um
    K = a * zb / RZ
    ex = (e["setup_eccentricity"] * np.cos(e["setup_phase"]) + e["mandrel_runout"] * np.cos(e["mandrel_phase"])) * um
    ey = (e["setup_eccentricity"] * np.sin(e["setup_phase"]) + e["mandrel_runout"] * np.sin(e["mandrel_phase"])) * um
    out = []
    for j in range(zb):
        psi0 = theta_T + 2 * np.pi * j / zb
        psi = psi0 + e["pin_tangential"][j] * um / R1
        rad = R1 + e["pin_radial"][j] * um
        ob = (
            np.array(
                [
                    e["pin_wheel_offset"] * np.cos(e["pin_wheel_offset_phase"]),
                    -(a + e["eccentricity"] * um) / um + e["pin_wheel_offset"] * np.sin(e["pin_wheel_offset_phase"]),
                ]
            )
            * um
        )
        c = (
            ob
            + rad * np.array([-np.sin(psi), np.cos(psi)])
            - e["disc_offset"] * um * np.array([np.cos(e["disc_offset_phase"]), np.sin(e["disc_offset_phase"])])
        )
        phi_nom = (psi0 - 2 * np.pi * j + np.pi) % (2 * np.pi) - np.pi
        s = 1.0 if phi_nom >= -1e-9 else -1.0
        n = int(np.floor((psi0 - 2 * np.pi * j) / (2 * np.pi) + 1e-9 + 0.5)) % za
        beta = 2 * np.pi * n / za + e["index_offset"] + e["indexing"][n]

        def locus(t, s=s, n=n, beta=beta):
            phi = s * t
            u, v = phi / za, phi * zb / za
            S = np.sqrt(1 + K * K - 2 * K * np.cos(phi))
            d = rZ - r1
            p = np.array(
                [
                    RZ * np.sin(u) - a * np.sin(v) - d * (np.sin(u) - K * np.sin(v)) / S,
                    RZ * np.cos(u) - a * np.cos(v) - d * (np.cos(u) - K * np.cos(v)) / S,
                ]
            )
            p = np.array([[np.cos(s * m), np.sin(s * m)], [-np.sin(s * m), np.cos(s * m)]]) @ p  # turned by −s m
            p = p + np.array([e["dressing_x"], e["dressing_y"] + e["infeed"][n]]) * um
            p = np.array([[np.cos(beta), np.sin(beta)], [-np.sin(beta), np.cos(beta)]]) @ p  # turned by −β
            return p - np.array([ex, ey])

        h = lambda t, c=c, locus=locus: np.hypot(*locus(t)) - np.hypot(*c)
        interference, reachable = h(0.0) > 0, h(np.pi) >= 0
        if interference or not reachable:
            out.append((np.nan, reachable, interference))
            continue
        t = brentq(h, 0.0, np.pi, xtol=1e-15, rtol=1e-15, maxiter=200)
        q = locus(t)
        rot = np.arctan2(c[1], c[0]) - np.arctan2(q[1], q[0]) - theta_T * zb / za
        out.append(((rot + np.pi) % (2 * np.pi) - np.pi, reachable, interference))
    return out


@pytest.mark.parametrize("make", [basic, modified])
def test_vectorised_contact_solve_matches_a_pin_by_pin_root_search(make):
    """The contact solve, vectorised over pins, input angles and reducers, against a pin-by-pin, angle-by-angle
    bracketing root search on the model written out in NumPy, for random reducers of the examples' error sizes and a
    grid with pins exactly at a tooth-space bottom and at a tooth tip (the folds of the solve)."""
    d = make()
    rng = np.random.default_rng(12)
    thetas = revolution_angles(d, 2)[[0, 1, 7, 30]]
    for _ in range(3):
        err = CycloidErrors(
            dressing_x=rng.uniform(-2, 2), dressing_y=rng.uniform(-2, 2), infeed=rng.uniform(-10, 10, 25),
            indexing=rng.uniform(-30, 30, 25) / ARCSEC, setup_eccentricity=rng.uniform(0, 31.5), setup_phase=rng.uniform(0, 2 * np.pi),
            mandrel_runout=5.0, pin_circle_radius=rng.uniform(-14.25, 14.25), pin_radius=rng.uniform(-58.5, -25),
            eccentricity=rng.uniform(-20, 20), pin_tangential=90 * np.sin(2 * np.pi * np.arange(26) / 26 + rng.uniform(0, 2 * np.pi)),
            pin_radial=rng.uniform(-5, 5, 26), disc_offset=rng.uniform(40, 90), disc_offset_phase=rng.uniform(0, 2 * np.pi),
            pin_wheel_offset=rng.uniform(12, 33), pin_wheel_offset_phase=rng.uniform(0, 2 * np.pi),
        )  # fmt: skip
        s = sweep(d, err, thetas, normal=False)
        assert bool(jnp.all(s.converged))
        for k, th in enumerate(thetas):
            ref = _reference_rotations(d, err, float(th))
            rot = np.asarray(s.rotation_to_contact[k])
            for j, (r_ref, reach, interf) in enumerate(ref):
                assert bool(s.reachable[k, j]) == reach and bool(s.interference[k, j]) == interf
                if reach and not interf:
                    assert abs(rot[j] - r_ref) < 1e-10, (k, j, rot[j], r_ref)


def test_polynomial_sines_and_arctangent_agree_with_numpy():
    """The solve's float64 kernels (`sincos`, `atan2`, and `_trig`'s unreduced series for the flank angles of
    t ∈ [0, π] and a little beyond) against NumPy's library functions: a few units in the last place."""
    from collections import namedtuple

    from gearte.drives.cycloid_pin_solve import _T_MARGIN, _trig, atan2, sincos

    sincos, atan2, trig = jax.jit(sincos), jax.jit(atan2), jax.jit(_trig, static_argnums=0)
    Lobes = namedtuple("Lobes", "z_lobes z_pins")

    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-40.0, 40.0, 4000), np.arange(-8, 9) * (np.pi / 4), [0.0, 1e-300, 1e6 + 0.5]])
    s, c = map(np.asarray, sincos(jnp.asarray(x)))
    assert np.max(np.abs(s - np.sin(x))) < 4e-16 and np.max(np.abs(c - np.cos(x))) < 4e-16
    y, z = rng.normal(size=4000) * 10.0 ** rng.uniform(-6, 3, 4000), rng.normal(size=4000)
    y, z = np.concatenate([y, [0.0, 1.0, -1.0, 0.0]]), np.concatenate([z, [1.0, 0.0, 0.0, -1.0]])
    assert np.max(np.abs(np.asarray(atan2(jnp.asarray(y), jnp.asarray(z))) - np.arctan2(y, z))) < 1e-15
    t = np.linspace(-_T_MARGIN, np.pi + _T_MARGIN, 20001)
    for za in (3, 4, 8, 9, 25, 39):  # short series where the ranges allow (z_a ≥ 9), `sincos` otherwise
        got = np.asarray(trig(Lobes(za, za + 1), jnp.asarray(t)))
        u, v = t / za, t * (za + 1) / za
        want = np.stack([np.sin(u), np.cos(u), np.sin(v), np.cos(v)])
        assert np.max(np.abs(got - want)) < 1.2e-15, za


def test_checked_errors_takes_plain_numbers_arrays_and_lists_of_traced_values():
    """Per-pin fields may come as a scalar, an array or a list, of numbers or of JAX values (traced ones too, under jit
    and grad); each is broadcast to one value per pin, with the same result."""
    d = basic()

    def total(x):
        return jnp.sum(cp.checked_errors(d, {"pin_radial": [x] * d.z_pins, "infeed": x}).pin_radial)

    assert float(jax.jit(total)(1.5)) == 1.5 * d.z_pins
    assert float(jax.grad(total)(1.5)) == d.z_pins
    for given in (2.0, [2.0], np.full(d.z_pins, 2.0), jnp.full(d.z_pins, 2.0), [jnp.asarray(2.0)] * d.z_pins):
        e = cp.checked_errors(d, {"pin_radial": given})
        np.testing.assert_array_equal(np.asarray(e.pin_radial), np.full(d.z_pins, 2.0))
