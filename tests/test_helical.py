"""Helical planetary dynamic model: geometry, mesh stiffness, modifications, errors, solver, gradients.

The stage is the wind-turbine parameter set (examples/dynamics/helical_wind_turbine.toml) reduced to 4 slices,
4 mesh periods and 32 samples per period, the model of tests/test_helical_modification.py and of the notebook
at its small size: they run on one worker (conftest.py) and share the compiled solves (`_fluctuation`,
`_smooth_objective`); a solve takes ~0.07 s once compiled.
"""

import math
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from trace_count import traces

from gearte import AbstractStiffnessModel, MeanStiffness, SinglePairStiffness, SlicedStiffness, TransverseStiffness
from gearte.core.signal import evaluate
from gearte.core.solution import RESULTS
from gearte.drives.helical import EXAMPLE, HelicalPlanetary, load_helical, wind_turbine_report
from gearte.drives.helical_equations import MeshedSystem, contact_force, loa_errors, stage_system
from gearte.drives.helical_geometry import geometry, iso6336_mesh_stiffness
from gearte.drives.helical_modifications import PathRelief, StageModifications, ToothModification, crowning, flank_pair_relief
from gearte.drives.helical_solve import PeriodicSolver, UnrolledExplicitRK, solve_periodic
from gearte.drives.helical_stiffness import SlicedMeshes, pair_range, slice_centres
from gearte.drives.planetary_2kh import Planetary2KH
from gearte.drives.protocol import Eccentricity
from gearte.optimise.helical_modification import _fluctuation, _smooth_objective

#: The reduced solver of the helical tests and of the notebook at its small size (one compiled solve for all).
SOLVER = PeriodicSolver(4, steps_per_period=256, samples_per_period=32)


@pytest.fixture(scope="module")
def model():
    base = load_helical(EXAMPLE)
    return HelicalPlanetary(base.stage, n_slices=4, solver=SOLVER)


@pytest.fixture(scope="module")
def response():
    return eqx.filter_jit(lambda m, mods, errors: m.response(mods, errors))


# ---------------------------------------------------------------- geometry, stiffness, modifications (no ODE)


def test_geometry_matches_iso21771_by_hand_and_the_file_uses_iso6336_stiffness(model):
    st = model.stage
    g = geometry(st)
    mn, b = 10.0, math.radians(11.5)  # the example's helix angle
    mt = mn / math.cos(b)
    at = math.atan(math.tan(math.radians(20)) / math.cos(b))
    d = np.array([21, 39, 99]) * mt
    db = d * math.cos(at)
    da = d + np.array([2, 2, -2]) * mn
    a = (d[0] + d[1]) / 2
    pbt = math.pi * mt * math.cos(at)
    eps_ext = (math.sqrt(da[0] ** 2 - db[0] ** 2) + math.sqrt(da[1] ** 2 - db[1] ** 2) - 2 * a * math.sin(at)) / (2 * pbt)
    eps_int = (math.sqrt(da[1] ** 2 - db[1] ** 2) - math.sqrt(da[2] ** 2 - db[2] ** 2) + 2 * a * math.sin(at)) / (2 * pbt)
    np.testing.assert_allclose(g.contact_ratio, [eps_ext, eps_int], rtol=1e-12)
    np.testing.assert_allclose(g.overlap_ratio, 230 * math.sin(b) / (math.pi * mn), rtol=1e-12)
    assert float(g.mesh_frequency) == pytest.approx(99 * 22 / 60)
    # ISO 6336-1 method B by hand (x = 0, solid gears, standard basic rack): z_n = z/(cos²β_b cos β) with
    # sin β_b = sin β cos α_n, so z_n = 22.21 (sun) and 41.25 (planet); q' = 0.04723 + 0.15551/z_n1 + 0.25791/z_n2,
    # with z_n2 = ∞ for the internal mesh (the planet is gear 1 there): q' = 0.06048 / 0.05100;
    # c' = 0.8 cos β / q' = 12.96 / 15.37 N/(mm·µm); c_γα = c' (0.75 ε_α + 0.25).
    c_single, c_gamma = iso6336_mesh_stiffness(st)
    np.testing.assert_allclose(c_single, [12.96, 15.37], rtol=2e-3)
    np.testing.assert_allclose(c_gamma, np.array([12.96, 15.37]) * (0.75 * np.array([eps_ext, eps_int]) + 0.25), rtol=2e-3)
    np.testing.assert_allclose(st.mesh_stiffness, c_gamma, atol=0.006)


def _weights(model, n_slices, stiffness_model: AbstractStiffnessModel = SlicedStiffness()):
    st = model.stage
    g = geometry(st)
    pairs = pair_range(g, float(st.face_width), n_slices)
    exc = SlicedMeshes(st, g, StageModifications(), None, n_slices=n_slices, pairs=pairs, stiffness_model=stiffness_model)
    taus = jnp.linspace(0.0, 1.0, 4000, endpoint=False)
    _, w = eqx.filter_jit(lambda e, t: jax.vmap(e.positions)(t))(exc, taus)
    return g, w  # (T, meshes, slices, pairs)


