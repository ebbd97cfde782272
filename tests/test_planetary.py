"""2K-H planetary model: kinematics, Wang et al.'s (2013) eq. (9), allocation, coupling modes, validation."""

import math
from fractions import Fraction
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte.cli.config import load_study
from gearte.drives import Planetary2KH, member_speeds, wang2013

ARCSEC = 180 * 3600 / math.pi
PI = math.pi
SOURCES = list(wang2013.TABLE1_TOLERANCES_UM)


def eq9_numpy(theta, E, ph, planet_freq):
    """Wang et al. (2013), eq. (9), typed in from the paper (rad); θ = input angle. E, ph: dicts by symbol."""
    pre = -1.0 / (48000.0 * math.cos(PI / 9))
    t = np.asarray(theta)
    return pre * (
        E["Es"] * np.sin(7 / 8 * t + ph["bs"] + PI / 9)
        + E["Ep"] * np.sin(planet_freq * t - ph["bp"] + 8 * PI / 9)
        + E["As"] * np.sin(1 / 8 * t - ph["gs"] + 8 * PI / 9)
        + E["Ap"] * np.sin(ph["gp"] + 10 * PI / 9)
        + E["Ac"] * np.sin(1 / 8 * t - ph["gc"] - PI / 9)
        + E["Er"] * np.sin(1 / 8 * t - ph["br"] + PI / 9)
        + E["Ep"] * np.sin(planet_freq * t - ph["bp"] + PI / 9)
        + E["Ap"] * np.sin(ph["gp"] + 8 * PI / 9)
        + E["Ac"] * np.sin(1 / 8 * t - ph["gc"] + PI / 9)
    )


SYM = {
    "sun_manufacturing": ("Es", "bs"),
    "planet_manufacturing": ("Ep", "bp"),
    "ring_manufacturing": ("Er", "br"),
    "sun_assembly": ("As", "gs"),
    "planet_assembly": ("Ap", "gp"),
    "carrier_assembly": ("Ac", "gc"),
}


def random_errors(rng, *, n_planets=3, scale=1.0):
    errs, E, ph = {}, {}, {}
    for name, tol in wang2013.TABLE1_TOLERANCES_UM.items():
        m, p = scale * tol * rng.uniform(0.3, 1.0), rng.uniform(0, 2 * PI)
        per_planet = name.startswith("planet")
        errs[name] = gearte.Eccentricity(np.full(n_planets, m) if per_planet else m, np.full(n_planets, p) if per_planet else p)
        E[SYM[name][0]], ph[SYM[name][1]] = m, p
    return errs, E, ph


def test_kinematics_of_table1():
    d = wang2013.table1_drive()
    w = d.speeds
    assert (w["sun"], w["carrier"], w["ring"], w["planet"]) == (1, Fraction(1, 8), 0, Fraction(-1, 6))
    assert d.ratio == 8
    f = d.source_frequencies()
    # The erratum: |ω_p − ω_c| = 7/24 ω_s, not 11/24.
    assert f["planet_manufacturing"] == Fraction(-7, 24)
    assert f["sun_manufacturing"] == Fraction(7, 8)
    assert f["ring_manufacturing"] == f["sun_assembly"] == f["carrier_assembly"] == Fraction(-1, 8)
    assert f["planet_assembly"] == 0


@pytest.mark.parametrize(
    "inp,fixed", [("sun", "ring"), ("ring", "sun"), ("carrier", "ring"), ("sun", "carrier"), ("ring", "carrier"), ("carrier", "sun")]
)
def test_willis_for_every_configuration(inp, fixed):
    zs, zr = 12, 84
    w = member_speeds(zs, zr, input=inp, fixed=fixed)
    assert w[inp] == 1 and w[fixed] == 0
    # Willis, written independently: (ω_s − ω_c)/(ω_r − ω_c) = −z_r/z_s.
    assert (w["sun"] - w["carrier"]) * zs == -(w["ring"] - w["carrier"]) * zr


