"""What `gearte run` writes for the RV (K-H-V) reducer (`gearte.drives.rv_khv_outputs`), against independent references.

References: the discrete spectrum of known sinusoids (and of one sampled above the grid's Nyquist order); the
drive's orders from its kinematics; the closed-form lost motion of undersize pins (tests/test_rv.py derives it);
the flank a pin must carry each load on (the sign of its lever arm a z_c sin φ / S); the Monte Carlo statistics
against NumPy on known values; and a whole `study_outputs` drawn into a folder.
"""

from __future__ import annotations

import json
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gearte.core.units import ARCMIN_PER_RAD, ARCSEC_PER_RAD
from gearte.drives.protocol import AbstractStudyContext, Eccentricity
from gearte.drives.rv_khv import RVKHV, RVLostMotion, RVPeakToPeak
from gearte.drives.rv_khv_contacts import DEFLECTION_MM
from gearte.drives.rv_khv_outputs import (
    LOADED_FRACTION,
    alias_order,
    contact_groups,
    drive_orders,
    loaded_contacts,
    monte_carlo_summary,
    order_spectrum,
    reference_unit,
    resolution,
    spectrum_lines,
    study_outputs,
    typical_index,
)
from gearte.drives.rv_khv_report import report
from gearte.studies.montecarlo import statistics

ZP, R, RPIN, A = 20, 50.0, 2.5, 1.5
ZS, ZG, RC = 12, 24, 30.0
POINTS = 24  # the grid and the report grid alike: one compiled solve serves every test


@pytest.fixture(scope="module")
def drive() -> RVKHV:
    return RVKHV(
        ZP,
        pin_circle_radius=R,
        pin_radius=RPIN,
        eccentricity=A,
        z_sun=ZS,
        z_planet=ZG,
        crank_circle_radius=RC,
        points=POINTS,
        trace_points=POINTS,
    )


def pin_angles(theta_o: np.ndarray, disc: int) -> np.ndarray:
    """φ of every pin (rows: output angles) from disc `disc`'s eccentric, in (−π, π]: the eccentric points along +y at
    θ_o = 0 (disc 2 opposite) and turns −z_c θ_o in the fixed frame; pin j sits at +y turned 2πj/z_p."""
    psi = (ZP - 1) * theta_o[:, None] - math.pi * disc + 2 * math.pi * np.arange(ZP)[None, :] / ZP
    return np.mod(psi + math.pi, 2 * math.pi) - math.pi


def lever(theta_o: np.ndarray, disc: int) -> np.ndarray:
    """Lever arms a z_c sin φ / S of the pins' lines of action about the disc centre (> 0: driving flank)."""
    K = A * ZP / R
    phi = pin_angles(theta_o, disc)
    return A * (ZP - 1) * np.sin(phi) / np.sqrt(1 + K * K - 2 * K * np.cos(phi))


UNDERSIZE_UM = 6.0


@pytest.fixture(scope="module")
def undersize(drive):
    """The reference unit with undersize pins (Δr′ = −6 µm), no other error: (summary, curves)."""
    return reference_unit(drive, {"pin_radius": -UNDERSIZE_UM}, index=0)


# ---------------------------------------------------------------- spectrum


@pytest.mark.parametrize("p", [24, 25])
def test_spectrum_of_known_sinusoids(p):
    th = 2 * np.pi * np.arange(p) / p
    te = 0.7 + 3.0 * np.cos(5 * th + 0.4) + 1.5 * np.sin(2 * th)
    orders, amp, phase = order_spectrum(te)
    assert orders[-1] == p // 2
    expect = np.zeros(orders.size)
    expect[[0, 5, 2]] = [0.7, 3.0, 1.5]
    np.testing.assert_allclose(amp, expect, atol=1e-12)
    assert phase[5] == pytest.approx(0.4, abs=1e-12)
    assert phase[2] == pytest.approx(-np.pi / 2, abs=1e-12)  # sin = cos(· − π/2)
    if p % 2 == 0:  # the Nyquist order: cos(π n) has amplitude 1, not 2
        _, amp_n, _ = order_spectrum(np.cos(p / 2 * th))
        assert amp_n[-1] == pytest.approx(1.0, abs=1e-12)


def test_an_order_above_the_grid_appears_at_its_alias():
    """The pin-mesh order of the example (z_c z_p = 1560) sampled at its 389 angles shows at order 4 = 1560 − 4 × 389."""
    p = 389
    th = 2 * np.pi * np.arange(p) / p
    _, amp, _ = order_spectrum(2.0 * np.cos(1560 * th + 1.0))
    assert int(np.argmax(amp)) == alias_order(1560, p) == 4
    assert amp[4] == pytest.approx(2.0, abs=1e-9)
    assert alias_order(1800, p) == 145  # 1800 = 5 × 389 − 145
    assert alias_order(7, p) == 7


