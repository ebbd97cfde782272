"""Harmonic drive: the tooth-mesh line from the two mesh zones, and both readings of Liu's eq. (8).

The reference for the tooth-mesh line is built here from the kinematics alone, not from the drive's
zone factor: each zone's mesh position on the circular spline (CS) and on the flexspline (FS), the
tooth phase there, a tooth-periodic error waveform of several harmonics, the output as the mean of
the two zones; sampled over one wave-generator (WG) turn and Fourier-transformed.
"""

import math
import tomllib
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte import ConfigError, Eccentricity
from gearte.cli.config import load_study
from gearte.core.twoscale import fast_line_order
from gearte.drives.harmonic import (
    HarmonicDrive,
    HarmonicSource,
    class_phasors,
    delta_for_arcmin,
    labelled_lines,
    statistical_estimate,
    tooth_zone_factor,
)

ARCSEC = 180 * 3600 / math.pi
ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "harmonic_liu.toml"
M = 8192  # samples over one WG turn: above twice the highest line, 3 z₂ ≤ 549
#: One zone's tooth-mesh error, µm: harmonic h → (amplitude, phase at tooth phase 0).
WAVE = {1: (2.0, 0.4), 2: (0.7, -1.1), 3: (0.3, 2.2)}


def _zone_mean(theta, tooth_phase_of_zone, share=0.5):
    """Output mesh error of the two zones: w₁ g(φ₁) + w₂ g(φ₂), g the tooth-periodic waveform WAVE."""
    g = lambda phi: sum(a * np.sin(h * phi + p) for h, (a, p) in WAVE.items())
    return share * g(tooth_phase_of_zone(theta, 0)) + (1 - share) * g(tooth_phase_of_zone(theta, 1))


def _cs_teeth(z1, z2):
    # Zone k sits at θ + kπ on the fixed CS (double wave); the CS tooth phase there is z₂ (θ + kπ).
    return lambda theta, k: z2 * (theta + k * math.pi)


def _fs_teeth(z1, z2):
    # The FS turns at −θ/i = −θ (z₂ − z₁)/z₁; zone k is at θ + kπ − (−θ/i) on it; its tooth phase is z₁ times that.
    return lambda theta, k: z1 * (theta * (1 + (z2 - z1) / z1) + k * math.pi)


def _lines(x):
    """{cycles per WG turn: amplitude} of a signal sampled at M points over one WG turn."""
    c = np.fft.rfft(x) / len(x)
    amp = 2 * np.abs(c)
    return {k: float(amp[k]) for k in np.nonzero(amp > 1e-9 * amp.max())[0]}


def _tooth_drive(z1, z2, cls_amp=None):
    src = [HarmonicSource(f"t{h}", "tooth", tolerance=2 * a, harmonic=h) for h, (a, _) in WAVE.items()]
    drive = HarmonicDrive(z1, z2, src, pitch_diameter=90.0)
    errs = {f"t{h}": Eccentricity(a, p) for h, (a, p) in WAVE.items()}
    return drive, errs


@pytest.mark.parametrize("z1,z2", [(180, 182), (181, 183), (100, 102), (99, 101)])
def test_tooth_lines_from_the_two_zones(z1, z2):
    theta = 2 * math.pi * np.arange(M) / M
    ref_cs = _lines(_zone_mean(theta, _cs_teeth(z1, z2)))
    ref_fs = _lines(_zone_mean(theta, _fs_teeth(z1, z2)))
    # FS teeth give the same lines as CS teeth (z₁ ≡ z₂ mod 2).
    assert ref_fs.keys() == ref_cs.keys() and all(ref_fs[k] == pytest.approx(ref_cs[k], rel=1e-9) for k in ref_cs)
    # The derivation: identical zones keep harmonic h in full when h z₂ is even and cancel it when odd.
    want = {h * z2: a for h, (a, _) in WAVE.items() if (h * z2) % 2 == 0}
    assert sorted(ref_cs) == sorted(want)
    assert all(ref_cs[k] == pytest.approx(want[k], rel=1e-9) for k in want)
    if z2 % 2 == 0:
        assert sorted(ref_cs) == [z2, 2 * z2, 3 * z2]  # fundamental z₂ and its harmonics
    else:
        assert sorted(ref_cs) == [2 * z2]  # the fundamental and 3z₂ cancel; 2z₂ stays
    # The drive's TE, sampled the same way, has exactly these lines (× its gain), with their phases.
    drive, errs = _tooth_drive(z1, z2)
    te = np.asarray(gearte.evaluate(drive.signal(errs), jnp.asarray(theta)))
    gain = float(drive.gain())
    got = _lines(te / gain)
    assert sorted(got) == sorted(ref_cs)
    assert all(got[k] == pytest.approx(ref_cs[k], rel=1e-9) for k in got)
    ref_te = _zone_mean(theta, _cs_teeth(z1, z2))
    np.testing.assert_allclose(te / gain, ref_te, rtol=0, atol=1e-9 * np.max(np.abs(ref_te)))
    assert {k: f for k, f in drive.line_frequencies().items() if k.startswith("tooth")} == {
        ("tooth" if h == 1 else f"tooth_h{h}"): h * z2 for h in WAVE if (h * z2) % 2 == 0
    }


