"""Identification of a grid drive's errors (`AbstractGridDrive`: the cycloid-pin reducer) from measured TE records.

A grid drive computes its TE only at the angles of its grid (`input_angles`, read from its `response` by `te`),
so each record is put on the grid angles it spans (linear interpolation of the record, which must sample at
least as finely as the grid), and the residual, model TE − measured TE there, is minimised by
Levenberg–Marquardt (`optimistix.least_squares`) through the drive's own model. The parameters are the
instances of the sources named in `adjust` (every source by default): a deviation's value (µm or rad), an
eccentricity's Cartesian phasor (x, y) = e (cos φ, sin φ) µm; the other sources are held at `start`, where
the solve also begins. Each record adds its own constant, as for a sinusoidal drive.

**Identifiability.** The model is not linear, so what the records show is read from its Jacobian at the start
point (the same column-by-column rank rule as for a sinusoidal drive, on the records' grid rows): an instance
with zero columns is *unseen*, one whose columns lie in the span of the record constants is a *constant*, one
in the span of earlier instances is *combined* with them (held at its start value, the earlier instance carries
the combination). A source that acts through another's size (the phase of an error of size 0) is unseen at a
start where that size is 0: start from non-zero values.

**Uncertainty.** σ² = |r|²/(n − p) and the covariance σ² (JᵀJ)⁻¹ at the solution, as for a sinusoidal drive,
with n the grid rows used: a grid coarser than the record uses fewer samples and gives wider intervals.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, PRNGKeyArray

from ..core.solution import RESULTS
from ..core.units import TWO_PI
from ..drives.protocol import AbstractGridDrive, Eccentricity, Errors
from .fit import Identification, _instances, estimates, unpack
from .identifiability import Group, Instance, groups, select
from .records import MeasuredRecord, RecordError


class GridIdentificationProblem(eqx.Module):
    """What `identify` solves for a grid drive: the drive, the start point, each record's grid rows and
    interpolation, and which instances are identified (see the module notes). `solve` as `IdentificationProblem.solve`."""

    drive: AbstractGridDrive
    start: dict
    origin: np.ndarray  # the start's parameter vector, every adjusted instance (µm, rad)
    scale: np.ndarray  # unit of each solver parameter in those units (1 / Jacobian column norm at the start)
    rows: tuple[np.ndarray, ...]  # per record: the grid rows it spans
    left: tuple[np.ndarray, ...]  # per record: sample before each of those grid angles
    weight: tuple[np.ndarray, ...]  # per record: interpolation weight of the sample after
    turns: tuple[tuple[tuple[str, float], ...], ...] = eqx.field(static=True)
    sources: tuple[str, ...] = eqx.field(static=True)
    instances: tuple[Instance, ...] = eqx.field(static=True)
    kept: tuple[int, ...] = eqx.field(static=True)
    groups: tuple[Group, ...] = eqx.field(static=True)
    starts: int = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)

    @property
    def labels(self) -> tuple[str, ...]:
        """Labels of the identified instances."""
        return tuple(self.instances[i].label for i in self.kept)

    @property
    def widths(self) -> list[int]:
        return [2 if inst.kind == "eccentricity" else 1 for inst in self.instances]

    def _columns(self) -> np.ndarray:
        """Solver columns of the kept instances in the full parameter vector."""
        starts_of = np.cumsum([0] + self.widths)
        return np.concatenate([np.arange(starts_of[i], starts_of[i + 1]) for i in self.kept]).astype(int)

    def full(self, p: Array) -> Array:
        """Every adjusted instance's parameters (µm, rad) from the solver's (scaled, kept) ones."""
        cols = self._columns()
        return jnp.asarray(self.origin).at[cols].add(jnp.asarray(self.scale)[cols] * p)

    def errors_from(self, p_full: Array, turns: Mapping[str, float] | None = None) -> dict:
        """The drive's errors for a full parameter vector: the adjusted sources from it, the others at `start`."""
        return errors_of(self.drive, self.start, self.sources, p_full, turns or {})

    def model(self, p_full: Array) -> list[Array]:
        """The model's TE (rad) on each record's grid rows."""
        out = []
        for t, rows in zip(self.turns, self.rows):
            te = self.drive.te(self.drive.response(self.errors_from(p_full, dict(t))))
            out.append(te[jnp.asarray(rows)])
        return out

    def measured(self, te: Sequence[Array]) -> list[Array]:
        """Each record's TE (rad) interpolated at its grid rows."""
        out = []
        for t, i, w in zip(te, self.left, self.weight):
            t = jnp.asarray(t, dtype=float)
            i, w = jnp.asarray(i), jnp.asarray(w)
            out.append((1.0 - w) * t[i] + w * t[jnp.minimum(i + 1, t.shape[0] - 1)])
        return out

    def _residual(self, y: Array, z: Sequence[Array]) -> Array:
        k = len(y) - len(self.rows)
        model = self.model(self.full(y[:k]))
        return jnp.concatenate([1e6 * (m - zr) + off for m, zr, off in zip(model, z, y[k:])])

    def solve(self, te: Sequence[Array], key: PRNGKeyArray) -> Identification:
        """Identify from the TE (rad) of each record, sampled as the records this problem was built from."""
        z = self.measured(te)
        widths = [self.widths[i] for i in self.kept]
        k = sum(widths)
        ecc = any(w == 2 for w in widths)
        n_starts = self.starts if ecc else 1
        # Start 0 at `start`; further starts turn the eccentricities' phasors by random angles.
        cols = self._columns()
        origin = jnp.asarray(self.origin)[cols]
        scale = jnp.asarray(self.scale)[cols]
        phi = TWO_PI * jax.random.uniform(key, (n_starts, len(self.kept)), dtype=float).at[0].set(0.0)
        rows, j = [], 0
        for m, w in enumerate(widths):
            if w == 2:
                x0, y0_ = origin[j], origin[j + 1]
                c, s = jnp.cos(phi[:, m]), jnp.sin(phi[:, m])
                rows += [(c * x0 - s * y0_ - x0) / scale[j], (s * x0 + c * y0_ - y0_) / scale[j + 1]]
            else:
                rows.append(jnp.zeros(n_starts))
            j += w
        offs = jnp.zeros((n_starts, len(z)))  # linear: Levenberg–Marquardt finds them in its first step
        y0 = jnp.concatenate([jnp.stack(rows, axis=1).reshape(n_starts, k), offs], axis=1)
        solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)

        def one(y):
            sol = optx.least_squares(lambda y, a: self._residual(y, a), solver, y, z, max_steps=self.max_steps, throw=False)
            # The residual and its Jacobian at the last accepted point, the solution: kept in the solver's state
            # (its linearisation), so the model is not traced again.
            info = sol.state.f_info
            return sol.value, jnp.sum(info.residual**2), info.jac.as_matrix(), sol.result, sol.stats["num_steps"]

        ys, cost, jacs, results, steps = jax.vmap(one)(y0)
        best = jnp.argmin(cost)
        y, jac = ys[best], jacs[best]
        result = RESULTS.promote(jax.tree_util.tree_map(lambda x: x[best], results))
        n, p = sum(len(zr) for zr in z), jac.shape[1]
        sigma2 = cost[best] / max(n - p, 1)
        cov_s = sigma2 * jnp.linalg.inv(jac.T @ jac)
        cov = cov_s[:k, :k] * jnp.outer(scale, scale)
        full = self.full(y[:k])
        mags, phases, mse, pse = estimates(full[cols], cov, widths)
        return Identification(
            magnitude=mags,
            phase=phases,
            magnitude_se=mse,
            phase_se=pse,
            phase_period=jnp.full(len(self.kept), TWO_PI),
            offset=y[k:] * 1e-6,
            residual_rms=jnp.sqrt(cost[best] / n) * 1e-6,
            sigma=jnp.sqrt(sigma2) * 1e-6,
            parameters=full,
            covariance=cov,
            errors=self.errors_from(full),
            result=result,
            steps=steps[best],
            labels=self.labels,
            groups=self.groups,
        )