def test_drive_orders_and_trace_lines_from_the_kinematics(drive):
    # i = 1 + z_p z_g / z_s = 41; planets in the fixed frame turn −z_c θ_o, cranks in the carrier −z_p θ_o.
    assert dict((o, n) for n, o in drive_orders(drive)).keys() == {1, 19, 20, 41, 19 * 20, 20 * 24}
    th = 2 * np.pi * np.arange(POINTS) / POINTS
    lines = dict(spectrum_lines(drive, 1e-5 + 2e-5 * np.cos(th) + 4e-5 * np.cos(3 * th), count=2))
    assert lines == pytest.approx({"0 (constant)": 1e-5, "1/41": 2e-5, "3/41": 4e-5}, abs=1e-18)


# ---------------------------------------------------------------- the reference unit


def test_reference_unit_without_errors_has_no_te_and_no_play(drive):
    s, _ = reference_unit(drive, None)
    ref = s["reference_unit"]
    assert ref["te_p2p_forward_arcsec"] == pytest.approx(0.0, abs=1e-7)
    assert ref["te_p2p_reverse_arcsec"] == pytest.approx(0.0, abs=1e-7)
    assert ref["lost_motion_arcmin"]["max"] == pytest.approx(0.0, abs=1e-9)
    assert ref["zero_lost_motion_share"] == 1.0 and not ref["negative_lost_motion"]
    assert ref["solves"] == {"count": 2 * POINTS, "successful": 2 * POINTS}
    assert s["spectrum"]["mean_arcsec"] == pytest.approx(0.0, abs=1e-7)
    assert max(ln["amplitude_arcsec"] for ln in s["spectrum"]["lines"]) == pytest.approx(0.0, abs=1e-7)


def test_reference_unit_lost_motion_of_undersize_pins(undersize):
    """The closed form of tests/test_rv.py: c (1/max l⁺ + 1/max |l⁻|) / (1 + r_c / (z_c r_g)) at every angle."""
    s, c = undersize
    th = 2 * np.pi * np.arange(POINTS) / POINTS
    lev = np.concatenate([lever(th, 0), lever(th, 1)], axis=1)
    rg = RC * ZG / (ZS + ZG)
    ref = 1e-3 * UNDERSIZE_UM * (1 / np.max(np.where(lev > 0, lev, 0), axis=1) + 1 / np.max(np.where(lev < 0, -lev, 0), axis=1))
    ref = ref / (1 + RC / ((ZP - 1) * rg)) * ARCMIN_PER_RAD
    lm = s["reference_unit"]["lost_motion_arcmin"]
    assert lm["max"] == pytest.approx(ref.max(), rel=2e-3)
    assert lm["min"] == pytest.approx(ref.min(), rel=2e-3)
    assert lm["mean"] == pytest.approx(ref.mean(), rel=2e-3)
    assert s["reference_unit"]["lost_motion_arcsec"]["max"] == pytest.approx(60 * lm["max"], rel=1e-12)
    assert s["reference_unit"]["zero_lost_motion_share"] == 0.0
    np.testing.assert_allclose(c["te_forward_arcsec"] - c["te_reverse_arcsec"], 60 * c["lost_motion_arcmin"], rtol=1e-12)
    assert s["reference_unit"]["te_p2p_forward_arcsec"] == pytest.approx(np.ptp(c["te_forward_arcsec"]), rel=1e-12)