def test_sliced_stiffness_has_the_iso_mean_and_the_spur_limit_alternates_single_double(model):
    g, w = _weights(model, 8)
    per_slice = jnp.sum(w, axis=-1)  # pairs in contact in each slice, averaged over its width
    n = model.stage.n_planets
    # Mean over a mesh period: ε_α pairs in every slice, so the mean mesh stiffness is c_γ b.
    np.testing.assert_allclose(jnp.mean(per_slice, axis=0)[:n], float(g.contact_ratio[0]), rtol=1e-3)
    np.testing.assert_allclose(jnp.mean(per_slice, axis=0)[n:], float(g.contact_ratio[1]), rtol=1e-3)
    # Spur limit (every slice in phase): one or two pairs; two for a fraction ε_α − 1 of the period.
    _, w = _weights(model, 8, TransverseStiffness())
    total = np.asarray(jnp.mean(jnp.sum(w, axis=-1), axis=-1)[:, 0])
    assert total.min() == pytest.approx(1.0, abs=1e-9) and total.max() == pytest.approx(2.0, abs=1e-9)
    np.testing.assert_allclose(np.mean(total > 1.5), float(g.contact_ratio[0]) - 1, atol=0.05)


def test_single_pair_stiffness_keeps_the_iso_mean_and_peaks_at_c_prime(model):
    """`SinglePairStiffness`: each pair weighs (1 − c x²)/(1 − c/3) along its path (x = 2u/g − 1). Its mean over the
    path is 1, so the mean mesh stiffness stays c_γ b (ε_α pairs per slice, as the sliced model); with c = 0.75 (1 −
    1/ε_α) its maximum, relative to the mean single-pair stiffness c_γα/ε_α, is ISO 6336-1's c'/(c_γα/ε_α): checked
    against `iso6336_mesh_stiffness`, which computes c' and c_γα = c'(0.75 ε_α + 0.25) on its own."""
    g, w = _weights(model, 8, SinglePairStiffness())
    n = model.stage.n_planets
    per_slice = jnp.mean(jnp.sum(w, axis=-1), axis=0)
    np.testing.assert_allclose(per_slice[:n], float(g.contact_ratio[0]), rtol=2e-3)
    np.testing.assert_allclose(per_slice[n:], float(g.contact_ratio[1]), rtol=2e-3)
    c_single, c_mesh = iso6336_mesh_stiffness(model.stage)
    peak = np.asarray(c_single / (c_mesh / g.contact_ratio))  # c' over the mean single-pair stiffness, per mesh
    # by hand from c_γα = c' (0.75 ε_α + 0.25): c'/(c_γα/ε_α) = ε_α/(0.75 ε_α + 0.25)
    eps = np.asarray(g.contact_ratio)
    np.testing.assert_allclose(peak, eps / (0.75 * eps + 0.25), rtol=1e-12)
    _, w_flat = _weights(model, 8)
    ratio = np.asarray(jnp.max(w, axis=(0, 2, 3)) / jnp.max(w_flat, axis=(0, 2, 3)))  # the largest weight of a pair
    np.testing.assert_allclose(ratio[:n], peak[0], rtol=1e-3)
    np.testing.assert_allclose(ratio[n:], peak[1], rtol=1e-3)
    # At the tip and root a pair is (1 − c) of its mid-path stiffness: with c = 0.4 for every mesh, pairs wholly on
    # the path (thin slices) weigh from 0.6/(1 − 0.4/3) near the ends to 1/(1 − 0.4/3) at mid path.
    _, w4 = _weights(model, 40, SinglePairStiffness(0.4))
    _, w1 = _weights(model, 40)
    on_path = np.asarray(w1) >= 1 - 1e-12
    ratio = np.asarray(w4)[on_path] / np.asarray(w1)[on_path]
    assert ratio.max() == pytest.approx(1 / (1 - 0.4 / 3), rel=1e-4)
    # A pair wholly on the path is at least a slice's half span s from its ends: x ≤ 1 − 2s/g there.
    half_span = float(model.stage.face_width) / 40 * math.tan(float(g.base_helix_angle)) / 2
    x_end = 1 - 2 * half_span / float(jnp.max(g.path_length))
    assert ratio.min() == pytest.approx((1 - 0.4 * x_end**2) / (1 - 0.4 / 3), rel=1e-3)
    with pytest.raises(ValueError, match="end_drop"):
        SinglePairStiffness(1.0)


@pytest.mark.parametrize("n_slices", [1, 3, 8, 40])
def test_pair_range_holds_every_pair_that_is_ever_on_the_path(model, n_slices):
    """`pair_range` is tight: with three more pairs on each side the extra pairs never carry weight,
    and each pair of the range does at some time (the range is no wider than it must be)."""
    st = model.stage
    g = geometry(st)
    lo, hi = pair_range(g, float(st.face_width), n_slices)
    wide = SlicedMeshes(st, g, StageModifications(), None, n_slices=n_slices, pairs=(lo - 3, hi + 3))
    taus = jnp.linspace(0.0, 1.0, 4001)
    _, w = eqx.filter_jit(lambda e, t: jax.vmap(e.positions)(t))(wide, taus)
    w = np.asarray(w)  # (T, meshes, slices, pairs lo − 3 … hi + 2)
    assert not w[..., :3].any() and not w[..., -3:].any()
    assert (w[..., 3:-3].max(axis=(0, 1, 2)) > 0).all()


