"""Where the planets of a planetary stage sit: their angles, the assembly condition and the clash of neighbours.

Shared by the 2K-H planetary drive (`gearte.drives.planetary_2kh`) and the helical stage
(`gearte.drives.helical_geometry`). Angles in rad about the sun's axis, lengths in mm.
"""

from __future__ import annotations

import math

import numpy as np

from ..core.validate import as_float


def most_planets(centre_distance: float, tip_diameter: float) -> int:
    """The most planets of tip circle `tip_diameter` that fit around the sun at `centre_distance` (mm), equally
    spaced: the most n whose gap keeps the planets' centres 2 a sin(π/n) apart by more than the tip diameter."""
    x = tip_diameter / (2 * centre_distance)
    return 1 if x >= 1 else max(1, math.ceil(math.pi / math.asin(x)) - 1)


def check_planet_count(n: int, centre_distance: float, tip_diameter: float, *, z_sun: int, z_planet: int) -> None:
    """Refuse more planets than fit around the sun (`most_planets`), before any list of n angles is made (a count of
    2³² would otherwise exhaust the memory before the angles could be checked)."""
    n_fit = most_planets(centre_distance, tip_diameter)
    if n > n_fit:
        raise ValueError(
            f"n_planets: planets clash: {n} planets of {z_planet} teeth do not fit around a {z_sun}-tooth sun (tip circles of "
            f"{tip_diameter:.1f} mm diameter overlap); at most {n_fit} fit"
        )


def planet_angles(planet_angles, n: int) -> list[float]:
    """The planets' angles (rad): equally spaced where `planet_angles` is None, else the given list of n angles."""
    if planet_angles is None:
        return [2 * math.pi * i / n for i in range(n)]
    if isinstance(planet_angles, (str, bytes)) or np.ndim(planet_angles) != 1:
        raise ValueError(f"planet_angles: a list of angles (rad), one per planet, got {planet_angles!r}")
    angles = [as_float(f"planet_angles[{i}]", x) for i, x in enumerate(planet_angles)]
    if len(angles) != n:
        raise ValueError(f"planet_angles: {len(angles)} angles for n_planets = {n}")
    return angles


def check_assembly(angles: list[float], z_sun: int, z_ring: int, *, equally_spaced: bool) -> None:
    """Planet i meshes with sun and ring at once only if (z_sun + z_ring) η_i / 2π is whole, η_i its angle from
    planet 1."""
    n = len(angles)
    for i, ang in enumerate(angles[1:], start=1):
        q = (z_sun + z_ring) * (ang - angles[0]) / (2 * math.pi)
        if abs(q - round(q)) > 1e-6:
            raise ValueError(
                f"planet_angles: planet {i + 1} at {math.degrees(ang - angles[0]):.6g}° from planet 1 cannot be assembled: "
                f"(z_sun + z_ring)·η/360° = {q:.6g} must be a whole number"
                + (f"; {n} equally spaced planets need (z_sun + z_ring)/{n} whole ({z_sun + z_ring}/{n})" if equally_spaced else "")
            )


def smallest_spacing(angles: list[float], centre_distance: float) -> float:
    """The smallest distance (mm) between the centres of two neighbouring planets, 2 a sin(Δ/2) for the smallest
    angular gap Δ between them (0 for two planets at one place)."""
    order = sorted(x % (2 * math.pi) for x in angles)
    n = len(order)
    gap = min((order[(i + 1) % n] - order[i]) % (2 * math.pi) for i in range(n))
    return 2 * centre_distance * math.sin(gap / 2)
