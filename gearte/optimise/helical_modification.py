"""Tooth modifications of a helical planetary stage: Zhang, Chen & Wang's response-surface strategies, and a
gradient optimum through the ODE solution.

The design variables are theirs, x = (x₁ sun tip relief, x₂ sun crowning, x₃ planet tip relief,
x₄ planet crowning), µm along the contact normal (`HelicalPlanetary.fluctuation`). Their levels come
from a normal probability model of each amount (`design_variables`): mean = the recommended amount
(`recommended_amounts`, the form of their eq. 19), std = F_p/6 of the gear's ISO 1328 class, coded
−1/0/+1 at the 1 %/50 %/99 % quantiles.

Strategies (`modification_strategies`), each a central composite design with a quadratic response
surface (`gearte.studies`), its optimum inside the design region and a direct model run there:

- ``sun``: x₁, x₂ (planet unmodified), minimising the external (sun–planet) fluctuation;
- ``planet``: x₃, x₄ (sun unmodified), minimising the internal (planet–ring) fluctuation, the mesh only
  the planet's modification reaches (the ring is not modified);
- ``joint``: x₁ … x₄ together, minimising the sum of both fluctuations;
- ``combined``: the ``sun`` and ``planet`` optima applied at once (no new design).

Beyond the paper, `optimise_modifications` minimises a weighted sum of the smooth fluctuations by BFGS
(optimistix) with gradients through the diffrax solution, inside a box (x = c + h sin z: the box is
reached exactly, with no projection).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from ..core.solution import RESULTS, check, promote
from ..core.validate import as_int
from ..drives.helical import HelicalPlanetary
from ..drives.helical_geometry import geometry
from ..drives.helical_modifications import recommended_tip_relief
from ..standards.iso1328 import iso1328_tolerances
from ..studies.doe import CentralComposite, DesignRun, Variable, run_design
from ..studies.response_surface import ResponseSurface, SurfaceOptimum, fit_response_surface

#: Names of the four design variables, in the order of `HelicalPlanetary.fluctuation`.
AMOUNT_NAMES = ("x1 sun tip relief", "x2 sun crowning", "x3 planet tip relief", "x4 planet crowning")


def _check_model(model) -> HelicalPlanetary:
    if not isinstance(model, HelicalPlanetary):
        raise ValueError(f"model: expected a HelicalPlanetary (gearte.load_helical), got {type(model).__name__}")
    return model


def mesh_deflections(model: HelicalPlanetary) -> np.ndarray:
    """Mean load deflection F_t/(c_γ b), µm, of the external and internal meshes (F_t: tangential force per
    mesh at the sun's reference circle, the same for both meshes of a planet)."""
    st = _check_model(model).stage
    g = geometry(st)
    f_t = 1e3 * float(st.carrier_torque) / st.ratio / (st.n_planets * float(g.radius[0]))  # N
    return f_t / (np.asarray(st.mesh_stiffness) * float(st.face_width))


def recommended_amounts(model: HelicalPlanetary) -> np.ndarray:
    """Recommended modification amounts, µm, (x₁, x₂, x₃, x₄): the mean of each variable's probability model.

    Tip relief of a gear = the mean load deflection of the mesh it is optimised for plus its lead mismatch,
    C_a = F_t/(c_γ b) + F_βy (Niemann's rule, the form of Zhang, Chen & Wang's eq. 19;
    `recommended_tip_relief`); the sun's from the external mesh, the planet's from the internal mesh.
    Crowning: the pair's crowning C_β = F_t/(c_γ b) + F_βy (the parabola that meets the loaded flank at the
    face ends when it is tilted by F_βy), shared equally by the two gears of the pair.
    """
    st = _check_model(model).stage
    delta = mesh_deflections(model)
    g = geometry(st)
    f_t = 1e3 * float(st.carrier_torque) / st.ratio / (st.n_planets * float(g.radius[0]))
    fby = np.asarray(st.lead_mismatch)
    b = float(st.face_width)
    tip = [
        recommended_tip_relief(mesh_stiffness=float(st.mesh_stiffness[i]), face_width=b, tangential_force=f_t, lead_mismatch=float(fby[i]))
        for i in (0, 1)
    ]
    return np.array([tip[0], 0.5 * (delta[0] + fby[0]), tip[1], 0.5 * (delta[1] + fby[1])])


def design_variables(model: HelicalPlanetary, *, grade: int = 6) -> tuple[Variable, ...]:
    """The four design variables as `Variable.normal`: mean `recommended_amounts`, std = F_p/6 of the gear's
    total cumulative pitch tolerance (ISO 1328-1:2013, class `grade`: the sun's for x₁, x₂, the planet's for
    x₃, x₄): coded −1/0/+1 at the 1 %/50 %/99 % quantiles (mean ∓ 2.326 std)."""
    st = _check_model(model).stage
    g = geometry(st)
    mean = recommended_amounts(model)
    mn = float(st.normal_module)
    fp = [iso1328_tolerances(standard="1328-1:2013", module=mn, diameter=2 * float(g.radius[i]), grade=grade)["F_p"] for i in (0, 1)]
    std = [fp[0] / 6, fp[0] / 6, fp[1] / 6, fp[1] / 6]
    return tuple(Variable.normal(name.split()[0], float(m), float(s), unit="µm") for name, m, s in zip(AMOUNT_NAMES, mean, std))


class _Objective(eqx.Module):
    """fn(x, model) for `run_design`: the chosen amounts put into the 4-vector (the others `fixed`), the
    weighted sum of the (external, internal) fluctuations."""

    indices: tuple[int, ...] = eqx.field(static=True)
    fixed: tuple[float, ...] = eqx.field(static=True)
    weights: tuple[float, float] = eqx.field(static=True)

    def __call__(self, x, model):
        full = jnp.asarray(self.fixed, dtype=float).at[jnp.asarray(self.indices)].set(x)
        f = model.fluctuation(full)
        return jnp.asarray(self.weights, dtype=float) @ f


class StrategyResult(eqx.Module):
    """One modification strategy.

    - `name`: ``"sun"``, ``"planet"``, ``"joint"`` or ``"combined"``; `objective`: ``"external"``,
      ``"internal"`` or ``"sum"`` (of the two fluctuations).
    - `run`, `surface`, `optimum`: the design, its quadratic surface and the surface's optimum inside the
      design region (coded ±1); None for ``"combined"``.
    - `amounts`: (4,) µm, the amounts applied (x₁ … x₄; those outside the strategy 0).
    - `predicted`: the surface's objective at the optimum, µm (NaN for ``"combined"``).
    - `fluctuation`: (external, internal) µm from a direct model run at `amounts`; `verified`: the
      objective there, µm.
    """

    name: str = eqx.field(static=True)
    objective: str = eqx.field(static=True)
    run: DesignRun | None
    surface: ResponseSurface | None
    optimum: SurfaceOptimum | None
    amounts: np.ndarray
    predicted: float
    fluctuation: np.ndarray
    verified: float

    @property
    def total(self) -> float:
        """Sum of the verified external and internal fluctuations, µm."""
        return float(np.sum(self.fluctuation))


class ModificationStudy(eqx.Module):
    """Zhang, Chen & Wang's strategies on one model (`modification_strategies`).

    - `variables`: the four `Variable`s; `unmodified`: (external, internal) fluctuations without
      modification, µm; `at_means`: at the recommended amounts.
    - `strategies`: ``sun``, ``planet``, ``joint``, ``combined`` (`StrategyResult`), by name.
    - `runs`: model runs spent (design runs plus direct verification runs); `seconds`: wall time.
    """

    variables: tuple[Variable, ...]
    unmodified: np.ndarray
    at_means: np.ndarray
    strategies: dict[str, StrategyResult]
    runs: int = eqx.field(static=True)
    seconds: float = eqx.field(static=True)

    def table(self) -> str:
        """The strategies as a markdown table."""
        lines = [
            "| strategy | objective | x₁ | x₂ | x₃ | x₄ (µm) | R² / adj R² / pred R² | predicted (µm) | verified ext / int (µm) | sum (µm) |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for s in self.strategies.values():
            a = s.amounts
            r2 = "—" if s.surface is None else f"{s.surface.r2:.3f} / {s.surface.adj_r2:.3f} / {s.surface.pred_r2:.3f}"
            pred = "—" if math.isnan(s.predicted) else f"{s.predicted:.3f}"
            lines.append(
                f"| {s.name} | {s.objective} | {a[0]:.1f} | {a[1]:.1f} | {a[2]:.1f} | {a[3]:.1f} | {r2} | {pred} "
                f"| {s.fluctuation[0]:.3f} / {s.fluctuation[1]:.3f} | {s.total:.3f} |"
            )
        return "\n".join(lines)


_OBJECTIVES = {"external": (1.0, 0.0), "internal": (0.0, 1.0), "sum": (1.0, 1.0)}


@eqx.filter_jit
def _fluctuation(model, x):
    return model.fluctuation(x)


@eqx.filter_jit
def _smooth_objective(model, x, weights, smooth):
    return weights @ model.fluctuation(x, smooth=smooth)


def modification_strategies(
    model: HelicalPlanetary,
    variables: Sequence[Variable] | None = None,
    *,
    center_points: int = 2,
) -> ModificationStudy:
    """Run the four strategies of Zhang, Chen & Wang on `model` (module docstring).

    **Arguments:**

    - `model`: a `HelicalPlanetary`.
    - `variables`: the four design variables (default `design_variables(model)`).
    - `center_points`: centre runs of each central composite design (≥ 2 makes PRESS defined): 8 + 2 runs
      for the two-variable strategies, 24 + 2 for the joint one.

    **Returns:** a `ModificationStudy`.
    """
    _check_model(model)
    vs = design_variables(model) if variables is None else tuple(variables)
    if len(vs) != 4:
        raise ValueError(f"variables: give four Variables (x₁ … x₄), got {len(vs)}")
    t0 = time.perf_counter()
    design = CentralComposite(center_points=center_points)
    runs = 0

    def verify(amounts) -> np.ndarray:
        nonlocal runs
        runs += 1
        return np.asarray(_fluctuation(model, jnp.asarray(amounts, dtype=float)))

    out: dict[str, StrategyResult] = {}
    for name, idx, objective in (("sun", (0, 1), "external"), ("planet", (2, 3), "internal"), ("joint", (0, 1, 2, 3), "sum")):
        w = _OBJECTIVES[objective]
        sub = tuple(vs[i] for i in idx)
        fn = _Objective(idx, (0.0, 0.0, 0.0, 0.0), w)
        run = run_design(fn, design, sub, model, vectorise=True, progress=False, desc=name)
        runs += run.natural.shape[0]
        surface = fit_response_surface(run.natural, run.responses, variables=sub)
        opt = surface.optimum("minimise")
        amounts = np.zeros(4)
        amounts[list(idx)] = opt.natural
        f = verify(amounts)
        out[name] = StrategyResult(name, objective, run, surface, opt, amounts, float(opt.value), f, float(np.dot(w, f)))
    both = out["sun"].amounts + out["planet"].amounts
    f = verify(both)
    out["combined"] = StrategyResult("combined", "sum", None, None, None, both, math.nan, f, float(np.sum(f)))
    unmodified = verify(np.zeros(4))
    at_means = verify(np.array([v.centre for v in vs]))
    runs -= 2  # the two reference runs are not part of the strategies
    return ModificationStudy(vs, unmodified, at_means, out, runs, time.perf_counter() - t0)


# ---------------------------------------------------------------- gradient optimum through the ODE


class ModificationSolution(eqx.Module):
    """A gradient optimum of the modification amounts (`optimise_modifications`).

    - `amounts`: (4,) µm; `value`: the optimised (smooth, weighted) objective there, µm.
    - `fluctuation`: (external, internal) sampled peak-to-peak fluctuations at `amounts`, µm (a direct run).
    - `result`: a `gearte.RESULTS` item; `num_steps`: BFGS steps.
    - `evaluations`: objective-and-gradient evaluations, each one ODE solve with its reverse-mode adjoint
      (≈ 4 forward solves, `benchmarks/results/helical.md`): optimistix's BFGS makes one per step
      (`jax.linearize` of the objective at the step's point), so this is `num_steps`.
    """

    amounts: Float[Array, " 4"]
    value: Float[Array, ""]
    fluctuation: Float[Array, " 2"]
    result: RESULTS
    num_steps: int
    evaluations: int


class _BoxObjective(eqx.Module):
    centre: Float[Array, " 4"]
    half: Float[Array, " 4"]
    weights: Float[Array, " 2"]
    smooth: float = eqx.field(static=True)

    def amounts(self, z):
        return self.centre + self.half * jnp.sin(z)

    def __call__(self, z, model):
        return self.weights @ model.fluctuation(self.amounts(z), smooth=self.smooth)


class _StepLimit(optx.AbstractMinimiser):
    """`solver` stopped after `max_steps` steps, a run-time value: one compiled solve serves every limit up
    to the static loop bound given to `optx.minimise` (`_loop_bound`)."""

    solver: optx.AbstractMinimiser
    max_steps: Array
    rtol: float
    atol: float
    norm: Callable = eqx.field(static=True)

    def __init__(self, solver, max_steps: int):
        self.solver, self.max_steps = solver, jnp.asarray(max_steps)
        self.rtol, self.atol, self.norm = solver.rtol, solver.atol, solver.norm

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        return self.solver.init(fn, y, args, options, f_struct, aux_struct, tags), jnp.asarray(0)

    def step(self, fn, y, args, options, state, tags):
        inner, k = state
        y, inner, aux = self.solver.step(fn, y, args, options, inner, tags)
        return y, (inner, k + 1), aux

    def terminate(self, fn, y, args, options, state, tags):
        inner, k = state
        done, result = self.solver.terminate(fn, y, args, options, inner, tags)
        capped = jnp.invert(done) & (k >= self.max_steps)
        return done | capped, optx.RESULTS.where(capped, optx.RESULTS.nonlinear_max_steps_reached, result)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return self.solver.postprocess(fn, y, aux, args, options, state[0], tags, result)


def _loop_bound(max_steps: int) -> int:
    """The static bound of the optimiser's loop: `max_steps` rounded up to a power of two, at least 64."""
    return max(64, 1 << (max_steps - 1).bit_length())


def optimise_modifications(
    model: HelicalPlanetary,
    *,
    x0,
    bounds,
    weights: Sequence[float] = (1.0, 1.0),
    smooth: float = 0.02,
    rtol: float = 1e-4,
    atol: float = 1e-3,
    max_steps: int = 100,
    throw: bool = True,
) -> ModificationSolution:
    """Minimise w_ext·f_ext + w_int·f_int, the smooth DTE fluctuations of planet 1's meshes
    (`HelicalPlanetary.fluctuation(x, smooth=smooth)`), over the amounts x inside `bounds`, by BFGS
    (optimistix) with reverse-mode gradients through the diffrax solution.

    The box is handled by the change of variables x = c + h sin z (c, h the box's centre and half-width):
    unconstrained in z, every x inside the box, a bound reached exactly (where the gradient in z vanishes).
    A variable with low = high is held there.

    **Arguments:**

    - `model`: a `HelicalPlanetary`.
    - `x0`: start, (4,) µm (inside the box).
    - `bounds`: (4, 2) µm, (low, high) per amount.
    - `weights`: (w_ext, w_int).
    - `smooth`: width of `smooth_peak_to_peak`, µm (the objective is at most 2·smooth·log S above the sampled one).
    - `rtol`, `atol`: BFGS's Cauchy termination on z and on the objective (µm).
    - `max_steps`: BFGS steps at most, rejected line-search trials included (a run-time value: up to 64, and within
      each power of two beyond, a new limit reuses the compiled solve). The objective is the smoothed maximum over
      samples, whose leading sample changes along the way: the example takes 19 steps, the tests' coarse 4-slice
      model 69.
    - `throw`: raise if the solve did not succeed (else inspect `result`).

    **Returns:** a `ModificationSolution`.
    """
    _check_model(model)
    box = np.asarray(bounds, dtype=float)
    if box.shape != (4, 2) or not np.all(np.isfinite(box)) or not np.all(box[:, 1] >= box[:, 0]):
        raise ValueError(f"bounds: one finite (low, high) pair per amount, shape (4, 2), low ≤ high; got {bounds!r}")
    x = np.asarray(x0, dtype=float)
    if x.shape != (4,) or not np.all(np.isfinite(x)):
        raise ValueError(f"x0: four finite amounts (x₁ … x₄, µm), got {x0!r}")
    if np.any(x < box[:, 0]) or np.any(x > box[:, 1]):
        raise ValueError(f"x0: {x.tolist()} is outside bounds {box.tolist()}")
    w = np.asarray(weights, dtype=float)
    if w.shape != (2,) or not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError(f"weights: (w_ext, w_int), ≥ 0, not both 0; got {weights!r}")
    if not (math.isfinite(smooth) and smooth > 0):
        raise ValueError(f"smooth: a width > 0 µm, got {smooth!r}")
    max_steps = as_int("max_steps", max_steps, minimum=1)
    centre = 0.5 * (box[:, 0] + box[:, 1])
    half = 0.5 * (box[:, 1] - box[:, 0])
    z0 = np.where(half > 0, np.arcsin(np.clip((x - centre) / np.where(half > 0, half, 1.0), -1.0, 1.0)), 0.0)
    fn = _BoxObjective(jnp.asarray(centre), jnp.asarray(half), jnp.asarray(w), float(smooth))
    solver = _StepLimit(optx.BFGS(rtol=rtol, atol=atol), max_steps)
    sol = optx.minimise(fn, solver, jnp.asarray(z0), args=model, max_steps=_loop_bound(max_steps), throw=False)
    amounts = fn.amounts(sol.value)
    value = _smooth_objective(model, amounts, jnp.asarray(w), float(smooth))
    fluct = _fluctuation(model, amounts)
    result = promote(sol.result)
    steps = int(sol.stats["num_steps"])
    out = ModificationSolution(amounts, value, fluct, result, steps, steps)
    check(result, throw=throw, what="optimise_modifications")
    return out


def study_report(model: HelicalPlanetary | None = None) -> str:
    """The four strategies and the gradient optimum on `model` (default: the wind-turbine example), markdown."""
    from ..drives.helical import EXAMPLE, load_helical

    m = load_helical(EXAMPLE) if model is None else model
    study = modification_strategies(m)
    box = np.array([[v.low, v.high] for v in study.variables])
    t0 = time.perf_counter()
    sol = optimise_modifications(m, x0=[v.centre for v in study.variables], bounds=box)
    seconds = time.perf_counter() - t0
    joint = study.strategies["joint"]
    assert joint.run is not None
    a = np.asarray(sol.amounts)
    f = np.asarray(sol.fluctuation)
    lines = [
        f"Unmodified: external {study.unmodified[0]:.3f} µm, internal {study.unmodified[1]:.3f} µm; "
        f"at the recommended amounts: {study.at_means[0]:.3f} / {study.at_means[1]:.3f} µm. "
        f"Strategies: {study.runs} runs, {study.seconds:.0f} s.",
        "",
        study.table(),
        f"| gradient (BFGS through diffrax) | sum (smooth) | {a[0]:.1f} | {a[1]:.1f} | {a[2]:.1f} | {a[3]:.1f} | — | {float(sol.value):.3f} "
        f"| {f[0]:.3f} / {f[1]:.3f} | {f.sum():.3f} |",
        "",
        f"Runs: joint response surface {joint.run.natural.shape[0]} design runs + 1 verification; gradient "
        f"{sol.evaluations} solve+adjoint evaluations ({sol.num_steps} BFGS steps, {seconds:.0f} s with compilation).",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    print(study_report())