def errors_of(drive, start: Mapping, sources: Sequence[str], p_full: Array, turns: Mapping[str, float]) -> dict:
    """`start` with the sources named in `sources` taken from `p_full` (`gearte.identification.fit.unpack`)."""
    return unpack(drive.error_sources, sources, p_full, turns, start)


def _origin(drive, start: Mapping, sources: Sequence[str]) -> np.ndarray:
    parts = []
    for name in sources:
        e = start[name]
        if isinstance(e, Eccentricity):
            m, p = np.asarray(e.magnitude).ravel(), np.asarray(e.phase).ravel()
            parts.append(np.stack([m * np.cos(p), m * np.sin(p)], axis=1).ravel())
        else:
            parts.append(np.asarray(e, dtype=np.float64).ravel())
    return np.concatenate(parts) if parts else np.zeros(0)


def _rows(rec: MeasuredRecord, grid: np.ndarray, grid_step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    theta = np.asarray(rec.theta, dtype=np.float64)
    if rec.step > grid_step * (1 + 1e-9):
        raise RecordError(
            f"{rec.source}: {rec.points_per_rev:.4g} samples per input revolution, coarser than the drive's grid "
            f"({TWO_PI / grid_step:.4g} per revolution): sample faster, or give the drive a coarser grid"
        )
    tol = 1e-9 * rec.step
    rows = np.nonzero((grid >= theta[0] - tol) & (grid <= theta[-1] + tol))[0]
    if rows.size < 2:
        raise RecordError(
            f"{rec.source}: the record spans input angles {theta[0]:.4g} … {theta[-1]:.4g} rad, which hold {rows.size} angle(s) of "
            f"the drive's grid ({grid[0]:.4g} … {grid[-1]:.4g} rad): record over the grid's input angles"
        )
    g = np.clip(grid[rows], theta[0], theta[-1])
    left = np.clip(np.searchsorted(theta, g, side="right") - 1, 0, len(theta) - 1)
    nxt = np.minimum(left + 1, len(theta) - 1)
    span = theta[nxt] - theta[left]
    weight = np.where(span > 0, (g - theta[left]) / np.where(span > 0, span, 1.0), 0.0)
    return rows, left, weight


def grid_problem(
    drive: AbstractGridDrive,
    recs: Sequence[MeasuredRecord],
    turn_list: Sequence[Mapping[str, float]],
    *,
    adjust: Sequence[str] | None,
    start: Errors | None,
    starts: int,
    max_steps: int,
) -> GridIdentificationProblem:
    """The grid drive's identification problem (records and turns already checked by `identification_problem`)."""
    specs = drive.error_sources
    sources = tuple(specs) if adjust is None else tuple(adjust)
    if isinstance(adjust, str):
        raise ValueError(f"adjust: give a list of source names, e.g. [{adjust!r}], not a string")
    bad = [s for s in sources if s not in specs]
    if bad or not sources or len(set(sources)) != len(sources):
        raise ValueError(f"adjust: name each source once, from {list(specs)}" + (f"; unknown {bad}" if bad else ""))
    sources = tuple(s for s in specs if s in sources)  # the drive's order
    given = dict(start or {})
    unknown = sorted(set(given) - set(specs))
    if unknown:
        raise ValueError(f"start: unknown sources {unknown}; use names from {list(specs)}")
    base = drive.checked({**drive.zero_errors(), **given})
    instances = [x for x in _instances(drive) if x.source in sources]
    width = [2 if x.kind == "eccentricity" else 1 for x in instances]
    starts_of = np.cumsum([0] + width)
    origin = _origin(drive, base, sources)
    grid = np.asarray(drive.input_angles(), dtype=np.float64)
    grid_step = float(np.min(np.diff(grid))) if grid.size > 1 else TWO_PI
    rows, left, weight = zip(*(_rows(r, grid, grid_step) for r in recs))
    turns = tuple(tuple(sorted((k, float(v)) for k, v in t.items())) for t in turn_list)

    jac = np.asarray(_jacobian(drive, base, sources, turns, rows, jnp.asarray(origin)))  # µrad per unit of each parameter
    if not np.all(np.isfinite(jac)):
        raise ValueError(
            f"identify: the model's TE is not differentiable at the start point (the Jacobian of {type(drive).__name__} is not finite)"
        )
    offs = np.zeros((jac.shape[0], len(recs)))
    ends = np.cumsum([0] + [len(r) for r in rows])
    for i in range(len(recs)):
        offs[ends[i] : ends[i + 1], i] = 1.0
    kept, status = select(jac, offs, starts_of)
    found = groups(instances, [()] * len(instances), jac, offs, starts_of, kept, status, len(recs), grid=True)
    p = sum(width[i] for i in kept)
    if jac.shape[0] < p + len(recs) + 1:
        raise RecordError(
            f"{recs[0].source}: the records hold {jac.shape[0]} angles of the drive's grid for {p} parameters and {len(recs)} "
            "constant(s): record over more input angles, give the drive a finer grid, or adjust fewer sources"
        )
    norms = np.linalg.norm(jac, axis=0)
    scale = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    return GridIdentificationProblem(
        drive=drive,
        start=base,
        origin=origin,
        scale=scale,
        rows=tuple(rows),
        left=tuple(left),
        weight=tuple(weight),
        turns=turns,
        sources=sources,
        instances=tuple(instances),
        kept=tuple(kept),
        groups=tuple(found),
        starts=int(starts),
        max_steps=int(max_steps),
    )


@eqx.filter_jit
def _jacobian(drive, base, sources, turns, rows, p):
    def stacked(p):
        out = []
        for t, r in zip(turns, rows):
            te = drive.te(drive.response(errors_of(drive, base, sources, p, dict(t))))
            out.append(1e6 * te[jnp.asarray(r)])
        return jnp.concatenate(out)

    return jax.jacfwd(stacked)(p)
