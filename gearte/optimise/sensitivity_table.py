"""Sensitivities of a tolerance budget: gradient contributions beside Sobol' indices, source by source."""

from __future__ import annotations

from collections.abc import Mapping

import equinox as eqx
import jax
import numpy as np
from jaxtyping import PRNGKeyArray

from ..core.units import UNIT_SYMBOLS, angle_from_rad
from ..studies.montecarlo import TEStudy, as_key
from ..studies.sensitivity import SobolIndices, sobol_indices
from .budget import contributions
from .budget_model import BudgetProblem, check_tolerances


class SensitivityTable(eqx.Module):
    """Per error source: tolerance (µm), gradient contribution ∂stat/∂T_i · T_i (rad) and its share
    of the constrained statistic, next to the Sobol' indices of the per-sample TE.

    `statistic`: the budget's smooth constrained statistic at these tolerances (rad), which the
    contributions add up to (Euler's theorem); `sobol`: the full `SobolIndices`.
    """

    tolerances: dict[str, float]
    contribution: dict[str, float]
    statistic: float
    sobol: SobolIndices

    @property
    def sources(self) -> list[str]:
        return list(self.tolerances)

    def rows(self) -> list[dict]:
        """One dict per source: tolerance_um, contribution_rad, share, sobol_first_order_sum,
        sobol_closed_first_order, sobol_total_order."""
        s = self.sobol
        return [
            {
                "source": n,
                "tolerance_um": self.tolerances[n],
                "contribution_rad": self.contribution[n],
                "share": self.contribution[n] / self.statistic if self.statistic else float("nan"),
                "sobol_first_order_sum": s.source_first_order_sum[n],
                "sobol_closed_first_order": s.source_closed_first_order[n],
                "sobol_total_order": s.source_total_order[n],
            }
            for n in self.sources
        ]

    def to_dict(self) -> dict:
        return {"statistic_rad": self.statistic, "rows": self.rows(), "sobol": self.sobol.to_dict()}

    def format(self, *, unit: str = "arcsec") -> str:
        """A plain-text table; contributions in `unit` ("arcsec", "arcmin", "urad" or "rad")."""
        sym = UNIT_SYMBOLS.get(unit)
        if sym is None:
            raise ValueError(f"unit: one of {sorted(UNIT_SYMBOLS)}, got {unit!r}")
        head = f"{'source':22s} {'T (µm)':>8s} {'∂stat/∂T·T':>12s} {'share':>7s} {'ΣS_i':>7s} {'S_clo':>7s} {'S_T':>7s}"
        lines = [head, "-" * len(head)]
        for r in self.rows():
            c = float(angle_from_rad(r["contribution_rad"], unit))
            lines.append(
                f"{r['source']:22s} {r['tolerance_um']:8.3g} {c:10.2f}{sym:2s} {r['share']:7.1%} "
                f"{r['sobol_first_order_sum']:7.3f} {r['sobol_closed_first_order']:7.3f} {r['sobol_total_order']:7.3f}"
            )
        lines.append(
            f"{'sum':22s} {'':>8s} {float(angle_from_rad(self.statistic, unit)):10.2f}{sym:2s} {'':>7s} "
            f"{sum(self.sobol.source_first_order_sum.values()):7.3f}"
        )
        return "\n".join(lines)


def sensitivity_table(
    problem: BudgetProblem,
    tolerances: Mapping[str, float] | None = None,
    *,
    key: int | PRNGKeyArray,
    n_sobol: int = 1024,
    n_samples: int = 8192,
) -> SensitivityTable:
    """Gradient contributions and Sobol' indices of a budget problem, source by source.

    **Arguments:**

    - `problem`: the budget problem (`gearte.budget_problem`): drive, error laws at the
      nominal tolerances, constrained statistic (its first constraint).
    - `tolerances`: µm per source (default: the nominal tolerances).
    - `key`: integer seed or `jax.random` key (split between the two analyses).
    - `n_sobol`: base samples of the Sobol' design (a power of 2).
    - `n_samples`: common random samples for the gradient contributions.

    **Returns:** a `SensitivityTable`. The two measures answer different questions: the
    contribution is the share of the *constrained statistic* (e.g. the 99.73 % point) that a
    source owns at these tolerances — what tightening it buys; a Sobol' index is the share of
    the *variance* of the per-sample TE that its random inputs explain.
    """
    if not isinstance(problem, BudgetProblem):
        raise ValueError(f"problem: expected a budget problem (gearte.budget_problem), got {type(problem).__name__}")
    tol = check_tolerances(problem, tolerances)
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 2:
        raise ValueError(f"n_samples: must be a whole number ≥ 2, got {n_samples!r}")
    k_grad, k_sobol = jax.random.split(as_key(key))
    contrib = contributions(problem, tol, key=k_grad, n_samples=int(n_samples))
    scale = {k: tol[k] / float(problem.nominal[k]) for k in problem.names}
    study = TEStudy(problem.drive, problem.model, metric=problem.constraints[0].metric)
    sob = sobol_indices(study, key=k_sobol, n=n_sobol, scale=scale)
    return SensitivityTable(tolerances=tol, contribution=contrib, statistic=float(sum(contrib.values())), sobol=sob)
