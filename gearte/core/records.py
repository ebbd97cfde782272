"""Measurement-like TE records: an encoder record of any `TESignal`, its windowed spectrum, its lines and envelopes.

A test bench records the TE against time at a constant input speed, with a fixed
sample rate, for a finite time (Liu, sec. 4: 40–80 s at 184 rpm, an FFT
analyser for the spectrum). `record` produces such a record from a model; the rest
analyses any record the way such a bench would, so that the model and a measurement
can be read side by side:

- `record_spectrum`: amplitude spectrum with a window (`HannWindow`, the default;
  `FlatTopWindow`, whose lines read their amplitude within 0.11 % wherever they fall
  between the bins; or `RectangularWindow`), in cycles per minute (cpm), scaled so that
  a sinusoid of amplitude A at a bin centre reads A;
- `spectral_lines`: the sinusoidal lines of a record — frequency, amplitude and
  phase — found one by one (largest first), each frequency read from the two
  largest Hann bins (the interpolated DFT), then all amplitudes and phases fitted
  together by least squares and the frequencies re-read from the residual, until
  nothing above the detection floor is left. Fitting the lines together removes the
  leakage of a large line into a small neighbour, so two lines a few cpm apart are
  resolved (given ≥ 2.5 bins, i.e. a record of ≥ 150/Δf seconds for lines Δf cpm apart);
- `record_envelope`: envelope of the part of a record inside a frequency band (the
  modulus of its analytic signal); `band_envelope`: the same, exactly, from a model.

Records are plain NumPy arrays: this is post-processing, not part of the jit-compiled TE.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from fractions import Fraction
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike
from scipy.signal import windows as _scipy_windows

from .signal import TESignal, evaluate
from .units import TWO_PI as _TWO_PI
from .validate import check_option

#: Fewest and most samples of a record (`record`).
MIN_RECORD_SAMPLES, MAX_RECORD_SAMPLES = 16, 50_000_000


def record_samples(duration_s: float, sample_rate_hz: float) -> int:
    """The samples of a record `duration_s` long at `sample_rate_hz` (`record`), checked against `MIN_RECORD_SAMPLES` and
    `MAX_RECORD_SAMPLES` (ValueError naming both keys)."""
    n = int(round(duration_s * sample_rate_hz))
    if n < MIN_RECORD_SAMPLES:
        raise ValueError(
            f"record: {duration_s:g} s at {sample_rate_hz:g} Hz is only {n} samples (at least {MIN_RECORD_SAMPLES}); "
            "record longer (duration_s) or sample faster (sample_rate_hz)"
        )
    if n > MAX_RECORD_SAMPLES:
        raise ValueError(
            f"record: {duration_s:g} s at {sample_rate_hz:g} Hz is {n:,} samples, more than {MAX_RECORD_SAMPLES:,}; "
            "lower sample_rate_hz or duration_s"
        )
    return n


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
    return v


class Record(eqx.Module):
    """A TE record sampled at a constant input speed.

    **Fields:**

    - `time`: sample times, s.
    - `theta`: input angle at each sample, rad.
    - `te`: TE at the output, rad.
    - `input_rpm`: input speed, rpm.
    - `sample_rate_hz`: samples per second.
    """

    time: np.ndarray
    theta: np.ndarray
    te: np.ndarray
    input_rpm: float = eqx.field(static=True)
    sample_rate_hz: float = eqx.field(static=True)

    @property
    def duration_s(self) -> float:
        """Record length, s (number of samples / sample rate)."""
        return len(self.time) / self.sample_rate_hz

    @property
    def resolution_cpm(self) -> float:
        """Spacing of the DFT bins, cycles per minute (60 / duration)."""
        return 60.0 / self.duration_s


def record(signal: TESignal, *, input_rpm: float, duration_s: float, sample_rate_hz: float, start_s: float = 0.0) -> Record:
    """Sample a TE signal like an encoder record.

    **Arguments:**

    - `signal`: the TE (rad), unbatched.
    - `input_rpm`: constant input speed n, rpm; the input angle is ``2π n t / 60``.
    - `duration_s`: record length, s.
    - `sample_rate_hz`: samples per second; lines above half of it alias, as on a real bench.
    - `start_s`: time of the first sample, s (the input angle is 0 at t = 0).

    **Returns:** a `Record`.
    """
    if signal.offset.ndim != 0:
        raise ValueError(f"record: give one TE signal (unbatched), got a batch of shape {signal.offset.shape}")
    rpm = _positive("input_rpm", input_rpm)
    dur = _positive("duration_s", duration_s)
    fs = _positive("sample_rate_hz", sample_rate_hz)
    n = record_samples(dur, fs)
    t = float(start_s) + np.arange(n) / fs
    theta = _TWO_PI * rpm / 60.0 * t
    te = np.asarray(evaluate(signal, jnp.asarray(theta)))
    return Record(time=t, theta=theta, te=te, input_rpm=rpm, sample_rate_hz=fs)


class AbstractWindow(eqx.Module):
    """The window `record_spectrum` weights a record with before its DFT. A window trades resolution (the width of
    a line's main lobe) against leakage (its side lobes) and against scalloping: how much less a line reads when its
    frequency falls between two bins (Harris 1978, table 1)."""

    #: The window's name (reports).
    name: ClassVar[str]
    #: Largest scalloping loss, dB: a sinusoid half-way between two bins reads this much below its amplitude.
    scalloping_db: ClassVar[float]

    @abc.abstractmethod
    def weights(self, n: int) -> np.ndarray:
        """The n weights (periodic, "DFT-even": the window of a record that repeats)."""


class HannWindow(AbstractWindow):
    """The periodic Hann window 0.5 − 0.5 cos(2π i / n): side lobes fall off fast, lines between bins read up to
    1.42 dB (15 %) low. `spectral_lines` reads frequencies from its bins (the interpolation is exact for it)."""

    name: ClassVar[str] = "hann"
    scalloping_db: ClassVar[float] = 1.42

    def weights(self, n: int) -> np.ndarray:
        return 0.5 - 0.5 * np.cos(_TWO_PI * np.arange(n) / n)


class FlatTopWindow(AbstractWindow):
    """A flat-top window (SciPy's `scipy.signal.windows.flattop`, periodic): a main lobe about 3.7 times wider
    than Hann's, so that a line reads its amplitude within 0.01 dB (0.11 %) wherever it falls between the bins: the
    window for reading mesh-order amplitudes straight off a spectrum."""

    name: ClassVar[str] = "flat top"
    scalloping_db: ClassVar[float] = 0.01

    def weights(self, n: int) -> np.ndarray:
        return _scipy_windows.flattop(n, sym=False)


class RectangularWindow(AbstractWindow):
    """No window: the narrowest main lobe and the most leakage; lines between bins read up to 3.92 dB (36 %) low."""

    name: ClassVar[str] = "rectangular"
    scalloping_db: ClassVar[float] = 3.92

    def weights(self, n: int) -> np.ndarray:
        return np.ones(n)


#: The windows by name.
WINDOWS: dict[str, type[AbstractWindow]] = {w.name: w for w in (HannWindow, FlatTopWindow, RectangularWindow)}


class RecordSpectrum(eqx.Module):
    """Windowed amplitude spectrum of a record.

    `freq_cpm` in cycles per minute; `amplitude` in rad (the record's unit), scaled by
    the window's coherent gain so that a sinusoid of amplitude A at a bin centre reads A
    (between bins up to the window's `scalloping_db` less: 15 % with the Hann window, 0.11 %
    with the flat-top; or read line amplitudes from `spectral_lines`). `resolution_cpm` is the
    record's bin spacing (60 / duration); with zero padding the points are `zero_pad` times
    denser than that.
    """

    freq_cpm: np.ndarray
    amplitude: np.ndarray
    window: AbstractWindow = eqx.field(static=True)
    resolution_cpm: float = eqx.field(static=True)
    zero_pad: int = eqx.field(static=True)


def record_spectrum(rec: Record, *, window: AbstractWindow = HannWindow(), zero_pad: int = 1) -> RecordSpectrum:
    """Amplitude spectrum of a record (mean removed), weighted by `window`: `HannWindow()` (the default),
    `FlatTopWindow()` or `RectangularWindow()` (see `AbstractWindow`).

    `zero_pad` > 1 interpolates the spectrum (the record is padded with zeros to that many
    times its length): the resolution does not change, but the window's side lobes, which
    fall between the bins, become visible.
    """
    if isinstance(zero_pad, bool) or not isinstance(zero_pad, int) or not 1 <= zero_pad <= 64:
        raise ValueError(f"zero_pad: must be a whole number in [1, 64], got {zero_pad!r}")
    window = check_option("window", window, AbstractWindow, WINDOWS, named=None)
    x = np.asarray(rec.te, dtype=np.float64)
    w = np.asarray(window.weights(len(x)), dtype=np.float64)
    X = np.fft.rfft((x - x.mean()) * w, n=zero_pad * len(x))
    amp = 2.0 * np.abs(X) / w.sum()
    freq = np.fft.rfftfreq(zero_pad * len(x), d=1.0 / rec.sample_rate_hz) * 60.0
    return RecordSpectrum(freq_cpm=freq, amplitude=amp, window=window, resolution_cpm=rec.resolution_cpm, zero_pad=zero_pad)


class SpectralLines(eqx.Module):
    """Sinusoidal lines found in a record, largest first: line j is ``amplitude_j sin(2π freq_j t / 60 + phase_j)``.

    `freq_cpm` in cycles per minute; `amplitude` in rad (the record's unit); `phase` in
    rad at t = 0; `offset` the fitted mean (rad); `residual_rms` what the lines leave
    unexplained (rad).
    """

    freq_cpm: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray
    offset: float
    residual_rms: float


def _interpolated_bin(X: np.ndarray, k: int) -> float:
    """Fractional bin of a Hann-windowed sinusoid from its largest bin k and the larger neighbour.

    For the periodic Hann window, a tone at bin k + δ gives |X_{k+1}|/|X_k| = (1 + δ)/(2 − δ),
    hence δ = (2α − 1)/(α + 1) with α that ratio (and mirrored for the left neighbour).
    """
    a = np.abs(X)
    right = a[k + 1] if k + 1 < len(a) else 0.0
    left = a[k - 1] if k >= 1 else 0.0
    if right >= left:
        alpha = right / a[k]
        return k + (2.0 * alpha - 1.0) / (alpha + 1.0)
    alpha = left / a[k]
    return k - (2.0 * alpha - 1.0) / (alpha + 1.0)


class _Basis:
    """cos 2πft and sin 2πft over the record's times, computed once per frequency: the fit, the model and each
    line's own part take the same columns (the same values as computing them again)."""

    def __init__(self, t: np.ndarray):
        self.t = t
        self._columns: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    def __call__(self, f: float) -> tuple[np.ndarray, np.ndarray]:
        if f not in self._columns:
            arg = _TWO_PI * f * self.t
            self._columns[f] = (np.cos(arg), np.sin(arg))
        return self._columns[f]

    def retain(self, freqs_hz: Sequence[float]) -> None:
        """Forget the columns of frequencies no longer in `freqs_hz` (each pass re-reads every frequency)."""
        keep = set(freqs_hz)
        self._columns = {f: c for f, c in self._columns.items() if f in keep}


def _fit(basis: _Basis, x: np.ndarray, w: np.ndarray, freqs_hz: Sequence[float]) -> tuple[np.ndarray, np.ndarray, float]:
    """Weighted least squares of x on [1, cos 2πft, sin 2πft …]: (cos coefs, sin coefs, offset)."""
    cols = [np.ones_like(basis.t)]
    for f in freqs_hz:
        cols += list(basis(f))
    sw = np.sqrt(w)
    A = np.stack(cols, axis=1) * sw[:, None]
    coef, *_ = np.linalg.lstsq(A, x * sw, rcond=None)
    return coef[1::2], coef[2::2], float(coef[0])


def _model(basis: _Basis, freqs_hz, ac, bs, offset: float) -> np.ndarray:
    out = np.full_like(basis.t, offset)
    for f, a, b in zip(freqs_hz, ac, bs):
        c, s = basis(f)
        out += a * c + b * s
    return out


def spectral_lines(
    rec: Record,
    *,
    max_lines: int = 16,
    min_relative: float = 1e-4,
    min_separation_bins: float = 2.5,
    refine_passes: int = 3,
) -> SpectralLines:
    """Find the sinusoidal lines of a record, largest first (see the module notes).

    **Arguments:**

    - `rec`: the record.
    - `max_lines`: at most this many lines.
    - `min_relative`: detection floor, as a fraction of the largest line's amplitude
      (1e-4 = −80 dB); the search stops at the first residual peak below it.
    - `min_separation_bins`: a new line must be at least this many bins (of
      `rec.resolution_cpm`) from the lines already found: the resolution limit of the
      Hann window.
    - `refine_passes`: rounds of joint fit and frequency re-reading after each new line.

    **Returns:** `SpectralLines` (cpm, rad).
    """
    if isinstance(max_lines, bool) or not isinstance(max_lines, int) or max_lines < 1:
        raise ValueError(f"max_lines: must be a whole number ≥ 1, got {max_lines!r}")
    if not 0.0 < float(min_relative) < 1.0:
        raise ValueError(f"min_relative: must be in (0, 1), got {min_relative!r}")
    if not float(min_separation_bins) >= 2.0:
        raise ValueError(f"min_separation_bins: must be ≥ 2 (the Hann main lobe), got {min_separation_bins!r}")
    x = np.asarray(rec.te, dtype=np.float64)
    n = len(x)
    fs = rec.sample_rate_hz
    t = np.arange(n) / fs  # local time from the first sample; phases are moved to t = 0 at the end
    basis = _Basis(t)
    w = HannWindow().weights(n)  # the interpolated-DFT formula of `_interpolated_bin` is exact for it
    gain = w.sum() / 2.0
    df = fs / n
    nyq_bin = n // 2
    freqs: list[float] = []
    ac = bs = np.zeros(0)
    offset = float(x.mean())
    resid = x - offset
    largest = None
    for _ in range(max_lines):
        X = np.fft.rfft(resid * w)
        a = np.abs(X)
        a[:2] = 0.0
        a[max(nyq_bin - 1, 2) :] = 0.0
        for f in freqs:
            k0 = f / df
            lo, hi = int(math.floor(k0 - min_separation_bins)), int(math.ceil(k0 + min_separation_bins))
            a[max(lo, 0) : max(hi + 1, 0)] = 0.0
        k = int(np.argmax(a))
        peak = a[k] / gain
        if largest is not None and peak < min_relative * largest:
            break
        if peak == 0.0:
            break
        freqs.append(_interpolated_bin(X, k) * df)
        for _p in range(refine_passes):
            basis.retain(freqs)
            ac, bs, offset = _fit(basis, x, w, freqs)
            fitted = _model(basis, freqs, ac, bs, offset)
            resid = x - fitted
            for j, f in enumerate(freqs):
                own = _model(basis, [f], ac[j : j + 1], bs[j : j + 1], 0.0)
                Xj = np.fft.rfft((resid + own) * w)
                k0 = int(round(f / df))
                lo, hi = max(k0 - 2, 1), min(k0 + 3, len(Xj) - 1)
                kj = lo + int(np.argmax(np.abs(Xj[lo:hi])))
                if 1 <= kj < len(Xj) - 1:
                    freqs[j] = _interpolated_bin(Xj, kj) * df
        basis.retain(freqs)
        ac, bs, offset = _fit(basis, x, w, freqs)
        resid = x - _model(basis, freqs, ac, bs, offset)
        largest = float(np.max(np.hypot(ac, bs)))
    f_hz = np.asarray(freqs)
    amp = np.hypot(ac, bs)
    # a cos(2πft) + b sin(2πft) = A sin(2πft + φ) with φ = atan2(a, b); move t = 0 to the record's t = 0.
    phase = np.mod(np.arctan2(ac, bs) - _TWO_PI * f_hz * rec.time[0], _TWO_PI) if len(f_hz) else np.zeros(0)
    order = np.argsort(-amp, kind="stable")
    return SpectralLines(
        freq_cpm=f_hz[order] * 60.0, amplitude=amp[order], phase=phase[order], offset=offset, residual_rms=float(np.sqrt(np.mean(resid**2)))
    )


def spectrum_peaks(
    spec: RecordSpectrum, *, exclude_cpm: Sequence[float] = (), exclude_bins: float = 2.5, count: int = 8
) -> list[tuple[float, float]]:
    """The `count` largest local maxima of a spectrum, as (cpm, amplitude), skipping DC and the
    bins within `exclude_bins` of each frequency in `exclude_cpm` (lines already accounted for)."""
    a = np.asarray(spec.amplitude)
    f = np.asarray(spec.freq_cpm)
    is_peak = np.zeros(len(a), dtype=bool)
    is_peak[1:-1] = (a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:])
    is_peak[: 2 * spec.zero_pad] = False
    for c in exclude_cpm:
        is_peak &= np.abs(f - c) > exclude_bins * spec.resolution_cpm
    idx = np.nonzero(is_peak)[0]
    idx = idx[np.argsort(-a[idx], kind="stable")][:count]
    return [(float(f[i]), float(a[i])) for i in idx]


def record_envelope(rec: Record, *, band_cpm: tuple[float, float], taper: float = 0.1) -> np.ndarray:
    """Envelope (rad) of the part of a record between `band_cpm` = (low, high) cycles per minute.

    The modulus of the analytic signal of the band (FFT band-pass): for two lines a₁, a₂
    in the band it runs between |a₁ − a₂| and a₁ + a₂ at their difference frequency. The
    FFT treats the record as periodic; so that the jump between its end and its start
    does not leak into the band, the record is first tapered to zero over a fraction
    `taper` of its length at each end (a Tukey window). The envelope is exact to
    ~1e-3 relative in the untapered middle and meaningless in the tapered ends.
    """
    lo, hi = (float(v) for v in band_cpm)
    if not 0.0 <= lo < hi:
        raise ValueError(f"band_cpm: need 0 ≤ low < high, got {band_cpm!r}")
    if not 0.0 <= float(taper) < 0.5:
        raise ValueError(f"taper: must be in [0, 0.5), got {taper!r}")
    x = np.asarray(rec.te, dtype=np.float64)
    n = len(x)
    w = np.ones(n)
    m = int(taper * n)
    if m > 0:
        ramp = 0.5 - 0.5 * np.cos(math.pi * np.arange(m) / m)
        w[:m], w[n - m :] = ramp, ramp[::-1]
    X = np.fft.fft((x - x.mean()) * w)
    f = np.fft.fftfreq(n, d=1.0 / rec.sample_rate_hz) * 60.0
    keep = (f >= lo) & (f <= hi)
    z = np.fft.ifft(np.where(keep, 2.0 * X, 0.0))
    return np.abs(z)


def band_envelope(signal: TESignal, theta: ArrayLike, *, band: tuple) -> np.ndarray:
    """Exact envelope (rad) of the lines of a TE signal whose frequencies lie in `band` (multiples of the input speed).

    ``|Σ_j (c_j − i s_j) e^{i k_j f₀ θ}|`` over the lines j in the band: for two lines of
    amplitudes a₁, a₂ this is ``√(a₁² + a₂² + 2 a₁ a₂ cos(Δω θ + Δφ))`` (Liu, sec. 3).
    """
    lo, hi = (Fraction(v) if not isinstance(v, float) else v for v in band)
    theta = np.asarray(theta, dtype=np.float64)
    c = np.asarray(signal.cos_coef)
    s = np.asarray(signal.sin_coef)
    if c.ndim != 1:
        raise ValueError("band_envelope: give one TE signal (unbatched)")
    z = np.zeros(theta.shape, dtype=np.complex128)
    f0 = float(signal.fundamental)
    for j, (k, fr) in enumerate(zip(signal.orders, signal.frequencies)):
        if lo <= fr <= hi:
            z += (c[j] - 1j * s[j]) * np.exp(1j * k * f0 * theta)
    return np.abs(z)
