"""Cycloid-pin reducer: the generating-grinding error model, Yao & Liang's (2001) numbering, and the disc centre
held at a fixed offset or floating. References are derived independently: the generated flank from the grinder's
exact kinematics, the paper's disc from its own eq. 2, its position numbers from its section 2."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import gearte
from gearte import cli
from gearte.drives.cycloid_pin import CycloidErrors, CycloidPin, pitch_angles, tooth_profile
from gearte.drives.cycloid_pin_geometry import errors_from_paper, paper_pin, paper_position, paper_tooth
from gearte.drives.cycloid_pin_metrics import floating_disc

ROOT = Path(__file__).resolve().parents[1]
ARCSEC = 180 * 3600 / math.pi
R, r, a, ZB = 195.0, 13.5, 6.0, 26
ZA = ZB - 1


def stage(**kw) -> CycloidPin:
    return CycloidPin(ZB, pin_circle_radius=R, pin_radius=r, eccentricity=a, **kw)


# ---------------------------------------------------------------- generating grinding


def _machine_wheel_centre(phi, n, *, RZ, slide, across, crank, chain, chain_phase, pitch, pitch_phase):
    """The wheel centre relative to the work (disc frame, mm) while space n is ground at generating parameter φ: the
    machine's motions composed exactly (wheel on its slide, work on the generating crank, work drive), no expansion."""
    u, v = phi / ZA, ZB * phi / ZA
    eps = chain * math.sin(phi + chain_phase)  # the crank turned counter-clockwise by ε
    U1 = np.array([math.sin(u), math.cos(u)])
    U1x = np.array([math.cos(u), -math.sin(u)])
    U2 = np.array([math.sin(v - eps), math.cos(v - eps)])
    w = (RZ + slide) * U1 + across * U1x - (a + crank) * U2
    turn = 2 * math.pi * n / ZA + pitch * math.sin((2 * math.pi * n + phi) / ZA + pitch_phase)  # clockwise
    c, s = math.cos(turn), math.sin(turn)
    return np.array([c * w[0] + s * w[1], -s * w[0] + c * w[1]])


@pytest.mark.parametrize("space", [0, 7])
def test_generated_flank_is_the_envelope_of_the_wheel_moved_by_the_machine(space):
    d = stage(wheel_pin_circle_radius=194.785, wheel_pin_radius=13.88, process=gearte.GeneratingGrinding())
    um = 1e-3
    e = dict(
        dressing_x=4.0,
        dressing_y=3.0,
        wheel_radius=2.5,
        generating_eccentricity=-5.0,
        generating_chain=12 / ARCSEC,
        generating_chain_phase=0.7,
        pitch_accumulated=40 / ARCSEC,
        pitch_accumulated_phase=-1.2,
    )
    infeed = np.linspace(-6.0, 6.0, ZA)
    err = CycloidErrors(infeed=infeed, **e)
    kw = dict(
        RZ=194.785,
        slide=(e["dressing_y"] + infeed[space]) * um,
        across=e["dressing_x"] * um,
        crank=e["generating_eccentricity"] * um,
        chain=e["generating_chain"],
        chain_phase=e["generating_chain_phase"],
        pitch=e["pitch_accumulated"],
        pitch_phase=e["pitch_accumulated_phase"],
    )
    radius = 13.88 + e["wheel_radius"] * um
    phis = np.concatenate([np.linspace(-2.8, -0.2, 7), np.linspace(0.2, 2.8, 7)])
    flank = np.asarray(tooth_profile(d, phis, errors=err, space=space))
    ideal = np.asarray(tooth_profile(d, phis, space=space))
    gaps = []
    for phi, f in zip(phis, flank, strict=True):
        dist = lambda t, f=f: float(np.hypot(*(f - _machine_wheel_centre(t, space, **kw))))
        best = minimize_scalar(dist, bounds=(phi - 0.3, phi + 0.3), method="bounded", options={"xatol": 1e-12})
        gaps.append(best.fun - radius)
    # On the envelope to first order: within 0.02 µm, while the errors move the flank by several µm.
    assert np.max(np.abs(gaps)) < 2e-5, gaps
    assert np.max(np.hypot(*(flank - ideal).T)) > 5e-3


