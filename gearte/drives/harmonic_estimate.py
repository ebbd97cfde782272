"""Harmonic drive: Liu's statistical estimate (eqs. 7–8), class lines and beats, labelled record lines.

- `statistical_estimate`: Liu's ±3σ design estimate of the kinematic error, in both readings of
  eq. (8): with the averaging factor 1/√N as printed, and without it (`Estimate`).
- `delta_for_arcmin`: the Δ of eq. (7) that gives an angle by eq. (8), in either reading (e.g. the
  Δ behind Liu's computed 2.51′).
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
from ..core.records import HannWindow, Record, record_spectrum, spectral_lines, spectrum_peaks
from ..core.signal import TESignal
from ..core.units import ARCSEC_PER_RAD
from .harmonic_sources import CLASSES, LIU_ARCSEC_PER_UM_MM, class_label, finite
from .protocol import Eccentricity

if TYPE_CHECKING:
    from .harmonic import HarmonicDrive


#: Liu's computed estimate for the drive of sec. 4 (Table 1), ′, from drawing tolerances the paper does not list.
LIU_COMPUTED_ARCMIN = 2.51
#: Liu's measured kinematic errors of units 1–3 (Table 1), ′: each the peak-to-peak of one unit's record.
LIU_MEASURED_ARCMIN = (2.12, 2.39, 2.08)


class Estimate(eqx.Module):
    """Liu's statistical design estimate (eqs. 7–8), in both readings of eq. (8).

    **Fields:**

    - `delta_um`: Δ of eq. (7), µm: ± this at 3σ, for one tooth pair at the deepest mesh.
    - `arcsec`, `arcmin`: Δφ of eq. (8) as printed, (K_b/√N) · Δ · 412.8/d, ″ and ′: Liu's
      averaging over the N tooth pairs in mesh and the two zones (factor 1/√N).
    - `sigma_arcsec`: the σ it stands for (Δφ/3), ″: the standard deviation of the TE at
      any instant when magnitudes are Rayleigh with scale tolerance/6 and phases uniform.
    - `averaging`: the factor 1/√N.
    - `arcsec_no_averaging`, `arcmin_no_averaging`: eq. (8) without the averaging factor,
      K_b · Δ · 412.8/d (= √N × the printed reading), ″ and ′.
    - `by_class_um`: Δ of each class alone, µm (its share of eq. 7).
    - `terms_um2`: each source's term under the root of eq. (7), µm².
    """

    delta_um: float
    arcsec: float
    arcmin: float
    sigma_arcsec: float
    averaging: float
    arcsec_no_averaging: float
    arcmin_no_averaging: float
    by_class_um: dict[str, float]
    terms_um2: dict[str, float]


def delta_for_arcmin(drive: HarmonicDrive, arcmin: float, *, averaging: bool = True) -> float:
    """The Δ of eq. (7), µm, that eq. (8) turns into `arcmin` for this drive (its K_b, N, d).

    With `averaging` (eq. 8 as printed): Δ = Δφ · √N · d / (412.8 K_b); without: Δ = Δφ · d / (412.8 K_b).
    E.g. Liu's 2.51′ = 150.6″ with d = 90 mm, N = 36.2, K_b = 1: 197.5 µm, or 32.8 µm without the averaging.
    """
    a = finite("arcmin", arcmin, nonnegative=True)
    kb, n, d = float(drive.k_b), float(drive.teeth_in_mesh), float(drive.pitch_diameter)
    per_um = kb * LIU_ARCSEC_PER_UM_MM / d * (1.0 / math.sqrt(n) if averaging else 1.0)  # ″ per µm of Δ
    return 60.0 * a / per_um


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
    averaging = 1.0 / math.sqrt(float(drive.teeth_in_mesh))
    return Estimate(
        delta_um=delta,
        arcsec=arcsec,
        arcmin=arcsec / 60.0,
        sigma_arcsec=arcsec / 3.0,
        averaging=averaging,
        arcsec_no_averaging=arcsec / averaging,
        arcmin_no_averaging=arcsec / averaging / 60.0,
        by_class_um={c: 0.5 * math.sqrt(v) for c, v in by_class.items()},
        terms_um2=terms,
    )


# ---------------------------------------------------------------- one unit: class lines and beats


def source_phasors(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> dict[str, tuple[str, complex]]:
    """Each source's line key (`gearte.drives.harmonic.line_key`) and phasor at the output, rad: ``g a e^{iψ}``
    (0 for a tooth harmonic the two zones cancel)."""
    e = drive.checked(errors)
    out = {}
    for s in drive.sources:
        term = drive.source_term(s, e[s.name])
        p = 0j if term is None else complex(float(term[0] * term[2]) * np.exp(1j * float(term[1])))
        out[s.name] = (drive.source_line(s)[0], p)
    return out


def class_phasors(drive: HarmonicDrive, errors: Mapping[str, Eccentricity]) -> dict[str, complex]:
    """Resultant of each line at the output, rad: ``Σ g a e^{iψ}`` over its sources (ψ the TE phase).

    Keys: the classes (``"tooth"`` the tooth-mesh fundamental) and ``"tooth_h2"``, … for higher tooth-mesh
    harmonics the sources hold. Sources of one line share a frequency, so they add as phasors; |resultant| is the
    line's amplitude in the spectrum.
    """
    out = {c: 0j for c in CLASSES}
    for key, p in source_phasors(drive, errors).values():
        out[key] = out.get(key, 0j) + p
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
    for c, f in drive.frequencies_cpm(input_rpm).items():  # the lines the drive's TE has
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
    - `signal`: the model TE the record was taken from, if any, to add each line's exact
      frequency and amplitude (``model_freq_cpm``, ``model_amplitude_arcsec``).

    **Returns:** a list of dicts with ``freq_cpm``, ``amplitude_arcsec``, ``source`` (label),
    ``class`` (or None), ``line`` (the line key, e.g. ``"tooth"`` or ``"tooth_h2"``, or None),
    ``kind`` (``"line"`` or ``"side_lobe"``) and, with `signal`, the model values.
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
            cls = next((c for c, fc in drive.line_frequencies().items() if fc == f), None)
            if cls is not None:
                model[cls] = (float(f) * rec.input_rpm, float(a) * ARCSEC_PER_RAD)
    out = []
    for f, a in zip(found.freq_cpm, found.amplitude):
        cls = label_for_frequency(drive, float(f), input_rpm=rec.input_rpm, tolerance_cpm=0.5 * res)
        entry = {
            "freq_cpm": float(f),
            "amplitude_arcsec": float(a) * ARCSEC_PER_RAD,
            "source": class_label(cls) if cls else "unassigned line (no source class at this frequency)",
            "class": cls.rpartition("_h")[0] if cls and cls not in CLASSES else cls,
            "line": cls,
            "kind": "line",
        }
        if cls in model:
            entry["model_freq_cpm"], entry["model_amplitude_arcsec"] = model[cls]
        out.append(entry)
    if len(out) < count:
        spec = record_spectrum(rec, window=HannWindow(), zero_pad=8)
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
                    "line": None,
                    "kind": "side_lobe",
                }
            )
    out.sort(key=lambda e: -e["amplitude_arcsec"])
    return out
