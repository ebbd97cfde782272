"""Tooth modifications of the helical stage: the lead mismatch, the U-shape of the fluctuation, Zhang, Chen &
Wang's strategies and the gradient optimum through the ODE.

A reduced model (4 slices: the fewest that see crowning as a load distribution; 4 mesh periods, whose
fluctuations are within 0.3 % of 12 periods'; 32 samples) keeps the module fast: the model of tests/test_helical.py
and of the notebook at its small size, run on the same worker (conftest.py), so that they share the compiled
solves. The strategies and the gradient optimum run once per module and are shared, under JAX's standard dtype
promotion as the notebook runs them (tests/notebook_runner.py): the promotion mode is part of a compiled
function's cache key, so the notebook reuses their compiled designs and optimiser. (The model's own code is
checked under strict promotion by tests/test_helical.py and the crowning sweep here.)
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gearte.core.solution import is_successful, result_name
from gearte.drives.helical import EXAMPLE, HelicalPlanetary, load_helical
from gearte.drives.helical_geometry import geometry, iso6336_lead_mismatch
from gearte.drives.helical_modifications import StageModifications
from gearte.drives.helical_solve import PeriodicSolver
from gearte.drives.helical_stiffness import SlicedMeshes, pair_range
from gearte.optimise.helical_modification import (
    _smooth_objective,
    design_variables,
    modification_strategies,
    optimise_modifications,
    recommended_amounts,
)


@pytest.fixture(scope="module")
def model():
    base = load_helical(EXAMPLE)
    return HelicalPlanetary(base.stage, n_slices=4, solver=PeriodicSolver(4, steps_per_period=256, samples_per_period=32))


@pytest.fixture(scope="module")
def study(model):
    with jax.numpy_dtype_promotion("standard"):  # as in the notebook (module docstring)
        return modification_strategies(model)


@pytest.fixture(scope="module")
def gradient_optimum(model, study):
    vs = study.variables
    box = np.array([[v.low, v.high] for v in vs])
    with jax.numpy_dtype_promotion("standard"):
        return optimise_modifications(model, x0=[v.centre for v in vs], bounds=box)


def test_iso6336_lead_mismatch_by_hand_and_in_the_example():
    # F_βx = 1.33 f_sh + f_ma; case-hardened running-in y_β = 0.15 F_βx, at most 6 µm.
    assert iso6336_lead_mismatch(f_ma=22.0, f_sh=5.0) == pytest.approx(28.65 - 0.15 * 28.65, abs=1e-12)
    assert iso6336_lead_mismatch(f_ma=60.0) == pytest.approx(54.0, abs=1e-12)  # y_β capped at 6
    assert iso6336_lead_mismatch(f_ma=60.0, case_hardened=False) == pytest.approx(51.0, abs=1e-12)
    with pytest.raises(ValueError, match="f_ma"):
        iso6336_lead_mismatch(f_ma=-1.0)
    st = load_helical(EXAMPLE).stage
    np.testing.assert_allclose(st.lead_mismatch, [24.35, 24.35], atol=5e-3)


def test_lead_mismatch_is_a_linear_gap_across_the_face():
    base = load_helical(EXAMPLE)
    st = eqx.tree_at(lambda s: s.lead_mismatch, base.stage, jnp.asarray([20.0, 8.0]))
    g = geometry(st)
    exc = SlicedMeshes(st, g, StageModifications(), None, n_slices=4, pairs=pair_range(g, float(st.face_width), 4))
    gap, _ = exc(jnp.asarray(0.3))
    gap = np.asarray(gap).reshape(6, 4, -1)
    # Slice centres of a 230 mm face in 4 slices: ±28.75, ±86.25 mm; gap = F_βy z / b = F_βy (∓0.375, ∓0.125).
    expected = np.array([-0.375, -0.125, 0.125, 0.375])
    np.testing.assert_allclose(gap[0], np.broadcast_to(20.0 * expected[:, None], gap[0].shape), atol=1e-12)
    np.testing.assert_allclose(gap[3], np.broadcast_to(8.0 * expected[:, None], gap[3].shape), atol=1e-12)


def test_fluctuation_falls_then_rises_with_crowning(model):
    # Sun crowning alone on the external mesh, planet crowning alone on the internal mesh: a coarse sweep.
    levels = np.array([0.0, 35.0, 70.0, 140.0])
    x = np.zeros((8, 4))
    x[:4, 1] = levels
    x[4:, 3] = levels
    f = np.asarray(eqx.filter_jit(jax.vmap(lambda m, a: m.fluctuation(a), in_axes=(None, 0)))(model, jnp.asarray(x)))
    ext, internal = f[:4, 0], f[4:, 1]
    for y in (ext, internal):
        k = int(np.argmin(y))
        assert 0 < k < 3, y
        assert y[k] < 0.7 * y[0] and y[k] < 0.7 * y[-1], y


def test_design_variables_are_the_normal_model_of_the_recommended_amounts(model):
    st = model.stage
    mean = recommended_amounts(model)
    # F_t = T_sun/(N r_sun), C_a = F_t/(c_γ b) + F_βy, pair crowning the same, half per gear.
    g = geometry(st)
    f_t = 1e3 * float(st.carrier_torque) / st.ratio / (3 * float(g.radius[0]))
    delta = f_t / (np.asarray(st.mesh_stiffness) * 230.0)
    np.testing.assert_allclose(mean, [delta[0] + 24.35, (delta[0] + 24.35) / 2, delta[1] + 24.35, (delta[1] + 24.35) / 2], rtol=1e-12)
    vs = design_variables(model)
    # ISO 1328-1:2013 class 6 F_p: 39 µm (sun), 44 µm (planet); levels at mean ± 2.326 F_p/6.
    for v, m, fp in zip(vs, mean, (39.0, 39.0, 44.0, 44.0)):
        assert v.centre == pytest.approx(m)
        assert v.half_range == pytest.approx(2.3263478740 * fp / 6, rel=1e-8)


def test_joint_optimum_beats_the_separate_optima_applied_together(study):
    s = study.strategies
    assert study.runs == 10 + 1 + 10 + 1 + 26 + 1 + 1
    for name in ("sun", "planet", "joint"):
        assert s[name].surface is not None and s[name].surface.r2 > 0.9, name
        # the surface's optimum is a good prediction of the direct run
        assert abs(s[name].predicted - s[name].verified) < 0.25 * s[name].verified + 0.5, name
    assert s["joint"].total <= s["combined"].total
    assert s["joint"].total < float(np.sum(study.unmodified))
    np.testing.assert_allclose(s["combined"].amounts, s["sun"].amounts + s["planet"].amounts)


def test_gradient_optimum_is_at_least_as_good_as_the_response_surface_optimum(model, study, gradient_optimum):
    sol = gradient_optimum
    assert is_successful(sol.result)
    assert sol.evaluations >= sol.num_steps >= 1
    vs = study.variables
    assert np.all(np.asarray(sol.amounts) >= np.array([v.low for v in vs]) - 1e-9)
    assert np.all(np.asarray(sol.amounts) <= np.array([v.high for v in vs]) + 1e-9)
    rs = float(_smooth_objective(model, jnp.asarray(study.strategies["joint"].amounts), jnp.asarray([1.0, 1.0]), 0.02))
    assert float(sol.value) <= rs + 1e-3
    assert float(jnp.sum(sol.fluctuation)) <= study.strategies["joint"].total + 0.05


def test_result_codes_and_throw(model, study):
    """max_steps is a run-time value: these runs reuse the compiled optimiser of `gradient_optimum`."""
    vs = study.variables
    box = np.array([[v.low, v.high] for v in vs])
    x0 = [v.centre for v in vs]
    with jax.numpy_dtype_promotion("standard"):
        sol = optimise_modifications(model, x0=x0, bounds=box, max_steps=1, throw=False)
        assert not is_successful(sol.result) and result_name(sol.result) == "nonlinear_max_steps_reached"
        assert sol.num_steps == 1
        with pytest.raises(RuntimeError, match="optimise_modifications"):
            optimise_modifications(model, x0=x0, bounds=box, max_steps=1)
    with pytest.raises(ValueError, match="max_steps"):
        optimise_modifications(model, x0=x0, bounds=box, max_steps=0)
    with pytest.raises(ValueError, match="outside bounds"):
        optimise_modifications(model, x0=[0.0, 0.0, 0.0, 0.0], bounds=box)
    with pytest.raises(ValueError, match="bounds"):
        optimise_modifications(model, x0=x0, bounds=box[:, ::-1])


def test_modifications_stiffness_and_smoothing_width_are_checked_where_given(model):
    """A plain number where a ToothModification is due, a word as the stiffness's end drop and a zero or negative
    smoothing width are refused naming the argument, before anything is computed (each had been accepted and failed
    later, or given inf/NaN)."""
    from gearte.drives.helical_modifications import ToothModification
    from gearte.drives.helical_stiffness import SinglePairStiffness

    with pytest.raises(ValueError, match=r"StageModifications\.ring: expected a ToothModification"):
        StageModifications(sun=ToothModification(10.0), ring=0.5)  # type: ignore[arg-type]
    for bad in ("x", True, [0.2]):
        with pytest.raises(ValueError, match=r"SinglePairStiffness\.end_drop: a fraction in"):
            SinglePairStiffness(bad)  # type: ignore[arg-type]
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="fluctuation: smooth: must be"):
            model.fluctuation(jnp.zeros(4), smooth=bad)
    # What is meant is taken: an array of end drops, a traced width.
    SinglePairStiffness(np.array([0.2, 0.3]))
    jax.eval_shape(lambda w: model.fluctuation(jnp.zeros(4), smooth=w), 0.02)
