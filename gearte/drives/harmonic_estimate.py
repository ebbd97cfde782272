"""Harmonic drive: Liu's statistical estimate (eqs. 7–8), class lines and beats, labelled record lines.

- `statistical_estimate`: Liu's ±3σ design estimate of the kinematic error.
- `class_phasors`, `beat_envelope_bounds`: the line of each source class of one unit, and
  the envelope of the CS and FS lines, which beat twice per output revolution (Liu, sec. 3).
- `labelled_lines`: the spectral lines of an encoder record, each labelled with its class
  (Liu, sec. 4: 184, 368 and 372 cpm at 184 rpm).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING

import equinox as eqx
import numpy as np
from jaxtyping import Array, Float

from ..core.extrema import spectrum
from ..core.records import Record, record_spectrum, spectral_lines, spectrum_peaks
from ..core.signal import TESignal
from ..core.units import ARCSEC_PER_RAD
from .harmonic_sources import CLASSES, class_label, finite
from .protocol import Eccentricity

if TYPE_CHECKING:
    from .harmonic import HarmonicDrive


class Estimate(eqx.Module):
    """Liu's statistical design estimate (eqs. 7–8).

    **Fields:**

    - `delta_um`: Δ of eq. (7), µm: ± this at 3σ, for one tooth pair at the deepest mesh.
    - `arcsec`, `arcmin`: Δφ of eq. (8) = (K_b/√N) · Δ · 412.8/d, ″ and ′.
    - `sigma_arcsec`: the σ it stands for (Δφ/3), ″: the standard deviation of the TE at
      any instant when magnitudes are Rayleigh with scale tolerance/6 and phases uniform.
    - `by_class_um`: Δ of each class alone, µm (its share of eq. 7).
    - `terms_um2`: each source's term under the root of eq. (7), µm².
    """

    delta_um: float
    arcsec: float
    arcmin: float
    sigma_arcsec: float
    by_class_um: dict[str, float]
    terms_um2: dict[str, float]


def statistical_estimate(drive: HarmonicDrive, *, tolerances_um: Mapping[str, float] | None = None) -> Estimate:
    """Liu's ±3σ design estimate of the kinematic error (eqs. 7–8).

    ``Δ = ½ √(F_p1² + F_p2² + f′₁² + f′₂² + (ΣE₁² + ΣE₂² + ΣE₃²)/cos² α_n)`` (µm), then
    ``Δφ = (K_b/√N) · Δ · 412.8/d`` (″). Each source enters with its tolerance: run-outs
    and clearances as E (divided by cos α_n), cumulative pitch as F_p, tooth-to-tooth as f′.

    **Arguments:**

    - `drive`: the `HarmonicDrive` (its sources carry the tolerances).
    - `tolerances_um`: optional tolerances (µm) that replace the sources' own, by name.

    **Returns:** an `Estimate`.
    """
    tol = {s.name: float(s.tolerance) for s in drive.sources}
    if tolerances_um is not None:
        unknown = sorted(set(tolerances_um) - set(tol))
        if unknown:
            raise ValueError(f"tolerances_um: {unknown} are not sources of this drive; use some of {sorted(tol)}")
        for k, v in tolerances_um.items():
            tol[k] = finite(f"tolerances_um[{k!r}]", v, nonnegative=True)
    cos_a = math.cos(float(drive.pressure_angle))
    terms, by_class = {}, {c: 0.0 for c in CLASSES}
    for s in drive.sources:
        t2 = tol[s.name] ** 2 / (cos_a**2 if s.kind == "runout" else 1.0)
        terms[s.name] = t2
        by_class[s.source_class] += t2
    delta = 0.5 * math.sqrt(sum(terms.values()))
    arcsec = delta * float(drive.gain()) * ARCSEC_PER_RAD
    return Estimate(
        delta_um=delta,
        arcsec=arcsec,
        arcmin=arcsec / 60.0,
        sigma_arcsec=arcsec / 3.0,
        by_class_um={c: 0.5 * math.sqrt(v) for c, v in by_class.items()},
        terms_um2=terms,
    )


# ---------------------------------------------------------------- one unit: class lines and beats


def class_phasors(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> dict[str, complex]:
    """Resultant of each class at the output, rad: ``Σ g a e^{iψ}`` over its sources (ψ the TE phase).

    Sources of one class share a frequency, so they add as phasors; |resultant| is the
    class's line amplitude in the spectrum.
    """
    comp = drive.components(errors)
    amp = np.asarray(comp.amplitude * comp.gain)
    ph = np.asarray(comp.phase)
    out = {c: 0j for c in CLASSES}
    for s, a, p in zip(drive.sources, amp, ph):
        out[s.source_class] += complex(a * np.exp(1j * p))
    return out


def beat_envelope_bounds(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> tuple[float, float]:
    """(largest, smallest) envelope of the CS + FS lines, rad: K(e₁ + e₂) and K|e₁ − e₂| (Liu, sec. 3)."""
    p = class_phasors(drive, errors)
    a, b = abs(p["circular_spline"]), abs(p["flexspline"])
    return a + b, abs(a - b)


def output_rev_peak_to_peak(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> Float[Array, ""]:
    """Peak-to-peak TE over one output revolution, rad (catalogue "transmission accuracy"; see
    `HarmonicDrive.output_rev_note`): ``gearte.PeakToPeak()(drive, drive.signal(errors))``."""
    e = drive.extrema(drive.signal(errors))
    return e.max - e.min


# ---------------------------------------------------------------- records


def label_for_frequency(drive: HarmonicDrive, freq_cpm: float, *, input_rpm: float, tolerance_cpm: float) -> str | None:
    """The class whose frequency is within `tolerance_cpm` of `freq_cpm` (nearest), or None."""
    best, dist = None, tolerance_cpm
    for c, f in drive.frequencies_cpm(input_rpm).items():
        if abs(f - freq_cpm) <= dist:
            best, dist = c, abs(f - freq_cpm)
    return best


def labelled_lines(drive: HarmonicDrive, rec: Record, *, count: int = 8, signal: TESignal | None = None) -> list[dict]:
    """Spectral lines of a record, labelled with their source class, largest first.

    The lines are found by `gearte.spectral_lines` (amplitudes fitted jointly, so close lines
    such as the CS and FS ones are resolved); each is labelled with the class whose
    frequency lies within half a bin. If fewer than `count` lines exist, the list is
    completed with the next-largest peaks of the Hann-windowed spectrum, which are the
    window's side lobes around the real lines — what an FFT analyser would show next —
    marked ``"kind": "side_lobe"`` and labelled as such (no error source makes them). They are
    read from the spectrum zero-padded 8 times: at the bare bin spacing a Hann side lobe
    shows no peak, every bin seeing the same |sin πδ|.

    **Arguments:**

    - `drive`: the `HarmonicDrive` (for the class frequencies).
    - `rec`: a `gearte.Record` (from `gearte.record`), at its own input speed.
    - `count`: list at least this many entries.
    - `signal`: the model TE the record was taken from, if any, to add each class's exact
      line (``model_freq_cpm``, ``model_amplitude_arcsec``).

    **Returns:** a list of dicts with ``freq_cpm``, ``amplitude_arcsec``, ``source`` (label),
    ``class`` (or None), ``kind`` (``"line"`` or ``"side_lobe"``) and, with `signal`, the model values.
    """
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f"count: must be a whole number ≥ 1, got {count!r}")
    found = spectral_lines(rec, max_lines=max(16, count))
    res = rec.resolution_cpm
    model = {}
    if signal is not None:
        sp = spectrum(signal)
        amp = np.asarray(sp.amplitude)
        for f, a in zip(sp.freq, amp):
            cls = next((c for c, fc in drive.class_frequencies().items() if fc == f), None)
            if cls is not None:
                model[cls] = (float(f) * rec.input_rpm, float(a) * ARCSEC_PER_RAD)
    out = []
    for f, a in zip(found.freq_cpm, found.amplitude):
        cls = label_for_frequency(drive, float(f), input_rpm=rec.input_rpm, tolerance_cpm=0.5 * res)
        entry = {
            "freq_cpm": float(f),
            "amplitude_arcsec": float(a) * ARCSEC_PER_RAD,
            "source": class_label(cls) if cls else "unassigned line (no source class at this frequency)",
            "class": cls,
            "kind": "line",
        }
        if cls in model:
            entry["model_freq_cpm"], entry["model_amplitude_arcsec"] = model[cls]
        out.append(entry)
    if len(out) < count:
        spec = record_spectrum(rec, window="hann", zero_pad=8)
        # Exclude each line's Hann main lobe (±2 bins); its side lobes are the next peaks an analyser shows.
        peaks = spectrum_peaks(spec, exclude_cpm=list(found.freq_cpm), exclude_bins=2.0, count=count - len(out))
        real = list(out)
        for f, a in peaks:
            near = min(real, key=lambda e: abs(e["freq_cpm"] - f)) if real else None
            what = f"the {near['freq_cpm']:.2f} cpm line" if near else "no line"
            out.append(
                {
                    "freq_cpm": f,
                    "amplitude_arcsec": a * ARCSEC_PER_RAD,
                    "source": f"none: side lobe of the Hann window around {what}",
                    "class": None,
                    "kind": "side_lobe",
                }
            )
    out.sort(key=lambda e: -e["amplitude_arcsec"])
    return out