def test_stiffness_models_lead_shifted_in_phase_and_constant(model):
    """`SlicedStiffness`: slice k runs (z_k − z_0) tan β_b / p_bt mesh periods ahead of slice 0.
    `TransverseStiffness`: every slice in phase, exactly the sliced pairs with the lead shift removed (what
    ``stiffness_model="transverse"`` computed). `MeanStiffness`: constant, the sliced model's time average ε_α."""
    st = model.stage
    g = geometry(st)
    exc = SlicedMeshes(st, g, StageModifications(), None, n_slices=8, pairs=pair_range(g, float(st.face_width), 8))
    taus = jnp.linspace(0.0, 1.0, 4000, endpoint=False)
    weights = eqx.filter_jit(lambda e, t: jax.vmap(e.positions)(t)[1])
    w_sliced = weights(exc, taus)
    per_slice = np.asarray(jnp.sum(w_sliced, axis=-1))  # (T, meshes, slices)
    z = slice_centres(st.face_width, 8)
    ahead = (z - z[0]) * jnp.tan(g.base_helix_angle) / g.base_pitch  # mesh periods
    assert float(ahead[-1]) > 0.5  # a large shift: the test sees it
    for k in (1, 7):
        slice_0_later = np.asarray(jnp.sum(weights(exc, taus + ahead[k]), axis=-1))[:, :, 0]
        np.testing.assert_allclose(per_slice[:, :, k], slice_0_later, atol=1e-9)
    _, w_trans = _weights(model, 8, TransverseStiffness())
    np.testing.assert_array_equal(w_trans, np.broadcast_to(w_trans[:, :, :1], w_trans.shape))  # every slice in phase
    no_lead = eqx.tree_at(lambda e: e.lead_shift, exc, jnp.zeros(8))
    np.testing.assert_array_equal(w_trans, weights(no_lead, taus))
    _, w_mean = _weights(model, 8, MeanStiffness())
    mean = np.asarray(jnp.sum(w_mean, axis=-1))
    np.testing.assert_array_equal(mean, np.broadcast_to(mean[:1], mean.shape))  # constant in time
    np.testing.assert_allclose(mean[0], per_slice.mean(axis=0), rtol=1e-3)


def test_stiffness_model_must_be_an_object_and_files_name_one(model, tmp_path):
    st = model.stage
    g = geometry(st)
    with pytest.raises(
        ValueError, match=r"stiffness_model: .*SlicedStiffness\(\), TransverseStiffness\(\), MeanStiffness\(\).*use MeanStiffness\(\)"
    ):
        HelicalPlanetary(st, n_slices=4, stiffness_model="mean")  # pyright: ignore[reportArgumentType]
    with pytest.raises(ValueError, match="stiffness_model: give a stiffness model object"):
        stage_system(st, StageModifications(), stiffness_model=SlicedStiffness)  # pyright: ignore[reportArgumentType]
    with pytest.raises(ValueError, match="stiffness_model: give a stiffness model object"):
        SlicedMeshes(st, g, StageModifications(), None, n_slices=4, pairs=(0, 1), stiffness_model="spur")  # pyright: ignore[reportArgumentType]
    with pytest.raises(ValueError, match=r"stiffness_models\[1\]: .*use TransverseStiffness\(\)"):
        wind_turbine_report(stiffness_models=(SlicedStiffness(), "transverse"))  # pyright: ignore[reportArgumentType]

    class NoContacts(AbstractStiffnessModel):
        name: ClassVar[str] = "half"

    class NoName(AbstractStiffnessModel):
        def contacts(self, meshes, tau):
            return SlicedStiffness().contacts(meshes, tau)

    for half in (NoContacts, NoName):  # a model declares both
        with pytest.raises(TypeError, match="abstract"):
            half()  # pyright: ignore[reportAbstractUsage]
    text = EXAMPLE.read_text(encoding="utf-8")
    assert 'stiffness_model = "slices"' in text
    for name, cls in (
        ("slices", SlicedStiffness),
        ("transverse", TransverseStiffness),
        ("mean", MeanStiffness),
        ("single_pair", SinglePairStiffness),
    ):
        path = tmp_path / f"{name}.toml"
        path.write_text(text.replace('stiffness_model = "slices"', f'stiffness_model = "{name}"'), encoding="utf-8")
        assert type(load_helical(path).stiffness_model) is cls
    path.write_text(text.replace('stiffness_model = "slices"', 'stiffness_model = "spur"'), encoding="utf-8")
    with pytest.raises(ValueError, match=r"\[model\]\.stiffness_model: one of 'slices', 'transverse', 'mean', 'single_pair', got 'spur'"):
        load_helical(path)


