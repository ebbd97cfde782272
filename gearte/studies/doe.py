"""Designs of experiments for any gearte model: the points to evaluate, in coded and natural units.

A design (`FullFactorial`, `CentralComposite`, `BoxBehnken`, `LatinHypercube`, `SobolSequence`) gives
*coded* points: ±1 are the ends of each variable's range (a CCD's axial points lie at ±α). Each
`Variable` maps coded to natural units linearly, ``x = centre + c · half_range``, so that a quadratic in
coded units is a quadratic in natural units. A variable is either a range ``(low, high)``, or a normal
probability model as in Zhang, Chen & Wang's response-surface study of helical planetary tooth modifications: coded −1, 0
and +1 are the 1 %, 50 % and 99 % quantiles of N(mean, std) (their eq. 17), so the range is
mean ± z₀.₉₉ · std with z₀.₉₉ = 2.3263.

`run_design` evaluates a model at every point, batched under `jax.vmap` when the model is a JAX function,
otherwise in a loop with a progress bar; `gearte.studies.response_surface` fits the quadratic surface.

References: Box & Wilson (1951) for the central composite design; Box & Hunter (1957) for rotatability,
α = (2^ρ)^{1/4} for a full 2^ρ factorial core; Box & Behnken (1960); McKay, Beckman & Conover (1979) for
Latin hypercubes; Sobol' (1967) and Owen (1998) for (scrambled) Sobol' sequences.
"""

from __future__ import annotations

import abc
import itertools
import math
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from tqdm import tqdm

from ..core.precision import require_x64

__all__ = [
    "AbstractCCDKind",
    "AbstractDesign",
    "BoxBehnken",
    "CentralComposite",
    "Circumscribed",
    "DesignRun",
    "FaceCentred",
    "FullFactorial",
    "Inscribed",
    "LatinHypercube",
    "SobolSequence",
    "Variable",
    "run_design",
]

#: The upper quantile of a normal variable's range: coded ±1 are its 1 % and 99 % quantiles.
NORMAL_QUANTILE = 0.99


