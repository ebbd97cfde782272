"""The helical planetary stage as a registered drive: its loaded TE over the carrier angle, error sources in.

`HelicalPlanetaryDrive` puts the helical stage of `gearte.drives.helical` (Zhang, Chen & Wang) on the drive
protocol, so a Monte Carlo, a sensitivity study or a tolerance budget runs on it from a study file
(``[drive] type = "helical_planetary"``) as on every other drive. Its error sources are the eccentricities of
`Planetary2KH` (Wang et al. 2013), entering as displacement excitation along the lines of action; its response
is the stage's loaded TE — the sun's (output's) rotation minus the ratio times the carrier's (input's) — on a
grid over a window of carrier turns, and the DTE of every mesh at mid face. Two analyses, as objects:

- `QuasiStatic()` (the default): at each angle of the grid, the static equilibrium of the stage's elastic model
  under the carrier torque, every tooth pair taken in contact (K(τ) q = F − Gᵀ k w gap(τ)). The eccentricities'
  frequencies are at most z_r/z_s times the carrier's (1.7 Hz in the wind-turbine example), far below the
  stage's first natural frequency, so their response is quasi-static; what the mesh stiffness's variation adds
  at the mesh frequency is the dynamic model's. The model is linear in the errors: the grid's equilibria of the
  error-free stage and the influence of each mesh's excitation on the TE are computed once per compiled call,
  and a unit costs one sum per angle (no solve).
- `Dynamic()`: the ODE of the stage (`gearte.drives.helical_solve`) integrated over the window after settling
  mesh periods, every unit one ODE solve (Tsit5, `steps_per_mesh_period` steps per mesh period): far slower than
  `QuasiStatic`, meant for a few units.

Both give the TE of the error-free stage too (`HelicalResponse.te_nominal`): with the time-varying mesh
stiffness a stage has a TE without errors; the metric ``error_peak_to_peak`` takes the errors' share alone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from fractions import Fraction
from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.linalg import solve_spd
from ..core.metrics import AbstractMetric, Quantity
from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.solution import RESULTS
from ..core.units import ARCSEC_PER_RAD
from .helical_equations import CARRIER, SUN, StageSystem, error_sources, loa_errors, stage_system
from .helical_geometry import HelicalStage
from .helical_modifications import StageModifications
from .helical_stiffness import STIFFNESS_MODELS, AbstractStiffnessModel, SlicedStiffness, check_stiffness_model, pair_range
from .protocol import AbstractGridDrive, AbstractStudyContext, Eccentricity, SourceSpec, StudyOutputs, Trace

if TYPE_CHECKING:
    from ..core.schema import Table


class AbstractHelicalAnalysis(eqx.Module):
    """How the drive's response is computed: over `carrier_turns` turns of the carrier (rounded up to whole mesh
    periods), `samples_per_mesh_period` angles per mesh period."""

    carrier_turns: eqx.AbstractVar[float]
    samples_per_mesh_period: eqx.AbstractVar[int]

    def mesh_periods(self, z_ring: int) -> int:
        """Mesh periods in the window (a carrier turn is z_ring mesh periods)."""
        return max(1, math.ceil(self.carrier_turns * z_ring - 1e-9))


def _check(name: str, carrier_turns: float, samples: int) -> tuple[float, int]:
    turns = float(carrier_turns)
    if not (math.isfinite(turns) and turns > 0):
        raise ValueError(f"{name}: carrier_turns must be > 0, got {carrier_turns!r}")
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 2:
        raise ValueError(f"{name}: samples_per_mesh_period must be a whole number ≥ 2, got {samples!r}")
    return turns, samples


class QuasiStatic(AbstractHelicalAnalysis):
    """The static equilibrium of the loaded stage at each angle of the grid, every tooth pair in contact (the module
    docstring). Exact for that model at the grid's angles; the TE between them is not taken."""

    carrier_turns: float = eqx.field(static=True)
    samples_per_mesh_period: int = eqx.field(static=True)

    def __init__(self, carrier_turns: float = 1.0, *, samples_per_mesh_period: int = 16):
        self.carrier_turns, self.samples_per_mesh_period = _check("QuasiStatic", carrier_turns, samples_per_mesh_period)


