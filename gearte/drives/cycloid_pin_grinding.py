"""Cycloid-pin reducer: the generating-grinding error model of the disc (the machine's kinematics).

Yao & Liang (2001) model a form-ground disc (the wheel dressed to the whole tooth-space profile,
rigid errors per space: `gearte.drives.cycloid_pin_geometry`). Most discs are generating-ground:
the wheel's working circle, of radius r_Z, is one pin, and the machine moves it relative to the
work as the pin moves relative to the disc in the reducer. This module gives the flank that this
motion leaves when the machine's chains are in error.

**The machine (gearte's kinematic scheme; an assumption stated here, not a particular make).** In
the machine frame the wheel centre W sits on the wheel slide at distance R_Z from a fixed point
O_b; the work spindle turns about a crank (the generating eccentric) of radius a about O_b: one
crank revolution per tooth space, while the work-spindle drive (the indexing chain) turns the
work by 2π/z_a. Relative to tooth space n of the work, with the generating parameter φ ∈ [−π, π]
(the reducer's flank parameter), the wheel centre traces the theoretical curve of the wheel

    P_Z(φ) = R_Z U_1 − a U_2,   U_1 = (sin(φ/z_a), cos(φ/z_a)),   U_2 = (sin(z_b φ/z_a), cos(z_b φ/z_a)),

U_1 being the wheel slide's direction and U_2 the crank's, and the wheel leaves the flank
P_Z − r_Z N_Z (N_Z the unit outward normal; `gearte.drives.cycloid_pin`). The work angle while
space n is ground at φ is (2πn + φ)/z_a: the grinding is continuous from one space to the next.

**The errors, to first order.** An error of the machine moves the wheel centre by a small e(φ)
relative to the work; the envelope of the wheel then moves along the normal by e_n = e · N_Z
(a move along the tangent only slides the wheel along the same envelope), so the generated flank
is P_Z − (r_Z − e_n(φ)) N_Z, a flank with its own equidistant at every φ. With K = a z_b / R_Z,
S = (1 + K² − 2K cos φ)^{1/2} and the identities U_1·N = (1 − K cos φ)/S, U_2·N = (cos φ − K)/S,
U_1^⊥·N = −K sin φ/S (U_1^⊥ = (cos(φ/z_a), −sin(φ/z_a)), the slide's cross direction) and
P_Z × N_Z = a z_a sin φ / S (the lever arm l of the contact):

| error (field of `CycloidErrors`) | e(φ) | e_n(φ) |
|---|---|---|
| wheel slide, δR = `dressing_y` + `infeed`[n] | δR U_1 | δR (1 − K cos φ)/S |
| wheel across the slide, δX = `dressing_x` | δX U_1^⊥ | −δX K sin φ/S |
| wheel radius, δr_w = `wheel_radius` | (the circle grows) | −δr_w |
| crank radius, δa_g = `generating_eccentricity` | −δa_g U_2 | −δa_g (cos φ − K)/S |
| crank angle ε_c(φ) = A_c sin(φ + p_c), counter-clockwise (`generating_chain`) | a ε_c ∂U_2/∂v, v = z_bφ/z_a | −a ε_c sin φ / S |
| work angle within a space, δ_p(φ), clockwise like `indexing` (`pitch_accumulated`) | −δ_p ẑ × P_Z | −δ_p a z_a sin φ / S |

e_n > 0 moves the flank towards the pins (less cut). The work drive's once-per-revolution error
A_p sin((2πn + φ)/z_a + p_p) is split into its value at the space centre, a rigid rotation of
space n added to its index angle (with the per-space `indexing` error, the single pitch
error), and the rest within the space, δ_p(φ) = A_p [sin((2πn + φ)/z_a + p_p) − sin(2πn/z_a + p_p)]
(at most A_p π/z_a). The blank's set-up eccentricity and the mandrel run-out displace the ground
disc rigidly, as in form grinding.

The first-order envelope is exact for a rigid shift along the normal and good to
~e² κ for the rest (κ the flank curvature): below 0.01 µm for errors of 10 µm.

Where each value of the example (``examples/cycloid_yao2001_generating.toml``) comes from is
stated there and in docs/cycloid.md.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from ..core.units import MM_PER_UM, TWO_PI


class GeneratingDeviation(eqx.Module):
    """The generating machine's errors while one tooth space is ground, for `normal_deviation` (mm, rad).

    - `slide`: δR, the wheel's offset along the slide (mm); `across`: δX, across it (mm).
    - `wheel`: δr_w, the wheel radius error (mm); `crank`: δa_g, the crank radius error (mm).
    - `chain`, `chain_phase`: A_c, p_c (rad), the generating chain's once-per-crank-revolution error.
    - `pitch`, `pitch_arg`: A_p (rad) and 2πn/z_a + p_p (rad), the work drive's error at this space.
    """

    slide: Array
    across: Array
    wheel: Array
    crank: Array
    chain: Array
    chain_phase: Array
    pitch: Array
    pitch_arg: Array


def generating_deviation(err, n) -> GeneratingDeviation:
    """The `GeneratingDeviation` of tooth space(s) `n` from a checked `CycloidErrors` (µm, rad)."""
    um = MM_PER_UM
    za = err.infeed.shape[-1]
    return GeneratingDeviation(
        slide=(err.dressing_y + err.infeed[n]) * um,
        across=err.dressing_x * um,
        wheel=err.wheel_radius * um,
        crank=err.generating_eccentricity * um,
        chain=err.generating_chain,
        chain_phase=err.generating_chain_phase,
        pitch=err.pitch_accumulated,
        pitch_arg=jnp.asarray(n).astype(float) * (TWO_PI / za) + err.pitch_accumulated_phase,
    )


def rigid_pitch_error(err, n) -> Array:
    """The work drive's error at the centre of space(s) `n`, A_p sin(2πn/z_a + p_p) (rad), a rigid index error."""
    za = err.infeed.shape[-1]
    return err.pitch_accumulated * jnp.sin(jnp.asarray(n).astype(float) * (TWO_PI / za) + err.pitch_accumulated_phase)


def normal_deviation(g: GeneratingDeviation, phi, *, wheel_pin_circle_radius, eccentricity, z_pins: int) -> Array:
    """e_n(φ): the generated flank's deviation along the outward normal (mm; > 0 towards the pins) at the
    generating parameter φ (rad), for the machine errors `g` (module notes)."""
    za = z_pins - 1
    a = eccentricity
    K = a * z_pins / wheel_pin_circle_radius
    c, s = jnp.cos(phi), jnp.sin(phi)
    S = jnp.sqrt(1.0 + K * K - 2.0 * K * c)
    lever = a * za * s / S  # P_Z × N_Z
    eps_c = g.chain * jnp.sin(phi + g.chain_phase)
    delta_p = g.pitch * (jnp.sin(g.pitch_arg + phi / za) - jnp.sin(g.pitch_arg))
    return g.slide * (1.0 - K * c) / S - g.across * K * s / S - g.wheel - g.crank * (c - K) / S - a * eps_c * s / S - delta_p * lever


__all__ = ("GeneratingDeviation", "generating_deviation", "normal_deviation", "rigid_pitch_error")
