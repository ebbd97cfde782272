"""Which instances a set of records can identify: the model's Jacobian in coefficient space, column by column
(see `gearte.identification.fit`)."""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import jax.numpy as jnp
import numpy as np

from ..core.units import TWO_PI

_ALIAS_TOL = 1e-6  # relative residual of a column against those before it, below which it is aliased


@dataclasses.dataclass(frozen=True)
class Instance:
    """One identified parameter set: `source` (name), `index` (instance), `kind`, `label` (``name`` or ``name[i]``)."""

    source: str
    index: int
    kind: str
    label: str


@dataclasses.dataclass(frozen=True)
class Group:
    """Instances that one set of records cannot tell apart.

    `kind`: ``"combined"`` (they share a line: `representative` carries their combined phasor),
    ``"unseen"`` (they do not reach the TE) or ``"constant"`` (a constant TE, lost in the record's zero).
    `frequencies`: the lines (× input speed) they act on. `advice`: how to separate them.
    """

    kind: str
    members: tuple[str, ...]
    representative: str | None
    frequencies: tuple[Fraction, ...]
    advice: str


def select(jac: np.ndarray, offs: np.ndarray, starts_of) -> tuple[list[int], dict[int, str]]:
    """Instances in order: kept when their columns add to the span of the record constants and those kept before."""
    norms = np.linalg.norm(jac, axis=0)
    top = float(norms.max()) if norms.size else 0.0
    if top == 0.0:
        raise ValueError("identify: no error source of this drive reaches the TE")
    basis = [c / np.linalg.norm(c) for c in offs.T]
    kept, status = [], {}
    for i in range(len(starts_of) - 1):
        cols = jac[:, starts_of[i] : starts_of[i + 1]]
        if np.linalg.norm(cols, axis=0).max() <= 1e-12 * top:
            status[i] = "unseen"
            continue
        q = np.stack(basis, axis=1)
        resid = cols - q @ (q.T @ cols)
        rel = np.linalg.norm(resid, axis=0) / np.linalg.norm(cols, axis=0)
        if rel.min() > _ALIAS_TOL:
            kept.append(i)
            for c in resid.T:  # Gram–Schmidt, re-orthogonalised
                qq = np.stack(basis, axis=1)
                c = c - qq @ (qq.T @ c)
                basis.append(c / np.linalg.norm(c))
        else:
            status[i] = "aliased"
    return kept, status


def period(coefs, tv, instances, i: int, probe: np.ndarray, starts_of) -> float:
    """The smallest 2π/k (k = 4, 3, 2, 1) by which instance i's phase can turn without changing the TE."""
    if instances[i].kind != "eccentricity":
        return TWO_PI
    base = np.asarray(coefs(jnp.asarray(probe), tv))
    j = int(starts_of[i])
    for k in (4, 3, 2):
        q = probe.copy()
        c, s = math.cos(TWO_PI / k), math.sin(TWO_PI / k)
        q[j], q[j + 1] = c * probe[j] - s * probe[j + 1], s * probe[j] + c * probe[j + 1]
        if np.abs(np.asarray(coefs(jnp.asarray(q), tv)) - base).max() <= 1e-10 * np.abs(base).max():
            return TWO_PI / k
    return TWO_PI


def groups(instances, freqs, jac, offs, starts_of, kept, status, n_records, *, grid: bool = False) -> list[Group]:
    """Connected groups of aliased instances with the identified instances they alias, unseen and constant ones
    (`grid`: the Jacobian is a grid drive's, on the records' input angles at the start point)."""
    kept_cols = np.concatenate([offs] + [jac[:, starts_of[i] : starts_of[i + 1]] for i in kept], axis=1)
    owner = [-1] * n_records + [i for i in kept for _ in range(starts_of[i + 1] - starts_of[i])]
    link: dict[int, set[int]] = {i: {i} for i in kept}
    unseen, constant = [], []
    for i, s in status.items():
        if s == "unseen":
            unseen.append(i)
            continue
        cols = jac[:, starts_of[i] : starts_of[i + 1]]
        coef, *_ = np.linalg.lstsq(kept_cols, cols, rcond=None)
        w = np.abs(coef).max(axis=1)
        partners = {owner[r] for r in np.nonzero(w > 1e-6 * w.max())[0] if owner[r] >= 0}
        if not partners:
            constant.append(i)
            continue
        merged = {i}
        for k in list(link):
            if link[k] & partners:
                merged |= link.pop(k)
        link[min(partners)] = merged | partners
    out = []
    for members in link.values():
        if len(members) < 2:
            continue
        order = sorted(members)
        rep = next(i for i in order if i in kept)
        labels = tuple(instances[i].label for i in order)
        others = [lab for lab in labels if lab != instances[rep].label]
        fr = freqs[rep]
        # `identify` turns a source's every instance together (one angle per source and record): turns separate
        # sources, never the instances of one source (planets' parts of one kind) from each other.
        bases = sorted({lab.split("[")[0] for lab in labels})
        rep_base = instances[rep].label.split("[")[0]
        if len(bases) == 1:
            separate = (
                f"They are instances of one source, {rep_base}; identify's turns turn every instance of a source together, "
                "which keeps their combination: separating them needs another measurement"
            )
        else:
            separate = (
                f"To separate them, turn one of the sources {', '.join(b for b in bases if b != rep_base)} by a known angle "
                f"at re-assembly and record again; {len(bases)} records with independent turns separate the {len(bases)} "
                "sources"
                + (" (not the instances of one source from each other)" if len(bases) < len(labels) else "")
                + " (identify(..., turns=[…]))"
            )
        advice = (
            f"{', '.join(labels)} change the TE on the records' input angles only together (their Jacobian columns are "
            f"linearly dependent there): the records give one combination, carried by {instances[rep].label} with "
            f"{', '.join(others)} held at their start values. Separating them needs records over other input angles or "
            "another measurement"
            if grid
            else f"{', '.join(labels)} act on the same line{'s' if len(fr) > 1 else ''} ({', '.join(map(str, fr))} × input speed): one record gives their combined phasor, reported as "
            f"{instances[rep].label}. {separate}"
        )
        out.append(Group("combined", labels, instances[rep].label, fr, advice))
    if unseen:
        labs = tuple(instances[i].label for i in unseen)
        why = (
            "do not reach the TE on the records' input angles at the start point (a source acting through another's size, "
            "such as the phase of an error whose size is 0 there, is unseen at that point: start from non-zero values)"
            if grid
            else "do not reach the TE in this drive's model: no record shows them"
        )
        out.append(Group("unseen", labs, None, (), f"{', '.join(labs)} {why}"))
    if constant:
        labs = tuple(instances[i].label for i in constant)
        out.append(
            Group(
                "constant",
                labs,
                None,
                (Fraction(0),),
                f"{', '.join(labs)} only shift the TE by a constant, which a record cannot tell from its encoders' zero",
            )
        )
    return out
