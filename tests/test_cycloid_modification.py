"""The cycloid-pin profile-modification optimiser (`gearte.optimise.modification`): its lower bound on the lost motion,
and the rotation modification in its result and summary. A file apart from tests/test_cycloid.py (over 600 lines); the
same scheduling group (tests/conftest.py)."""

import math

import equinox as eqx
import jax.numpy as jnp
import pytest

import gearte
from gearte.drives.cycloid_pin import CycloidAnalysis, CycloidPin, pitch_angles, unit_metrics
from gearte.optimise.modification import ModificationSpec, modification_report, modification_summary

ARCMIN = 180 * 60 / math.pi  # ′ per rad
ARCSEC = 180 * 3600 / math.pi  # ″ per rad


def test_the_lower_bound_on_the_lost_motion_lifts_a_start_below_it():
    """With a deformation budget of 50 mm every driving pair is loaded anywhere near the start, so the loaded-pair
    surrogate is flat there and only the constraints move the modification. The start (ΔR_Z, Δr_Z) = (0, 0.15) mm
    has a lost motion of about 2 Δr_Z / (a z_a) = 0.3/150 rad = 6.9′, below the required 12′: the lower bound alone
    lifts it (a penalty on lost_motion_min below its bound, none above), to a feasible modification."""
    d = CycloidPin(26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, analysis=CycloidAnalysis(budget_mm=50.0))
    pos = pitch_angles(d, 4)
    start = (0.0, 0.15)
    own = CycloidPin(26, pin_circle_radius=195.0, pin_radius=13.5, eccentricity=6.0, wheel_pin_radius=13.65, analysis=d.analysis)
    at_start = unit_metrics(own, None, positions=pos)
    assert float(at_start["lost_motion_max"]) * ARCMIN == pytest.approx(2 * 0.15 / (6.0 * 25) * ARCMIN, rel=0.01)
    lo, hi = 12.0, 20.0
    r = gearte.optimise_modification(
        d,
        None,
        lost_motion_max=hi / ARCMIN,
        lost_motion_min=lo / ARCMIN,
        radial_clearance_min=0.1,
        positions=pos,
        starts=[start],
        max_steps=60,
        throw=False,
    )
    assert r.result == gearte.RESULTS.successful and r.feasible
    assert lo <= r.lost_motion_min * ARCMIN <= r.lost_motion_max * ARCMIN <= hi * (1 + 1e-9)
    assert r.radial_clearance >= 0.1 - 1e-12
    # The reported lost motion is the exact one at the reported modification.
    m = unit_metrics(r.drive, None, positions=pos)
    assert float(m["lost_motion_min"]) == pytest.approx(r.lost_motion_min, rel=1e-12)
    # A modification whose lost motion reaches below the bound somewhere is infeasible, however the rest holds: the
    # drive's own (Δr_Z = 0.15 mm, 6.88′ … 6.90′ over the positions) against a bound of 6.89′.
    r = gearte.optimise_modification(
        own,
        None,
        lost_motion_max=hi / ARCMIN,
        lost_motion_min=6.89 / ARCMIN,
        radial_clearance_min=0.1,
        positions=pos,
        starts=[start],
        max_steps=60,
        throw=False,
    )
    assert r.initial.lost_motion_min * ARCMIN < 6.89 < r.initial.lost_motion_max * ARCMIN <= hi
    assert r.initial.radial_clearance == pytest.approx(0.15, rel=1e-12) and not r.initial.feasible


def _optimise(drive, pos, **options):
    """`optimise_modification` of an error-free `drive` at `pos` for a lost motion in [7′, 20′] and a radial clearance
    ≥ 0.1 mm, the result returned whether or not feasible."""
    return gearte.optimise_modification(
        drive,
        None,
        lost_motion_max=20.0 / ARCMIN,
        lost_motion_min=7.0 / ARCMIN,
        radial_clearance_min=0.1,
        positions=pos,
        throw=False,
        **options,
    )


def _stage_with_its_own_rotation():
    """26 pins on R_z = 195 mm, a = 6 mm (K₁ = 0.8), wheel pins 0.15 mm larger (the equidistant), a 10″ rotation
    modification of its own, and a 50 mm deformation budget (every driving pin counts as loaded)."""
    return CycloidPin(
        26,
        pin_circle_radius=195.0,
        pin_radius=13.5,
        eccentricity=6.0,
        wheel_pin_radius=13.65,
        rotation_modification=10.0 / ARCSEC,
        analysis=CycloidAnalysis(budget_mm=50.0),
    )


