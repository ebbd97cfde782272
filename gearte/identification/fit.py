"""Identification of a drive's errors from measured TE records: least squares on the model itself.

Every error source instance (a scalar source, or one planet of a per-planet source) is a parameter:
an eccentricity as its Cartesian phasor (x, y) = e (cos φ, sin φ), µm, a signed deviation as its value;
each record adds its own constant (an encoder's zero is arbitrary). The residual, model TE − measured
TE on the record's input angles, is minimised by Levenberg–Marquardt (`optimistix.least_squares`),
differentiating through the drive's model (`AbstractSinusoidalDrive.signal`), from a few starts, one after another (`jax.lax.map`).
A grid drive (`AbstractGridDrive`, the cycloid-pin reducer) is identified on its own grid of input angles by
`gearte.identification.fit_grid`, with the same result (`identify(..., adjust=, start=)`).

**Identifiability.** One record shows each line of the TE once: sources that act at the same
frequency (and in the same way) add up to one phasor, and no record of this assembly can tell
them apart. gearte finds them from the model's Jacobian at a random point, column by column in the
drive's source order: an instance whose columns lie in the span of those before it is *aliased*
(it joins their group and is held at zero; the group's first instance carries the *combined phasor*,
the single error of that instance that gives the same TE), an instance with zero columns is *unseen*
(it does not reach the TE, e.g. planets 2… under single-path coupling), and one that is a constant is
lost in the record's zero. Re-assembling with one member of a group turned by a known angle and
recording again changes that member's column: `identify` takes several records with their `turns`,
and each further record with an independent turn separates one more member.

**Uncertainty.** With σ² = |r|²/(n − p) from the residual and J the Jacobian at the solution, the
covariance of the parameters is σ² (JᵀJ)⁻¹; magnitudes and phases take theirs by the delta method,
and their 95 % intervals are ±1.96 standard errors (normal, as n ≫ p). Sources whose TE repeats
when their phase turns by 2π/k (the double-wave classes of a harmonic drive, k = 2) are known
modulo 2π/k only: `phase_period`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float, PRNGKeyArray

from ..core.precision import require_x64
from ..core.solution import RESULTS, check
from ..core.units import TWO_PI
from ..core.validate import as_int, check_array_values
from ..drives.protocol import AbstractGridDrive, AbstractSinusoidalDrive, Eccentricity, Errors, zero_signal
from ..studies.montecarlo import as_key
from .identifiability import Group, Instance, groups, period, select
from .records import MeasuredRecord, RecordError

if TYPE_CHECKING:
    from .fit_grid import GridIdentificationProblem

Z95 = 1.959963984540054  # two-sided 95 % point of the normal law


class IdentificationProblem(eqx.Module):
    """What `identify` solves: the drive, the records' input angles and turns, and which instances are identified.
    Build it once with `identification_problem` and call `solve` for many records on the same grid (e.g. under `vmap`)."""

    drive: AbstractSinusoidalDrive
    r_factors: tuple[np.ndarray, ...]
    q_factors: tuple[np.ndarray, ...]
    turns: tuple[tuple[tuple[str, float], ...], ...] = eqx.field(static=True)
    instances: tuple[Instance, ...] = eqx.field(static=True)
    kept: tuple[int, ...] = eqx.field(static=True)
    groups: tuple[Group, ...] = eqx.field(static=True)
    phase_period: tuple[float, ...] = eqx.field(static=True)
    frequencies: tuple[tuple[Fraction, ...], ...] = eqx.field(static=True)
    scale: tuple[float, ...] = eqx.field(static=True)
    starts: int = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)

    @property
    def labels(self) -> tuple[str, ...]:
        """Labels of the identified instances (the group representatives and the separable sources)."""
        return tuple(self.instances[i].label for i in self.kept)

    def _full(self, p: Array) -> Array:
        """Full parameter vector (every instance; aliased and unseen ones at zero) from the identified ones."""
        width = [2 if inst.kind == "eccentricity" else 1 for inst in self.instances]
        parts, j = [], 0
        for i, w in enumerate(width):
            if i in self.kept:
                parts.append(p[j : j + w])
                j += w
            else:
                parts.append(jnp.zeros(w))
        return jnp.concatenate(parts)

    def errors_from(self, p_full: Array, turns: Mapping[str, float] | None = None) -> dict:
        """The drive's errors for a full parameter vector (µm, rad), with sources turned by `turns`."""
        return errors_from(self.drive, self.instances, p_full, turns or {})

    def coefficients(self, p_full: Array) -> list[Array]:
        """The TE signal's coefficients (offset, cosines, sines; rad) in each record's assembly."""
        return [signal_coefficients(self.drive, self.errors_from(p_full, dict(t))) for t in self.turns]

    def _residual(self, y: Array, z: Sequence[Array]) -> Array:
        # Jitted: the solve, the residual at its solution and its Jacobian trace it once.
        return _residual_jit(self, y, list(z))

    def _residual_body(self, y: Array, z: Sequence[Array]) -> Array:
        # |B c − te|² = |R c − Qᵀte|² + |te − Q Qᵀte|² with B = QR the record's basis [1, cos kθ, sin kθ]:
        # the model's residual on the record, less a constant; in µrad.
        k = len(y) - len(self.r_factors)
        full = self._full(y[:k])
        out = []
        for c, r, zr, off in zip(self.coefficients(full), self.r_factors, z, y[k:]):
            out.append(1e6 * (jnp.asarray(r) @ c - zr) + off * jnp.asarray(r)[:, 0])
        return jnp.concatenate(out)

    def solve(self, te: Sequence[Array], key: PRNGKeyArray) -> Identification:
        """Identify from the TE (rad) of each record, on this problem's grids (jit- and vmap-friendly)."""
        te = [jnp.asarray(t, dtype=float) for t in te]
        z = [jnp.asarray(q).T @ t for q, t in zip(self.q_factors, te)]
        rss_perp = sum(1e12 * (jnp.sum(t**2) - jnp.sum(zr**2)) for t, zr in zip(te, z))
        widths = [2 if self.instances[i].kind == "eccentricity" else 1 for i in self.kept]
        k = sum(widths)
        phi = TWO_PI * jax.random.uniform(key, (self.starts, len(self.kept)), dtype=float)
        cols = []
        for j, (i, w) in enumerate(zip(self.kept, widths)):
            s = self.scale[i]
            cols += [s * jnp.cos(phi[:, j]), s * jnp.sin(phi[:, j])] if w == 2 else [jnp.zeros(self.starts)]
        offs = jnp.stack([jnp.full(self.starts, 1e6 * jnp.mean(t)) for t in te], axis=1)
        y0 = jnp.concatenate([jnp.stack(cols, axis=1).reshape(self.starts, k), offs], axis=1)
        solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10)

        def one(y):
            sol = optx.least_squares(lambda y, a: self._residual(y, a), solver, y, z, max_steps=self.max_steps, throw=False)
            r = self._residual(sol.value, z)
            return sol.value, jnp.sum(r**2) + rss_perp, sol.result, sol.stats["num_steps"]

        # One start after another, not under `jax.vmap`: batching optimistix's while loop batches its body (the
        # model and its Jacobian) several times over while finding which of the loop's state is batched, and
        # tracing the solve took 3-4 s instead of 1 s (the first `identify` of a planetary drive: 11 s -> 6-7 s).
        # The starts are few and each converges in a few steps, so the solve itself takes as long as before.
        ys, cost, results, steps = jax.lax.map(one, y0)
        best = jnp.argmin(cost)
        y = ys[best]
        result = RESULTS.promote(jax.tree_util.tree_map(lambda x: x[best], results))
        jac = jax.jacfwd(lambda y_: self._residual(y_, z))(y)
        n, p = sum(len(t) for t in te), jac.shape[1]
        sigma2 = cost[best] / max(n - p, 1)
        cov = sigma2 * jnp.linalg.inv(jac.T @ jac)
        mags, phases, mse, pse = estimates(y, cov, widths)
        period = jnp.asarray([self.phase_period[i] for i in self.kept])
        full = self._full(y[:k])
        return Identification(
            magnitude=mags,
            phase=jnp.mod(phases, period),
            magnitude_se=mse,
            phase_se=pse,
            phase_period=period,
            offset=y[k:] * 1e-6,
            residual_rms=jnp.sqrt(cost[best] / n) * 1e-6,
            sigma=jnp.sqrt(sigma2) * 1e-6,
            parameters=full,
            covariance=cov[:k, :k],
            errors=self.errors_from(full),
            result=result,
            steps=steps[best],
            labels=self.labels,
            groups=self.groups,
        )


