"""Quadratic response surfaces with cross terms: least-squares fit, goodness of fit, canonical analysis and the
optimum inside the design region.

The model in coded units c (see `gearte.studies.doe.Variable`) is

    y = η₀ + Σ_λ η_λ c_λ + Σ_λ η_λλ c_λ² + Σ_{λ<γ} η_λγ c_λ c_γ,

p = (ρ + 1)(ρ + 2)/2 terms for ρ variables (Zhang, Chen & Wang, eq. 15). The least-squares coefficients are
η = (XᵀX)⁻¹Xᵀy (their eq. 16); gearte computes the same η from the QR factorisation X = QR as η = R⁻¹Qᵀy
(since XᵀX = RᵀR, (XᵀX)⁻¹Xᵀ = R⁻¹R⁻ᵀRᵀQᵀ = R⁻¹Qᵀ), which never forms XᵀX and so does not square X's
condition number. The hat matrix H = X(XᵀX)⁻¹Xᵀ = QQᵀ gives the leverages h_i = Σ_j Q_ij², hence
PRESS = Σ (e_i / (1 − h_i))² (the sum of squared leave-one-out prediction errors, without refitting) and
the predicted R² = 1 − PRESS / SSY. R² = 1 − SSE/SSY (their eq. 18) and the adjusted
R²_adj = 1 − (SSE/(n − p)) / (SSY/(n − 1)).

The optimum is found exactly on the box of the design region: a quadratic's minimum over a box lies in the
relative interior of one of its 3^ρ faces (each variable free, at its low or at its high bound), where it is
the stationary point of the quadratic restricted to that face; gearte solves each face's stationary point
(a small linear system), keeps the feasible ones and the vertices, and takes the best. No iterative solver,
no starting point, no local optimum.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any, Literal

import equinox as eqx
import numpy as np

from .doe import Variable, check_variables, to_coded, to_natural

__all__ = ["CanonicalAnalysis", "ResponseSurface", "SurfaceOptimum", "fit_response_surface", "quadratic_terms"]

#: A leverage within this of 1 leaves PRESS undefined (the model without that run is not estimable).
LEVERAGE_ONE = 1e-10
#: Above this many variables the 3^ρ faces of the box are too many to enumerate.
MAX_OPTIMUM_VARIABLES = 10


def quadratic_terms(names: Sequence[str]) -> tuple[str, ...]:
    """The term names of the full quadratic in `names`: ``1``, each ``a``, each ``a^2``, each ``a*b`` (a before b)."""
    n = list(names)
    return ("1", *n, *(f"{a}^2" for a in n), *(f"{a}*{b}" for a, b in itertools.combinations(n, 2)))


def model_matrix(coded: np.ndarray) -> np.ndarray:
    """The quadratic model's matrix X (runs, p) of coded points (runs, ρ), columns in `quadratic_terms` order."""
    c = np.atleast_2d(np.asarray(coded, dtype=float))
    rho = c.shape[1]
    cols = [np.ones(c.shape[0]), *(c[:, i] for i in range(rho)), *(c[:, i] ** 2 for i in range(rho))]
    cols += [c[:, i] * c[:, j] for i, j in itertools.combinations(range(rho), 2)]
    return np.stack(cols, axis=1)


class CanonicalAnalysis(eqx.Module):
    """The quadratic part of a surface, y = η₀ + bᵀc + cᵀBc, in its principal axes (coded units).

    - `eigenvalues` (ascending) and `eigenvectors` (columns) of B: the curvature along each principal axis.
    - `nature`: ``"minimum"`` (all eigenvalues > 0), ``"maximum"`` (all < 0), ``"saddle"`` (both signs),
      ``"ridge"`` (some eigenvalue ≈ 0 relative to the largest: a line or plane of near-optima), or
      ``"plane"`` (no curvature).
    - `stationary_coded`, `stationary_natural`, `stationary_value`: the stationary point c_s = −½B⁻¹b and the
      surface there (NaN for a ridge or plane, where it is not unique).
    """

    b: np.ndarray
    B: np.ndarray
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    nature: str = eqx.field(static=True)
    stationary_coded: np.ndarray
    stationary_natural: np.ndarray
    stationary_value: float