def test_the_rotation_modification_in_the_result_and_its_summary():
    """With `rotation`, x = (ΔR_Z, Δr_Z, δ·R_z) in mm: the result's modification turns each flank by δ = x₂ / R_z (rad),
    its lost motion carries the first-order 2δ on top of 2 Δr_Z / (a z_a), and the summary gives δ in ″ for the
    optimum, the drive's own modification (10″ here) and every start."""
    R = 195.0
    own = _stage_with_its_own_rotation()
    pos = pitch_angles(own, 4)
    start = (0.0, 0.15, 20.0 / ARCSEC * R)  # δ = 20″
    spec = ModificationSpec(
        lost_motion_max_arcmin=20.0, lost_motion_min_arcmin=7.0, radial_clearance_min_mm=0.1, rotation=True, positions_per_pitch=4
    )
    r = _optimise(own, pos, rotation=True, starts=[start], max_steps=60)
    assert r.feasible and len(r.starts) == 1
    end = r.starts[0].end
    assert len(end) == 3 and float(r.modification.rotation) == pytest.approx(end[2] / R, rel=1e-14)
    assert (float(r.modification.shift), float(r.modification.equidistant)) == pytest.approx(end[:2], rel=1e-14)
    first_order = lambda dR, dr, delta: (2 * (dr - dR * 0.6) / (6.0 * 25) + 2 * delta) * ARCMIN  # √(1 − K₁²) = 0.6
    # The drive's own modification (x₂ = 10″ · R): 6.875′ + 20″ = 7.21′, to first order.
    assert r.initial.end == pytest.approx((0.0, 0.15, 10.0 / ARCSEC * R), rel=1e-14)
    assert r.initial.lost_motion_max * ARCMIN == pytest.approx(first_order(0.0, 0.15, 10.0 / ARCSEC), rel=0.01)
    assert r.lost_motion_max * ARCMIN == pytest.approx(first_order(end[0], end[1], end[2] / R), rel=0.02)
    m = unit_metrics(r.drive, None, positions=pos)
    assert float(m["lost_motion_max"]) == pytest.approx(r.lost_motion_max, rel=1e-12)

    s = modification_summary(own, spec, r)
    assert s["best"]["rotation_arcsec"] == pytest.approx(end[2] / R * ARCSEC, rel=1e-12)
    assert s["initial"]["rotation_arcsec"] == pytest.approx(10.0, rel=1e-12)
    row = s["starts"][0]
    assert row["start"] == pytest.approx(list(start), rel=1e-14) and row["rotation_arcsec"] == pytest.approx(end[2] / R * ARCSEC, rel=1e-12)
    assert s["best"]["wheel_pin_radius_mm"] == pytest.approx(13.5 + end[1], rel=1e-14) and s["result"] == "successful"
    # Without `rotation` the rows have no rotation (x is (ΔR_Z, Δr_Z)); a stage's own rotation is held (next test).
    plain = eqx.tree_at(lambda d: d.modification.rotation, own, jnp.zeros(()))
    flat = ModificationSpec(
        lost_motion_max_arcmin=20.0, lost_motion_min_arcmin=7.0, radial_clearance_min_mm=0.1, rotation=False, positions_per_pitch=4
    )
    r2 = _optimise(plain, pos, starts=[start[:2]], max_steps=60)
    s2 = modification_summary(plain, flat, r2)
    assert all("rotation_arcsec" not in row for row in (s2["best"], s2["initial"], *s2["starts"]))
    assert len(r2.starts[0].end) == 2 and len(r2.initial.end) == 2


def test_without_rotation_the_stages_own_rotation_is_held():
    """`rotation=False` optimises (ΔR_Z, Δr_Z) with the stage's own rotation modification (10″) kept: its `initial` row
    is the stage as designed (lost motion 6.875′ + 2 × 10″ = 7.21′ to first order, the unit's own metrics exactly), the
    answer keeps δ = 10″, and the summary and report say it is held. (It had been dropped: `initial` read 6.88′ and a
    7′ lower bound that the stage meets marked it infeasible.)"""
    own = _stage_with_its_own_rotation()
    pos = pitch_angles(own, 4)
    r = _optimise(own, pos, starts=[(0.0, 0.15)], max_steps=60)
    designed = unit_metrics(own, None, positions=pos)
    assert r.initial.lost_motion_max == pytest.approx(float(designed["lost_motion_max"]), rel=1e-12)
    assert r.initial.lost_motion_min == pytest.approx(float(designed["lost_motion_min"]), rel=1e-12)
    assert r.initial.lost_motion_max * ARCMIN == pytest.approx((2 * 0.15 / (6.0 * 25) + 2 * 10.0 / ARCSEC) * ARCMIN, rel=0.01)
    assert r.initial.feasible  # 7.21′ meets the 7′ lower bound
    assert float(r.modification.rotation) == pytest.approx(10.0 / ARCSEC, rel=1e-14)
    assert float(unit_metrics(r.drive, None, positions=pos)["lost_motion_max"]) == pytest.approx(r.lost_motion_max, rel=1e-12)
    flat = ModificationSpec(
        lost_motion_max_arcmin=20.0, lost_motion_min_arcmin=7.0, radial_clearance_min_mm=0.1, rotation=False, positions_per_pitch=4
    )
    s = modification_summary(own, flat, r)
    assert s["rotation_held_arcsec"] == pytest.approx(10.0, rel=1e-12)
    assert "the rotation modification held at the design's 10″" in "\n".join(modification_report(own, s))
    # The default starts aim the shift and equidistant at the middle of the spec less the held rotation's 2δ (first
    # order: 2(Δr_Z − ΔR_Z·0.6)/(a z_a) + 2δ = 13.5′), not past it by 2δ.
    r2 = _optimise(own, pos, max_steps=1)
    assert len(r2.starts) == 6  # the design, then five splits between shift and equidistant
    for st in r2.starts[1:]:
        dR, dr = st.start
        assert (2 * (dr - dR * 0.6) / (6.0 * 25) + 2 * 10.0 / ARCSEC) * ARCMIN == pytest.approx(13.5, rel=1e-9)