class Identification(eqx.Module):
    """Result of `identify`.

    Per identified instance (`labels`; a group's representative carries the group's combined phasor):
    `magnitude` (µm; a signed value for a deviation source), `phase` (rad, modulo `phase_period`; NaN for a
    deviation), their standard errors `magnitude_se`, `phase_se`, and `interval95` (±1.96 se).
    `errors`: the identified errors as the drive takes them (aliased and unseen instances at zero);
    `offset`: each record's constant (rad); `sigma`: the residual's standard deviation (rad);
    `residual_rms`; `covariance` of the Cartesian parameters (µm²); `groups`: the identifiability report;
    `result`: the solve's `RESULTS` code; `steps`: Levenberg–Marquardt steps of the best start.
    """

    magnitude: Float[Array, " k"]
    phase: Float[Array, " k"]
    magnitude_se: Float[Array, " k"]
    phase_se: Float[Array, " k"]
    phase_period: Float[Array, " k"]
    offset: Float[Array, " r"]
    residual_rms: Float[Array, ""]
    sigma: Float[Array, ""]
    parameters: Array
    covariance: Array
    errors: dict
    result: RESULTS
    steps: Array
    labels: tuple[str, ...] = eqx.field(static=True)
    groups: tuple[Group, ...] = eqx.field(static=True)

    def interval95(self) -> dict[str, tuple[tuple[float, float], tuple[float, float]]]:
        """label → ((magnitude low, high) µm, (phase low, high) rad), the 95 % intervals."""
        m, p = np.asarray(self.magnitude), np.asarray(self.phase)
        ms, ps = np.asarray(self.magnitude_se), np.asarray(self.phase_se)
        return {
            lab: ((m[i] - Z95 * ms[i], m[i] + Z95 * ms[i]), (p[i] - Z95 * ps[i], p[i] + Z95 * ps[i])) for i, lab in enumerate(self.labels)
        }