@pytest.mark.parametrize("literal", [True, False])
def test_eq9_explicit_drive_matches_the_paper(literal):
    rng = np.random.default_rng(11)
    drive = wang2013.eq9_drive(literal=literal)
    theta = np.linspace(0, 2 * PI * 24, 777)
    for _ in range(5):
        errs, E, ph = random_errors(rng, n_planets=1)
        errs = {k: gearte.Eccentricity(v.magnitude.reshape(-1)[0], v.phase.reshape(-1)[0]) for k, v in errs.items()}
        got = gearte.evaluate(drive.signal(errs), theta)
        np.testing.assert_allclose(got, eq9_numpy(theta, E, ph, 11 / 24 if literal else 7 / 24), rtol=1e-10, atol=1e-16)


def test_first_principles_model_is_eq9_with_the_physical_planet_frequency():
    rng = np.random.default_rng(12)
    drive = wang2013.table1_drive()
    theta = np.linspace(0, 2 * PI * 24, 1001)
    for _ in range(5):
        errs, E, ph = random_errors(rng)
        got = gearte.evaluate(drive.signal(errs), theta)
        np.testing.assert_allclose(got, eq9_numpy(theta, E, ph, 7 / 24), rtol=1e-10, atol=1e-16)
        # ... and it is not the literal 11/24 equation.
        assert np.max(np.abs(got - eq9_numpy(theta, E, ph, 11 / 24))) > 1e-6


def test_eq9_amplitudes_frequencies_and_phase_structure():
    # All phases 0: each frequency's line is the phasor sum of eq. (9)'s terms at that frequency.
    errs = {k: gearte.Eccentricity(v, 0.0) for k, v in wang2013.TABLE1_TOLERANCES_UM.items()}
    k = 1 / (48000 * math.cos(PI / 9))
    for literal, pf in ((True, Fraction(11, 24)), (False, Fraction(7, 24))):
        sp = gearte.spectrum(wang2013.eq9_drive(literal=literal).signal(errs))
        lines = dict(zip(sp.freq, np.asarray(sp.amplitude) / k))
        assert set(lines) == {Fraction(7, 8), pf, Fraction(1, 8)}
        np.testing.assert_allclose(lines[Fraction(7, 8)], 13, rtol=1e-12)
        np.testing.assert_allclose(lines[pf], abs(16 * np.exp(8j * PI / 9) + 16 * np.exp(1j * PI / 9)), rtol=1e-12)  # 10.94
        np.testing.assert_allclose(lines[pf], 10.94, atol=0.005)
        eighth = abs(12 * np.exp(8j * PI / 9) + 15 * np.exp(-1j * PI / 9) + 21 * np.exp(1j * PI / 9) + 15 * np.exp(1j * PI / 9))
        np.testing.assert_allclose(lines[Fraction(1, 8)], eighth, rtol=1e-12)
        # The constant: 8 sin(10π/9) + 8 sin(8π/9) = 0 at γ_p = 0.
        np.testing.assert_allclose(float(sp.offset), 0.0, atol=1e-18)


def allocated_errors(beta_s, beta_p, beta_r=0.0):
    T = wang2013.TABLE1_TOLERANCES_UM
    return {
        "sun_manufacturing": gearte.Eccentricity(T["sun_manufacturing"], beta_s),
        "planet_manufacturing": gearte.Eccentricity(T["planet_manufacturing"], beta_p),
        "ring_manufacturing": gearte.Eccentricity(T["ring_manufacturing"], beta_r),
        "sun_assembly": gearte.Eccentricity(T["sun_assembly"], beta_r + 7 * PI / 9),
        "planet_assembly": gearte.Eccentricity(T["planet_assembly"], 0.0),
        "carrier_assembly": gearte.Eccentricity(T["carrier_assembly"], beta_r + 8 * PI / 9),
    }


def test_table3_allocation_group_amplitudes():
    k = 1 / (48000 * math.cos(PI / 9))
    sp = gearte.spectrum(wang2013.table1_drive().signal(allocated_errors(0.3, 1.1)))
    lines = dict(zip(sp.freq, np.asarray(sp.amplitude) / k))
    np.testing.assert_allclose(lines[Fraction(1, 8)], 4.81, atol=0.005)  # |21 + 12 − 28.19|
    np.testing.assert_allclose(lines[Fraction(7, 24)], 10.94, atol=0.005)
    np.testing.assert_allclose(lines[Fraction(7, 8)], 13.0, rtol=1e-12)
    np.testing.assert_allclose(float(sp.offset), 0.0, atol=1e-18)