def test_generating_errors_are_refused_for_a_form_ground_disc_and_listed_for_a_generating_one():
    form, gen = stage(), stage(process=gearte.GeneratingGrinding())
    assert len(form.error_sources) == 20 and len(gen.error_sources) == 26
    assert list(gen.error_sources)[:20] == list(form.error_sources)
    assert gen.error_sources["generating_chain"].unit == "rad" and gen.error_sources["wheel_radius"].unit == "µm"
    with pytest.raises(ValueError, match="generating-ground"):
        form.errors_dict({"wheel_radius": 2.0})
    with pytest.raises(ValueError, match="process: the disc is ground by FormGrinding"):
        stage(process="hobbing")
    with pytest.raises(ValueError, match=r"gearte.GeneratingGrinding\(\) is 'generating' in a study file"):
        stage(process="generating")
    with pytest.raises(ValueError, match=r"an instance: GeneratingGrinding\(\)"):
        stage(process=gearte.GeneratingGrinding)
    assert isinstance(stage().process, gearte.FormGrinding)  # the default
    # Without generating-machine errors the two processes grind the same disc.
    e = CycloidErrors(dressing_y=3.0, infeed=2.0, indexing=1e-5, setup_eccentricity=10.0, setup_phase=0.3)
    phi = np.linspace(-3, 3, 9)
    np.testing.assert_allclose(
        np.asarray(tooth_profile(gen, phi, errors=CycloidErrors(indexing=1e-5, setup_eccentricity=10.0, setup_phase=0.3), space=3)),
        np.asarray(tooth_profile(form, phi, errors=CycloidErrors(indexing=1e-5, setup_eccentricity=10.0, setup_phase=0.3), space=3)),
        atol=1e-12,
    )
    # A wheel-slide offset shifts a form profile rigidly but a generated one by (1 − K cos φ)/S along the normal:
    # the same at the space bottom (φ = 0), less on the flanks.
    f0, g0 = (np.asarray(tooth_profile(x, [0.0], errors=e, space=0)) for x in (form, gen))
    np.testing.assert_allclose(f0, g0, atol=1e-12)


# ---------------------------------------------------------------- Yao & Liang's numbering


def _paper_tooth_points(n, theta, *, beta_err, dX, dY, dA, phiA, dB):
    """Yao & Liang (2001), eqs. 1–2: their tooth n (1-based) in their disc frame X′_2 O Y′_2 (mm): the wheel's
    profile (X_4, Y_4) + (δX_4, δY_4), turned counter-clockwise by β = 2π(n − 1)/z_a + Δβ(n), minus the bore offsets."""
    K = a * ZB / R
    S = np.sqrt(1 + K * K - 2 * K * np.cos(theta))
    u, v = theta / ZA, ZB * theta / ZA
    x = -(R * np.sin(u) - a * np.sin(v)) + r * (np.sin(u) - K * np.sin(v)) / S + dX  # their θ_b runs counter-clockwise
    y = (R * np.cos(u) - a * np.cos(v)) - r * (np.cos(u) - K * np.cos(v)) / S + dY
    b = 2 * np.pi * (n - 1) / ZA + beta_err
    return np.stack([x * np.cos(b) - y * np.sin(b) - dA * np.cos(phiA) - dB, x * np.sin(b) + y * np.cos(b) - dA * np.sin(phiA)], -1)


def _distance_to_polyline(points, line):
    seg0, seg1 = line[:-1], line[1:]
    d = seg1 - seg0
    out = []
    for p in points:
        t = np.clip(np.sum((p - seg0) * d, 1) / np.sum(d * d, 1), 0, 1)
        out.append(np.min(np.hypot(*(seg0 + t[:, None] * d - p).T)))
    return np.asarray(out)


def test_errors_given_in_the_paper_frame_grind_the_paper_disc():
    J = 6
    d = stage()
    um = 1e-3
    dbeta = 30 / ARCSEC * np.sin(2 * np.pi * np.arange(1, ZA + 1) / ZA)
    mine = errors_from_paper(d, J=J, indexing=dbeta, setup_phase=math.radians(45), mandrel_phase=0.0)
    err = CycloidErrors(dressing_x=2.0, dressing_y=2.0, setup_eccentricity=31.5, mandrel_runout=5.0, **{k: v for k, v in mine.items()})
    rot = -2 * np.pi * J / ZA  # the paper's disc frame is gearte's turned 2πJ/z_a clockwise
    c, s = np.cos(rot), np.sin(rot)
    theta = np.linspace(-3.0, 3.0, 41)
    worst = 0.0
    for n in (1, 4, 7, 13, 20):
        pts = _paper_tooth_points(n, theta, beta_err=dbeta[n - 1], dX=2 * um, dY=2 * um, dA=31.5 * um, phiA=math.radians(45), dB=5 * um)
        pts = np.stack([c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]], -1)
        space = int(np.flatnonzero(paper_tooth(d, np.arange(ZA), J=J) == n)[0])
        line = np.asarray(tooth_profile(d, np.linspace(-np.pi, np.pi, 20001), errors=err, space=space))
        worst = max(worst, float(np.max(_distance_to_polyline(pts, line))))
        # The old reading (space n − 1 = tooth n, the same sense of rotation) is a different disc.
        if n == 4:
            old = CycloidErrors(
                dressing_x=2.0, dressing_y=2.0, setup_eccentricity=31.5, mandrel_runout=5.0, setup_phase=math.radians(45), indexing=dbeta
            )
            wrong = np.asarray(tooth_profile(d, np.linspace(-np.pi, np.pi, 20001), errors=old, space=n - 1))
            assert np.max(_distance_to_polyline(pts, wrong)) > 0.02
    assert worst < 1e-5  # the polyline's chords: 0.01 µm