class Dynamic(AbstractHelicalAnalysis):
    """The stage's equations of motion integrated with Tsit5 at `steps_per_mesh_period` constant steps per mesh
    period: `settle_mesh_periods` periods from the quasi-static state at τ = 0, then the window, sampled
    from the solver's dense output."""

    carrier_turns: float = eqx.field(static=True)
    samples_per_mesh_period: int = eqx.field(static=True)
    settle_mesh_periods: int = eqx.field(static=True)
    steps_per_mesh_period: int = eqx.field(static=True)

    def __init__(
        self,
        carrier_turns: float = 1.0,
        *,
        samples_per_mesh_period: int = 16,
        settle_mesh_periods: int = 19,
        steps_per_mesh_period: int = 256,
    ):
        self.carrier_turns, self.samples_per_mesh_period = _check("Dynamic", carrier_turns, samples_per_mesh_period)
        for name, v, low in (("settle_mesh_periods", settle_mesh_periods, 1), ("steps_per_mesh_period", steps_per_mesh_period, 4)):
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise ValueError(f"Dynamic: {name} must be a whole number ≥ {low}, got {v!r}")
        self.settle_mesh_periods, self.steps_per_mesh_period = settle_mesh_periods, steps_per_mesh_period


ANALYSES = {"quasi_static": QuasiStatic, "dynamic": Dynamic}


class HelicalResponse(eqx.Module):
    """The drive's response on its grid of P angles (the window): `te` (P,) rad, the output's TE of the unit;
    `te_nominal` (P,) rad, that of the error-free stage; `dte` (2N, P) µm, every mesh's DTE at mid face (sun–planet
    1 … N, then planet–ring 1 … N; > 0: the members approach); `compression` (2N, P) µm, the DTE plus the errors'
    excitation: the mid-face compression of every mesh (< 0: the mesh opens at mid face); `periodicity` µm (the dynamic analysis: the
    coordinates' largest change over the window, NaN where a solve failed; 0 for the quasi-static one); `result`:
    `RESULTS.successful`, or the dynamic solve's failure (`PeriodicSolution.result`; for the quasi-static analysis
    `RESULTS.nonfinite` where the TE is not finite)."""

    te: Float[Array, " p"]
    te_nominal: Float[Array, " p"]
    dte: Float[Array, "m p"]
    compression: Float[Array, "m p"]
    periodicity: Float[Array, ""]
    result: RESULTS


class HelicalPeakToPeak(AbstractMetric):
    """Peak-to-peak of the unit's loaded TE over the grid (rad)."""

    name: ClassVar[str] = "peak_to_peak"
    label: ClassVar[str] = "loaded TE p-p"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcsec"

    def __call__(self, drive: Any, response: HelicalResponse) -> Float[Array, ""]:
        del drive
        return jnp.max(response.te) - jnp.min(response.te)

    def describe(self) -> str:
        return (
            "peak-to-peak over the analysis window's grid (its carrier turns: the accuracy line) of the loaded TE = "
            "θ_sun − i θ_carrier, i the carrier-to-sun ratio (the errors, and the mesh stiffness variation where the "
            "stiffness model has one)"
        )


class HelicalErrorPeakToPeak(AbstractMetric):
    """Peak-to-peak of the unit's TE minus the error-free stage's over the grid (rad): the errors' share."""

    name: ClassVar[str] = "error_peak_to_peak"
    label: ClassVar[str] = "TE p-p of the errors"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcsec"

    def __call__(self, drive: Any, response: HelicalResponse) -> Float[Array, ""]:
        del drive
        d = response.te - response.te_nominal
        return jnp.max(d) - jnp.min(d)

    def describe(self) -> str:
        return (
            "peak-to-peak over the analysis window's grid (its carrier turns: the accuracy line) of the unit's loaded TE "
            "minus the error-free stage's (the errors' share)"
        )