def test_allocated_te_estimate_and_exact_peak():
    k_arcsec = ARCSEC / (48000 * math.cos(PI / 9))
    # Wang et al.'s sum-of-amplitudes estimate: (13 + 4.81 + 10.94) µm → 131.5″.
    # Table 3 with β_r = 0 puts eq. (9)'s ω_s/8 terms at π/9 (A_s), −π and −7π/9 (A_c), π/9 (E_r).
    group = abs((12 + 21) * np.exp(1j * PI / 9) + 15 * np.exp(-1j * PI) + 15 * np.exp(-7j * PI / 9))
    assert round(group, 2) == 4.81
    estimate = (13 + group + abs(16 * np.exp(8j * PI / 9) + 16 * np.exp(1j * PI / 9))) * k_arcsec
    assert round(estimate, 1) == 131.5
    drive = wang2013.table1_drive()
    # The exact peak (″) on a grid of β_s × β_p, all grid points in one compiled, vectorised call.
    peak_on_grid = jax.jit(lambda bs, bp: jax.vmap(lambda a, b: gearte.peak(drive.signal(allocated_errors(a, b))))(bs, bp) * ARCSEC)

    def grid(n_s, n_p):
        bs, bp = np.meshgrid(np.linspace(0, 2 * PI, n_s, endpoint=False), np.linspace(0, 2 * PI, n_p, endpoint=False), indexing="ij")
        return bs.ravel(), bp.ravel()

    (s13, p13), (s72, p24) = grid(13, 13), grid(72, 24)
    both = np.asarray(peak_on_grid(jnp.asarray(np.concatenate([s13, s72])), jnp.asarray(np.concatenate([p13, p24]))))
    peaks, fine = both[: s13.size], both[s13.size :]
    # The exact peak over the hyper-period never exceeds the estimate and, for most β, stays below it ...
    assert np.all(peaks <= estimate * (1 + 1e-9))
    assert np.median(peaks) < estimate - 1.0
    # ... and the estimate is the worst case over β_s, β_p (the three lines can align).
    worst = float(np.max(fine))
    assert estimate * 0.995 < worst <= estimate * (1 + 1e-9)


def test_load_sharing_cancels_first_harmonics_of_frame_fixed_and_sun_errors():
    d_single = wang2013.table1_drive(coupling=gearte.SinglePath())
    d_shared = wang2013.table1_drive(coupling=gearte.LoadSharing())
    for name in ("sun_manufacturing", "ring_manufacturing", "sun_assembly", "carrier_assembly"):
        errs = {k: gearte.Eccentricity(0.0, 0.0) for k in SOURCES}
        errs[name] = gearte.Eccentricity(10.0, 0.4)
        assert float(gearte.peak(d_single.signal(errs))) > 1e-5
        assert float(gearte.peak(d_shared.signal(errs))) < 1e-18
    # Planet errors do not cancel: with identical planets the mean of the paths is one path.
    errs = {k: gearte.Eccentricity(0.0, 0.0) for k in SOURCES}
    errs["planet_manufacturing"] = gearte.Eccentricity(np.full(3, 10.0), np.full(3, 0.4))
    np.testing.assert_allclose(gearte.peak(d_shared.signal(errs)), gearte.peak(d_single.signal(errs)), rtol=1e-12)
    # Per-planet errors: one planet's error is shared by all paths → a third of it.
    errs["planet_manufacturing"] = gearte.Eccentricity(np.array([10.0, 0, 0]), np.zeros(3))
    np.testing.assert_allclose(gearte.peak(d_shared.signal(errs)), gearte.peak(d_single.signal(errs)) / 3, rtol=1e-12)


