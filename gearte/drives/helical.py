"""Helical planetary stage: dynamic transmission error with tooth micro-modifications (Zhang, Chen & Wang).

A lumped-parameter model of a helical 2K-H stage, 6 degrees of freedom per member, time-varying
sliced mesh stiffness, unilateral contact, eccentricity errors and tooth modifications as
displacement excitation along the lines of action, integrated to periodic steady state with
diffrax. Its outputs per mesh: the dynamic transmission error (DTE: the members' relative
displacement along the contact normal at mid face) over one mesh period, its fluctuation
(peak-to-peak), the mesh force, the DTE spectrum; and the output's angular TE.

The pieces, one concept per file: `helical_geometry` (parameters and geometry), `helical_stiffness`
(sliced mesh stiffness), `helical_modifications`, `helical_equations` (equations of motion),
`helical_solve` (steady state). This file puts them together (`HelicalPlanetary`) and reads a
parameter file (`load_helical`, e.g. ``examples/dynamics/helical_wind_turbine.toml``).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..core.programs import kept_jit
from ..core.solution import RESULTS
from ..core.units import ARCSEC_PER_RAD
from ..core.validate import as_float, as_int, is_traced
from .helical_equations import SUN, StageSystem, error_sources, stage_system
from .helical_geometry import HelicalStage, geometry
from .helical_modifications import StageModifications, modifications_from_amounts
from .helical_solve import PeriodicSolver, harmonics, peak_to_peak, smooth_peak_to_peak, solve_periodic
from .helical_stiffness import (
    AbstractStiffnessModel,
    SlicedStiffness,
    TransverseStiffness,
    check_stiffness_model,
    pair_range,
)
from .helical_table import read_stage_file
from .protocol import Eccentricity

#: Zhang, Chen & Wang's unmodified DTE fluctuations of the 750 kW stage, µm (external s–p, internal p–r).
PAPER_FLUCTUATION_UM = (26.17, 8.79)


#: Harmonics of the window's fundamental in `DynamicResponse.spectrum` (0 … 15).
HARMONICS = 16


class DynamicResponse(eqx.Module):
    """The periodic steady state of a stage over the kept window (meshes: sun–planet 1 … N, then planet–ring 1 … N).

    - `time`: s from the start of the window, (S,).
    - `dte`: DTE of every mesh, µm along its contact normal (> 0: the members approach), (2N, S).
    - `fluctuation`: peak-to-peak of `dte`, µm, (2N,).
    - `mesh_force`: total normal force of every mesh, N, (2N, S).
    - `output_te`: the sun's rotation minus the ratio times the carrier's, rad, (S,);
      `output_te_peak_to_peak`: its peak-to-peak, rad.
    - `spectrum`: amplitude of harmonics 0 … 15 of the window's fundamental in `dte`, µm, (2N, 16).
    - `periodicity`: max change of the coordinates over the window, µm (≈ 0 at steady state; NaN where the
      solve failed).
    - `result`: the solve's `RESULTS` (`PeriodicSolution.result`).
    """

    time: Float[Array, " s"]
    dte: Float[Array, "m s"]
    fluctuation: Float[Array, " m"]
    mesh_force: Float[Array, "m s"]
    output_te: Float[Array, " s"]
    output_te_peak_to_peak: Float[Array, ""]
    spectrum: Float[Array, "m h"]
    periodicity: Float[Array, ""]
    result: RESULTS


class HelicalPlanetary(eqx.Module):
    """A `HelicalStage` with the options of its dynamic model.

    **Arguments:**

    - `stage`: the `HelicalStage`.
    - `n_slices`: K slices across the face width (8 resolves the wind-turbine stage's fluctuation to < 0.5 %).
    - `stiffness_model`: an `AbstractStiffnessModel`: `SlicedStiffness()` (time-varying, helical overlap
      included; the default), `TransverseStiffness()` (every slice in phase: the rectangular
      single/double-contact alternation of a spur pair, ε_α only), `MeanStiffness()` (constant c_γ b) or
      `SinglePairStiffness()` (the sliced model with each pair stiffest at mid path, ISO 6336-1's c' at its peak).
    - `contact_smoothing`: ℓ, µm, of the smooth unilateral contact law.
    - `solver`: a `PeriodicSolver`.
    """

    stage: HelicalStage
    solver: PeriodicSolver
    contact_smoothing: float = eqx.field(static=True)
    n_slices: int = eqx.field(static=True)
    stiffness_model: AbstractStiffnessModel
    pairs: tuple[int, int] = eqx.field(static=True)

    def __init__(
        self,
        stage: HelicalStage,
        *,
        n_slices: int = 8,
        stiffness_model: AbstractStiffnessModel = SlicedStiffness(),
        contact_smoothing: float = 0.02,
        solver: PeriodicSolver | None = None,
    ):
        if not isinstance(stage, HelicalStage):
            raise ValueError("HelicalPlanetary: stage must be a HelicalStage")
        contact_smoothing = as_float("contact_smoothing", contact_smoothing, positive=True, hint="µm")
        solver = solver if solver is not None else PeriodicSolver()
        if not isinstance(solver, PeriodicSolver):
            raise ValueError(f"solver: a gearte.PeriodicSolver(n_periods, steps_per_period=…, samples_per_period=…), got {solver!r}")
        window = solver.samples_per_period * solver.record_periods
        if window < 2 * (HARMONICS - 1):
            raise ValueError(
                f"solver: samples_per_period × record_periods = {window} samples over the kept window; the DTE spectrum's "
                f"{HARMONICS} harmonics need at least {2 * (HARMONICS - 1)}"
            )
        self.stage = stage
        self.n_slices = as_int("n_slices", n_slices, minimum=1)
        self.stiffness_model = check_stiffness_model("stiffness_model", stiffness_model)
        self.contact_smoothing = contact_smoothing
        self.solver = solver
        self.pairs = pair_range(geometry(stage), float(stage.face_width), self.n_slices)

    @property
    def error_sources(self):
        """The eccentricity sources (those of `Planetary2KH`), by name."""
        return error_sources(self.stage.n_planets)

    def system(self, modifications: StageModifications | None = None, errors: Mapping[str, Eccentricity] | None = None) -> StageSystem:
        """The dimensionless equations of motion with these modifications and eccentricity errors."""
        return stage_system(
            self.stage,
            modifications if modifications is not None else StageModifications(),
            errors,
            n_slices=self.n_slices,
            stiffness_model=self.stiffness_model,
            contact_smoothing=self.contact_smoothing,
            pairs=self.pairs,
        )

    def response(
        self, modifications: StageModifications | None = None, errors: Mapping[str, Eccentricity] | None = None
    ) -> DynamicResponse:
        """The periodic steady state (`DynamicResponse`). Jit it with `eqx.filter_jit`."""
        # A jitted function: the objectives, gradients and checks of a study that call it several times with arrays
        # of the same shapes trace the solve once.
        return _response_jit(self, modifications, errors)

    def _response(self, modifications: StageModifications | None, errors: Mapping[str, Eccentricity] | None) -> DynamicResponse:
        sys = self.system(modifications, errors)
        sol = solve_periodic(sys.system, self.solver)
        dte = (sol.q @ sys.mid_projection.T).T
        start = float(self.solver.n_periods - self.solver.record_periods)
        forces = jax.vmap(sys.system.pair_forces)(start + sol.tau, sol.q, sol.v)
        n_mesh = sys.mid_projection.shape[0]
        mesh_force = jnp.sum(forces.reshape(forces.shape[0], n_mesh, -1), axis=-1).T * sys.reference_stiffness
        geom, lay = sys.geometry, sys.layout
        theta_sun = 1e-3 * sol.q[:, 6 * SUN + 5] / lay.radius[SUN]
        theta_carrier = 1e-3 * sol.q[:, 5] / lay.radius[0]
        te = theta_sun - self.stage.ratio * theta_carrier
        return DynamicResponse(
            time=sol.tau * geom.mesh_period,
            dte=dte,
            fluctuation=peak_to_peak(dte),
            mesh_force=mesh_force,
            output_te=te,
            output_te_peak_to_peak=peak_to_peak(te),
            spectrum=harmonics(dte, HARMONICS),
            periodicity=sol.periodicity,
            result=sol.result,
        )

    def fluctuation(self, amounts: Float[Array, " 4"], *, smooth: float | None = None) -> Float[Array, " 2"]:
        """DTE fluctuation (µm) of planet 1's external and internal meshes for the design variables of
        Zhang, Chen & Wang, `amounts` = (sun tip relief, sun crowning, planet tip relief, planet crowning), µm
        (`modifications_from_amounts`). Jittable, vmappable over `amounts`, differentiable.

        `smooth`: None for the sampled peak-to-peak (differentiable almost everywhere: its gradient is the
        difference of the gradients at the two extreme samples), or a width w (µm) for
        `smooth_peak_to_peak` (infinitely differentiable, within 2 w log S above).
        """
        if smooth is not None and not is_traced(smooth):
            as_float("fluctuation: smooth", smooth, positive=True, hint="µm, the smoothing width, or None for the sampled peak-to-peak")
        r = self.response(modifications_from_amounts(amounts))
        n = self.stage.n_planets
        dte = r.dte[jnp.asarray([0, n])]
        if smooth is None:
            return peak_to_peak(dte)
        return smooth_peak_to_peak(dte, smooth)


@kept_jit
def _response_jit(drive: HelicalPlanetary, modifications, errors) -> DynamicResponse:
    return drive._response(modifications, errors)


# ---------------------------------------------------------------- parameter files


def load_helical(path: str | Path) -> HelicalPlanetary:
    """Read a helical stage parameter file (the layout of ``examples/dynamics/helical_wind_turbine.toml``;
    `gearte.drives.helical_table`)."""
    f = read_stage_file(path)
    solver = PeriodicSolver(f.n_periods, steps_per_period=f.steps_per_period, samples_per_period=f.samples_per_period)
    return HelicalPlanetary(
        f.stage, n_slices=f.n_slices, stiffness_model=f.stiffness_model, contact_smoothing=f.contact_smoothing, solver=solver
    )


EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "dynamics" / "helical_wind_turbine.toml"


def wind_turbine_report(
    path: str | Path = EXAMPLE,
    *,
    stiffness_models: tuple[AbstractStiffnessModel, ...] = (SlicedStiffness(), TransverseStiffness()),
) -> str:
    """Solve the unmodified wind-turbine stage and compare its DTE fluctuations with Zhang, Chen & Wang's (markdown),
    one row per stiffness model (`AbstractStiffnessModel`s, named by their `name`)."""
    models = [check_stiffness_model(f"stiffness_models[{i}]", m) for i, m in enumerate(stiffness_models)]
    base = load_helical(path)
    lines = [
        "| stiffness model | external s–p (µm) | internal p–r (µm) | mean DTE ext / int (µm) | output TE p-p (″) | periodicity (µm) |",
        "|---|---|---|---|---|---|",
    ]
    n = base.stage.n_planets
    for model in models:
        m = HelicalPlanetary(
            base.stage, n_slices=base.n_slices, stiffness_model=model, contact_smoothing=base.contact_smoothing, solver=base.solver
        )
        r = m.response()  # jitted at module level (`_response_jit`): a second report of the same shapes traces nothing
        mean = jnp.mean(r.dte, axis=-1)
        lines.append(
            f"| {model.name} | {float(r.fluctuation[0]):.3f} | {float(r.fluctuation[n]):.3f} | {float(mean[0]):.2f} / {float(mean[n]):.2f} "
            f"| {float(r.output_te_peak_to_peak) * ARCSEC_PER_RAD:.3f} | {float(r.periodicity):.1e} |"
        )
    lines.append(
        f"| Zhang, Chen & Wang (paper) | {PAPER_FLUCTUATION_UM[0]} | {PAPER_FLUCTUATION_UM[1]} | 47.2 / 23.0 (mid-range of their Fig. 2) | | |"
    )
    return "\n".join(lines)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    print(wind_turbine_report())
