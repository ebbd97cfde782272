"""`gearte.core.twoscale.extrema_two_scale`: the certificate it returns, against independent references.

F = S + b sin(k τ + φ), a slow part S (orders 1-3) and one fast line (order k = 240). The references are SciPy's
(`helpers.reference_extrema`: a dense grid of 64 points per period of the fastest term and bounded Brent refinement
of every grid extremum that could hold the maximum), never gearte's own extrema. Checked:

- the default search finds the extrema (to 1e-12 of the span);
- the gap is the closed form (max S + b) − (value found), with max S from SciPy and b the fast line's amplitude;
- the certificate brackets the true extremum, also where the search is weakened (one candidate, no Newton steps)
  so that it misses the true extremum;
- the value found is never below the lower bound max S + b − ½ D₂ (π/k)², D₂ = Σ k_j² |c_j| over the slow part.
"""

from __future__ import annotations

import math
from fractions import Fraction

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import reference_extrema

from gearte.core.signal import TESignal
from gearte.core.twoscale import extrema_two_scale

K = 240
ORDERS = (1, 2, 3, K)
SCALE = np.array([1.0, 0.7, 0.5, 0.3])  # amplitudes' ranges (rad, arbitrary): the fast line the smallest


@pytest.fixture(scope="module")
def cases():
    rng = np.random.default_rng(20261128)
    amps = rng.uniform(0.2, 1.0, (12, 4)) * SCALE
    phases = rng.uniform(0.0, 2 * math.pi, (12, 4))
    sig = TESignal(
        offset=jnp.zeros(12),
        cos_coef=jnp.asarray(amps * np.sin(phases)),  # A sin(kθ + φ) = A sin φ cos kθ + A cos φ sin kθ
        sin_coef=jnp.asarray(amps * np.cos(phases)),
        orders=ORDERS,
        fundamental=Fraction(1),
    )
    full = [reference_extrema(a, p, ORDERS) for a, p in zip(amps, phases)]
    slow = [reference_extrema(a[:3], p[:3], ORDERS[:3]) for a, p in zip(amps, phases)]
    return amps, sig, np.array(full), np.array(slow)


def _gap_bounds(amps):
    """(b, ½ D₂ (π/k)²) per case: the fast line's amplitude and the most the slow part drops within π/k."""
    d2 = np.sum(np.array(ORDERS[:3]) ** 2 * amps[:, :3], axis=1)
    return amps[:, 3], 0.5 * d2 * (math.pi / K) ** 2


def test_default_search_finds_the_extrema_and_its_gap_is_the_closed_form(cases):
    amps, sig, full, slow = cases
    two = extrema_two_scale(sig)
    span = full[:, 0] - full[:, 1]
    np.testing.assert_array_less(np.abs(np.asarray(two.max) - full[:, 0]), 1e-12 * span)
    np.testing.assert_array_less(np.abs(np.asarray(two.min) - full[:, 1]), 1e-12 * span)
    b, drop = _gap_bounds(amps)
    # (max S + b) − max found, and max found − (min S − b) for the minimum.
    np.testing.assert_allclose(np.asarray(two.max_gap), slow[:, 0] + b - np.asarray(two.max), rtol=0, atol=1e-12 * span.max())
    np.testing.assert_allclose(np.asarray(two.min_gap), np.asarray(two.min) - (slow[:, 1] - b), rtol=0, atol=1e-12 * span.max())
    # The gaps are real (the crests of the fast line miss the slow part's extrema) and within the a-priori bound.
    assert np.all(np.asarray(two.max_gap) > 1e-9 * span) and np.all(np.asarray(two.min_gap) > 1e-9 * span)
    assert np.all(np.asarray(two.max_gap) <= drop) and np.all(np.asarray(two.min_gap) <= drop)


def test_certificate_brackets_the_true_extrema_where_the_search_misses_them(cases):
    amps, sig, full, _ = cases
    weak = extrema_two_scale(sig, candidates=1, newton_steps=0)
    span = full[:, 0] - full[:, 1]
    found_max, found_min = np.asarray(weak.max), np.asarray(weak.min)
    gap_max, gap_min = np.asarray(weak.max_gap), np.asarray(weak.min_gap)
    slack = 1e-12 * span
    # Values of F at points: never beyond the true extrema. The true ones lie within the gaps.
    assert np.all(found_max <= full[:, 0] + slack) and np.all(found_min >= full[:, 1] - slack)
    assert np.all(full[:, 0] <= found_max + gap_max + slack) and np.all(full[:, 1] >= found_min - gap_min - slack)
    # The weakened search does miss: otherwise this test would not exercise the certificate.
    missed = np.maximum(full[:, 0] - found_max, found_min - full[:, 1])
    assert np.sum(missed > 1e-8 * span) >= 3, missed / span
    # Still within the a-priori bound: the crests nearest the slow part's extremum are among the starts.
    _, drop = _gap_bounds(amps)
    assert np.all(gap_max <= drop) and np.all(gap_min <= drop)