def _whole(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise ValueError(f"{name}: must be a whole number ≥ {minimum}, got {value!r}")
    return int(value)


def _count_vars(n_vars: Any, minimum: int = 1) -> int:
    return _whole("number of variables", n_vars, minimum)


# ---------------------------------------------------------------- designs


class AbstractDesign(eqx.Module):
    """A design of experiments: `points(n_vars)` gives its coded points, one row per run."""

    @abc.abstractmethod
    def points(self, n_vars: int) -> np.ndarray:
        """The coded points, shape (runs, n_vars): ±1 at the ends of each variable's range."""

    @abc.abstractmethod
    def describe(self) -> str:
        """One line for reports."""

    def runs(self, n_vars: int) -> int:
        """The number of runs for `n_vars` variables."""
        return int(self.points(n_vars).shape[0])


class FullFactorial(AbstractDesign):
    """Every combination of `levels` equally spaced levels in [−1, 1]: levels^ρ runs.

    **Arguments:**

    - `levels`: levels per variable (≥ 2; 3 or more for a quadratic surface).
    """

    levels: int = eqx.field(static=True)

    def __init__(self, levels: int = 3):
        self.levels = _whole("FullFactorial.levels", levels, 2)

    def points(self, n_vars: int) -> np.ndarray:
        n = _count_vars(n_vars)
        grid = np.linspace(-1.0, 1.0, self.levels)
        return np.array(list(itertools.product(grid, repeat=n)), dtype=float).reshape(-1, n)

    def describe(self) -> str:
        return f"full factorial, {self.levels} levels per variable"


class AbstractCCDKind(eqx.Module):
    """Where a central composite design's points lie relative to the variables' ranges."""

    @abc.abstractmethod
    def scale(self, alpha: float) -> tuple[float, float]:
        """(corner distance, axial distance) in coded units, for the design's α."""


class Circumscribed(AbstractCCDKind):
    """Corners at ±1 (the ranges), axial points at ±α, outside the ranges (CCC)."""

    def scale(self, alpha: float) -> tuple[float, float]:
        return 1.0, alpha


class Inscribed(AbstractCCDKind):
    """The circumscribed design shrunk by 1/α: axial points at ±1, corners at ±1/α (CCI)."""

    def scale(self, alpha: float) -> tuple[float, float]:
        return 1.0 / alpha, 1.0


class FaceCentred(AbstractCCDKind):
    """Axial points on the faces of the cube, α = 1 (CCF); not rotatable."""

    def scale(self, alpha: float) -> tuple[float, float]:
        return 1.0, 1.0


class CentralComposite(AbstractDesign):
    """Central composite design (Box & Wilson 1951): the 2^ρ factorial corners, 2ρ axial points and centre
    points, 2^ρ + 2ρ + `center_points` runs (9 for ρ = 2, 25 for ρ = 4 with one centre point).

    **Arguments:**

    - `kind`: `Circumscribed()` (default), `Inscribed()` or `FaceCentred()`.
    - `alpha`: axial distance relative to the corners; default the rotatable α = (2^ρ)^{1/4} (Box & Hunter
      1957), 1.414 for ρ = 2, 2 for ρ = 4. A face-centred design has α = 1 (give None or 1).
    - `center_points`: runs at the centre (≥ 1). With one, a rotatable design for ρ = 2 or 4 gives the
      centre a leverage of 1, so PRESS is undefined; two or more make it defined.
    """

    kind: AbstractCCDKind
    alpha: float | None = eqx.field(static=True)
    center_points: int = eqx.field(static=True)

    def __init__(self, kind: AbstractCCDKind | None = None, *, alpha: float | None = None, center_points: int = 1):
        kind = Circumscribed() if kind is None else kind
        if not isinstance(kind, AbstractCCDKind):
            raise ValueError(f"CentralComposite.kind: expected Circumscribed(), Inscribed() or FaceCentred(), got {kind!r}")
        if alpha is not None:
            if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or not math.isfinite(alpha) or alpha <= 0:
                raise ValueError(f"CentralComposite.alpha: must be a number > 0 (or None for the rotatable α), got {alpha!r}")
            if isinstance(kind, FaceCentred) and alpha != 1:
                raise ValueError(f"CentralComposite.alpha: a face-centred design has α = 1, got {alpha}; leave alpha out")
            alpha = float(alpha)
        self.kind, self.alpha = kind, alpha
        self.center_points = _whole("CentralComposite.center_points", center_points, 1)

    def axial_distance(self, n_vars: int) -> float:
        """α for `n_vars` variables: the given one, or the rotatable (2^ρ)^{1/4}."""
        if isinstance(self.kind, FaceCentred):
            return 1.0
        return self.alpha if self.alpha is not None else float((2.0 ** _count_vars(n_vars)) ** 0.25)

    def points(self, n_vars: int) -> np.ndarray:
        n = _count_vars(n_vars)
        corner, axial = self.kind.scale(self.axial_distance(n))
        corners = corner * np.array(list(itertools.product((-1.0, 1.0), repeat=n)), dtype=float)
        axials = np.zeros((2 * n, n))
        for i in range(n):
            axials[2 * i, i], axials[2 * i + 1, i] = -axial, axial
        return np.concatenate([corners, axials, np.zeros((self.center_points, n))])

    def describe(self) -> str:
        kind = {Circumscribed: "circumscribed", Inscribed: "inscribed", FaceCentred: "face-centred"}[type(self.kind)]
        a = "α = 1" if isinstance(self.kind, FaceCentred) else ("rotatable α = (2^ρ)^¼" if self.alpha is None else f"α = {self.alpha:g}")
        return f"central composite, {kind}, {a}, {self.center_points} centre point(s)"


#: Box & Behnken (1960): the blocks of variables varied together at ±1 (the others at 0). For ρ = 3, 4, 5
#: every pair; for ρ = 6 six blocks of three (pairs 1-4, 2-5, 3-6 twice); for ρ = 7 the Fano plane
#: (every pair once).
_BB_BLOCKS: dict[int, list[tuple[int, ...]]] = {
    6: [(0, 1, 3), (1, 2, 4), (2, 3, 5), (0, 3, 4), (1, 4, 5), (0, 2, 5)],
    7: [(3, 4, 5), (0, 5, 6), (1, 4, 6), (0, 1, 3), (2, 3, 6), (0, 2, 4), (1, 2, 5)],
}


class BoxBehnken(AbstractDesign):
    """Box-Behnken design (Box & Behnken 1960), for 3 to 7 variables: blocks of two or three variables at ±1
    with the rest at 0, plus centre points; no corner points. Runs without centre points: 12 (ρ = 3),
    24 (ρ = 4), 40 (ρ = 5), 48 (ρ = 6), 56 (ρ = 7).

    **Arguments:**

    - `center_points`: runs at the centre (≥ 1; default 3, as in Box & Behnken's tables for ρ = 3, 4).
    """

    center_points: int = eqx.field(static=True)

    def __init__(self, *, center_points: int = 3):
        self.center_points = _whole("BoxBehnken.center_points", center_points, 1)

    def points(self, n_vars: int) -> np.ndarray:
        n = _count_vars(n_vars)
        if not 3 <= n <= 7:
            raise ValueError(
                f"BoxBehnken: defined for 3 to 7 variables, got {n}; use CentralComposite() or FullFactorial() for "
                f"{'fewer' if n < 3 else 'more'}"
            )
        blocks = _BB_BLOCKS.get(n, list(itertools.combinations(range(n), 2)))
        rows = []
        for b in blocks:
            for signs in itertools.product((-1.0, 1.0), repeat=len(b)):
                r = np.zeros(n)
                r[list(b)] = signs
                rows.append(r)
        return np.concatenate([np.array(rows), np.zeros((self.center_points, n))])

    def describe(self) -> str:
        return f"Box-Behnken, {self.center_points} centre point(s)"


def _rng_seed(name: str, seed: Any) -> int:
    return _whole(name, seed, 0)


class LatinHypercube(AbstractDesign):
    """Latin hypercube of `n` runs (McKay et al. 1979; `scipy.stats.qmc.LatinHypercube`): each variable's
    range is cut into `n` equal strata and each stratum holds exactly one run.

    **Arguments:**

    - `n`: runs (≥ 2).
    - `seed`: the random seed (integer ≥ 0, required); the same seed gives the same design.
    - `centred`: put each run at its stratum's centre instead of uniformly inside it.
    """

    n: int = eqx.field(static=True)
    seed: int = eqx.field(static=True)
    centred: bool = eqx.field(static=True)

    def __init__(self, n: int, *, seed: int, centred: bool = False):
        self.n, self.seed, self.centred = _whole("LatinHypercube.n", n, 2), _rng_seed("LatinHypercube.seed", seed), bool(centred)

    def points(self, n_vars: int) -> np.ndarray:
        d = _count_vars(n_vars)
        from scipy.stats import qmc  # scipy.stats takes a second to import: only when a design needs it

        u = qmc.LatinHypercube(d, scramble=not self.centred, rng=np.random.default_rng(self.seed)).random(self.n)
        return 2.0 * u - 1.0

    def describe(self) -> str:
        return f"Latin hypercube, {self.n} runs, seed {self.seed}" + (", centred" if self.centred else "")


class SobolSequence(AbstractDesign):
    """The first `n` = 2^m points of a Sobol' sequence (`scipy.stats.qmc.Sobol`), Owen-scrambled by default:
    every elementary interval of volume 2^−m holds exactly one point (balance needs a power of two).

    **Arguments:**

    - `n`: runs, a power of two (≥ 2).
    - `scramble`: Owen scrambling (randomised, unbiased); False gives the plain sequence from 0.
    - `seed`: the scrambling seed (integer ≥ 0), required with `scramble` (none is needed without).
    """

    n: int = eqx.field(static=True)
    scramble: bool = eqx.field(static=True)
    seed: int = eqx.field(static=True)

    def __init__(self, n: int, *, scramble: bool = True, seed: int | None = None):
        n = _whole("SobolSequence.n", n, 2)
        if n & (n - 1):
            lo = 1 << (n.bit_length() - 1)
            raise ValueError(f"SobolSequence.n: a Sobol' sequence is balanced on 2^m points; use {lo} or {2 * lo}, not {n}")
        if seed is None and scramble:
            raise ValueError("SobolSequence.seed: a scrambled sequence is random; give its seed (e.g. seed=0), or scramble=False")
        self.n, self.scramble, self.seed = n, bool(scramble), _rng_seed("SobolSequence.seed", 0 if seed is None else seed)

    def points(self, n_vars: int) -> np.ndarray:
        d = _count_vars(n_vars)
        if d > 21201:
            raise ValueError(f"SobolSequence: at most 21201 variables, got {d}")
        from scipy.stats import qmc

        s = qmc.Sobol(d, scramble=self.scramble, rng=np.random.default_rng(self.seed))
        return 2.0 * s.random_base2(int(math.log2(self.n))) - 1.0

    def describe(self) -> str:
        return f"Sobol' sequence, {self.n} runs" + (f", scrambled (seed {self.seed})" if self.scramble else ", unscrambled")


# ---------------------------------------------------------------- variables


class Variable(eqx.Module):
    """One design variable: its name, unit and how coded units map to natural ones,
    ``x = centre + c · half_range``.

    Build it from a range, ``Variable("E_s", 0.0, 26.0, unit="µm")`` (coded ±1 at low and high), or from a
    normal probability model, ``Variable.normal("x1", mean, std, unit="µm")`` (coded −1, 0, +1 at its 1 %,
    50 %, 99 % quantiles).

    **Arguments:**

    - `name`: a label (a term of the response surface is named after it).
    - `low`, `high`: the natural values at coded −1 and +1 (low < high).
    - `unit`: the unit of the natural values, for reports.
    - `basis`: how the range was set, for reports.
    """

    name: str = eqx.field(static=True)
    low: float = eqx.field(static=True)
    high: float = eqx.field(static=True)
    unit: str = eqx.field(static=True)
    basis: str = eqx.field(static=True)

    def __init__(self, name: str, low: float, high: float, *, unit: str = "", basis: str = ""):
        if not isinstance(name, str) or not name:
            raise ValueError(f"Variable.name: give a non-empty string, got {name!r}")
        for k, v in (("low", low), ("high", high)):
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"Variable {name!r}: {k} must be a finite number, got {v!r}")
        if not high > low:
            raise ValueError(f"Variable {name!r}: high ({high:g}) must be above low ({low:g})")
        self.name, self.low, self.high, self.unit = name, float(low), float(high), str(unit)
        self.basis = basis or f"range [{low:g}, {high:g}]" + (f" {unit}" if unit else "")

    @classmethod
    def normal(cls, name: str, mean: float, std: float, *, unit: str = "") -> Variable:
        """A variable drawn from N(`mean`, `std`²): coded −1, 0, +1 at its 1 %, 50 %, 99 % quantiles."""
        if isinstance(std, bool) or not isinstance(std, (int, float)) or not math.isfinite(std) or not std > 0:
            raise ValueError(f"Variable {name!r}: std must be a number > 0, got {std!r}")
        if isinstance(mean, bool) or not isinstance(mean, (int, float)) or not math.isfinite(mean):
            raise ValueError(f"Variable {name!r}: mean must be a finite number, got {mean!r}")
        from scipy.stats import norm

        z = float(norm.ppf(NORMAL_QUANTILE))
        u = f" {unit}" if unit else ""
        return cls(
            name,
            mean - z * std,
            mean + z * std,
            unit=unit,
            basis=f"normal, mean {mean:g}{u}, std {std:g}{u}: coded −1/0/+1 at its 1 %/50 %/99 % quantiles",
        )

    @property
    def centre(self) -> float:
        return 0.5 * (self.low + self.high)

    @property
    def half_range(self) -> float:
        return 0.5 * (self.high - self.low)

    def natural(self, coded):
        """Natural value(s) of coded value(s)."""
        return self.centre + np.asarray(coded, dtype=float) * self.half_range

    def coded(self, natural):
        """Coded value(s) of natural value(s)."""
        return (np.asarray(natural, dtype=float) - self.centre) / self.half_range