def test_contact_map_counts_the_forces_and_the_right_flanks(drive, undersize):
    s, c = undersize
    force = np.asarray(drive.solve_at({"pin_radius": -UNDERSIZE_UM}, drive.output_angles()).force)
    loaded = force > LOADED_FRACTION * float(drive.deflection_mm)  # k_pin = 1
    np.testing.assert_array_equal(loaded_contacts(drive, force), loaded)
    np.testing.assert_array_equal(c["contact_loaded_forward"], loaded[0])
    assert [g[1:] for g in contact_groups(drive)] == [(0, ZP), (ZP, 2 * ZP), (2 * ZP, 2 * ZP + 6)]
    th = 2 * np.pi * np.arange(POINTS) / POINTS
    cm = s["contact_map"]
    for d in range(2):
        n = loaded[0, :, d * ZP : (d + 1) * ZP].sum(axis=1)
        np.testing.assert_array_equal(c[f"loaded_pins_disc_{d + 1}_forward"], n)
        assert cm[f"loaded_pins_disc_{d + 1}"] == {"mean": pytest.approx(n.mean()), "min": n.min(), "max": n.max(), "of": ZP}
        # A forward (CCW) torque on the carrier turns the discs onto the pins with a positive lever arm, the reverse one
        # onto those with a negative arm; a pin on the eccentric's line (arm 0: valley or tip) may carry either.
        lv = lever(th, d)
        tiny = 1e-9 * A * ZP
        assert np.all(lv[loaded[0, :, d * ZP : (d + 1) * ZP]] > -tiny)
        assert np.all(lv[loaded[1, :, d * ZP : (d + 1) * ZP]] < tiny)
        assert np.any(lv[loaded[0, :, d * ZP : (d + 1) * ZP]] > 1.0) and np.any(lv[loaded[1, :, d * ZP : (d + 1) * ZP]] < -1.0)
        assert n.min() >= 1
    # Each load direction closes one flank of each mesh (no backlash error beyond the nominal 0).
    np.testing.assert_array_equal(loaded[:, :, 2 * ZP :].reshape(2, POINTS, 3, 2).sum(axis=-1), 1)
    with pytest.raises(ValueError, match="expected 46 contacts"):
        loaded_contacts(drive, force[..., :-1])


# ---------------------------------------------------------------- the Monte Carlo


def test_monte_carlo_summary_statistics_units_and_failed_solves():
    rng = np.random.default_rng(0)
    n = 50
    out = {
        "lost_motion": rng.uniform(1e-4, 3e-4, n),
        "lost_motion_min": np.r_[-1e-12, 0.0, rng.uniform(1e-5, 2e-5, n - 3), -1e-6],
        "te_pp": rng.uniform(1e-5, 2e-5, n),
        "te_pp_reverse": rng.uniform(1e-5, 2e-5, n),
        "solved": np.r_[np.ones(7), 0.75, np.ones(n - 8)],
    }
    s, arrays = monte_carlo_summary(out, points=97, solves_per_sample=194, resolution_rad=1e-9)
    lm = out["lost_motion"] * ARCMIN_PER_RAD
    q = s["lost_motion_max_arcmin"]
    assert q["unit"] == "arcmin" and q["n"] == n
    assert q["mean"] == pytest.approx(lm.mean(), rel=1e-14)
    assert q["std"] == pytest.approx(lm.std(ddof=1), rel=1e-14)
    assert q["percentiles"]["99.73"] == pytest.approx(np.percentile(lm, 99.73), rel=1e-14)
    assert s["te_p2p_reverse_arcsec"]["max"] == pytest.approx(out["te_pp_reverse"].max() * ARCSEC_PER_RAD, rel=1e-14)
    np.testing.assert_allclose(arrays["te_p2p_forward_arcsec"], out["te_pp"] * ARCSEC_PER_RAD, rtol=1e-15)
    assert s["zero_lost_motion_somewhere_fraction"] == pytest.approx(3 / n)
    assert s["negative_lost_motion_fraction"] == pytest.approx(1 / n)
    sv = s["solves"]
    assert sv["successful_share"] == pytest.approx(1 - 0.25 / n)
    assert sv["samples_with_failed_solves"] == 1 and sv["failed_samples"] == [{"index": 7, "solved_share": 0.75}]


# ---------------------------------------------------------------- the whole run's outputs


class _Context(AbstractStudyContext):
    def __init__(self, drive, errors: list[dict], metric):
        self._errors = errors
        self.unit, self.seed, self.samples, self.chunk_size, self.progress = "arcmin", 0, len(errors), None, False
        self.model, self.metric = None, metric
        rows = [(metric(drive, r), drive.sample_outputs(e, r)) for e in errors for r in [drive.response(e)]]
        self.values_rad = np.asarray([float(v) for v, _ in rows])
        self.outputs = {k: np.asarray([float(o[k]) for _, o in rows]) for k in rows[0][1]}

    def monte_carlo(self, fn, *, desc: str) -> np.ndarray:
        raise NotImplementedError

    def sample_errors(self, index: int) -> dict:
        return self._errors[index]


SAMPLES: list[dict[str, Any]] = [
    {"pin_radius": -6.0},
    {"pin_radius": -2.0},
    {"pin_radius": -4.0, "carrier_hole": Eccentricity(np.asarray([2.0, 1.0, 3.0]), np.asarray([0.3, 2.0, 4.0]))},
]