def test_wind_turbine_report_shares_the_drive_s_compiled_solve(model, tmp_path):
    # The report solves each stage with the drive's own jitted `response` (`_response_jit`), not with a jit of its
    # own around it: after the drive's solve, a report of the same structure and shapes (the fixture's reduced model,
    # read from a file) traces nothing, and neither does a report of another stage (less power) of those shapes.
    text = EXAMPLE.read_text(encoding="utf-8")
    for old, new in (
        ("n_slices = 8 ", "n_slices = 4 "),
        ("n_periods = 20 ", "n_periods = 4 "),
        ("samples_per_period = 128", "samples_per_period = 32"),
    ):
        assert old in text
        text = text.replace(old, new)
    small, other = tmp_path / "small.toml", tmp_path / "other.toml"
    small.write_text(text, encoding="utf-8")
    other.write_text(text.replace("power_kw = 750.0", "power_kw = 700.0"), encoding="utf-8")
    own = model.response()
    with traces() as seen:
        first = wind_turbine_report(small, stiffness_models=(SlicedStiffness(),))
    assert not {"_response_jit", "response"} & set(seen), dict(seen)  # neither the solve nor a jit around it
    with traces() as seen:
        second = wind_turbine_report(other, stiffness_models=(SlicedStiffness(),))
    assert not seen, dict(seen)
    n = model.stage.n_planets
    for table, r in ((first, own), (second, load_helical(other).response())):
        row = table.splitlines()[2]
        assert row.startswith(f"| slices | {float(r.fluctuation[0]):.3f} | {float(r.fluctuation[n]):.3f} | "), row
    assert first.splitlines()[2] != second.splitlines()[2]


def test_the_model_refuses_a_solver_it_cannot_use(model):
    """A solver that is not a PeriodicSolver, or a kept window too short for the 16 harmonics of the DTE spectrum
    (it had failed inside the solve with a shape error), or a smoothing that is not a positive number."""
    with pytest.raises(ValueError, match=r"solver: a gearte.PeriodicSolver"):
        HelicalPlanetary(model.stage, solver={"n_periods": 4})  # pyright: ignore[reportArgumentType]
    with pytest.raises(ValueError, match=r"samples_per_period × record_periods = 29 samples .* need at least 30"):
        HelicalPlanetary(model.stage, solver=PeriodicSolver(4, samples_per_period=29))
    assert HelicalPlanetary(model.stage, solver=PeriodicSolver(4, samples_per_period=15, record_periods=2)).solver.record_periods == 2
    with pytest.raises(ValueError, match=r"contact_smoothing: expected a number, got 'x'"):
        HelicalPlanetary(model.stage, contact_smoothing="x")  # pyright: ignore[reportArgumentType]


def test_parameter_files_name_the_table_and_key_of_a_bad_number(tmp_path):
    """Tooth counts and solver counts are whole numbers: 21.5 teeth or "8" slices are named, not truncated."""
    text = EXAMPLE.read_text(encoding="utf-8")
    path = tmp_path / "bad.toml"
    for old, new, msg in (
        ("z_sun = 21", "z_sun = 21.5", r"bad\.toml \[gears\]\.z_sun: must be a whole number, got 21\.5"),
        ("n_slices = 8", 'n_slices = "8"', r"bad\.toml \[model\]\.n_slices: must be a whole number, got '8'"),
        ("n_periods = 20", "n_periods = 0", r"bad\.toml \[model\]\.n_periods: must be ≥ 2, got 0"),  # the solver's bound
        # the study's dynamic analysis takes it as its default: named here, not as Dynamic's steps_per_mesh_period
        ("steps_per_period = 256", "steps_per_period = 1", r"bad\.toml \[model\]\.steps_per_period: must be ≥ 4, got 1"),
        ("carrier_speed_rpm = 22", "carrier_speed_rpm = 0", r"bad\.toml \[operation\]\.carrier_speed_rpm: must be > 0, got 0"),
        ("power_kw = 750.0", "power_kw = nan", r"bad\.toml \[operation\]\.power_kw: must be a finite number, got nan"),
        # Five planets of 39 teeth around 21: centres 359.9 mm apart, tip circles 418 mm (four fit: 433 mm).
        (
            "n_planets = 3",
            "n_planets = 5",
            r"bad\.toml: n_planets: planets clash: 5 planets of 39 teeth .* 418\.0 mm diameter overlap\); at most 4 fit",
        ),
        # a count that sizes lists: refused by the same bound before a list of 2³² − 1 angles is made
        ("n_planets = 3", "n_planets = 4294967295", r"bad\.toml: n_planets: planets clash: 4294967295 planets .* at most 4 fit"),
    ):
        assert old in text
        path.write_text(text.replace(old, new), encoding="utf-8")
        with pytest.raises(ValueError, match=msg):
            load_helical(path)
    path.write_text(text.replace("z_sun = 21", "z_sun = 21.0"), encoding="utf-8")
    assert load_helical(path).stage.z_sun == 21  # a float with no fractional part is a whole number


def test_parameter_files_refuse_unknown_tables_and_keys(tmp_path):
    """A misspelt key would leave its default in force silently: every table and key of the file must be one the
    format has, named with the nearest one."""
    text = EXAMPLE.read_text(encoding="utf-8")
    path = tmp_path / "bad.toml"
    for old, new, msg in (
        ("n_slices = 8", "n_slice = 8", r"bad\.toml \[model\]: unknown key `n_slice` \(did you mean `n_slices`\?\)"),
        (
            "contact_smoothing_um",
            "contact_smoothing_mm",
            r"\[model\]: unknown key `contact_smoothing_mm` \(did you mean `contact_smoothing_um`\?\)",
        ),
        ("power_kw", "foo = 1\npower_kw", r"\[operation\]: unknown key `foo`"),
        ("[members.carrier]", "[members.carier]", r"\[members\]: unknown key `carier` \(did you mean `carrier`\?\)"),
        ("[members.carrier]\nmass_kg", "[members.carrier]\nmas_kg = 1\nmass_kg", r"\[members.carrier\]: unknown key `mas_kg`"),
        ("[model]", "[extra]\nx = 1\n[model]", r"bad\.toml: unknown table `\[extra\]`"),
    ):
        assert old in text, old
        path.write_text(text.replace(old, new, 1), encoding="utf-8")
        with pytest.raises(ValueError, match=msg):
            load_helical(path)