def check_variables(variables: Sequence[Variable]) -> tuple[Variable, ...]:
    """The variables as a tuple, checked: at least one, all `Variable`, distinct names."""
    vs = tuple(variables)
    if not vs:
        raise ValueError("variables: give at least one Variable")
    for v in vs:
        if not isinstance(v, Variable):
            raise ValueError(f"variables: expected Variable objects, got {type(v).__name__}")
    names = [v.name for v in vs]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"variables: names must differ, {dup} repeated")
    return vs


def to_natural(coded: np.ndarray, variables: Sequence[Variable]) -> np.ndarray:
    """Coded points (runs, ρ) → natural units."""
    return np.stack([v.natural(coded[:, i]) for i, v in enumerate(variables)], axis=1)


def to_coded(natural: np.ndarray, variables: Sequence[Variable]) -> np.ndarray:
    """Natural points (runs, ρ) → coded units."""
    natural = np.atleast_2d(np.asarray(natural, dtype=float))
    return np.stack([v.coded(natural[:, i]) for i, v in enumerate(variables)], axis=1)


# ---------------------------------------------------------------- running a design


class DesignRun(eqx.Module):
    """A design evaluated: its points and the responses.

    **Arguments:**

    - `design`, `variables`: what was run.
    - `coded`, `natural`: the points, (runs, ρ), in coded and natural units.
    - `responses`: the model's outputs, (runs,) or (runs, k).
    - `vectorised`: whether the runs were evaluated in one `jax.vmap`ped call.
    - `seconds`: wall time of the evaluation (compilation included).
    """

    design: AbstractDesign
    variables: tuple[Variable, ...]
    coded: np.ndarray
    natural: np.ndarray
    responses: np.ndarray
    vectorised: bool = eqx.field(static=True)
    seconds: float = eqx.field(static=True)