@pytest.mark.parametrize("metric", [RVLostMotion(), RVPeakToPeak()], ids=lambda m: m.name)
def test_study_outputs_draw_every_figure_the_report_shows(drive, metric, tmp_path):
    from gearte.cli.run import _draw

    ctx = _Context(drive, SAMPLES, metric)
    median = statistics(ctx.values_rad * ARCMIN_PER_RAD).percentiles["50"]  # as `gearte run` picks its typical sample
    assert typical_index(ctx) == int(np.argmin(np.abs(ctx.values_rad * ARCMIN_PER_RAD - median)))
    out = study_outputs(drive, ctx)
    json.dumps(out.summary)  # plain JSON types only
    assert out.summary["reference_unit"]["index"] == typical_index(ctx)
    assert out.summary["monte_carlo"]["solves"]["successful_share"] == 1.0
    # The typical unit on the study's grid is its own Monte Carlo sample: here the reference grid is the same grid,
    # so the two agree and the study grid misses nothing (the report says nothing of it).
    ref = out.summary["reference_unit"]
    g = ref["on_study_grid"]
    assert g["te_p2p_forward_arcsec"] == pytest.approx(ref["te_forward_arcsec"]["p2p"], rel=1e-9)
    assert g["te_p2p_reverse_arcsec"] == pytest.approx(ref["te_reverse_arcsec"]["p2p"], rel=1e-9)
    assert g["lost_motion_max_arcmin"] == pytest.approx(ref["lost_motion_arcmin"]["max"], rel=1e-9)
    assert g["understated_by"] == pytest.approx(0.0, abs=1e-9) and "Monte Carlo's grid" not in "\n".join(out.report)
    coarse = ref | {
        "on_study_grid": g | {"grid_points": 12, "te_p2p_forward_arcsec": 0.9 * g["te_p2p_forward_arcsec"], "understated_by": 0.1}
    }
    note = "\n".join(report(drive, out.summary | {"reference_unit": coarse}, metric=metric.name))
    assert "On the Monte Carlo's grid of 12 output angles" in note and "misses up to 10.0 %" in note
    for f in out.figures:
        _draw(f, tmp_path)
    text = "\n".join(out.report)
    shown = {part.split(")")[0] for part in text.split("](")[1:]}
    assert shown == {f.filename for f in out.figures}
    assert all((tmp_path / name).stat().st_size > 0 for name in shown)
    assert "WARNING" not in text
    bad = out.summary | {"monte_carlo": out.summary["monte_carlo"] | {"negative_lost_motion_fraction": 0.5}}
    assert "WARNING: lost motion below" in "\n".join(report(drive, bad, metric=metric.name))
    # The lost motion's histogram is the generic histogram.png when it is the study's metric, never drawn twice.
    mc = next(f for f in out.figures if f.filename == "monte_carlo.png")
    labels = [s[0] for s in mc.data["series"]]
    assert any(label.startswith("lost motion, max") for label in labels) == (metric.name != "lost_motion")
    assert set(out.arrays) >= {"lost_motion_max_arcmin", "te_p2p_forward_arcsec", "solved"}
    assert out.files["reference_unit.npz"]["force_forward"].shape == (POINTS, 2 * ZP + 6)
    assert resolution(drive) == pytest.approx(10 * DEFLECTION_MM / R, rel=1e-12, abs=0)  # the default deflection_mm


def test_no_jax_arrays_leak_into_the_summary(undersize):
    s, _ = undersize
    leaves = jax.tree.leaves(s)
    assert not any(isinstance(x, jnp.ndarray) for x in leaves)


def test_a_metric_of_another_drive_is_refused_naming_the_drives_own_classes():
    # The cycloid-pin drive's lost motion has the RV reducer's metric name but not its meaning (a rigid disc on
    # fixed pins): a study or budget given it is refused, and the message names the classes to use instead.
    import gearte
    from gearte.cli.config import load_study

    study = load_study("examples/rv_robot_joint_tolerances.toml")
    drive, model = study.drive, study.errors
    source = next(iter(model.specs))
    for make in (
        lambda m: gearte.TEStudy(drive, model, metric=m),
        lambda m: gearte.budget_problem(
            drive, model, costs={source: gearte.Reciprocal(0.0, 1.0)}, nominal={source: 1.0}, spec=1e-4, metric=m
        ),
    ):
        with pytest.raises(
            ValueError,
            match=r"offers gearte\.RVLostMotion\(\), gearte\.RVPeakToPeak\(\), gearte\.RVPeakToPeakReverse\(\); got gearte\.LostMotion\(\)",
        ):
            make(gearte.LostMotion())
        make(gearte.RVLostMotion())  # the drive's own: accepted
    assert {type(m) for m in drive.metrics.values()} == {gearte.RVLostMotion, gearte.RVPeakToPeak, gearte.RVPeakToPeakReverse}
