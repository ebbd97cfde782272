"""Assembly of measured parts: one drive re-assembled from its identified errors, or a batch by selective assembly.

**One drive** (`reassemble`): the identified phasors go to `gearte.allocate_measured`, which chooses the
turns of the named parts that minimise the exact TE metric; only a source identified on its own can
be turned (a member of a combined phasor has no phase of its own in the record).

**A batch** (`assemble_batch`): N drives are built from measured parts, each part type (a source of the
drive: sun, ring, or one per planet position) with its eccentricity phasor. Which parts go together
and at which turns decide each drive's TE; the aim is the smallest worst (and 99.73 %) TE of the batch.
This is a multi-dimensional assignment problem (NP-hard beyond two part types); gearte's heuristic:

1. start from a random matching;
2. for each part type in turn, the others held: the cost of part p in drive slot d is the drive's peak
   TE with p there at its best turn (of `candidates` equally spaced turns); solve the assignment
   (`scipy.optimize.linear_sum_assignment`) on the costs raised to the power 8 (relative to the
   largest), a smooth stand-in for the bottleneck (the worst drive); keep it if the batch's worst improves;
3. repeat for `rounds` rounds, then swap parts between the worst drive and every other drive while that
   lowers the worst;
4. turn every part of every drive to its best turn (coordinate descent over the candidate turns).

Peaks during the search are taken on a grid of 16 points per period of the fastest line over the
hyper-period; the reported figures are the drive's exact metric. Random assembly (random matching,
random turns) of the same parts is the comparison.
"""

from __future__ import annotations

import dataclasses
import operator
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PRNGKeyArray
from scipy.optimize import linear_sum_assignment

from ..core.metrics import AbstractMetric, Peak, PeakToPeak
from ..core.signal import evaluate
from ..core.units import TWO_PI
from ..core.validate import as_int
from ..drives.protocol import AbstractSinusoidalDrive, Eccentricity, zero_signal
from ..optimise.allocation_measured import MeasuredAllocation, allocate_measured
from ..studies.montecarlo import as_key
from .fit import Identification


def reassemble(
    drive: AbstractSinusoidalDrive,
    solution: Identification,
    *,
    adjust: Mapping[str, float | None],
    key: int | PRNGKeyArray,
    metric: AbstractMetric = Peak(),
    starts: int = 16,
    throw: bool = True,
) -> MeasuredAllocation:
    """The turns of the `adjust` sources (source → step between allowed positions, rad, or None) that minimise the
    TE of the drive with its identified errors (`gearte.allocate_measured`); `te_before` is the identified TE as
    assembled, `te` the predicted TE after re-assembly. `key`: seed or key of the random starts (required, as PRNG keys
    always are). `throw`: raise if the best start did not converge (else check
    the result's `result`), as for `gearte.allocate_measured`."""
    combined = {m.split("[")[0]: g for g in solution.groups if g.kind == "combined" for m in g.members}
    for name in adjust:
        if name in combined:
            g = combined[name]
            others = [m for m in g.members if m.split("[")[0] != name]
            what = f"shares its line with {', '.join(others)}" if others else f"has its instances {', '.join(g.members)} on one line"
            raise ValueError(
                f"adjust: {name!r} {what}; the record gives only their combined phasor, so turning {name} alone cannot be "
                f"predicted. {g.advice}"
            )
    return allocate_measured(drive, solution.errors, adjust=adjust, key=key, metric=metric, starts=starts, throw=throw)


@dataclasses.dataclass(frozen=True)
class BatchAssembly:
    """Result of `assemble_batch`: `assignment` (source → part indices, shape (drives, instances)), `turns`
    (source → rad, same shape), the drives' exact metric (`te`, rad), and the same for the random assemblies
    (`random_worst`: the worst of each random batch; `random_te`: every drive of them), `random_matched_te` (the
    start's random matching with optimised turns), and the batch figures (`worst`, `p9973`)."""

    assignment: dict[str, np.ndarray]
    turns: dict[str, np.ndarray]
    te: np.ndarray
    random_te: np.ndarray
    random_worst: np.ndarray
    random_matched_te: np.ndarray

    @property
    def worst(self) -> float:
        return float(np.max(self.te))

    @property
    def p9973(self) -> float:
        return float(np.percentile(self.te, 99.73))


