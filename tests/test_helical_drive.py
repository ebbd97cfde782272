"""The helical stage as a registered drive (`gearte.drives.helical_drive`): its quasi-static TE against a direct
solve of the same equilibria, against the kinematic planetary model, against the dynamic analysis; linear in
the errors; the study-file keys. (The contract of every registered drive is tests/test_contract.py.)"""

from __future__ import annotations

import math
import shutil
from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import gearte
from gearte import cli
from gearte.cli.config import load_study
from gearte.core.signal import evaluate
from gearte.core.solution import RESULTS
from gearte.drives.helical_drive import Dynamic, HelicalPlanetaryDrive, QuasiStatic
from gearte.drives.helical_geometry import geometry
from gearte.drives.helical_stiffness import MeanStiffness
from gearte.drives.planetary_2kh import Planetary2KH
from gearte.drives.protocol import Eccentricity

EXAMPLE = "examples/helical_wind_turbine.toml"


@pytest.fixture(scope="module")
def stage():
    return load_study(EXAMPLE).drive.stage


@pytest.fixture(scope="module")
def respond():
    return eqx.filter_jit(lambda drive, errors: drive.response(errors))


def _errors(drive, seed, high=10.0):
    rng = np.random.default_rng(seed)
    return {n: Eccentricity(rng.uniform(1, high, s.shape), rng.uniform(0, 2 * np.pi, s.shape)) for n, s in drive.error_sources.items()}


def _short(stage, **kwargs):
    """Four mesh periods, 8 angles each, 4 slices: the example's stage on a small grid."""
    kwargs.setdefault("analysis", QuasiStatic(4 / 99, samples_per_mesh_period=8))
    return HelicalPlanetaryDrive(stage, n_slices=4, **kwargs)


def _direct(sys, taus, rows):
    """(TE, mid-face DTE) at each τ from K(τ) q = F − Gᵀ(k w gap(τ)) solved afresh by LAPACK (`jnp.linalg.solve`),
    every pair in contact: the reference, independent of the drive's tiling, superposition and solver."""
    s = sys.system

    def one(tau):
        gap, w = s.excitation(tau)
        rhs = s.load - s.projection.T @ (s.pair_stiffness * jnp.sum(w * gap, axis=-1))
        return jnp.linalg.solve(s.linear_stiffness(tau), rhs)

    return jax.vmap(one)(taus) @ rows.T


_direct_jit = eqx.filter_jit(_direct)


def test_grid_window_and_hyper_period(stage):
    d = HelicalPlanetaryDrive(stage, analysis=QuasiStatic(0.5, samples_per_mesh_period=6))
    assert d.window_turns() == Fraction(50, 99)  # 49.5 mesh periods rounded up
    np.testing.assert_allclose(np.diff(np.asarray(d.input_angles())), 2 * np.pi / (99 * 6), rtol=1e-12)
    assert d.input_angles().shape == (50 * 6,)
    # Sun, planet and ring turn 99/21 = 33/7, 99/39 = 33/13 and 1 times per carrier turn relative to the carrier.
    assert d.hyper_period_turns() == 91


def test_quasi_static_is_the_direct_equilibrium_with_the_errors(stage, respond):
    """The drive's equilibria (one mesh period's factorisations, the errors by superposition) against K(τ)q = F(τ)
    solved afresh at each angle with the errors in the gaps (`MeshedSystem.static`), the whole window."""
    d = HelicalPlanetaryDrive(stage, analysis=QuasiStatic(1.0, samples_per_mesh_period=4), n_slices=4)
    errors = _errors(d, 0, high=15.0)
    r = respond(d, errors)
    sys = d.system(errors)
    idx = np.arange(0, 99 * 4, 13)
    y = _direct_jit(sys, jnp.asarray(d.mesh_times()[idx]), d._rows(sys))
    np.testing.assert_allclose(y[:, 0], r.te[idx], rtol=0, atol=1e-10 * float(jnp.ptp(r.te)))
    np.testing.assert_allclose(y[:, 1:].T, r.dte[:, idx], rtol=0, atol=1e-9)  # µm
    assert float(jnp.ptp(r.te - r.te_nominal)) > 1e-6  # the errors matter (rad)
    assert r.result == RESULTS.successful and bool(d.solved(r))


def test_errors_te_with_constant_mesh_stiffness_is_the_kinematic_load_sharing_model(stage, respond):
    """With every mesh at its mean stiffness, the elastic model's TE of the eccentricities is `Planetary2KH`'s with
    load sharing (the mean of the planets' path errors), whatever the supports: three planets on one carrier in
    series with mesh springs of equal stiffness share any path error equally."""
    g = geometry(stage)
    kin = Planetary2KH(
        stage.z_sun,
        stage.z_planet,
        stage.z_ring,
        n_planets=stage.n_planets,
        module=float(g.transverse_module),
        pressure_angle=float(g.transverse_pressure_angle),
        input="carrier",
        output="sun",
        fixed="ring",
        coupling=gearte.LoadSharing(),
    )
    errors = _errors(kin, 3)
    for scale in (1.0, 1e4):  # the example's floating sun, and every support 10⁴ × stiffer
        sup = np.asarray(stage.support_stiffness).copy()
        sup[:, :5] *= scale
        stiff = eqx.tree_at(lambda s: s.support_stiffness, stage, jnp.asarray(sup))
        d = HelicalPlanetaryDrive(stiff, analysis=QuasiStatic(1.0, samples_per_mesh_period=4), stiffness_model=MeanStiffness(), n_slices=2)
        r = respond(d, errors)
        ref = np.asarray(evaluate(kin.signal(errors), d.input_angles()))
        assert np.ptp(ref) > 1e-5  # rad: the planets' eccentricities
        np.testing.assert_allclose(np.ptp(r.te_nominal), 0.0, atol=1e-15)
        np.testing.assert_allclose(r.te - r.te_nominal, ref, rtol=0, atol=1e-11 * np.ptp(ref))


