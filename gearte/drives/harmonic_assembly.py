"""Harmonic drive: choose the assembly phases of one unit whose errors are known (measured parts).

Sources of one class share a frequency and can be turned against each other at assembly
(e.g. the CS mounting orientation against the flexible-bearing run-out); the CS and FS
classes differ by 2ω_o, so their relative phase turns through 2π every half output
revolution (the beat, Liu sec. 3) and no choice cancels them for all time.

The optimiser works on this one drive's own model (optimistix's BFGS on a smooth surrogate,
exact re-evaluation), not on an error model, so it lives beside the drive and is used by
its `study_outputs`; it returns a solution with a `gearte.RESULTS` code, as every gearte solve.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, PRNGKeyArray

from ..core.grid import _basis, _grid_values, grid_size
from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.signal import to_signal
from ..core.solution import RESULTS, check
from ..core.validate import as_int, as_key
from .harmonic_estimate import class_phasors, source_phasors
from .protocol import Eccentricity

if TYPE_CHECKING:
    from .harmonic import HarmonicDrive


class AssemblyResult(eqx.Module):
    """Assembly phases chosen for one unit (`optimise_assembly`).

    **Fields:**

    - `errors`: the unit's errors with the adjusted phases.
    - `turns`: change of each adjustable source's angle Θ, rad (in (−π, π]).
    - `before`, `after`: peak-to-peak TE over one output revolution, rad.
    - `class_before`, `class_after`: |resultant| of each class (each line: a tooth-mesh harmonic
      above the first is its own, `class_phasors`), rad.
    - `class_least`: the least |resultant| each class can reach by turning its adjustable
      sources (closed form: a polygon closes only if no side exceeds the sum of the others).
    - `result`: the solve's `gearte.RESULTS` code: that of the best start, or
      `some_starts_failed` when it succeeded but other starts did not converge.
    - `starts`, `converged`: optimiser runs (random starts + the unit as assembled) and how
      many of them reported success.
    """

    errors: dict[str, Eccentricity]
    turns: dict[str, float]
    before: float
    after: float
    class_before: dict[str, float]
    class_after: dict[str, float]
    class_least: dict[str, float]
    result: RESULTS
    starts: int = eqx.field(static=True)
    converged: int = eqx.field(static=True)


def _least_resultant(fixed: complex, adjustable: Sequence[float]) -> float:
    sides = [abs(fixed)] + [abs(a) for a in adjustable]
    return max(0.0, 2.0 * max(sides) - sum(sides))


def _starts_result(results, best: int) -> tuple[int, Any]:
    ok = np.asarray(results == optx.RESULTS.successful)
    if not bool(ok[best]):
        return int(ok.sum()), RESULTS.promote(jax.tree.map(lambda v: v[best], results))
    return int(ok.sum()), RESULTS.successful if ok.all() else RESULTS.some_starts_failed


def _turned(base: Mapping[str, Eccentricity], adjustable: Sequence[str], y) -> dict[str, Eccentricity]:
    """`base` with the phase of each adjustable source advanced by its entry of `y`."""
    out = dict(base)
    for j, a in enumerate(adjustable):
        out[a] = Eccentricity(base[a].magnitude, base[a].phase + y[j])
    return out


@kept_jit
def _solve_all(
    drive: HarmonicDrive,
    base: dict[str, Eccentricity],
    adjustable: tuple[str, ...],
    cos_b: np.ndarray,
    sin_b: np.ndarray,
    width: Array,
    atol: Array,
    y0s: Array,
    max_steps: int,
) -> tuple[Array, Any, Array, Array]:
    """BFGS on the smooth peak-to-peak from every start in `y0s`, then the exact peak-to-peak at every end and at
    the unit as assembled (`optimise_assembly`). Module level, with the unit's values as arguments: a second unit
    of the same drive and shapes reuses the compiled solve (`adjustable` and `max_steps` are static)."""

    def smooth_p2p(y, args):
        del args
        sig = to_signal(drive.components(_turned(base, adjustable, y), tooth=False))
        f = _grid_values(sig, cos_b, sin_b) / width
        return width * (jax.nn.logsumexp(f) + jax.nn.logsumexp(-f))

    def exact_p2p(y):
        e = drive.extrema(drive.signal(_turned(base, adjustable, y)))
        return e.max - e.min

    solver = optx.BFGS(rtol=1e-9, atol=atol)  # pyright: ignore[reportArgumentType]  (a traced tolerance: a leaf, not static)

    def one(y):
        sol = optx.minimise(smooth_p2p, solver, y, max_steps=max_steps, throw=False)
        return sol.value, sol.result

    ys, results = jax.vmap(one)(y0s)
    # The exact peak-to-peak at every end and as assembled, in one `lax.map`: under `vmap` (twice, as before) the
    # two-scale extrema search was batched twice and half the solve's tracing went there (first call 14-15 s,
    # now 9 s; the values are identical).
    exact = jax.lax.map(exact_p2p, jnp.concatenate([ys, y0s[:1]]))
    return ys, results, exact[:-1], exact[-1:]


def check_adjustable(drive: HarmonicDrive, adjustable: Sequence[str]) -> list[str]:
    """The adjustable sources as a list, checked: sources of the drive, unique, none of the tooth class."""
    names = [s.name for s in drive.sources]
    if isinstance(adjustable, str) or not isinstance(adjustable, Sequence):
        raise ValueError(f"adjustable: a list of source names, e.g. [{names[0]!r}]; got {adjustable!r}")
    adjustable = list(adjustable)
    if not adjustable:
        raise ValueError("adjustable: name at least one source whose phase can be set at assembly")
    unknown = [a for a in adjustable if a not in names]
    if unknown:
        raise ValueError(f"adjustable: {unknown} are not sources of this drive; use some of {names}")
    if len(set(adjustable)) != len(adjustable):
        raise ValueError(f"adjustable: names repeated in {adjustable}")
    by_name = dict(zip(names, drive.sources))
    tooth = [a for a in adjustable if by_name[a].source_class == "tooth"]
    if tooth:
        raise ValueError(f"adjustable: {tooth} are tooth-to-tooth sources, whose phase is not set at assembly")
    return adjustable


def optimise_assembly(
    drive: HarmonicDrive,
    errors: Mapping[str, Eccentricity],
    *,
    adjustable: Sequence[str],
    starts: int = 32,
    key: int | PRNGKeyArray,
    max_steps: int = 256,
    throw: bool = True,
) -> AssemblyResult:
    """Choose the phases of the `adjustable` sources at assembly to minimise the per-output-revolution peak-to-peak TE.

    The CS and FS classes beat (see the module notes), so the objective is the peak-to-peak
    over the whole hyper-period, never over a shorter stretch. It is minimised with
    optimistix's BFGS on a smooth log-sum-exp version of it (`gearte.smooth_peak`'s idea
    applied to max − min, on the hyper-period grid of the non-tooth classes — the tooth class
    adds the same 2b to every assembly, see `gearte.extrema_two_scale`), from `starts` random
    starting phases plus the unit as assembled; every result is then re-evaluated exactly
    and the best kept (never worse than as assembled).

    **Arguments:**

    - `drive`: the `HarmonicDrive`.
    - `errors`: the unit's errors (magnitudes µm, phases rad).
    - `adjustable`: names of the sources whose angle Θ can be chosen (not tooth-class ones).
    - `starts`: random starting points.
    - `key`: a seed (an integer ≥ 0) or a `jax.random.key` for the random starting points (required, as PRNG keys always
      are).
    - `max_steps`: BFGS steps per start.
    - `throw`: raise if the best start did not converge (else check `result`); a solve whose
      best start converged but some others did not is reported as `some_starts_failed`, not raised.

    **Returns:** an `AssemblyResult`.
    """
    require_x64()
    adjustable = check_adjustable(drive, adjustable)
    starts = as_int("starts", starts, minimum=1)
    max_steps = as_int("max_steps", max_steps, minimum=1)
    rng = as_key(key)
    base = drive.checked(errors)
    comp0 = drive.components(base, tooth=False)
    sig0 = to_signal(comp0)
    m = grid_size(sig0.orders, 16)
    cos_b, sin_b = _basis(sig0.orders, m)
    scale = float(jnp.sum(comp0.amplitude * comp0.gain)) or 1.0
    width = 1e-3 * scale

    y0 = jax.random.uniform(rng, (starts, len(adjustable)), minval=0.0, maxval=2 * math.pi)
    y0 = jnp.concatenate([jnp.zeros((1, len(adjustable))), y0], axis=0)
    # The unit's scale enters as arrays (the smoothing width and the solver's atol), so that other units of the
    # same drive and shapes reuse the compiled solve.
    ys, results, vals, before = _solve_all(
        drive, base, tuple(adjustable), cos_b, sin_b, jnp.asarray(width), jnp.asarray(1e-12 * scale), y0, max_steps
    )
    vals = np.asarray(vals)
    best = int(np.argmin(vals))
    converged, result = _starts_result(results, best)
    before = float(before[0])
    if vals[best] >= before:
        y_best, after = np.zeros(len(adjustable)), before
    else:
        y_best, after = np.asarray(ys[best]), float(vals[best])
    final = _turned(base, adjustable, jnp.asarray(y_best))
    turns = {a: float((y_best[j] + math.pi) % (2 * math.pi) - math.pi) for j, a in enumerate(adjustable)}
    # Closed-form least resultant per line (fixed sources as one phasor, adjustable ones free).
    phasors = source_phasors(drive, base)
    least = {}
    for c in class_phasors(drive, base):
        fixed = sum((p for n, (k, p) in phasors.items() if k == c and n not in adjustable), 0j)
        adj = [abs(p) for n, (k, p) in phasors.items() if k == c and n in adjustable]
        least[c] = _least_resultant(fixed, adj)
    check(result, throw=throw and not bool(result == RESULTS.some_starts_failed), what="optimise_assembly")
    return AssemblyResult(
        errors=final,
        turns=turns,
        before=before,
        after=after,
        class_before={c: abs(v) for c, v in class_phasors(drive, base).items()},
        class_after={c: abs(v) for c, v in class_phasors(drive, final).items()},
        class_least=least,
        result=result,
        starts=int(y0.shape[0]),
        converged=converged,
    )