_TRACE_ERRORS = (jax.errors.JAXTypeError, jax.errors.JAXIndexError)


@eqx.filter_jit
def _vmapped(fn, x, args):
    # One compiled program per function, number of runs and `args` structure: a second design of the same
    # size reuses it (Python numbers in `args` are compile-time constants; pass arrays to vary them).
    return jax.vmap(fn, in_axes=(0, None))(x, args)


def run_design(
    fn: Callable[[Any, Any], Any],
    design: AbstractDesign,
    variables: Sequence[Variable],
    args: Any = None,
    *,
    vectorise: bool | None = None,
    progress: bool | None = None,
    desc: str = "design",
) -> DesignRun:
    """Evaluate ``fn(x, args)`` at every point of `design`, x the vector of the variables in natural units.

    **Arguments:**

    - `fn`: the model, ``fn(x, args) -> response`` (a scalar or a vector), x of shape (ρ,) in the
      variables' natural units: any gearte drive and metric (see docs/doe.md).
    - `design`: a design (`CentralComposite()`, `BoxBehnken()`, …).
    - `variables`: one `Variable` per entry of x.
    - `args`: passed to `fn` unchanged (a pytree; under `vmap` its arrays are traced and its Python numbers
      are constants, so pass arrays for values that change between calls).
    - `vectorise`: True: all runs in one `jax.vmap`ped, jitted call (`fn` must be a JAX function);
      False: a Python loop with a progress bar; None (default): vmap, falling back to the loop when `fn`
      cannot be traced (it converts a tracer to NumPy or branches on a value).
    - `progress`: show the loop's progress bar (default: when stderr is a terminal).

    **Returns:** a `DesignRun`; `fit_response_surface(run.natural, run.responses, variables=run.variables)`
    fits the quadratic surface.
    """
    if not callable(fn):
        raise ValueError(f"fn: expected a function fn(x, args), got {type(fn).__name__}")
    if not isinstance(design, AbstractDesign):
        raise ValueError(f"design: expected a design such as gearte.CentralComposite(), got {design!r}")
    vs = check_variables(variables)
    coded = design.points(len(vs))
    natural = to_natural(coded, vs)
    require_x64()
    t0 = time.perf_counter()
    out = None
    if vectorise is not False:
        try:
            out = np.asarray(_vmapped(fn, jnp.asarray(natural), args))
        except _TRACE_ERRORS:
            if vectorise:
                raise
    vectorised = out is not None
    if out is None:
        if progress is None:
            progress = sys.stderr.isatty()
        rows = []
        for x in tqdm(natural, desc=desc, unit="runs", disable=not progress, leave=False):
            rows.append(np.asarray(fn(x, args), dtype=float))
        shapes = {r.shape for r in rows}
        if len(shapes) > 1:
            raise ValueError(f"fn: every run must return the same shape, got {sorted(shapes)}")
        out = np.stack(rows)
    out = np.asarray(out, dtype=float)
    if out.ndim > 2:
        raise ValueError(f"fn: return a scalar or a vector per run, got shape {out.shape[1:]}")
    return DesignRun(
        design=design,
        variables=vs,
        coded=coded,
        natural=natural,
        responses=out,
        vectorised=vectorised,
        seconds=time.perf_counter() - t0,
    )
