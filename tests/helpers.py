"""Shared problems and independent references for the tests."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
from scipy.optimize import minimize_scalar


def trig_eval(amps, phases, freqs, theta):
    """Σ A sin(r θ + φ) evaluated plainly in NumPy (independent of gearte)."""
    theta = np.asarray(theta, dtype=np.float64)
    out = np.zeros_like(theta)
    for a, p, r in zip(amps, phases, freqs):
        out += a * np.sin(float(r) * theta + p)
    return out


def hyper_period(freqs) -> float:
    """Hyper-period in input rad of rational frequencies (multiples of the input speed)."""
    nz = [abs(Fraction(f)) for f in freqs if Fraction(f) != 0]
    if not nz:
        return 2 * math.pi
    num = 0
    den = 1
    for v in nz:
        num, den = math.gcd(num * v.denominator, v.numerator * den), den * v.denominator
    g = Fraction(num, den)
    return 2 * math.pi / float(g)


def reference_extrema(amps, phases, freqs, *, per_period: int = 64):
    """Max and min of Σ A sin(rθ + φ) over the hyper-period: a dense grid (`per_period`
    points per period of the fastest term), then bounded Brent refinement around every
    grid local extremum (scipy), to ~1e-13 in θ."""
    T = hyper_period(freqs)
    rmax = max((abs(float(Fraction(f))) for f in freqs), default=1.0) or 1.0
    n = int(per_period * rmax * T / (2 * math.pi)) + 8
    th = np.linspace(0.0, T, n, endpoint=False)
    h = th[1] - th[0]
    f = trig_eval(amps, phases, freqs, th)
    # Within h of a grid point, a local extremum exceeds that point's value by at most
    # h²/2 · max|f''| ≤ h²/2 · Σ r²|A|: grid extrema below the best grid value by more than
    # that cannot hold the extremum, and skipping their refinement changes no result.
    bound = 0.5 * h * h * sum(float(Fraction(r)) ** 2 * abs(a) for a, r in zip(amps, freqs))
    out = []
    for sign in (1.0, -1.0):
        g = sign * f
        loc = np.nonzero((g >= np.roll(g, 1)) & (g >= np.roll(g, -1)))[0]
        best = g.max()
        loc = loc[g[loc] + 2.0 * bound >= best]  # (twice the bound: a margin for rounding)
        for i in loc:
            r = minimize_scalar(
                lambda t, sign=sign: -sign * trig_eval(amps, phases, freqs, np.array([t]))[0],
                bounds=(th[i] - h, th[i] + h),
                method="bounded",
                options={"xatol": 1e-13},
            )
            best = max(best, -r.fun)
        out.append(sign * best)
    return out[0], out[1]