def test_paper_position_numbers_follow_its_section_2():
    d = stage()
    p = 2 * np.pi / ZB
    rng = np.random.default_rng(4)
    for tp in np.concatenate([[0.0], rng.uniform(0, p, 5)]):
        for K in range(1, ZB + 1):
            theta_b = (K - 1) * p - tp  # the paper's pin of position K, counter-clockwise from the static axis
            j = int(np.flatnonzero(np.isclose(np.mod(-tp + np.arange(ZB) * p - theta_b + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-9))[0])
            assert int(paper_position(d, j, -tp)) == K
    # Pins and teeth: at θ_T = 0 the paper's pair n = K + J sits at position K; gearte's pin K − 1 meets space 1 − K.
    assert list(paper_pin(d, np.arange(3))) == [7, 8, 9] and list(paper_tooth(d, [0, 1, 24])) == [7, 6, 8]
    assert int(paper_position(d, 0, p / 2)) == 2 and int(paper_position(d, 0, -p / 2)) == 1


# ---------------------------------------------------------------- the disc centre


def test_a_fixed_offset_beyond_the_radial_clearance_interferes_and_a_floating_disc_does_not():
    """Unmodified disc, pins 20 µm smaller: a radial clearance g = 20 µm at the space bottoms and the tips. A crank
    longer by c leaves g − c at the bottom next to the crank: c = 15 µm clears, c = 25 µm interferes; a disc free to
    float by 10 µm moves back towards the pin wheel and clears."""
    d = stage()
    pos = pitch_angles(d, 4)  # θ_T = 0: a pin exactly at a space bottom
    ok = floating_disc(d, {"pin_radius": -20.0, "eccentricity": 15.0}, radius_um=10.0, positions=pos, rings=2, directions=12)
    bad = floating_disc(d, {"pin_radius": -20.0, "eccentricity": 25.0}, radius_um=10.0, positions=pos, rings=2, directions=12)
    assert (
        ok["radial_clearance"] == pytest.approx(20.0) and bad["root_gap"] == pytest.approx(-5.0) and bad["tip_gap"] == pytest.approx(45.0)
    )
    assert ok["interfering_rigid"] == 0 and ok["lost_motion_min_rigid"] >= 0
    assert bad["interfering_rigid"] > 0 and bad["lost_motion_min_rigid"] < 0
    assert bad["interfering_floating"] == 0 and bad["lost_motion_min_floating"] >= 0
    assert math.sin(bad["best_offset"]["phase"]) < 0  # towards the pin-wheel centre


@pytest.mark.slow
def test_generating_example_reports_both_numberings(tmp_path):
    text = (ROOT / "examples" / "cycloid_yao2001_generating.toml").read_text().split("# Monte Carlo:")[0]
    p = tmp_path / "gen.toml"
    p.write_text(text)
    out = tmp_path / "out"
    assert cli.main(["run", str(p), "--out", str(out), "--samples", "4"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["process"] == "generating" and s["paper_J"] == 6
    cp = s["contact_pair"]
    assert cp["K"] == cp["pin"] + 1 and cp["paper_pin"] == cp["pin"] + 6 and cp["paper_tooth"] == (6 - (cp["tooth_space"] - 1)) % 25 + 1
    assert sum(x["share_of_pitch"] for x in s["contact_pairs_over_paper_pitch"]) == pytest.approx(1.0)
    assert not s["interference"] and s["disc_centre"]["interfering_share_floating"] == 0
    assert "K = " in (out / "report.md").read_text()
    bad = p.with_name("bad.toml")
    bad.write_text(text.replace('process = "generating"', 'process = "generatin"'))
    assert cli.main(["check", str(bad)]) == 2


@pytest.mark.parametrize(
    "example, name, process",
    [
        ("cycloid_yao2001_modified", None, gearte.FormGrinding),  # the default
        ("cycloid_yao2001_modified", "form", gearte.FormGrinding),
        ("cycloid_yao2001_generating", "generating", gearte.GeneratingGrinding),
    ],
)
def test_a_study_files_process_is_the_process_object(tmp_path, example, name, process):
    from gearte.cli.config import load_study

    text = (ROOT / "examples" / f"{example}.toml").read_text(encoding="utf-8")
    text = text.replace('process = "generating"', "")
    assert "process =" not in text
    if name is not None:
        text = text.replace('type = "cycloid_pin"', f'type = "cycloid_pin"\nprocess = "{name}"', 1)
    p = tmp_path / "study.toml"
    p.write_text(text, encoding="utf-8")
    d = load_study(p).drive
    assert type(d.process) is process and d.error_fields == process.fields
    assert ("disc ground by", process.description) in d.describe()


def test_a_generating_machines_errors_in_a_form_ground_disc_study_are_refused(tmp_path):
    from gearte.cli.config import ConfigError, load_study

    text = (ROOT / "examples" / "cycloid_yao2001_generating.toml").read_text(encoding="utf-8")
    p = tmp_path / "study.toml"
    p.write_text(text.replace('process = "generating"', 'process = "form"'), encoding="utf-8")
    with pytest.raises(ConfigError, match="unknown key `pitch_accumulated_arcsec`"):
        load_study(p)