def _grid(drive) -> np.ndarray:
    sig = zero_signal(drive)
    revs = float(sig.hyper_period_revs)
    n = 16 * max(sig.orders) if sig.orders else 16
    return np.linspace(0.0, TWO_PI * revs, n, endpoint=False)


class _Batch(eqx.Module):
    """What every unit of a batch shares, for the jitted functions below: the drive, the fixed sources' errors and the
    measured parts of each type (name, value pairs in the order given), and how many candidate turns each part
    tries. The functions are traced once per drive structure, shapes and `candidates`; the values are data."""

    drive: AbstractSinusoidalDrive
    fixed: tuple[tuple[str, Any], ...]
    parts: tuple[tuple[str, Eccentricity], ...]
    candidates: int = eqx.field(static=True)

    @property
    def grid(self) -> Array:
        """The search's grid of input angles (rad): a constant of the traced program (it depends on the drive's structure only)."""
        return jnp.asarray(_grid(self.drive))

    @property
    def cand(self) -> Array:
        """The candidate turns (rad), equally spaced: a constant of the traced program."""
        return jnp.asarray(TWO_PI * np.arange(self.candidates) / self.candidates)


def _unit_errors(batch: _Batch, idx: Mapping[str, Array], tr: Mapping[str, Array]) -> dict:
    """One unit's errors: the fixed sources, then each part type's parts `idx` turned by `tr` (rad)."""
    errs = dict(batch.fixed)
    for s, e in batch.parts:
        errs[s] = Eccentricity(e.magnitude[idx[s]], e.phase[idx[s]] + tr[s])
    return errs


def _unit_peak(batch: _Batch, idx: Mapping[str, Array], tr: Mapping[str, Array]) -> Array:
    """One unit's peak |TE| on the search grid (rad)."""
    return jnp.max(jnp.abs(evaluate(batch.drive.signal(_unit_errors(batch, idx, tr)), batch.grid)))


@eqx.filter_jit
def _batch_peak(batch: _Batch, idx: dict[str, Array], tr: dict[str, Array]) -> Array:
    """Every unit's peak on the search grid: `idx`, `tr` are source → (units, instances) part indices and turns."""
    return jax.vmap(lambda i, t: _unit_peak(batch, i, t))(idx, tr)


@eqx.filter_jit
def _best_turn(batch: _Batch, idx: dict[str, Array], tr: dict[str, Array], s: str, slot: Array) -> tuple[Array, Array]:
    """Every unit: the best of the candidate turns of its part of type `s` in the slot `slot` (one-hot over the type's
    instances), the others held; (peak, turn) per unit."""

    def at(t):
        tr2 = dict(tr)
        tr2[s] = tr[s] * (1 - slot) + t * slot
        return jax.vmap(lambda i, t_: _unit_peak(batch, i, t_))(idx, tr2)

    vals = jax.vmap(at)(batch.cand)  # (candidates, units)
    k = jnp.argmin(vals, axis=0)
    return vals[k, jnp.arange(vals.shape[1])], batch.cand[k]


@eqx.filter_jit
def _row_costs(
    batch: _Batch, idx: dict[str, Array], tr: dict[str, Array], slot: dict[str, Array], d: Array, part_ids: Array
) -> tuple[Array, Array]:
    """Unit `d` with each part `part_ids` of the type being assigned in the slot marked by `slot` (source → boolean over
    its instances: true at that one slot of that type, false for every other type), at each candidate turn, the others
    held: (its best peak, that turn) per part. The type is data, not a static argument, so one trace serves every type
    of the same count, in every round."""

    def one(p, t):
        i2 = {k: jnp.where(slot[k], p, v[d]) for k, v in idx.items()}
        t2 = {k: jnp.where(slot[k], t, v[d]) for k, v in tr.items()}
        return _unit_peak(batch, i2, t2)

    vals = jax.vmap(lambda p: jax.vmap(lambda t: one(p, t))(batch.cand))(part_ids)
    return jnp.min(vals, axis=1), batch.cand[jnp.argmin(vals, axis=1)]


@eqx.filter_jit
def _batch_metric(batch: _Batch, metric: AbstractMetric, idx: dict[str, Array], tr: dict[str, Array]) -> Array:
    """Every unit's exact metric (rad)."""
    return jax.vmap(lambda i, t: metric(batch.drive, batch.drive.signal(_unit_errors(batch, i, t))))(idx, tr)