def estimates(y: Array, cov: Array, widths: Sequence[int]) -> tuple[Array, Array, Array, Array]:
    """Magnitudes, phases (rad) and their standard errors (delta method) of the parameters `y` (Cartesian phasors
    for width 2, signed values for width 1) with covariance `cov`; a deviation's phase and its error are NaN."""
    mags, phases, mse, pse, j = [], [], [], [], 0
    for w in widths:
        if w == 2:
            x_, y_ = y[j], y[j + 1]
            m = jnp.hypot(x_, y_)
            g_m = jnp.stack([x_ / m, y_ / m])
            g_p = jnp.stack([-y_ / m**2, x_ / m**2])
            c = cov[j : j + 2, j : j + 2]
            mags.append(m)
            phases.append(jnp.mod(jnp.arctan2(y_, x_), TWO_PI))
            mse.append(jnp.sqrt(g_m @ c @ g_m))
            pse.append(jnp.sqrt(g_p @ c @ g_p))
        else:
            mags.append(y[j])
            phases.append(jnp.asarray(jnp.nan))
            mse.append(jnp.sqrt(cov[j, j]))
            pse.append(jnp.asarray(jnp.nan))
        j += w
    return jnp.stack(mags), jnp.stack(phases), jnp.stack(mse), jnp.stack(pse)


def errors_from(drive, instances: Sequence[Instance], p_full: Array, turns: Mapping[str, float]) -> dict:
    """The drive's errors from a full parameter vector (see `IdentificationProblem`)."""
    del instances  # every source of the drive, in its order
    return unpack(drive.error_sources, drive.error_sources, p_full, turns)


