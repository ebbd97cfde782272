"""Spectra of TE records (`gearte.record_spectrum`): every window against the closed form of a line at a bin centre and
the published scalloping losses of a line half-way between two bins (Harris 1978, table 1: rectangle 3.92 dB, Hann
1.42 dB; a flat-top window below 0.01 dB), and windows as option objects."""

from __future__ import annotations

import numpy as np
import pytest

import gearte
from gearte.core.records import WINDOWS, AbstractWindow

FS = 1000.0  # Hz
N = 4096  # samples
RPM = 60.0


def _record(bins: float, amplitude: float = 3e-5, phase: float = 0.7) -> gearte.Record:
    """A record of one sinusoid of `amplitude` (rad) at `bins` × the bin spacing, plus an offset."""
    t = np.arange(N) / FS
    te = 1e-4 + amplitude * np.sin(2 * np.pi * bins * FS / N * t + phase)
    return gearte.Record(time=t, theta=2 * np.pi * RPM / 60.0 * t, te=te, input_rpm=RPM, sample_rate_hz=FS)


def _peak(spec) -> tuple[float, float]:
    k = int(np.argmax(spec.amplitude))
    return float(spec.freq_cpm[k]), float(spec.amplitude[k])


@pytest.mark.parametrize("window", [w() for w in WINDOWS.values()], ids=list(WINDOWS))
def test_a_line_at_a_bin_centre_reads_its_amplitude_and_frequency(window: AbstractWindow):
    """2|X_k| / Σw = A for a sinusoid at bin k, for any periodic window (its image at −k leaks nothing there)."""
    spec = gearte.record_spectrum(_record(200.0), window=window)
    freq, amp = _peak(spec)
    assert freq == pytest.approx(200.0 * FS / N * 60.0, rel=1e-12)
    assert amp == pytest.approx(3e-5, rel=1e-12, abs=0)  # (approx would otherwise allow 1e-12 rad absolute)
    assert spec.window == window


@pytest.mark.parametrize("window", [w() for w in WINDOWS.values()], ids=list(WINDOWS))
def test_a_line_between_bins_reads_the_windows_scalloping_loss(window: AbstractWindow):
    """The largest loss over a bin's width: at half a bin for Hann and the rectangle, Harris's 1.42 and 3.92 dB; within
    0.01 dB anywhere for the flat-top. Each window's `scalloping_db` states it."""
    loss = [-20 * np.log10(_peak(gearte.record_spectrum(_record(200.0 + d), window=window))[1] / 3e-5) for d in np.linspace(0, 0.5, 11)]
    published = {"hann": 1.42, "rectangular": 3.92}
    if window.name in published:
        assert max(loss) == pytest.approx(published[window.name], abs=0.01)
        assert loss[-1] == pytest.approx(max(loss), abs=1e-9)  # half a bin is the worst
    else:
        assert max(loss) <= 0.01
    assert max(loss) <= window.scalloping_db + 0.005


def test_flat_top_reads_a_line_between_bins_where_hann_reads_it_low():
    """What the flat-top window is for: a mesh-order line half a bin off the grid, read off the spectrum."""
    rec = _record(200.5)
    flat = _peak(gearte.record_spectrum(rec, window=gearte.FlatTopWindow()))[1]
    hann = _peak(gearte.record_spectrum(rec, window=gearte.HannWindow()))[1]
    assert flat == pytest.approx(3e-5, rel=1.2e-3)
    assert hann < 0.86 * 3e-5  # 1.42 dB low


@pytest.mark.parametrize(
    "window, message",
    [
        ("hann", "for 'hann', write gearte.HannWindow()"),
        ("flat top", "for 'flat top', write gearte.FlatTopWindow()"),
        (gearte.HannWindow, "(an instance: HannWindow())"),
        (None, "must be HannWindow() or FlatTopWindow() or RectangularWindow()"),
    ],
)
def test_a_window_is_an_object(window, message):
    with pytest.raises(ValueError, match=r"^window: ") as info:
        gearte.record_spectrum(_record(200.0), window=window)
    assert message in str(info.value)