@pytest.mark.parametrize("z2", [182, 183])
@pytest.mark.parametrize("share", [0.5, 0.7, 1.0])
def test_zone_factor_against_unequal_zones(z2, share):
    # Unequal zones (zone 1 carrying `share` of the load): the sampled two-zone mean against the closed form, as
    # signed complex lines (an odd h z₂ with share ≠ ½ flips the sign if the zones are swapped). One zone's
    # a sin(kθ + p), k = h z₂, has the rfft line 2 c_k = a e^{i(p − π/2)}; the two zones' line is zf times that.
    theta = 2 * math.pi * np.arange(M) / M
    c = np.fft.rfft(_zone_mean(theta, _cs_teeth(z2 - 2, z2), share)) / M
    for h, (a, p) in WAVE.items():
        zf = tooth_zone_factor(z2, h, share=share)
        assert abs(2 * c[h * z2] - zf * a * np.exp(1j * (p - math.pi / 2))) <= 1e-9 * a
    assert tooth_zone_factor(z2, 1) == (1.0 if z2 % 2 == 0 else 0.0)


RPM = 184.0


@pytest.mark.parametrize(
    "z1,z2,want",
    [
        (180, 182, {"tooth": 182 * RPM, "tooth_h2": 2 * 182 * RPM}),  # 33,488 cpm (zones in phase) and 66,976 cpm
        (181, 183, {"tooth_h2": 2 * 183 * RPM}),  # 67,344 cpm: the fundamental (33,672) cancels, 2z₂n stays
    ],
)
def test_example_and_odd_variant_lines_in_cpm(z1, z2, want):
    # The example's z₂ = 182 (even) and an odd variant (z₁ = 181, z₂ = 183) at Liu's 184 rpm, each with a tooth-mesh
    # fundamental and a second harmonic, read off a record.
    rpm = RPM
    src = [
        HarmonicSource("cs", "circular_spline", tolerance=20.0),
        HarmonicSource("fs", "flexspline", tolerance=12.0),
        HarmonicSource("wg", "wave_generator", tolerance=10.0),
        HarmonicSource("t1", "tooth", tolerance=8.0),
        HarmonicSource("t2", "tooth", tolerance=3.0, harmonic=2),
    ]
    drive = HarmonicDrive(z1, z2, src, pitch_diameter=90.0)
    errs = {
        "cs": Eccentricity(7.0, 0.4),
        "fs": Eccentricity(5.0, -1.0),
        "wg": Eccentricity(3.0, 0.7),
        "t1": Eccentricity(4.0, 1.9),
        "t2": Eccentricity(1.5, -0.3),
    }
    sig = drive.signal(errs)
    top = max(sig.orders)
    assert top * sig.fundamental == 2 * z2  # the 2z₂ line is the fastest in both
    # Odd z₂: one fast line (2z₂), so the drive's extrema keep the two-scale method; even z₂ with a second
    # harmonic: two fast lines (z₂, 2z₂), the full grid.
    assert fast_line_order(sig) == (top if z2 % 2 else None)
    rec = gearte.record(sig, input_rpm=rpm, duration_s=40.0, sample_rate_hz=2400.0)  # Nyquist 72,000 cpm
    lines = labelled_lines(drive, rec, count=4, signal=sig)
    tooth = {e["line"]: e["freq_cpm"] for e in lines if e["kind"] == "line" and e["class"] == "tooth"}
    assert tooth.keys() == want.keys()
    for k, f in want.items():
        assert tooth[k] == pytest.approx(f, abs=1e-4)
    ph = class_phasors(drive, errs)
    assert abs(ph["tooth"]) == (pytest.approx(4.0 * float(drive.gain()), rel=1e-12) if z2 % 2 == 0 else 0.0)
    assert abs(ph["tooth_h2"]) == pytest.approx(1.5 * float(drive.gain()), rel=1e-12)
    others = {e["class"]: e["freq_cpm"] for e in lines if e["kind"] == "line" and e["class"] != "tooth"}
    assert others["circular_spline"] == pytest.approx(2 * rpm, abs=1e-4)
    assert others["flexspline"] == pytest.approx(2 * rpm * z2 / z1, abs=1e-4)
    assert others["wave_generator"] == pytest.approx(rpm, abs=1e-4)