def test_tip_relief_and_crowning_values():
    g_alpha, pbt = 48.0, 30.0
    default = g_alpha - pbt  # from the single/double-contact boundary to the tip
    lin = ToothModification(40.0, crowning=12.0)
    par = ToothModification(40.0, shape="parabolic")
    none = ToothModification()
    u = jnp.asarray([0.0, default / 2, default, g_alpha - default, g_alpha])
    # `first`'s tip is at u = 0, `last`'s at u = g_α.
    np.testing.assert_allclose(flank_pair_relief(lin, none, u, g_alpha, pbt), [40.0, 20.0, 0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(flank_pair_relief(none, par, u, g_alpha, pbt), [0.0, 0.0, 0.0, 0.0, 40.0], atol=1e-12)
    np.testing.assert_allclose(
        flank_pair_relief(none, par, jnp.asarray(g_alpha - default / 2), g_alpha, pbt), 10.0, atol=1e-12
    )  # parabolic: a quarter at half length
    root = ToothModification(root_relief=8.0, root_relief_length=6.0)
    np.testing.assert_allclose(flank_pair_relief(root, none, jnp.asarray([g_alpha, g_alpha - 3.0]), g_alpha, pbt), [8.0, 4.0])
    np.testing.assert_allclose(crowning(lin, none, jnp.asarray([-115.0, 0.0, 57.5]), 230.0), [12.0, 0.0, 3.0])


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    amounts=st.lists(st.floats(0.0, 60.0), min_size=8, max_size=8),
    lengths=st.lists(st.one_of(st.none(), st.floats(0.5, 20.0)), min_size=8, max_size=8),
    shapes=st.lists(st.sampled_from(["linear", "parabolic"]), min_size=2, max_size=2),
)
def test_path_relief_of_all_meshes_at_once_is_the_definition_for_each(amounts, lengths, shapes):
    """`PathRelief` (what `SlicedMeshes` evaluates, three meshes at once) against the definition written out here in
    NumPy: on a path of length g from the tip of gear `first` to the tip of gear `last`, first's tip relief C_a over
    L from u = 0 and last's root relief from u = 0, last's tip relief and first's root relief from u = g; each
    C (max(L − d, 0)/L)^e, e = 1 linear or 2 parabolic, L = g − p_bt when not given."""
    pbt = 30.0
    path = np.asarray([48.0, 55.0, 41.0])

    def tooth(i, shape):
        return ToothModification(
            amounts[i], tip_relief_length=lengths[i], root_relief=amounts[i + 1], root_relief_length=lengths[i + 1], shape=shape
        )

    def reference(first, last, uu, g):
        def one(amount, length, d, shape):
            L = g - pbt if length is None else length
            return amount * (np.maximum(L - d, 0.0) / L) ** (1 if shape == "linear" else 2)

        (a_tip, a_root, a_len, a_rlen, a_shape), (b_tip, b_root, b_len, b_rlen, b_shape) = first, last
        return (
            one(a_tip, a_len, uu, a_shape)
            + one(b_root, b_rlen, uu, b_shape)
            + one(b_tip, b_len, g - uu, b_shape)
            + one(a_root, a_rlen, g - uu, a_shape)
        )

    spec = [(amounts[i], amounts[i + 1], lengths[i], lengths[i + 1], shapes[k]) for i, k in ((0, 0), (2, 1), (4, 0))]
    teeth = [tooth(0, shapes[0]), tooth(2, shapes[1]), tooth(4, shapes[0])]
    pairs = [(0, 1), (1, 2), (2, 0)]
    u = np.linspace(-5.0, 60.0, 53)[None, :] * np.ones((3, 1))
    got = np.asarray(PathRelief([(teeth[a], teeth[b]) for a, b in pairs], jnp.asarray(path), pbt)(jnp.asarray(u), jnp.asarray(path)))
    for m, (a, b) in enumerate(pairs):
        np.testing.assert_allclose(got[m], reference(spec[a], spec[b], u[m], path[m]), rtol=1e-13, atol=1e-12)


def test_unrolled_runge_kutta_is_diffrax_own_step_to_rounding():
    """`UnrolledExplicitRK` with a diffrax tableau takes the same steps as diffrax's solver of that tableau (Tsit5 and
    Dopri5 first-same-as-last, Heun not), on the forced oscillator over two periods; an implicit tableau is refused."""
    sys = _oscillator()
    y0 = jnp.asarray([LOAD, 0.0])

    def run(method):
        ys = diffrax.diffeqsolve(
            diffrax.ODETerm(sys.vector_field),
            method,
            t0=0.0,
            t1=2.0,
            dt0=1.0 / 64,
            y0=y0,
            saveat=diffrax.SaveAt(ts=jnp.linspace(0.0, 2.0, 9)),
            stepsize_controller=diffrax.ConstantStepSize(),
        ).ys
        assert ys is not None
        return np.asarray(ys)

    for ref in (diffrax.Tsit5, diffrax.Dopri5, diffrax.Heun):
        np.testing.assert_allclose(run(UnrolledExplicitRK(ref)), run(ref()), rtol=1e-13, atol=1e-12)
        assert UnrolledExplicitRK(ref).order(None) == ref().order(None)
    with pytest.raises(ValueError, match="explicit"):
        UnrolledExplicitRK(diffrax.Kvaerno3)  # pyright: ignore[reportArgumentType]


def test_eccentricities_are_the_kinematic_models_errors_on_the_lines_of_action(model):
    """With rigid meshes, e_s + e_r of planet 1 turns the sun by Planetary2KH's TE (same sources, phases, frequencies):
    the excitation along the helical mesh's normal is the transverse one times cos β_b."""
    st = model.stage
    g = geometry(st)
    rng = np.random.default_rng(3)
    kin = Planetary2KH(
        21,
        39,
        99,
        module=float(g.transverse_module),
        pressure_angle=float(g.transverse_pressure_angle),
        input="carrier",
        output="sun",
        fixed="ring",
    )
    errors = {
        name: Eccentricity(rng.uniform(1, 10, spec.shape), rng.uniform(0, 2 * np.pi, spec.shape))
        for name, spec in kin.error_sources.items()
    }
    exc = loa_errors(st, g, errors)
    taus = jnp.linspace(0.0, 99.0, 997)  # one carrier turn = z_ring mesh periods
    e = eqx.filter_jit(lambda f, t: jax.vmap(f)(t))(exc, taus)
    theta = 2 * jnp.pi * taus / 99
    te = evaluate(kin.signal(errors), theta)
    transverse = (e[:, 0] + e[:, 3]) / jnp.cos(g.base_helix_angle)
    np.testing.assert_allclose(-kin._gain() * transverse, te, rtol=1e-10, atol=1e-14)


# ---------------------------------------------------------------- one mesh: the damped oscillator


class _Sine(eqx.Module):
    amplitude: jax.Array
    phase: jax.Array

    def __call__(self, tau):
        return jnp.reshape(self.amplitude * jnp.sin(2 * jnp.pi * tau + self.phase), (1, 1)), jnp.ones((1, 1))


EPS = 1.0 / (6 * math.pi) ** 2  # natural frequency 3 × the forcing
ZETA = 0.2
LOAD, AMP, PHASE = 50.0, 2.0, 0.7


def _oscillator():
    c = 2 * ZETA * math.sqrt(EPS)
    return MeshedSystem(
        mass=jnp.asarray([EPS]),
        stiffness=jnp.zeros((1, 1)),
        damping=jnp.zeros((1, 1)),
        load=jnp.asarray([LOAD]),
        projection=jnp.ones((1, 1)),
        pair_stiffness=jnp.asarray([1.0]),
        pair_damping=jnp.asarray([c]),
        excitation=_Sine(jnp.asarray(AMP), jnp.asarray(PHASE)),
        contact_smoothing=jnp.asarray(0.02),
    )


def _oscillator_solution(steps):
    return eqx.filter_jit(solve_periodic)(_oscillator(), PeriodicSolver(10, steps_per_period=steps, samples_per_period=32))


def test_single_mesh_with_sinusoidal_error_is_the_damped_oscillator_closed_form():
    """ε q'' + c (q' + e') + k (q + e) = F with e = E sin(ωτ + φ): q = F/k + Im(Q e^{i(ωτ+φ)}), Q = −E (k + icω)/(k − εω² + icω)."""
    sol = _oscillator_solution(128)
    w, c = 2 * math.pi, 2 * ZETA * math.sqrt(EPS)
    q_amp = -AMP * (1 + 1j * c * w) / (1 - EPS * w**2 + 1j * c * w)
    exact = LOAD + np.imag(q_amp * np.exp(1j * (w * np.asarray(sol.tau) + PHASE)))
    np.testing.assert_allclose(sol.q[:, 0], exact, atol=1e-7)
    assert abs(q_amp) > 1.1 * AMP  # amplified near resonance: the test sees the dynamics, not the static limit


def test_a_solve_whose_state_turns_non_finite_says_so_in_its_result():
    # The same compiled solve (the excitation's amplitude is an input): a finite state is `successful`, a NaN one
    # (here a NaN error amplitude) `nonfinite`, with a NaN periodicity.
    ok = _oscillator_solution(128)
    assert ok.result == RESULTS.successful and math.isfinite(float(ok.periodicity))
    bad_system = eqx.tree_at(lambda s: s.excitation.amplitude, _oscillator(), jnp.asarray(jnp.nan))
    bad = eqx.filter_jit(solve_periodic)(bad_system, PeriodicSolver(10, steps_per_period=128, samples_per_period=32))
    assert bad.result == RESULTS.nonfinite and math.isnan(float(bad.periodicity))
    # 4 steps per mesh period put the oscillator's mode (6π per period) beyond Tsit5's stability limit (h ω = 4.7): the
    # state grows to 6e17 µm, finite, and is reported as diverged rather than as a solution.
    unstable = _oscillator_solution(4)
    assert float(jnp.max(jnp.abs(unstable.q))) > 1e15 and unstable.result == RESULTS.nonfinite


def test_solution_converges_at_the_fifth_order_of_tsit5():
    """Tsit5 is of order 5: the error falls at least 2⁵-fold per halving (about 2⁶ here: its leading error
    terms are small on this linear problem) and far from the 2⁴ of a fourth-order method."""
    ref = _oscillator_solution(1024).q[:, 0]
    errs = [float(jnp.max(jnp.abs(_oscillator_solution(s).q[:, 0] - ref))) for s in (16, 32, 64)]
    orders = np.log2(np.asarray(errs[:-1]) / np.asarray(errs[1:]))
    assert np.all((orders > 4.7) & (orders < 6.5)), (errs, orders)


# ---------------------------------------------------------------- the stage


def test_contact_law_is_a_smooth_max_within_its_stated_error():
    """One pair of unit stiffness and weight (k w = 1): its elastic force is max_ℓ(x) with 0 < max_ℓ(x) − max(0, x) ≤ ℓ,
    = ℓ at x = 0, ≤ 2ℓ⁴/|x|³; its viscous force per unit speed is dmax_ℓ/dx (the same law's slope, checked against
    jax.grad of the elastic force), in [0, 1], ½ at x = 0."""
    ell = 0.02
    x = np.concatenate([-np.geomspace(1e-4, 100.0, 60)[::-1], [0.0], np.geomspace(1e-4, 100.0, 60)])

    def pair(xx, damping):
        s = MeshedSystem(
            mass=jnp.ones(1),
            stiffness=jnp.zeros((1, 1)),
            damping=jnp.zeros((1, 1)),
            load=jnp.zeros(1),
            projection=jnp.ones((1, 1)),
            pair_stiffness=jnp.asarray([1.0 - damping]),
            pair_damping=jnp.asarray([damping]),
            excitation=lambda tau: (jnp.zeros((1, 1)), jnp.ones((1, 1))),
            contact_smoothing=jnp.asarray(ell),
        )
        return s.pair_forces(jnp.asarray(0.0), jnp.reshape(xx, (1,)), jnp.ones(1))[0, 0]

    elastic = np.asarray(jax.vmap(lambda xx: pair(xx, 0.0))(jnp.asarray(x)))
    slope = np.asarray(jax.vmap(lambda xx: pair(xx, 1.0))(jnp.asarray(x)))
    err = elastic - np.maximum(x, 0.0)
    assert np.all(err > 0) and np.all(err <= ell * (1 + 1e-15))
    assert err[60] == pytest.approx(ell, rel=1e-15)
    far = np.abs(x) > 0
    assert np.all(err[far] <= 2 * ell**4 / np.abs(x[far]) ** 3 + 8 * np.finfo(float).eps * np.abs(x[far]))  # + rounding of x
    assert err[-1] < 1e-12 and np.all(np.diff(elastic) > 0)  # 3e-12 µm at 40 µm; increasing
    np.testing.assert_allclose(
        slope, np.asarray(jax.vmap(jax.grad(lambda xx: pair(xx, 0.0)))(jnp.asarray(x))), rtol=1e-12, atol=1e-13
    )  # ½(1 + z³/r³) cancels where x ≪ 0
    assert np.all((slope >= 0) & (slope <= 1)) and slope[60] == pytest.approx(0.5, rel=1e-15)


def test_contact_force_derivatives_match_the_law_differentiated():
    """`contact_force`'s written-out derivatives (its custom JVP, used in forward and reverse mode, and again for second
    derivatives) against JAX's derivatives of the law written plainly, ½(x + (x⁴ + 16ℓ⁴)^¼) and ½(1 + x³/(x⁴ + 16ℓ⁴)^¾),
    with respect to every argument, across the contact (x from far open to far closed)."""

    def plain(x, xd, w, k, c, ell):
        a = x**4 + 16.0 * ell**4
        return k * w * 0.5 * (x + a**0.25) + c * w * 0.5 * (1.0 + x**3 / a**0.75) * xd

    rng = np.random.default_rng(7)
    n = 64
    args = (
        jnp.asarray(np.concatenate([-np.geomspace(1e-3, 30.0, n // 2), np.geomspace(1e-3, 30.0, n // 2)]) * 0.05),
        jnp.asarray(rng.normal(0.0, 2.0, n)),
        jnp.asarray(rng.uniform(0.1, 1.0, n)),
        jnp.asarray(rng.uniform(0.5, 2.0, n)),
        jnp.asarray(rng.uniform(0.01, 0.2, n)),
        jnp.asarray(rng.uniform(0.01, 0.05, n)),
    )
    np.testing.assert_allclose(contact_force(*args), plain(*args), rtol=1e-13, atol=1e-15)
    for i in range(6):
        mine = jax.vmap(jax.grad(contact_force, argnums=i))(*args)
        ref = jax.vmap(jax.grad(plain, argnums=i))(*args)
        np.testing.assert_allclose(mine, ref, rtol=1e-10, atol=1e-12, err_msg=f"argument {i}")
        tangent = tuple(jnp.ones(n) if j == i else jnp.zeros(n) for j in range(6))
        value, slope = jax.jvp(contact_force, args, tangent)
        np.testing.assert_allclose(slope, ref, rtol=1e-10, atol=1e-12, err_msg=f"argument {i}")
        np.testing.assert_array_equal(value, contact_force(*args))  # the same value with and without derivatives
    second = jax.vmap(jax.hessian(contact_force, argnums=(0, 1)))(*args)
    second_ref = jax.vmap(jax.hessian(plain, argnums=(0, 1)))(*args)
    for row, row_ref in zip(second, second_ref, strict=True):
        for h, h_ref in zip(row, row_ref, strict=True):
            np.testing.assert_allclose(h, h_ref, rtol=1e-8, atol=1e-8)


def test_constant_stiffness_and_no_excitation_give_no_fluctuation(model, response):
    const = HelicalPlanetary(model.stage, n_slices=4, stiffness_model=MeanStiffness(), solver=SOLVER)
    r = response(const, None, None)
    assert float(jnp.max(r.fluctuation)) < 1e-9
    assert float(r.output_te_peak_to_peak) < 1e-14
    n = model.stage.n_planets
    np.testing.assert_allclose(r.dte[:n, 0], r.dte[0, 0], rtol=1e-12)  # equal load sharing
    np.testing.assert_allclose(r.dte[n:, 0], r.dte[n, 0], rtol=1e-12)


def test_slow_speed_is_the_quasi_static_load_sharing_solution(model):
    """At 22/40 rpm the lowest mode is 140 × the mesh frequency: q(τ) = K(τ)⁻¹ F(τ). The static sun mesh forces
    carry the sun's torque T_c z_s/(z_s + z_r), a third per planet."""
    st = eqx.tree_at(lambda s: s.carrier_speed, model.stage, jnp.asarray(22.0 / 40))
    slow = HelicalPlanetary(st, n_slices=4, solver=PeriodicSolver(2, steps_per_period=12000, samples_per_period=32))
    r = eqx.filter_jit(lambda m: m.response())(slow)
    sys = eqx.filter_jit(lambda m: m.system())(slow)
    taus = 1.0 + r.time / sys.mesh_period

    @eqx.filter_jit
    def static(sys, taus):
        q = jax.vmap(sys.system.static)(taus)
        return q, jax.vmap(sys.system.pair_forces)(taus, q, jnp.zeros_like(q))

    q_static, f = static(sys, taus)
    dte_static = (q_static @ sys.mid_projection.T).T
    assert float(jnp.max(r.fluctuation)) > 0.5  # the stiffness varies: the reference is not a constant
    np.testing.assert_allclose(r.dte, dte_static, atol=5e-3 * float(jnp.max(r.fluctuation)))
    geom, n = sys.geometry, st.n_planets
    f_mesh = jnp.sum(f.reshape(taus.shape[0], 2 * n, -1), axis=-1) * sys.reference_stiffness  # N
    torque_sun = jnp.sum(f_mesh[:, :n], axis=-1) * jnp.cos(geom.base_helix_angle) * geom.base_radius[0] * 1e-3  # N·m
    np.testing.assert_allclose(torque_sun, float(st.carrier_torque) * 21 / 120, rtol=1e-9)
    per_planet = float(st.carrier_torque) * 21 / 120 / 3 / (float(jnp.cos(geom.base_helix_angle) * geom.base_radius[0]) * 1e-3)
    np.testing.assert_allclose(jnp.mean(f_mesh[:, :n], axis=0), per_planet, rtol=1e-2)
    np.testing.assert_allclose(r.mesh_force, f_mesh.T, rtol=5e-3)


def test_gradient_of_the_fluctuation_matches_float64_finite_differences(model):
    """Reverse mode through diffrax (RecursiveCheckpointAdjoint) on the smooth peak-to-peak, against central
    differences of the same float64 computation (the optimiser's objective, `_smooth_objective`) along two
    directions that mix all four amounts."""
    x = jnp.asarray([20.0, 10.0, 20.0, 10.0])
    ones = jnp.asarray([1.0, 1.0])
    grad = eqx.filter_jit(jax.grad(lambda x, m: jnp.sum(m.fluctuation(x, smooth=0.02))))(x, model)
    assert bool(jnp.all(jnp.isfinite(grad))) and float(jnp.max(jnp.abs(grad))) > 1e-2  # the amounts matter
    h = 1e-3
    for v in (jnp.asarray([1.0, -0.5, 0.3, 0.8]), jnp.asarray([-0.2, 0.9, 1.0, -0.6])):
        fd = (_smooth_objective(model, x + h * v, ones, 0.02) - _smooth_objective(model, x - h * v, ones, 0.02)) / (2 * h)
        np.testing.assert_allclose(grad @ v, fd, rtol=1e-6, atol=1e-8)


def test_vmap_over_amounts_and_planet_rotation_symmetry(model):
    xs = jnp.asarray([[0.0, 0.0, 0.0, 0.0], [30.0, 20.0, 10.0, 40.0]])
    batched = eqx.filter_jit(jax.vmap(lambda x, m: m.fluctuation(x), in_axes=(0, None)))(xs, model)
    one = jnp.stack([_fluctuation(model, x) for x in xs])
    np.testing.assert_allclose(batched, one, rtol=1e-10)
    assert not np.allclose(one[0], one[1], rtol=1e-3)
    # Turning the whole stage (isotropic supports, no gravity) changes nothing.
    turned = eqx.tree_at(lambda m: m.stage.planet_angles, model, model.stage.planet_angles + 0.4)
    np.testing.assert_allclose(_fluctuation(turned, xs[1]), one[1], rtol=1e-8)