def assemble_batch(
    drive: AbstractSinusoidalDrive,
    parts: Mapping[str, Eccentricity],
    *,
    fixed: Mapping[str, Eccentricity] | None = None,
    key: int | PRNGKeyArray,
    metric: AbstractMetric = Peak(),
    rounds: int = 3,
    candidates: int = 12,
    random_batches: int = 100,
) -> BatchAssembly:
    """Selective assembly of a batch of measured parts (see the module notes).

    **Arguments:**

    - `drive`: the drive every unit is.
    - `parts`: source name → the measured parts of that type, an `Eccentricity` of shape (N·count,) for a source
      with `count` instances per drive (e.g. 50 suns, 150 planets for three planets, 50 rings: N = 50 drives).
    - `fixed`: the other sources' errors, the same in every drive (default zero).
    - `key`: seed or key (random start, random turns of the comparison; required, as PRNG keys always are).
    - `metric`: `gearte.Peak()` or `gearte.PeakToPeak()` for the reported figures.
    - `rounds`, `candidates`: assignment rounds; turns tried per part.
    - `random_batches`: random assemblies of the same parts for the comparison.
    """
    specs = drive.error_sources
    try:
        batches = operator.index(random_batches)  # Python's and NumPy's integers
    except TypeError:
        batches = 0
    if isinstance(random_batches, bool) or batches < 1:
        raise ValueError(f"random_batches: the comparison needs at least one random assembly (a whole number ≥ 1), got {random_batches!r}")
    rounds = as_int("rounds", rounds, minimum=0)  # 0: the start assignment, then the swaps
    candidates = as_int("candidates", candidates, minimum=1)
    if type(metric) not in (Peak, PeakToPeak):
        raise ValueError(f"metric: gearte.Peak() or gearte.PeakToPeak() (an instance), got {metric!r}")
    if not parts:
        raise ValueError("parts: give at least one part type (source name → Eccentricity of the measured parts)")
    counts, n_drives = {}, None
    for s, e in parts.items():
        if s not in specs or specs[s].kind != "eccentricity":
            raise ValueError(f"parts: {s!r} is not an eccentricity source of this drive; use one of {sorted(specs)}")
        c = specs[s].count
        m = np.asarray(e.magnitude).reshape(-1)
        if len(m) % c:
            raise ValueError(f"parts[{s!r}]: {len(m)} parts do not fill {c} positions per drive")
        if n_drives is not None and len(m) // c != n_drives:
            raise ValueError(f"parts: {s!r} makes {len(m) // c} drives but the other part types make {n_drives}")
        n_drives, counts[s] = len(m) // c, c
    assert n_drives is not None
    parts = {
        s: Eccentricity(jnp.asarray(e.magnitude, dtype=float).reshape(-1), jnp.asarray(e.phase, dtype=float).reshape(-1))
        for s, e in parts.items()
    }
    base = drive.zero_errors()
    # A deviation given as a number becomes an array (as the drive takes it), so that its value is data, not a constant.
    base.update({k: v if isinstance(v, Eccentricity) else jnp.asarray(v, dtype=float) for k, v in (fixed or {}).items()})
    names = list(parts)
    batch = _Batch(
        drive=drive,
        fixed=tuple((k, v) for k, v in base.items() if k not in parts),
        parts=tuple((s, parts[s]) for s in names),
        candidates=int(candidates),
    )

    rng = np.random.default_rng(int(np.asarray(jax.random.randint(as_key(key), (), 0, 2**31 - 1))))
    assign = {s: rng.permutation(n_drives * counts[s]).reshape(n_drives, counts[s]) for s in names}
    turns = {s: np.zeros((n_drives, counts[s])) for s in names}

    def optimise_turns(assign, turns, sweeps=2):
        idx = {s: jnp.asarray(assign[s]) for s in names}
        tr = {s: jnp.asarray(turns[s]) for s in names}
        for _ in range(sweeps):
            for s in names:
                for j in range(counts[s]):
                    oh = jnp.zeros(counts[s]).at[j].set(1.0)
                    _, t = _best_turn(batch, idx, tr, s, oh)
                    tr[s] = tr[s].at[:, j].set(t)
        return {s: np.array(tr[s]) for s in names}, np.array(_batch_peak(batch, idx, tr))

    turns, vals = optimise_turns(assign, turns, sweeps=1)
    # Copies: `_swap_worst` changes the arrays of `assign` and `turns` in place, and the matched baseline below starts
    # from the assignment and turns as they were here.
    start_assign, start_turns = {s: a.copy() for s, a in assign.items()}, {s: t.copy() for s, t in turns.items()}
    worst = float(vals.max())
    for _ in range(rounds):
        for s in names:
            cand_assign, cand_turns = _assign_type(batch, names, assign, turns, s)
            t2, v2 = optimise_turns(cand_assign, cand_turns, sweeps=1)
            if v2.max() < worst:
                assign, turns, worst, vals = cand_assign, t2, float(v2.max()), v2
    assign, turns, vals = _swap_worst(assign, turns, vals, names, counts, optimise_turns)
    turns, vals = optimise_turns(assign, turns, sweeps=2)

    def exact_b(a, t):
        return np.asarray(_batch_metric(batch, metric, {s: jnp.asarray(a[s]) for s in names}, {s: jnp.asarray(t[s]) for s in names}))

    te = exact_b(assign, turns)
    matched_turns = optimise_turns(start_assign, start_turns, sweeps=2)[0]
    matched = exact_b(start_assign, matched_turns)
    rand = []
    for _ in range(random_batches):
        ra = {s: rng.permutation(n_drives * counts[s]).reshape(n_drives, counts[s]) for s in names}
        rt = {s: rng.uniform(0.0, TWO_PI, (n_drives, counts[s])) for s in names}
        rand.append(exact_b(ra, rt))
    rand = np.stack(rand)
    return BatchAssembly(assignment=assign, turns=turns, te=te, random_te=rand, random_worst=rand.max(axis=1), random_matched_te=matched)