METRICS: tuple[type[AbstractMetric], ...] = (HelicalPeakToPeak, HelicalErrorPeakToPeak)


class HelicalPlanetaryDrive(AbstractGridDrive):
    """A helical 2K-H stage (carrier in, sun out, ring fixed) as a drive: eccentricities in, loaded TE out.

    **Arguments:**

    - `stage`: the `HelicalStage`.
    - `analysis`: `QuasiStatic(...)` (default) or `Dynamic(...)` (the module docstring).
    - `n_slices`, `stiffness_model`, `contact_smoothing`: the elastic model's options (`HelicalPlanetary`).
    """

    type_name: ClassVar[str] = "helical_planetary"

    stage: HelicalStage
    analysis: AbstractHelicalAnalysis
    stiffness_model: AbstractStiffnessModel
    n_slices: int = eqx.field(static=True)
    contact_smoothing: float = eqx.field(static=True)
    pairs: tuple[int, int] = eqx.field(static=True)

    def __init__(
        self,
        stage: HelicalStage,
        *,
        analysis: AbstractHelicalAnalysis | None = None,
        n_slices: int = 8,
        stiffness_model: AbstractStiffnessModel = SlicedStiffness(),
        contact_smoothing: float = 0.02,
    ):
        from .helical_geometry import geometry

        if not isinstance(stage, HelicalStage):
            raise ValueError("HelicalPlanetaryDrive: stage must be a HelicalStage")
        analysis = QuasiStatic() if analysis is None else analysis
        if not isinstance(analysis, AbstractHelicalAnalysis):
            raise ValueError(f"HelicalPlanetaryDrive: analysis must be QuasiStatic(...) or Dynamic(...), got {analysis!r}")
        if isinstance(n_slices, bool) or not isinstance(n_slices, int) or n_slices < 1:
            raise ValueError(f"HelicalPlanetaryDrive: n_slices must be a whole number ≥ 1, got {n_slices!r}")
        if not (math.isfinite(contact_smoothing) and contact_smoothing > 0):
            raise ValueError(f"HelicalPlanetaryDrive: contact_smoothing must be > 0 µm, got {contact_smoothing!r}")
        self.stage, self.analysis, self.n_slices = stage, analysis, n_slices
        self.stiffness_model = check_stiffness_model("stiffness_model", stiffness_model)
        self.contact_smoothing = float(contact_smoothing)
        self.pairs = pair_range(geometry(stage), float(stage.face_width), n_slices)

    # ------------------------------------------------------------ the grid

    @property
    def _start(self) -> int:
        """Mesh periods from τ = 0 to the window's start."""
        return self.analysis.settle_mesh_periods if isinstance(self.analysis, Dynamic) else 0

    def mesh_times(self) -> np.ndarray:
        """τ of the grid, mesh periods from the carrier angle 0 (the window, `samples_per_mesh_period` per period)."""
        a = self.analysis
        n = a.mesh_periods(self.stage.z_ring) * a.samples_per_mesh_period
        return self._start + np.arange(n, dtype=float) / a.samples_per_mesh_period

    def input_angles(self) -> Float[Array, " p"]:
        """The carrier (input) angles of the grid, rad: a carrier turn is z_ring mesh periods."""
        return jnp.asarray(2 * np.pi * self.mesh_times() / self.stage.z_ring)

    def window_turns(self) -> Fraction:
        """The window in carrier turns (whole mesh periods)."""
        return Fraction(self.analysis.mesh_periods(self.stage.z_ring), self.stage.z_ring)

    def hyper_period_turns(self) -> Fraction:
        """Carrier turns after which every eccentricity's excitation repeats (their frequencies' hyper-period)."""
        zs, zp, zr = self.stage.z_sun, self.stage.z_planet, self.stage.z_ring
        freqs = [Fraction(zr, zs), Fraction(zr, zp), Fraction(1)]  # sun, planet, ring/carrier relative to the carrier
        num = math.gcd(*(f.numerator for f in freqs))
        den = math.lcm(*(f.denominator for f in freqs))
        return 1 / Fraction(num, den)

    # ------------------------------------------------------------ the protocol

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        """The eccentricity sources of `Planetary2KH` (per planet where the planets differ)."""
        return error_sources(self.stage.n_planets)

    @property
    def metrics(self) -> dict[str, AbstractMetric]:
        return {m.name: m() for m in METRICS}

    def system(self, errors: Mapping[str, Any] | None = None) -> StageSystem:
        """The stage's equations (no tooth modifications) with these eccentricity errors."""
        return stage_system(
            self.stage,
            StageModifications(),
            errors,
            n_slices=self.n_slices,
            stiffness_model=self.stiffness_model,
            contact_smoothing=self.contact_smoothing,
            pairs=self.pairs,
        )

    def _rows(self, sys: StageSystem) -> Float[Array, "r d"]:
        """Rows reading (TE rad, mid-face DTE of every mesh µm) from the coordinates q (µm)."""
        d = self.stage.n_dof
        r = sys.layout.radius
        te = jnp.zeros(d).at[6 * SUN + 5].set(1e-3 / r[SUN]).at[6 * CARRIER + 5].set(-self.stage.ratio * 1e-3 / r[CARRIER])
        return jnp.concatenate([te[None], sys.mid_projection])

    def response(self, errors: Mapping[str, Any] | None) -> HelicalResponse:
        """The TE and DTE of the unit with these errors (names left out are zero) on the grid (`HelicalResponse`)."""
        require_x64()
        full = self.zero_errors()
        if errors is not None:
            unknown = sorted(set(errors) - set(full))
            if unknown:
                raise ValueError(f"errors: unknown error source(s) {unknown}; the sources are {list(full)}")
            full.update(errors)
        e = self.checked(full)
        if isinstance(self.analysis, Dynamic):
            return self._dynamic(e)
        return self._quasi_static(e)

    def _excitation_basis(self, sys: StageSystem, taus: Array) -> tuple[Array, list[tuple[str, int]]]:
        """The errors' LOA excitation e(τ) is linear in (e cos φ, e sin φ) of every source instance: its value for each
        of them at 1 µm, (J, P, 2N), and the instances in order (source, index), J = 2 × their number."""
        specs = self.error_sources
        instances = [(name, i) for name, spec in specs.items() for i in range(spec.count)]
        n = 2 * len(instances)
        mags = {name: np.zeros((n, *spec.shape)) for name, spec in specs.items()}
        phases = {name: np.zeros((n, *spec.shape)) for name, spec in specs.items()}
        for j, (name, i) in enumerate(instances):
            for quad in (0, 1):
                mags[name][2 * j + quad].flat[i] = 1.0
                phases[name][2 * j + quad].flat[i] = quad * np.pi / 2
        stacked = {name: Eccentricity(mags[name], phases[name]) for name in specs}

        def one(errors):
            return jax.vmap(loa_errors(self.stage, sys.geometry, errors))(taus)

        return jax.vmap(one)(stacked), instances

    def _coefficients(self, errors: Mapping[str, Any], instances: list[tuple[str, int]]) -> Float[Array, " j"]:
        """(e cos φ, e sin φ) of every source instance, in the order of `_excitation_basis`."""
        out = []
        for name, i in instances:
            ecc = errors[name]
            mag, ph = ecc.magnitude.reshape(-1)[i], ecc.phase.reshape(-1)[i]
            out += [mag * jnp.cos(ph), mag * jnp.sin(ph)]
        return jnp.stack(out)

    def _quasi_static(self, errors: Mapping[str, Any]) -> HelicalResponse:
        sys = self.system(None)
        s = sys.system
        rows = self._rows(sys)
        taus = jnp.asarray(self.mesh_times())
        n_mesh, d = 2 * self.stage.n_planets, self.stage.n_dof

        # The stiffness and the error-free gaps repeat every mesh period (every mesh meshes at the mesh frequency, the
        # planets' phases fixed): the equilibria of one mesh period serve every period of the window.
        per = self.analysis.samples_per_mesh_period
        gap, w = jax.vmap(s.excitation)(taus[:per])  # (s, S, J)
        kw = s.pair_stiffness * jnp.sum(w, axis=-1)  # (P, S)
        # K(τ) = K_supports + Σ_s k_s w_s(τ) g_s g_sᵀ, every angle in one matrix product.
        outer = (s.projection[:, :, None] * s.projection[:, None, :]).reshape(s.projection.shape[0], d * d)
        k = s.stiffness + (kw @ outer).reshape(-1, d, d)
        rhs = s.load - (s.pair_stiffness * jnp.sum(w * gap, axis=-1)) @ s.projection  # (P, D)
        # An eccentricity's excitation e_m is one gap for every slice and pair of mesh m: its load is −B e.
        b = jnp.sum((kw[:, :, None] * s.projection).reshape(-1, n_mesh, s.projection.shape[0] // n_mesh, d), axis=2)  # (P, 2N, D)
        # K is symmetric positive definite (supports and closed meshes): Cholesky, and the rows' adjoint solve K X = Rᵀ
        # (gearte.core.linalg, not LAPACK: LAPACK's batched kernels can hang a run on several CPU devices).
        x = solve_spd(k, jnp.broadcast_to(rows.T, (k.shape[0], *rows.T.shape)))  # (P, D, R)
        tile = np.arange(taus.shape[0]) % per
        nominal = jnp.einsum("pdr,pd->pr", x, rhs)[tile]  # (P, R)
        influence = -jnp.einsum("pdr,pmd->prm", x, b)[tile]  # (P, R, 2N)

        # Everything but the last two products is independent of the errors: under vmap over units, computed once per
        # call; a unit then costs two products with its J coefficients.
        basis_e, instances = self._excitation_basis(sys, taus)  # (J, P, 2N)
        basis_y = jnp.einsum("prm,jpm->prj", influence, basis_e)
        c = self._coefficients(errors, instances)
        y = nominal + basis_y @ c
        e = jnp.einsum("jpm,j->mp", basis_e, c)
        dte = y[:, 1:].T
        finite = jnp.all(jnp.isfinite(y))
        result = RESULTS.where(finite, RESULTS.successful, RESULTS.nonfinite)  # pyright: ignore[reportArgumentType]
        return HelicalResponse(
            te=y[:, 0], te_nominal=nominal[:, 0], dte=dte, compression=dte + e, periodicity=jnp.asarray(0.0), result=result
        )

    def _dynamic(self, errors: Mapping[str, Any]) -> HelicalResponse:
        from .helical_solve import PeriodicSolver, solve_periodic

        a = self.analysis
        assert isinstance(a, Dynamic)
        rec = a.mesh_periods(self.stage.z_ring)
        solver = PeriodicSolver(
            a.settle_mesh_periods + rec,
            steps_per_period=a.steps_per_mesh_period,
            samples_per_period=a.samples_per_mesh_period,
            record_periods=rec,
        )

        def solve(err):
            sys = self.system(err)
            sol = solve_periodic(sys.system, solver)
            return sol.q @ self._rows(sys).T, sol, sys

        y, sol, sys = solve(errors)
        y0, _, _ = solve(None)
        taus = jnp.asarray(self.mesh_times())
        e = jax.vmap(loa_errors(self.stage, sys.geometry, errors))(taus).T
        dte = y[:, 1:].T
        return HelicalResponse(
            te=y[:, 0], te_nominal=y0[:, 0], dte=dte, compression=dte + e, periodicity=sol.periodicity, result=sol.result
        )

    def te(self, response: HelicalResponse) -> Float[Array, " p"]:
        return response.te

    def trace(self, errors: Mapping[str, Any] | None) -> Trace:
        """The unit's loaded TE over the window, against the carrier (input) angle."""
        r = _response_jit(self, errors)
        return Trace.of_grid(np.asarray(self.input_angles()), np.asarray(r.te), str(self.window_turns()))

    def solved(self, response: HelicalResponse) -> Array:
        return response.result == RESULTS.successful

    def sample_outputs(self, errors, response: HelicalResponse) -> dict[str, Array]:
        """Per sample: the errors' TE p-p (rad), the largest DTE fluctuation of a mesh and the smallest mid-face DTE
        (µm; < 0: a mesh opens somewhere on the grid, outside the every-pair-in-contact model)."""
        del errors
        d = response.te - response.te_nominal
        return {
            "error_pp": jnp.max(d) - jnp.min(d),
            "compression_min": jnp.min(response.compression),
            "dte_fluctuation_max": jnp.max(jnp.max(response.dte, axis=-1) - jnp.min(response.dte, axis=-1)),
            "dte_min": jnp.min(response.dte),
        }

    def study_outputs(self, context: AbstractStudyContext) -> StudyOutputs:
        """The error-free stage's TE over the window, and how often a mesh's mid-face compression (its DTE plus the
        errors' excitation) falls below zero: the mesh opens there, outside the every-pair-in-contact model."""
        squeeze = np.asarray(context.outputs["compression_min"])
        opened = int(np.sum(squeeze < 0))
        nominal = np.asarray(_response_jit(self, None).te_nominal)
        pp0 = float(np.ptp(nominal)) * ARCSEC_PER_RAD
        fluct = float(np.median(context.outputs["dte_fluctuation_max"]))
        report = [
            "## Helical stage",
            "",
            f"- Loaded TE p-p of the error-free stage over the window (mesh stiffness variation alone): {pp0:.4f}″.",
            f"- Smallest mid-face compression of a mesh over all samples (DTE plus the errors' excitation): {float(np.min(squeeze)):.2f} µm; "
            f"samples where a mesh opens (compression < 0 somewhere on the grid, outside the every-pair-in-contact model): "
            f"{opened} of {squeeze.size}.",
            f"- Largest DTE fluctuation of a mesh over the window, median over the samples: {fluct:.3f} µm.",
        ]
        summary = {
            "nominal_te_pp_arcsec": pp0,
            "compression_min_um": float(np.min(squeeze)),
            "samples_mesh_opens": opened,
            "dte_fluctuation_max_median_um": fluct,
        }
        return StudyOutputs(summary=summary, report=report)

    def describe(self) -> list[tuple[str, str]]:
        st = self.stage
        a = self.analysis
        return [
            ("teeth z_s / z_p / z_r, planets", f"{st.z_sun} / {st.z_planet} / {st.z_ring}, {st.n_planets}"),
            ("ratio carrier → sun", f"{st.ratio:.6g}"),
            ("carrier torque, speed", f"{float(st.carrier_torque) / 1e3:.4g} kN·m, {float(st.carrier_speed):g} rpm"),
            ("mesh stiffness model, slices", f"{self.stiffness_model.name}, {self.n_slices}"),
            ("analysis", f"{type(a).__name__}: {self.window_turns()} carrier turn(s), {a.samples_per_mesh_period} angles per mesh period"),
            ("errors' hyper-period", f"{self.hyper_period_turns()} carrier turns"),
        ]

    def accuracy(self) -> str:
        a = self.analysis
        window = f"over {self.window_turns()} carrier turn(s) ({a.mesh_periods(self.stage.z_ring)} mesh periods, {a.samples_per_mesh_period} angles each)"
        span = f"; the errors' hyper-period is {self.hyper_period_turns()} carrier turns, so a longer window can only widen the p-p"
        if isinstance(a, Dynamic):
            return (
                f"taken on a grid {window} of the ODE solution (Tsit5, {a.steps_per_mesh_period} constant steps per mesh period, "
                f"{a.settle_mesh_periods} settling periods), not between the grid's angles{span}"
            )
        return (
            f"exact for the quasi-static model (every tooth pair in contact, static equilibrium under the carrier torque) at a grid "
            f"{window}, not between them{span}"
        )

    def bytes_per_sample(self) -> int:
        a = self.analysis
        p = a.mesh_periods(self.stage.z_ring) * a.samples_per_mesh_period
        m = 2 * self.stage.n_planets
        per_step = 8 * 2 * self.stage.n_dof * 8 if isinstance(a, Dynamic) else 0
        steps = (a.settle_mesh_periods + a.mesh_periods(self.stage.z_ring)) * a.steps_per_mesh_period if isinstance(a, Dynamic) else 0
        return 8 * p * (4 * m + 8) + per_step * steps + 4096

    @classmethod
    def from_table(cls, table: Table) -> HelicalPlanetaryDrive:
        """``[drive] type = "helical_planetary"``: `parameters` (the stage's parameter file, relative to the study
        file), `analysis` ("quasi_static" or "dynamic"), `carrier_turns`, `samples_per_mesh_period`, and overrides of
        the file's `n_slices` and `stiffness_model`; the dynamic analysis also `settle_mesh_periods` and
        `steps_per_mesh_period` (defaults: the file's ``[model]`` n_periods − 1 and steps_per_period)."""
        from ..core.schema import ConfigError
        from .helical_table import MAX_PERIODS, MAX_SLICES, MAX_STEPS_PER_PERIOD, read_stage_file

        path = table.path("parameters")
        try:
            f = read_stage_file(path)
        except ValueError as e:
            raise ConfigError(f"{table.where} parameters: {e}") from None
        kind = table.string("analysis", "quasi_static", choices=tuple(ANALYSES))
        turns = table.number("carrier_turns", 1.0, positive=True)
        if turns > 100:
            raise ConfigError(f"{table.where} carrier_turns: at most 100 (every sample solves them all), got {turns:g}")
        samples = table.integer("samples_per_mesh_period", 16, minimum=2, maximum=MAX_STEPS_PER_PERIOD)
        n_slices = table.integer("n_slices", f.n_slices, minimum=1, maximum=MAX_SLICES)
        by_name = {m.name: m for m in STIFFNESS_MODELS}
        stiffness = table.string("stiffness_model", f.stiffness_model.name, choices=tuple(by_name))
        if kind == "dynamic":
            settle = table.integer("settle_mesh_periods", f.n_periods - 1, minimum=1, maximum=MAX_PERIODS)
            steps = table.integer("steps_per_mesh_period", f.steps_per_period, minimum=4, maximum=MAX_STEPS_PER_PERIOD)
            analysis: AbstractHelicalAnalysis = Dynamic(
                turns, samples_per_mesh_period=samples, settle_mesh_periods=settle, steps_per_mesh_period=steps
            )
        else:
            for key in ("settle_mesh_periods", "steps_per_mesh_period"):
                if table.has(key):
                    raise ConfigError(f'{table.where} {key}: only the dynamic analysis integrates; remove it or set analysis = "dynamic"')
            analysis = QuasiStatic(turns, samples_per_mesh_period=samples)
        try:
            return cls(
                f.stage,
                analysis=analysis,
                n_slices=n_slices,
                stiffness_model=by_name[stiffness](),
                contact_smoothing=f.contact_smoothing,
            )
        except ValueError as e:
            raise ConfigError(f"{table.where} {e}") from None


@kept_jit
def _response_jit(drive: HelicalPlanetaryDrive, errors: Mapping[str, Any] | None) -> HelicalResponse:
    return drive.response(errors)


__all__ = (
    "METRICS",
    "AbstractHelicalAnalysis",
    "Dynamic",
    "HelicalErrorPeakToPeak",
    "HelicalPeakToPeak",
    "HelicalPlanetaryDrive",
    "HelicalResponse",
    "QuasiStatic",
)