@pytest.mark.parametrize(
    "inp,out,fixed,radius",
    [
        ("sun", "carrier", "ring", lambda rbs, rbr: rbs + rbr),
        ("sun", "ring", "carrier", lambda rbs, rbr: -rbr),
        ("ring", "sun", "carrier", lambda rbs, rbr: -rbs),
        ("carrier", "sun", "ring", lambda rbs, rbr: -rbs),
    ],
)
def test_output_gain_per_configuration(inp, out, fixed, radius):
    # A planet assembly error is a constant e_w + e_n = A[sin(γ + α) + sin(γ − α)] = 2A sin γ cos α.
    m, a = 2.0, math.radians(20)
    d = Planetary2KH(20, 30, 80, module=m, pressure_angle=a, n_planets=4, input=inp, output=out, fixed=fixed)
    errs = {k: gearte.Eccentricity(0.0, 0.0) for k in SOURCES}
    errs["planet_assembly"] = gearte.Eccentricity(np.full(4, 5.0), np.full(4, 0.9))
    rbs, rbr = m * 20 * math.cos(a) / 2, m * 80 * math.cos(a) / 2
    expected = 2 * 5.0 * math.sin(0.9) * math.cos(a) * 1e-3 / radius(rbs, rbr)
    np.testing.assert_allclose(float(d.signal(errs).offset), expected, rtol=1e-12)


def test_profile_shifted_working_angles():
    m, a0 = 1.0, math.radians(20)
    d = Planetary2KH(12, 36, 85, module=m, pressure_angle=a0, n_planets=1, centre_distance=24.4)
    np.testing.assert_allclose(float(d.working_angle_external), math.acos(48 * math.cos(a0) / (2 * 24.4)), rtol=1e-12)
    np.testing.assert_allclose(float(d.working_angle_internal), math.acos(49 * math.cos(a0) / (2 * 24.4)), rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(z_sun=12, z_planet=36, z_ring=85), "z_ring = z_sun"),
        (dict(z_sun=13, z_planet=36, z_ring=85, n_planets=3), "cannot be assembled"),
        (dict(z_sun=12, z_planet=36, z_ring=84, n_planets=6), "clash"),
        # a count that sizes lists is refused by the clash bound before any list of n angles is made
        (dict(z_sun=12, z_planet=36, z_ring=84, n_planets=2**32 - 1), "at most 3 fit"),
        (dict(z_sun=12.5, z_planet=36, z_ring=84), "whole number"),
        (dict(z_sun=0, z_planet=36, z_ring=84), "z_sun"),
        (dict(z_sun=12, z_planet=36, z_ring=84, module=float("nan")), "module"),
        (dict(z_sun=12, z_planet=36, z_ring=84, module=-1.0), "module"),
        (dict(z_sun=12, z_planet=36, z_ring=84, pressure_angle=20.0), "pressure_angle"),
        (dict(z_sun=12, z_planet=36, z_ring=84, output="sun"), "input, output, fixed"),
        (dict(z_sun=12, z_planet=36, z_ring=84, coupling="mean"), "coupling: must be SinglePath"),
        (dict(z_sun=12, z_planet=36, z_ring=84, coupling="load_sharing"), r"gearte.LoadSharing\(\) is 'load_sharing' in a study file"),
        (dict(z_sun=12, z_planet=36, z_ring=84, coupling=gearte.LoadSharing), r"an instance: LoadSharing\(\)"),
        (dict(z_sun=12, z_planet=36, z_ring=84, n_planets=3, planet_angles=[0.0, 1.0]), "planet_angles"),
        (
            dict(z_sun=12, z_planet=36, z_ring=84, n_planets=1, planet_angles=0.0),
            r"planet_angles: a list of angles \(rad\), one per planet",
        ),
        # two planets at one place (also a whole number of turns apart): they clash
        (dict(z_sun=12, z_planet=36, z_ring=84, n_planets=3, planet_angles=[0.0, 2 * math.pi / 3, 0.0]), "clash"),
        (dict(z_sun=12, z_planet=36, z_ring=84, n_planets=3, planet_angles=[0.0, 2 * math.pi / 3, 20 * math.pi]), "clash"),
    ],
)
def test_bad_drives_are_rejected_clearly(kwargs, match):
    base = dict(module=1.0, n_planets=3)
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        Planetary2KH(base.pop("z_sun"), base.pop("z_planet"), base.pop("z_ring"), **base)


def test_bad_errors_are_rejected_at_trace_time():
    d = wang2013.table1_drive()
    errs = {k: gearte.Eccentricity(1.0, 0.0) for k in SOURCES}
    with pytest.raises(ValueError, match="missing"):
        d.signal({k: v for k, v in errs.items() if k != "sun_assembly"})
    with pytest.raises(ValueError, match="unknown"):
        d.signal(errs | {"ring_assembly": gearte.Eccentricity(1.0)})
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        d.signal(errs | {"planet_manufacturing": gearte.Eccentricity(np.ones(2), np.zeros(2))})