def unpack(specs: Mapping, names: Sequence[str], p_full: Array, turns: Mapping[str, float], start: Mapping | None = None) -> dict:
    """`start` (default: none) with the sources `names` taken from `p_full` in that order: an eccentricity from its
    Cartesian phasors (x, y) per instance, its phase turned by ``turns[name]``; a deviation from its values."""
    out, j = dict(start or {}), 0
    for name in names:
        spec = specs[name]
        if spec.kind == "eccentricity":
            xs = p_full[j : j + 2 * spec.count : 2]
            ys = p_full[j + 1 : j + 2 * spec.count : 2]
            j += 2 * spec.count
            r2 = xs**2 + ys**2
            ok = r2 > 0
            mag = jnp.where(ok, jnp.sqrt(jnp.where(ok, r2, 1.0)), 0.0)
            ph = jnp.arctan2(jnp.where(ok, ys, 0.0), jnp.where(ok, xs, 1.0)) + turns.get(name, 0.0)
            out[name] = Eccentricity(mag.reshape(spec.shape), ph.reshape(spec.shape))
        else:
            out[name] = p_full[j : j + spec.count].reshape(spec.shape)
            j += spec.count
    return out


def signal_coefficients(drive, errors) -> Array:
    """The drive's TE signal for these errors as one vector: offset, cosine and sine coefficients (rad)."""
    sig = drive.signal(errors)
    return jnp.concatenate([sig.offset.reshape(1), sig.cos_coef, sig.sin_coef])


def _instances(drive) -> list[Instance]:
    out = []
    for name, spec in drive.error_sources.items():
        for i in range(spec.count):
            out.append(Instance(name, i, spec.kind, name if spec.count == 1 and spec.shape in ((), (1,)) else f"{name}[{i}]"))
    return out


def _basis(theta: np.ndarray, orders, f0: float) -> np.ndarray:
    """Columns [1, cos(k f₀ θ)…, sin(k f₀ θ)…] on a record's input angles: the model is B · coefficients."""
    arg = np.outer(theta * f0, np.asarray(orders, dtype=np.float64))
    return np.concatenate([np.ones((len(theta), 1)), np.cos(arg), np.sin(arg)], axis=1)


@eqx.filter_jit
def _record_coefficients(
    drive: AbstractSinusoidalDrive, instances: tuple[Instance, ...], p_full: Array, turned: tuple[tuple[str, ...], ...], values: list[Array]
) -> Array:
    """The TE signal's coefficients (records × (1 + 2K), rad) for the full parameter vector `p_full`, in record r's
    assembly the sources ``turned[r]`` turned by ``values[r]`` (rad); jitted once per drive structure and turned sources."""
    return jnp.stack([signal_coefficients(drive, errors_from(drive, instances, p_full, dict(zip(t, v)))) for t, v in zip(turned, values)])


@eqx.filter_jit
def _record_coefficients_jacobian(
    drive: AbstractSinusoidalDrive, instances: tuple[Instance, ...], p_full: Array, turned: tuple[tuple[str, ...], ...], values: list[Array]
) -> Array:
    """∂ `_record_coefficients` / ∂ `p_full` (records × (1 + 2K) × parameters), forward mode."""
    return jax.jacfwd(lambda p: _record_coefficients(drive, instances, p, turned, values))(p_full)


@eqx.filter_jit
def _residual_jit(problem: IdentificationProblem, y: Array, z: list[Array]) -> Array:
    return problem._residual_body(y, z)