@settings(max_examples=12, deadline=None)
@given(scale=st.floats(0.05, 20.0), turn=st.floats(0.0, 2 * math.pi), seed=st.integers(0, 2**16))
@example(scale=0.5, turn=0.0, seed=5771)  # errors that nearly cancel: their TE is 1/100 of the usual (5e-7 rad)
def test_errors_te_is_linear_in_the_eccentricity_vectors(stage, respond, scale, turn, seed):
    """Scaling every magnitude scales the errors' TE; two sets of errors add as vectors (magnitude, phase)."""
    d = _short(stage)
    a, b = _errors(d, seed), _errors(d, seed + 1)

    def err_te(errors):
        r = respond(d, errors)
        return np.asarray(r.te - r.te_nominal)

    ta, tb = err_te(a), err_te(b)
    scaled = {n: Eccentricity(scale * e.magnitude, e.phase) for n, e in a.items()}
    size = np.max(np.abs(ta))  # the rounding of the solves scales with the values, not with their spread
    # The errors' TE is a difference of two TEs of about 7.6e-3 rad (the load's deflection): it cannot be known
    # better than its last bits, 8 ε × 7.6e-3 rad (ε × 7.6e-3 rad = 1.7e-18 rad), whatever the errors' size.
    floor = 8 * np.finfo(np.float64).eps * float(np.max(np.abs(respond(d, a).te_nominal)))
    np.testing.assert_allclose(err_te(scaled), scale * ta, rtol=0, atol=1e-12 * scale * size + floor)
    both = {}
    for n in a:
        z = np.asarray(a[n].magnitude) * np.exp(1j * np.asarray(a[n].phase))
        z = z + np.asarray(b[n].magnitude) * np.exp(1j * (np.asarray(b[n].phase) + turn))
        both[n] = Eccentricity(np.abs(z), np.angle(z))
    turned = {n: Eccentricity(e.magnitude, e.phase + turn) for n, e in b.items()}
    np.testing.assert_allclose(err_te(both), ta + err_te(turned), rtol=0, atol=1e-11 * (size + np.max(np.abs(tb))) + floor)


def test_dynamic_analysis_with_constant_stiffness_is_the_quasi_static_one(stage, respond):
    """The eccentricities excite at most 4.7 × the carrier frequency (1.7 Hz), far below the stage's modes: with the
    mesh stiffness constant, the ODE's TE after settling is the quasi-static TE (within 3e-5 of its p-p measured;
    2e-4 allowed). (With the sliced stiffness the mesh frequency adds a dynamic part, ~6 % of the p-p in the
    example, which the quasi-static analysis leaves out: docs/helical.md.)"""
    errors = _errors(_short(stage), 3)
    dyn = _short(stage, analysis=Dynamic(4 / 99, samples_per_mesh_period=8, settle_mesh_periods=19), stiffness_model=MeanStiffness())
    ry = respond(dyn, errors)
    assert bool(dyn.solved(ry)) and ry.result == RESULTS.successful
    sys = dyn.system(errors)
    yq = _direct_jit(sys, jnp.asarray(dyn.mesh_times()), dyn._rows(sys))
    ptp = float(jnp.ptp(yq[:, 0]))
    assert ptp > 1e-6
    np.testing.assert_allclose(ry.te, yq[:, 0], rtol=0, atol=2e-4 * ptp)
    # without errors and with constant stiffness nothing varies: the nominal TE is the load's constant twist
    np.testing.assert_allclose(np.ptp(ry.te_nominal), 0.0, atol=1e-12 * float(jnp.max(jnp.abs(ry.te_nominal))))


def test_study_file_keys_are_checked(tmp_path, capsys):
    text = open(EXAMPLE, encoding="utf-8").read()
    cases = {
        "no_file.toml": (text.replace('"dynamics/helical_wind_turbine.toml"', '"dynamics/nothing.toml"'), "parameters: no file"),
        "settle.toml": (
            text.replace("samples_per_mesh_period = 16", "samples_per_mesh_period = 16\nsettle_mesh_periods = 5"),
            "settle_mesh_periods",
        ),
        "model.toml": (
            text.replace('analysis = "quasi_static"', 'analysis = "quasi_static"\nstiffness_model = "constant"'),
            "stiffness_model",
        ),
        "turns.toml": (text.replace("carrier_turns = 1 ", "carrier_turns = -1 "), "carrier_turns"),
    }
    shutil.copytree("examples/dynamics", tmp_path / "dynamics")
    for name, (body, message) in cases.items():
        assert body != text, name
        p = tmp_path / name
        p.write_text(body, encoding="utf-8")
        assert cli.main(["check", str(p)]) == 2, name
        err = capsys.readouterr().err
        assert message in err and name in err and "Traceback" not in err, err
    ok = tmp_path / "ok.toml"
    ok.write_text(text, encoding="utf-8")
    assert cli.main(["check", str(ok)]) == 0  # the parameter file is found beside the study file, not the working folder