def _assign_type(batch: _Batch, names: list[str], assign: dict, turns: dict, s: str) -> tuple[dict, dict]:
    """One assignment step for part type `s`: costs of every part in every (drive, slot), others held."""
    n_drives, c = assign[s].shape
    n_parts = n_drives * c
    idx = {k: jnp.asarray(assign[k]) for k in names}
    tr = {k: jnp.asarray(turns[k]) for k in names}
    part_ids = jnp.arange(n_parts)

    def row_costs(d, j):
        slot = {k: jnp.asarray((np.arange(assign[k].shape[1]) == j) & (k == s)) for k in names}
        return _row_costs(batch, idx, tr, slot, jnp.asarray(d), part_ids)

    costs = np.zeros((n_parts, n_parts))
    best_t = np.zeros((n_parts, n_parts))
    for d in range(n_drives):
        for j in range(c):
            v, t = row_costs(d, j)
            costs[d * c + j], best_t[d * c + j] = np.asarray(v), np.asarray(t)
    scaled = (costs / costs.max()) ** 8 if costs.max() > 0 else costs
    rows, cols = linear_sum_assignment(scaled)
    new_a = {k: v.copy() for k, v in assign.items()}
    new_t = {k: v.copy() for k, v in turns.items()}
    new_a[s] = cols[np.argsort(rows)].reshape(n_drives, c)
    new_t[s] = best_t[rows, cols][np.argsort(rows)].reshape(n_drives, c)
    return new_a, new_t


def _swap_worst(assign, turns, vals, names, counts, optimise_turns, max_passes: int = 200):
    """Swap parts between the worst drive and each other drive while that lowers the batch's worst
    (only the two drives concerned are re-evaluated, each at its best turns)."""
    vals = vals.copy()
    for _ in range(max_passes):
        w = int(np.argmax(vals))
        improved = False
        for s in names:
            for j in range(counts[s]):
                for d in range(len(vals)):
                    if d == w:
                        continue
                    sub_a = {k: v[[w, d]].copy() for k, v in assign.items()}
                    sub_a[s][0, j], sub_a[s][1, j] = assign[s][d, j], assign[s][w, j]
                    t2, v2 = optimise_turns(sub_a, {k: v[[w, d]] for k, v in turns.items()}, sweeps=1)
                    if v2.max() < vals[w] * (1 - 1e-12):
                        for k in names:
                            assign[k][[w, d]] = sub_a[k]
                            turns[k][[w, d]] = t2[k]
                        vals[[w, d]] = v2
                        improved = True
                        break
                if improved:
                    break
            if improved:
                break
        if not improved:
            break
    return assign, turns, vals


def part_turn_steps(drive) -> dict[str, float | None]:
    """Any-angle turns for every eccentricity source (a helper for `reassemble`'s `adjust`)."""
    return {n: None for n, s in drive.error_sources.items() if s.kind == "eccentricity"}