def test_only_cancelled_tooth_sources_give_zero_te():
    drive = HarmonicDrive(181, 183, [HarmonicSource("t", "tooth", tolerance=8.0)], pitch_diameter=90.0)
    sig = drive.signal({"t": Eccentricity(4.0, 0.3)})
    v = np.asarray(gearte.evaluate(sig, jnp.linspace(0.0, 7.0, 101)))
    assert np.all(v == 0.0)
    assert "tooth" not in drive.line_frequencies()


@pytest.mark.parametrize(
    "make,msg",
    [
        (lambda: HarmonicSource("x", "circular_spline", tolerance=1.0, harmonic=2), "tooth-class sources only"),
        (lambda: HarmonicSource("x", "tooth", tolerance=1.0, harmonic=0), "harmonic: must be ≥ 1"),
        (lambda: HarmonicSource("x", "tooth", tolerance=1.0, harmonic=1.5), "harmonic: must be a whole number"),
        (lambda: HarmonicSource("x", "tooth", tolerance=1.0, basis=3), "basis must be a string"),
        (lambda: tooth_zone_factor(182, 1, share=1.5), "share"),
    ],
)
def test_bad_harmonic_inputs(make, msg):
    with pytest.raises(ValueError, match=msg):
        make()


def test_config_harmonic_and_basis(tmp_path):
    text = EXAMPLE.read_text(encoding="utf-8")
    st = load_study(EXAMPLE)
    by = {s.name: s for s in st.drive.sources}
    assert by["cam_profile"].basis == "gearte's assumption" and by["fs_tooth_to_tooth"].harmonic == 1
    bad = text.replace('name = "wg_shaft_runout"\n', 'name = "wg_shaft_runout"\nharmonic = 2\n', 1)
    (tmp_path / "bad.toml").write_text(bad, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"\(wg_shaft_runout\).*tooth-class sources only"):
        load_study(tmp_path / "bad.toml")


# ---------------------------------------------------------------- Liu's eq. (8): both readings


def test_both_readings_of_eq8_by_hand():
    st = load_study(EXAMPLE)
    drive = st.drive
    est = statistical_estimate(drive)
    cfg = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))["drive"]
    c2 = math.cos(math.radians(20.0)) ** 2
    s = sum(x["tolerance_um"] ** 2 / (c2 if x.get("kind", "runout") == "runout" and x["class"] != "tooth" else 1.0) for x in cfg["sources"])
    delta = 0.5 * math.sqrt(s)  # eq. (7)
    assert est.delta_um == pytest.approx(delta, rel=1e-13)
    # Eq. (8) as printed: (K_b/√N)·Δ·412.8/d with K_b = 1, N = 36.2, d = 90 mm; without the factor 1/√N.
    assert est.arcsec == pytest.approx(delta * 412.8 / 90 / math.sqrt(36.2), rel=1e-13)
    assert est.arcsec_no_averaging == pytest.approx(delta * 412.8 / 90, rel=1e-13)
    assert est.averaging == pytest.approx(1 / math.sqrt(36.2), rel=1e-15)
    assert est.arcmin == pytest.approx(0.47590, abs=5e-5)  # the example's figure, as before
    assert est.arcmin_no_averaging == pytest.approx(2.8633, abs=5e-4)
    # The Δ behind Liu's 2.51′ = 150.6″: 150.6 · 90/412.8 = 32.83 µm without the averaging, × √36.2 = 197.55 µm with it.
    assert delta_for_arcmin(drive, 2.51, averaging=False) == pytest.approx(32.834, abs=1e-3)
    assert delta_for_arcmin(drive, 2.51) == pytest.approx(197.55, abs=1e-2)
    # Round trip: the Δ found gives the angle back in each reading.
    for avg in (True, False):
        d = delta_for_arcmin(drive, est.arcmin if avg else est.arcmin_no_averaging, averaging=avg)
        assert d == pytest.approx(est.delta_um, rel=1e-12)