def identification_problem(
    drive: AbstractSinusoidalDrive | AbstractGridDrive,
    records: MeasuredRecord | Sequence[MeasuredRecord],
    *,
    turns: Sequence[Mapping[str, float]] | None = None,
    starts: int = 4,
    max_steps: int = 100,
    adjust: Sequence[str] | None = None,
    start: Errors | None = None,
) -> IdentificationProblem | GridIdentificationProblem:
    """Check the records against the drive and find what they can identify (see the module notes; for a grid
    drive, `gearte.identification.fit_grid`, with `adjust` and `start` as in `identify`).

    Raises `RecordError` when a record is too short to separate the lines it needs or samples too slowly.
    """
    require_x64()
    if not isinstance(drive, (AbstractSinusoidalDrive, AbstractGridDrive)):
        raise ValueError(f"identify: {type(drive).__name__} is neither a sinusoidal nor a grid drive of the drive protocol")
    if not isinstance(records, (MeasuredRecord, Sequence)) or isinstance(records, str):
        raise ValueError(f"records: a MeasuredRecord or a list of them (gearte.identification.read_record), got {type(records).__name__}")
    recs = [records] if isinstance(records, MeasuredRecord) else list(records)
    if not recs:
        raise ValueError("identify: give at least one record")
    if not all(isinstance(r, MeasuredRecord) for r in recs):
        raise ValueError("records: every record must be a MeasuredRecord (gearte.identification.read_record)")
    starts = as_int("identify: starts", starts, minimum=1)
    max_steps = as_int("identify: max_steps", max_steps, minimum=1)
    if turns is not None and (isinstance(turns, Mapping) or not all(isinstance(t, Mapping) for t in turns)):
        raise ValueError("turns: one dict per record (source → turn, rad; {} for none), e.g. turns=[{}, {'sun_assembly': 1.57}]")
    turn_list = [dict(t) for t in turns] if turns is not None else [{} for _ in recs]
    if len(turn_list) != len(recs):
        raise ValueError(f"turns: {len(turn_list)} entries for {len(recs)} records (one dict per record, {{}} for none)")
    specs = drive.error_sources
    for t in turn_list:
        for name in t:
            if name not in specs or specs[name].kind != "eccentricity":
                raise ValueError(f"turns: {name!r} is not an eccentricity source of this drive; use one of {sorted(specs)}")
            check_array_values(f"turns[{name!r}]", t[name], unit="rad")
            if np.ndim(t[name]) != 0:
                raise ValueError(f"turns[{name!r}]: one angle (rad) per source: a turn turns every instance of the source together")
    if isinstance(drive, AbstractGridDrive):
        from .fit_grid import grid_problem

        return grid_problem(drive, recs, turn_list, adjust=adjust, start=start, starts=starts, max_steps=max_steps)
    if adjust is not None or start is not None:
        raise ValueError("adjust, start: only for a grid drive; a sinusoidal drive's identification fits every source from random phases")
    instances = _instances(drive)
    width = [2 if x.kind == "eccentricity" else 1 for x in instances]
    starts_of = np.cumsum([0] + width)
    rng = np.random.default_rng(0)
    probe = np.concatenate(
        [np.r_[np.cos(a), np.sin(a)] if w == 2 else np.r_[1.0] for a, w in zip(rng.uniform(0, TWO_PI, len(width)), width)]
    )

    turned = tuple(tuple(t) for t in turn_list)
    tv = [jnp.asarray(list(t.values()), dtype=float) for t in turn_list]
    # Identifiability from the model's Jacobian in coefficient space (exact: no record length enters).
    jac3 = np.asarray(_record_coefficients_jacobian(drive, tuple(instances), jnp.asarray(probe), turned, tv))  # (records, 1 + 2K, params)
    m = jac3.shape[1]
    jac = jac3.reshape(-1, jac3.shape[2])
    offs = np.zeros((jac.shape[0], len(recs)))
    for r in range(len(recs)):
        offs[r * m, r] = 1.0
    kept, status = select(jac, offs, starts_of)
    sig = zero_signal(drive)
    freq_of_row = [Fraction(0)] + [k * sig.fundamental for k in sig.orders] * 2
    used = np.abs(jac3[0]) > 1e-9 * np.abs(jac3).max()
    freqs = tuple(
        tuple(sorted({freq_of_row[r] for r in np.nonzero(used[:, starts_of[i] : starts_of[i + 1]].any(axis=1))[0]}))
        for i in range(len(instances))
    )
    found = groups(instances, freqs, jac, offs, starts_of, kept, status, len(recs))
    _check_records(recs, sorted({f for i in kept for f in freqs[i]} | {Fraction(0)}))

    def coefs(p: Array, values: list[Array]) -> Array:
        return _record_coefficients(drive, tuple(instances), p, turned, values)

    periods = tuple(period(coefs, tv, instances, i, probe, starts_of) for i in range(len(instances)))
    qs, rs = [], []
    for rec in recs:
        q, r = np.linalg.qr(_basis(np.asarray(rec.theta, dtype=np.float64), sig.orders, float(sig.fundamental)))
        qs.append(q)
        rs.append(r)
    scale = tuple(float(specs[x.source].tolerance or 10.0) if x.kind == "eccentricity" else 0.0 for x in instances)
    return IdentificationProblem(
        drive=drive,
        r_factors=tuple(rs),
        q_factors=tuple(qs),
        turns=tuple(tuple(sorted((k, float(v)) for k, v in t.items())) for t in turn_list),
        instances=tuple(instances),
        kept=tuple(kept),
        groups=tuple(found),
        phase_period=periods,
        frequencies=freqs,
        scale=scale,
        starts=int(starts),
        max_steps=int(max_steps),
    )