class SurfaceOptimum(eqx.Module):
    """The best point of a surface inside a box.

    - `natural`, `coded`: where it is; `value`: the surface there (the predicted response).
    - `goal`: ``"minimise"`` or ``"maximise"``.
    - `at_bounds`: (variable name, ``"low"`` or ``"high"``) for each variable at a bound of the box;
      empty when the optimum is the surface's stationary point inside the region.
    - `bounds`: the box, (ρ, 2), natural units.
    """

    natural: np.ndarray
    coded: np.ndarray
    value: float
    goal: str = eqx.field(static=True)
    at_bounds: tuple[tuple[str, str], ...] = eqx.field(static=True)
    bounds: np.ndarray

    @property
    def interior(self) -> bool:
        """Whether the optimum is inside the box (the stationary point), not on its boundary."""
        return not self.at_bounds


class ResponseSurface(eqx.Module):
    """A quadratic response surface fitted by least squares (`fit_response_surface`).

    Coefficients are in coded units (the convention of response-surface work: comparable across variables);
    `predict` takes natural units.

    - `variables`, `terms`, `coefficients`: the model, term by term.
    - `coded`, `y`, `fitted`, `residuals`, `leverage`: per run.
    - `r2`, `adj_r2`: R² = 1 − SSE/SSY and the adjusted R² (NaN when there is nothing to explain, SSY = 0,
      or for the adjusted one when n = p).
    - `press`, `pred_r2`: PRESS = Σ (eᵢ/(1 − hᵢ))² and the predicted R² = 1 − PRESS/SSY; NaN when a run has
      leverage 1 (e.g. the single centre point of a rotatable CCD for ρ = 2 or 4): the model without it is
      not estimable. Add centre points to make them defined.
    """

    variables: tuple[Variable, ...]
    terms: tuple[str, ...] = eqx.field(static=True)
    coefficients: np.ndarray
    coded: np.ndarray
    y: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    leverage: np.ndarray
    r2: float
    adj_r2: float
    press: float
    pred_r2: float

    @property
    def n_runs(self) -> int:
        return int(self.y.shape[0])

    @property
    def n_terms(self) -> int:
        return len(self.terms)

    def named(self) -> dict[str, float]:
        """The coefficients by term name (coded units)."""
        return {t: float(c) for t, c in zip(self.terms, self.coefficients)}

    def predict_coded(self, coded) -> np.ndarray:
        """The surface at coded point(s) (…, ρ)."""
        c = np.asarray(coded, dtype=float)
        flat = c.reshape(-1, len(self.variables))
        return (model_matrix(flat) @ self.coefficients).reshape(c.shape[:-1])

    def predict(self, x) -> np.ndarray:
        """The surface at natural point(s) x, shape (…, ρ), in the variables' units."""
        x = np.asarray(x, dtype=float)
        if x.shape[-1:] != (len(self.variables),):
            raise ValueError(f"predict: x must end in {len(self.variables)} values (one per variable), got shape {x.shape}")
        return self.predict_coded(to_coded(x.reshape(-1, len(self.variables)), self.variables).reshape(x.shape))

    def quadratic_form(self) -> tuple[float, np.ndarray, np.ndarray]:
        """(η₀, b, B) with y = η₀ + bᵀc + cᵀBc in coded units, B symmetric (B_λγ = η_λγ / 2 off the diagonal)."""
        rho = len(self.variables)
        eta = self.coefficients
        b = eta[1 : 1 + rho].copy()
        B = np.diag(eta[1 + rho : 1 + 2 * rho])
        for k, (i, j) in enumerate(itertools.combinations(range(rho), 2)):
            B[i, j] = B[j, i] = 0.5 * eta[1 + 2 * rho + k]
        return float(eta[0]), b, B

    def canonical(self, *, rtol: float = 1e-8) -> CanonicalAnalysis:
        """The canonical analysis of the quadratic part (eigenvalues of B; `rtol`: an eigenvalue below
        rtol × the largest |eigenvalue| counts as zero)."""
        eta0, b, B = self.quadratic_form()
        lam, vec = np.linalg.eigh(B)
        big = float(np.max(np.abs(lam)))
        zero = np.abs(lam) <= rtol * big
        if big == 0.0:
            nature = "plane"
        elif np.any(zero):
            nature = "ridge"
        elif np.all(lam > 0):
            nature = "minimum"
        elif np.all(lam < 0):
            nature = "maximum"
        else:
            nature = "saddle"
        if nature in ("plane", "ridge"):
            cs = np.full(len(b), math.nan)
            value = math.nan
        else:
            cs = -0.5 * np.linalg.solve(B, b)
            value = eta0 + 0.5 * float(b @ cs)
        return CanonicalAnalysis(
            b=b,
            B=B,
            eigenvalues=lam,
            eigenvectors=vec,
            nature=nature,
            stationary_coded=cs,
            stationary_natural=to_natural(cs[None, :], self.variables)[0],
            stationary_value=value,
        )

    def optimum(self, goal: Literal["minimise", "maximise"] = "minimise", *, bounds: Any = None) -> SurfaceOptimum:
        """The minimum or maximum of the surface inside a box (exact: see the module's docstring).

        **Arguments:**

        - `goal`: ``"minimise"`` (default) or ``"maximise"``.
        - `bounds`: the box: None (default) the variables' ranges (coded ±1: low and high, or a normal
          variable's 1 % and 99 % quantiles); ``"design"`` the extent of the fitted runs (±α for a
          circumscribed CCD); or one (low, high) per variable in natural units.

        **Returns:** a `SurfaceOptimum`.
        """
        if goal not in ("minimise", "maximise"):
            raise ValueError(f"goal: 'minimise' or 'maximise', got {goal!r}")
        rho = len(self.variables)
        if rho > MAX_OPTIMUM_VARIABLES:
            raise ValueError(f"optimum: at most {MAX_OPTIMUM_VARIABLES} variables (3^ρ faces are enumerated), got {rho}")
        if bounds is None:
            box = np.tile([-1.0, 1.0], (rho, 1))
        elif isinstance(bounds, str):
            if bounds != "design":
                raise ValueError(f"bounds: None, 'design' or one (low, high) per variable, got {bounds!r}")
            box = np.stack([self.coded.min(axis=0), self.coded.max(axis=0)], axis=1)
        else:
            nb = np.asarray(bounds, dtype=float)
            if nb.shape != (rho, 2) or not np.all(np.isfinite(nb)) or not np.all(nb[:, 1] >= nb[:, 0]):
                raise ValueError(f"bounds: one finite (low, high) pair per variable ({rho}), low ≤ high; got {bounds!r}")
            box = np.stack([self.variables[i].coded(nb[i]) for i in range(rho)])
        sign = 1.0 if goal == "minimise" else -1.0
        eta0, b, B = self.quadratic_form()
        best_c, best_f = None, math.inf
        for assign in itertools.product((None, 0, 1), repeat=rho):
            fixed = [i for i in range(rho) if assign[i] is not None]
            free = [i for i in range(rho) if assign[i] is None]
            c = np.zeros(rho)
            for i in fixed:
                c[i] = box[i, assign[i]]
            if free:
                Bff = B[np.ix_(free, free)]
                rhs = -0.5 * (b[free] + 2.0 * B[np.ix_(free, fixed)] @ c[fixed])
                if np.linalg.cond(Bff) > 1e12:
                    continue  # not a unique stationary point: the face's optimum is on its own boundary
                cf = np.linalg.solve(Bff, rhs)
                lo, hi = box[free, 0], box[free, 1]
                span = np.maximum(hi - lo, 1.0)
                if np.any(cf < lo - 1e-12 * span) or np.any(cf > hi + 1e-12 * span):
                    continue
                c[free] = np.clip(cf, lo, hi)
            f = sign * (eta0 + b @ c + c @ B @ c)
            if best_c is None or f < best_f - 1e-12 * max(1.0, abs(best_f)):
                best_c, best_f = c, f
        assert best_c is not None  # the vertices are always feasible
        tol = 1e-9 * np.maximum(box[:, 1] - box[:, 0], 1.0)
        at = []
        for i, v in enumerate(self.variables):
            if box[i, 1] > box[i, 0] and abs(best_c[i] - box[i, 0]) <= tol[i]:
                at.append((v.name, "low"))
            elif box[i, 1] > box[i, 0] and abs(best_c[i] - box[i, 1]) <= tol[i]:
                at.append((v.name, "high"))
        return SurfaceOptimum(
            natural=to_natural(best_c[None, :], self.variables)[0],
            coded=best_c,
            value=float(self.predict_coded(best_c)),
            goal=goal,
            at_bounds=tuple(at),
            bounds=np.stack([v.natural(box[i]) for i, v in enumerate(self.variables)]),
        )