def test_te_is_linear_in_small_errors_and_differentiable():
    rng = np.random.default_rng(13)
    d = wang2013.table1_drive(coupling=gearte.LoadSharing())
    errs, _, _ = random_errors(rng)
    theta = np.linspace(0, 2 * PI * 24, 300)
    te = lambda s: gearte.evaluate(d.signal({k: gearte.Eccentricity(s * v.magnitude, v.phase) for k, v in errs.items()}), theta)
    np.testing.assert_allclose(te(0.37), 0.37 * te(1.0), rtol=1e-12, atol=1e-18)

    def f(mags):
        e = {k: gearte.Eccentricity(mags[i] * jnp.ones_like(v.magnitude), v.phase) for i, (k, v) in enumerate(errs.items())}
        return gearte.peak(d.signal(e))

    m0 = jnp.array([float(np.mean(v.magnitude)) for v in errs.values()])
    g = jax.grad(f)(m0)
    eps = 1e-4
    fd = np.array([(f(m0.at[i].add(eps)) - f(m0.at[i].add(-eps))) / (2 * eps) for i in range(len(m0))])
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-12)

    # ... and in the phases, against float64 central differences (per planet: 3 + 3 + 1 × 4 = 10 phases).
    names = list(errs)

    def f_phase(ph):
        e, i = {}, 0
        for k in names:
            c = errs[k].phase.size
            e[k] = gearte.Eccentricity(errs[k].magnitude, ph[i : i + c].reshape(errs[k].phase.shape))
            i += c
        return gearte.peak(d.signal(e))

    p0 = jnp.concatenate([jnp.ravel(errs[k].phase) for k in names])
    p0 = p0 + jnp.asarray(np.random.default_rng(14).uniform(-0.3, 0.3, p0.size))  # planets' phases apart
    gp = jax.grad(f_phase)(p0)
    h = 1e-6
    fdp = np.array([(float(f_phase(p0.at[i].add(h))) - float(f_phase(p0.at[i].add(-h)))) / (2 * h) for i in range(p0.size)])
    np.testing.assert_allclose(gp, fdp, rtol=1e-5, atol=1e-6 * float(jnp.max(jnp.abs(gp))))


def test_eq9_literal_config_is_the_paper_equation():
    s = load_study(Path(__file__).resolve().parents[1] / "examples" / "planetary_wang2013_eq9_literal.toml")
    rng = np.random.default_rng(21)
    theta = np.linspace(0, 2 * PI * 24, 500)
    errs, E, ph = random_errors(rng, n_planets=1)
    errs = {k: gearte.Eccentricity(v.magnitude.reshape(-1)[0], v.phase.reshape(-1)[0]) for k, v in errs.items()}
    np.testing.assert_allclose(gearte.evaluate(s.drive.signal(errs), theta), eq9_numpy(theta, E, ph, 11 / 24), rtol=1e-10, atol=1e-16)


@pytest.mark.parametrize("name, coupling", [("single_path", gearte.SinglePath), ("load_sharing", gearte.LoadSharing)])
def test_a_study_files_coupling_is_the_coupling_object(tmp_path, name, coupling):
    text = (Path(__file__).resolve().parents[1] / "examples" / "planetary_wang2013_random.toml").read_text(encoding="utf-8")
    path = tmp_path / "study.toml"
    path.write_text(text.replace('coupling = "single_path"', f'coupling = "{name}"'), encoding="utf-8")
    d = load_study(path).drive
    assert type(d.coupling) is coupling
    # The study file's drive is the Python one: the same TE for the same errors.
    errs, _, _ = random_errors(np.random.default_rng(5))
    theta = np.linspace(0, 2 * PI * 24, 200)
    ref = wang2013.table1_drive(coupling=coupling())
    np.testing.assert_array_equal(gearte.evaluate(d.signal(errs), theta), gearte.evaluate(ref.signal(errs), theta))
    assert ("planet coupling", coupling.description) in d.describe()