def _check_records(recs: Sequence[MeasuredRecord], freqs: list[Fraction]) -> None:
    gaps = [(b - a, a, b) for a, b in zip(freqs, freqs[1:])]
    need = float(1 / min(gaps)[0]) if gaps else 0.0
    f_max = float(max(freqs))
    for r in recs:
        if gaps and r.revolutions < need * (1 - 1e-9):
            d, a, b = min(gaps)
            extra = f" ({need * 60.0 / r.input_rpm:.4g} s at {r.input_rpm:g} rpm)" if r.input_rpm else ""
            raise RecordError(
                f"{r.source}: the record spans {r.revolutions:.4g} input revolutions; separating the lines at {a} and {b} × input "
                f"speed needs at least 1/{d} = {need:.4g} revolutions{extra}: record longer"
            )
        if r.points_per_rev <= 2 * f_max:
            raise RecordError(
                f"{r.source}: {r.points_per_rev:.4g} samples per input revolution; the line at {max(freqs)} × input speed needs more "
                f"than {2 * f_max:.4g} (Nyquist): sample faster"
            )


def identify(
    drive: AbstractSinusoidalDrive | AbstractGridDrive,
    records: MeasuredRecord | Sequence[MeasuredRecord],
    *,
    key: int | PRNGKeyArray,
    turns: Sequence[Mapping[str, float]] | None = None,
    starts: int = 4,
    max_steps: int = 100,
    adjust: Sequence[str] | None = None,
    start: Errors | None = None,
    throw: bool = True,
) -> Identification:
    """Identify the errors of `drive` from measured TE records (see the module notes).

    **Arguments:**

    - `drive`: a sinusoidal drive (`gearte.Planetary2KH`, `gearte.HarmonicDrive`, `gearte.ExplicitDrive`), or a grid
      drive (`gearte.CycloidPin`; see `gearte.identification.fit_grid`).
    - `records`: one `MeasuredRecord`, or several of the same drive re-assembled.
    - `key`: seed or key of the random starting phases (required: PRNG keys are always explicit).
    - `turns`: with several records, for each a dict source → turn (rad) of that source at its assembly
      relative to the first (e.g. ``[{}, {"sun_assembly": pi/2}]``).
    - `starts`: Levenberg–Marquardt starts, run one after another; the best is kept.
    - `adjust`: a grid drive's sources to identify (default: all); the others are held at `start`.
    - `start`: a grid drive's errors where the solve begins and the identifiability is read (source → value;
      sources left out are 0).
    - `throw`: raise if the best start did not converge (else check `result`).

    **Returns:** an `Identification`.
    """
    problem = identification_problem(drive, records, turns=turns, starts=starts, max_steps=max_steps, adjust=adjust, start=start)
    recs = [records] if isinstance(records, MeasuredRecord) else list(records)
    sol = _solve(problem, [jnp.asarray(r.te) for r in recs], as_key(key))
    check(sol.result, throw=throw, what="identify")
    return sol


@eqx.filter_jit
def _solve(problem: IdentificationProblem | GridIdentificationProblem, te, key):
    return problem.solve(te, key)
