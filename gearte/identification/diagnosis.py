"""Diagnosis of a measured record: each spectral line mapped to the parts that can cause it, with the identified share of each.

For every line of the drive's model (a frequency of its TE signal) the record's own amplitude is read by
least squares on the record (all lines together, so that they do not leak into each other); the
identified errors give each part's phasor on that line, and its *share* is the projection of that
phasor on the line's identified phasor, ``Re(p_part · conj(P)) / |P|²``: the shares of a line add to 1,
and a negative share is a part that cancels some of the others. A group of sources that one record
cannot separate has one share, that of its combined phasor, and all its members are named. What the
model does not explain is in the residual's lines (`gearte.spectral_lines` of the residual).
"""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import jax.numpy as jnp
import numpy as np

from ..core.records import spectral_lines
from ..drives.protocol import zero_signal
from .fit import Identification, IdentificationProblem, _basis, signal_coefficients
from .records import MeasuredRecord


@dataclasses.dataclass(frozen=True)
class LineDiagnosis:
    """One line: `frequency` (× input speed), `measured` and `identified` amplitudes (rad), and `parts`:
    (label, share, amplitude rad, members it stands for) for each part with a non-zero phasor on it."""

    frequency: Fraction
    measured: float
    identified: float
    parts: tuple[tuple[str, float, float, tuple[str, ...]], ...]


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of `diagnose`: the model's `lines` (largest measured first), the residual's lines not explained by the
    model (`unexplained`: (frequency × input speed, amplitude rad)), and the residual's RMS (rad); `theta`,
    `measured`, `identified` (rad) for plots."""

    lines: tuple[LineDiagnosis, ...]
    unexplained: tuple[tuple[float, float], ...]
    residual_rms: float
    theta: np.ndarray
    measured: np.ndarray
    identified: np.ndarray


def diagnose(problem: IdentificationProblem, solution: Identification, record: MeasuredRecord, *, lines: int = 8) -> Diagnosis:
    """Map the lines of `record` (the first record identified) to the parts, with the identified share of each."""
    drive = problem.drive
    sig = zero_signal(drive)
    orders, f0 = sig.orders, sig.fundamental
    theta = np.asarray(record.theta, dtype=np.float64)
    te = np.asarray(record.te, dtype=np.float64)
    basis = _basis(theta, orders, float(f0))
    meas, *_ = np.linalg.lstsq(basis, te, rcond=None)
    K = len(orders)
    full = np.asarray(solution.parameters)
    total = np.asarray(signal_coefficients(drive, solution.errors))
    per = {}
    j = 0
    members = {g.representative: g.members for g in solution.groups if g.kind == "combined"}
    for i, inst in enumerate(problem.instances):
        w = 2 if inst.kind == "eccentricity" else 1
        if i in problem.kept:
            p = np.zeros_like(full)
            p[j : j + w] = full[j : j + w]
            per[inst.label] = np.asarray(signal_coefficients(drive, problem.errors_from(jnp.asarray(p))))
        j += w
    out = []
    for k in range(K):
        C, S = total[1 + k], total[1 + K + k]
        amp_id = float(np.hypot(C, S))
        amp_m = float(np.hypot(meas[1 + k], meas[1 + K + k]))
        parts = []
        for lab, c in per.items():
            a = float(np.hypot(c[1 + k], c[1 + K + k]))
            if a <= 1e-12 * max(amp_id, 1e-30) or a == 0.0:
                continue
            share = float((c[1 + k] * C + c[1 + K + k] * S) / (C**2 + S**2)) if amp_id > 0 else float("nan")
            parts.append((lab, share, a, members.get(lab, (lab,))))
        if parts or amp_m > 0:
            out.append(LineDiagnosis(orders[k] * f0, amp_m, amp_id, tuple(sorted(parts, key=lambda x: -abs(x[1])))))
    out.sort(key=lambda ln: -ln.measured)
    model = basis @ total + float(solution.offset[0])
    resid = MeasuredRecord(theta=theta, te=te - model, input_rpm=record.input_rpm, source=record.source)
    found = spectral_lines(resid.as_record(), max_lines=lines, min_relative=1e-3)
    rpm = resid.as_record().input_rpm
    model_f = {float(ln.frequency) for ln in out}
    step = 1.0 / max(record.revolutions, 1e-12)
    unexplained = tuple(
        (float(f) / rpm, float(a))
        for f, a in zip(found.freq_cpm, found.amplitude)
        if all(abs(float(f) / rpm - m) > 2 * step for m in model_f)
        and a > 8 * float(solution.sigma) * np.sqrt(2 / len(te))  # far above the noise floor
    )
    return Diagnosis(
        lines=tuple(out[:lines]),
        unexplained=unexplained,
        residual_rms=float(np.sqrt(np.mean((te - model) ** 2))),
        theta=theta,
        measured=te,
        identified=model,
    )