def fit_response_surface(x, y, *, variables: Sequence[Variable] | None = None) -> ResponseSurface:
    """Fit the full quadratic (with cross terms) to responses `y` at points `x` by least squares (QR).

    **Arguments:**

    - `x`: the points, (runs, ρ), in the variables' natural units (e.g. `DesignRun.natural`).
    - `y`: the responses, (runs,).
    - `variables`: one `Variable` per column of x (their ranges give the coded units); default: x is
      already coded, variables ``x1 … xρ`` with range [−1, 1].

    **Returns:** a `ResponseSurface`.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 2:
        raise ValueError(f"x: expected the points as an array (runs, variables), got shape {x.shape}")
    if y.shape != (x.shape[0],):
        raise ValueError(f"y: expected one response per run, shape ({x.shape[0]},), got {y.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("x, y: every point and response must be finite (a run that failed gives NaN: look at it, rerun or drop it)")
    rho = x.shape[1]
    if variables is None:
        variables = tuple(Variable(f"x{i + 1}", -1.0, 1.0) for i in range(rho))
    vs = check_variables(variables)
    if len(vs) != rho:
        raise ValueError(f"variables: {len(vs)} given for {rho} columns of x")
    c = to_coded(x, vs)
    X = model_matrix(c)
    n, p = X.shape
    terms = quadratic_terms([v.name for v in vs])
    rank = int(np.linalg.matrix_rank(X))
    if rank < p:
        raise ValueError(
            f"the quadratic model in {rho} variable(s) has {p} terms but these {n} runs determine only {rank} of them; "
            "use a design made for it (CentralComposite, BoxBehnken, FullFactorial(levels=3)) or more runs"
        )
    Q, R = np.linalg.qr(X)
    from scipy.linalg import solve_triangular  # imported here: a study that fits no surface does not load SciPy

    eta = solve_triangular(R, Q.T @ y)
    fitted = X @ eta
    e = y - fitted
    h = np.sum(Q**2, axis=1)
    sse = float(e @ e)
    ssy = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - sse / ssy if ssy > 0 else math.nan
    adj = 1.0 - (sse / (n - p)) / (ssy / (n - 1)) if ssy > 0 and n > p else math.nan
    if np.any(1.0 - h < LEVERAGE_ONE):
        press = math.nan
    else:
        press = float(np.sum((e / (1.0 - h)) ** 2))
    pred = 1.0 - press / ssy if ssy > 0 and math.isfinite(press) else math.nan
    return ResponseSurface(
        variables=vs,
        terms=terms,
        coefficients=eta,
        coded=c,
        y=y,
        fitted=fitted,
        residuals=e,
        leverage=h,
        r2=r2,
        adj_r2=adj,
        press=press,
        pred_r2=pred,
    )
