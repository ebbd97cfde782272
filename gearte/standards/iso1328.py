"""ISO 1328 accuracy grades: gear tolerances from module, reference diameter and face width.

Two standards are supported, named by the `standard` argument:

- `"1328-1:2013"`: ISO 1328-1:2013, flank tolerance classes 1 to 11, evaluated at
  the gear's own module m, reference diameter d and face width b.
- `"1328-1:1995"`: ISO 1328-1:1995 with ISO 1328-2:1997 (run-out), identical to
  GB/T 10095.1-2008 and GB/T 10095.2-2008, accuracy grades 0 to 12, evaluated at the
  geometric mean of the limits of the range that contains m, d and b, as the
  published tables are.

In both, one grade is a factor √2: the value of grade Q is the unrounded grade-5
value times 2^((Q − 5)/2), so halving a tolerance costs two grades. The published
value is then rounded ("rounding the final value only"): above 10 µm to 1 µm, from
5 µm to 10 µm to 0.5 µm, below 5 µm to 0.1 µm (`round_tolerance`).

Quantities (all in µm) are named by the keys

| key         | meaning                         | 2013 symbol | 1995 symbol |
|-------------|---------------------------------|-------------|-------------|
| `"f_pt"`    | single pitch tolerance          | f_pT        | f_pt        |
| `"F_p"`     | total cumulative pitch          | F_pT        | F_p         |
| `"F_alpha"` | total profile                   | F_αT        | F_α         |
| `"F_beta"`  | total helix                     | F_βT        | F_β         |
| `"F_r"`     | radial run-out                  | F_rT        | F_r         |

The whole-grade, rounded values are what a drawing carries (`iso1328_tolerances`);
the continuous, unrounded law (`iso1328_tolerance`, `grade_for_tolerance`) is what an
optimiser differentiates.
"""

from __future__ import annotations

import math
import numbers

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..core.validate import is_traced

STANDARDS: tuple[str, ...] = ("1328-1:2013", "1328-1:1995")
QUANTITIES: tuple[str, ...] = ("f_pt", "F_p", "F_alpha", "F_beta", "F_r")

GRADES = {"1328-1:2013": (1, 11), "1328-1:1995": (0, 12)}

# ISO 1328-1:2013, scope: 0.5 ≤ m ≤ 70, 5 ≤ d ≤ 15000, 4 ≤ b ≤ 1200 (mm), 5 ≤ z ≤ 1000.
_RANGE_2013 = {"module": (0.5, 70.0), "diameter": (5.0, 15000.0), "face_width": (4.0, 1200.0)}
_TEETH_2013 = (5, 1000)

# ISO 1328-1:1995 / GB/T 10095.1-2008: the limits of the ranges of the published tables.
_LIMITS_1995 = {
    "module": (0.5, 2.0, 3.5, 6.0, 10.0, 16.0, 25.0, 40.0, 70.0),
    "diameter": (5.0, 20.0, 50.0, 125.0, 280.0, 560.0, 1000.0, 1600.0, 2500.0, 4000.0, 6000.0, 8000.0, 10000.0),
    "face_width": (4.0, 10.0, 20.0, 40.0, 80.0, 160.0, 250.0, 400.0, 650.0, 1000.0),
}

_SYMBOL = {"module": "m", "diameter": "d", "face_width": "b"}


def check_standard(standard: str) -> str:
    if standard not in STANDARDS:
        raise ValueError(f"standard: expected one of {', '.join(repr(s) for s in STANDARDS)}, got {standard!r}")
    return standard


def _quantity(quantity: str) -> str:
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity: expected one of {', '.join(repr(q) for q in QUANTITIES)}, got {quantity!r}")
    return quantity


def check_length(name: str, value, standard: str) -> float:
    """`value` (mm) as a finite length within the range of ISO `standard` for `name` (``"module"``, ``"diameter"``
    or ``"face_width"``); ValueError naming it and the range otherwise."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number (mm), got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    lo, hi = _RANGE_2013[name] if standard == "1328-1:2013" else (_LIMITS_1995[name][0], _LIMITS_1995[name][-1])
    if not lo <= v <= hi:
        s = _SYMBOL[name]
        raise ValueError(f"{name} = {v:g} mm is outside the range of ISO {standard}: {lo:g} ≤ {s} ≤ {hi:g} mm")
    return v


def _range_mean(name: str, v: float) -> float:
    """Geometric mean of the limits of the 1995 range that contains `v`.

    The ranges are closed above and open below (5 ≤ d ≤ 20, 20 < d ≤ 50, ...), the
    first one closed at both ends, so a value on a limit takes the lower range.
    """
    limits = _LIMITS_1995[name]
    for lo, hi in zip(limits[:-1], limits[1:]):
        if v <= hi:
            return math.sqrt(lo * hi)
    raise AssertionError("unreachable: range checked by check_length")


def _teeth(teeth, standard: str) -> None:
    if teeth is None:
        return
    if isinstance(teeth, bool) or not isinstance(teeth, numbers.Integral):
        raise ValueError(f"teeth: expected a whole number, got {teeth!r}")
    z = int(teeth)
    if standard == "1328-1:2013":
        lo, hi = _TEETH_2013
        if not lo <= z <= hi:
            raise ValueError(f"teeth = {z} is outside the range of ISO 1328-1:2013: {lo} ≤ z ≤ {hi}")
    elif z < 1:
        raise ValueError(f"teeth: must be ≥ 1, got {z}")


def grade_range(standard: str) -> tuple[int, int]:
    """Finest and coarsest whole grade of `standard`: (1, 11) for 2013, (0, 12) for 1995."""
    return GRADES[check_standard(standard)]


def _whole_grade(grade, standard: str) -> int:
    lo, hi = GRADES[standard]
    if isinstance(grade, bool):
        raise ValueError(f"grade: expected a whole number from {lo} to {hi}, got {grade!r}")
    if isinstance(grade, numbers.Integral):
        q = int(grade)
    else:
        try:
            g = float(grade)
        except (TypeError, ValueError):
            raise ValueError(f"grade: expected a whole number from {lo} to {hi}, got {grade!r}") from None
        if not (math.isfinite(g) and g.is_integer()):
            raise ValueError(f"grade: ISO {standard} has whole grades only, got {grade!r}; use `iso1328_tolerance` for a continuous grade")
        q = int(g)
    if not lo <= q <= hi:
        raise ValueError(f"grade {q} is outside ISO {standard}'s grades {lo} (finest) to {hi} (coarsest)")
    return q


def _grade5(quantity: str, standard: str, module, diameter, face_width, teeth) -> float:
    """Validated, unrounded grade-5 value (µm) of one quantity."""
    standard = check_standard(standard)
    quantity = _quantity(quantity)
    m = check_length("module", module, standard)
    d = check_length("diameter", diameter, standard)
    b = None if face_width is None else check_length("face_width", face_width, standard)
    _teeth(teeth, standard)
    if quantity == "F_beta" and b is None:
        raise ValueError("F_beta (total helix tolerance) needs the face width: pass face_width (mm)")
    if standard == "1328-1:2013":
        # ISO 1328-1:2013 tolerance formulae (docs: tolerances.md); F_αT and F_βT combine the
        # unrounded slope and form parts.
        if quantity == "f_pt":
            return 0.001 * d + 0.4 * m + 5.0
        if quantity in ("F_p", "F_r"):
            F_p = 0.002 * d + 0.55 * math.sqrt(d) + 0.7 * m + 12.0
            return F_p if quantity == "F_p" else 0.9 * F_p
        if quantity == "F_alpha":
            f_H = 0.4 * m + 0.001 * d + 4.0
            f_f = 0.55 * m + 5.0
            return math.hypot(f_H, f_f)
        assert b is not None  # F_beta needs it (checked above)
        f_H = 0.05 * math.sqrt(d) + 0.35 * math.sqrt(b) + 4.0
        f_f = 0.07 * math.sqrt(d) + 0.45 * math.sqrt(b) + 4.0
        return math.hypot(f_H, f_f)
    # ISO 1328-1:1995 / ISO 1328-2:1997 (GB/T 10095.1/.2-2008), at the ranges' geometric means.
    m = _range_mean("module", m)
    d = _range_mean("diameter", d)
    if quantity == "f_pt":
        return 0.3 * (m + 0.4 * math.sqrt(d)) + 4.0
    if quantity == "F_p":
        return 0.3 * m + 1.25 * math.sqrt(d) + 7.0
    if quantity == "F_alpha":
        return 3.2 * math.sqrt(m) + 0.22 * math.sqrt(d) + 0.7
    if quantity == "F_r":
        # ISO 1328-2:1997, Annex B: F_r = 0.8 F_p.
        return 0.24 * m + 1.0 * math.sqrt(d) + 5.6
    assert b is not None  # F_beta needs it (checked above)
    b = _range_mean("face_width", b)
    return 0.1 * math.sqrt(d) + 0.63 * math.sqrt(b) + 4.2


def round_tolerance(value_um: float) -> float:
    """Round a tolerance as ISO 1328 publishes it.

    Above 10 µm to the nearest 1 µm; from 5 µm to 10 µm (both included) to the nearest
    0.5 µm; below 5 µm to the nearest 0.1 µm. An exact half-way value is rounded up.
    The rounding is monotone: a larger value never rounds to a smaller one.

    **Arguments:**

    - `value_um`: unrounded tolerance, µm, finite and ≥ 0.

    **Returns:** the rounded tolerance, µm (a float that prints as the published value).
    """
    v = float(value_um)
    if not (math.isfinite(v) and v >= 0):
        raise ValueError(f"value_um: expected a finite tolerance ≥ 0 µm, got {value_um!r}")
    step = 1.0 if v > 10.0 else 0.5 if v >= 5.0 else 0.1
    return round(math.floor(v / step + 0.5) * step, 1)


def iso1328_tolerance(
    quantity: str,
    *,
    standard: str,
    module: float,
    diameter: float,
    face_width: float | None = None,
    grade: ArrayLike,
    teeth: int | None = None,
) -> Float[Array, ...]:
    """Unrounded tolerance of one quantity at a continuous grade (for optimisers).

    T(Q) = T₅ · 2^((Q − 5)/2), with T₅ the unrounded grade-5 value of the standard's
    formula. At a whole grade this is the value before `round_tolerance`. Between and
    beyond the standard's grades the √2-per-grade law is simply continued: the standard
    defines whole grades only, so a non-whole grade, or one outside `grade_range`, is an
    interpolation or extrapolation of that law, not a value of the standard.

    The result is a JAX array, differentiable in `grade` (dT/dQ = T · ln 2 / 2) and
    traceable under `jit`/`vmap`/`grad`; the geometry is plain Python numbers,
    validated when called.

    **Arguments:**

    - `quantity`: `"f_pt"`, `"F_p"`, `"F_alpha"`, `"F_beta"` or `"F_r"`.
    - `standard`: `"1328-1:2013"` or `"1328-1:1995"`.
    - `module`, `diameter`: normal module m and reference diameter d, mm.
    - `face_width`: face width b, mm; required for `"F_beta"`, range-checked when given.
    - `grade`: continuous grade (float or array; finite when concrete).
    - `teeth`: number of teeth z (optional); ISO 1328-1:2013 applies for 5 ≤ z ≤ 1000.

    **Returns:** the tolerance, µm, with the shape of `grade`.
    """
    base = _grade5(quantity, standard, module, diameter, face_width, teeth)
    if not is_traced(grade):
        g = np.asarray(grade, dtype=float)
        if not np.all(np.isfinite(g)):
            raise ValueError(f"grade: must be finite, got {grade!r}")
    q = jnp.asarray(grade, dtype=float)
    return base * jnp.exp2((q - 5.0) / 2.0)


def iso1328_tolerances(
    *,
    standard: str,
    module: float,
    diameter: float,
    face_width: float | None = None,
    grade: int,
    teeth: int | None = None,
) -> dict[str, float]:
    """The published (rounded) tolerances of a whole grade.

    **Arguments:**

    - `standard`: `"1328-1:2013"` (classes 1–11, formulae at the gear's own m, d, b) or
      `"1328-1:1995"` (ISO 1328-1:1995 with ISO 1328-2:1997 for run-out; = GB/T 10095.1/.2-2008;
      grades 0–12). For 1995, m, d and b are replaced by the geometric mean of the limits of
      the range containing them, as in the standard's tables. The ranges are
      m: 0.5/2/3.5/6/10/16/25/40/70, d: 5/20/50/125/280/560/1000/1600/2500/4000/6000/8000/10000,
      b: 4/10/20/40/80/160/250/400/650/1000 mm, with the tables' convention that a range
      includes its upper limit and excludes its lower one (5 ≤ d ≤ 20, 20 < d ≤ 50, …):
      d = 20 mm is evaluated at √(5·20) = 10 mm, d = 20.1 mm at √(20·50) mm.
    - `module`: normal module m, mm (2013: 0.5–70; 1995: 0.5–70).
    - `diameter`: reference diameter d, mm (2013: 5–15000; 1995: 5–10000).
    - `face_width`: face width b, mm (2013: 4–1200; 1995: 4–1000). Optional: without it
      the result has no `"F_beta"` key (the helix tolerance depends on b).
    - `grade`: whole accuracy grade (2013: 1–11; 1995: 0–12); 1 or 0 is the finest.
    - `teeth`: number of teeth z (optional, checked only): ISO 1328-1:2013 applies for
      5 ≤ z ≤ 1000. Its helix-angle limit β ≤ 45° is not checked.

    Out-of-range geometry, an unknown standard, or a non-whole or out-of-range grade raise
    `ValueError` naming the parameter and its range.

    The value of grade Q is the *unrounded* grade-5 value times 2^((Q − 5)/2), rounded once
    at the end (`round_tolerance`); F_α and F_β of the 2013 standard combine the unrounded
    slope and form parts, and F_r is 0.9 F_p (2013) or 0.8 F_p (1995) before rounding.
    For the 1995 standard this order — scale the unrounded grade-5 value, then round — is
    the one stated in ISO 1328-1:1995, clause 5 (GB/T 10095.1-2008, 5.2: "the unrounded
    calculated value of grade 5 multiplied by 2^(0.5(Q−5))", then the rounding rules), and it
    is the one that reproduces the published tables: for 5 ≤ d ≤ 20 mm, 0.5 ≤ m ≤ 2 mm,
    F_p of grade 7 is 11.253 · 2 = 22.5 → 23 µm as tabulated, where doubling the rounded
    grade-5 value (11 µm) would give 22 µm.

    **Returns:** `{"f_pt", "F_p", "F_alpha", ["F_beta",] "F_r"}` → tolerance, µm.
    """
    standard = check_standard(standard)
    q = _whole_grade(grade, standard)
    scale = 2.0 ** ((q - 5) / 2.0)
    out = {}
    for name in QUANTITIES:
        if name == "F_beta" and face_width is None:
            continue
        out[name] = round_tolerance(_grade5(name, standard, module, diameter, face_width, teeth) * scale)
    return out


def grade_for_tolerance(
    value_um: ArrayLike,
    *,
    quantity: str,
    standard: str,
    module: float,
    diameter: float,
    face_width: float | None = None,
    teeth: int | None = None,
) -> Float[Array, ...]:
    """The continuous grade whose unrounded tolerance is `value_um`: the inverse of `iso1328_tolerance`.

    Q = 5 + 2 log₂(T / T₅), T₅ the unrounded grade-5 value. Not clamped: a tolerance finer
    than the finest grade gives a grade below it (e.g. negative), one coarser than the
    coarsest a grade above it. Differentiable and traceable in `value_um`.

    **Arguments:**

    - `value_um`: tolerance, µm (> 0 and finite when concrete; float or array).
    - `quantity`, `standard`, `module`, `diameter`, `face_width`, `teeth`: as in
      `iso1328_tolerance`.

    **Returns:** the continuous grade, with the shape of `value_um`.
    """
    base = _grade5(quantity, standard, module, diameter, face_width, teeth)
    if not is_traced(value_um):
        v = np.asarray(value_um, dtype=float)
        if not np.all(np.isfinite(v) & (v > 0)):
            raise ValueError(f"value_um: a tolerance must be finite and > 0 µm, got {value_um!r}")
    t = jnp.asarray(value_um, dtype=float)
    return 5.0 + 2.0 * jnp.log2(t / base)


def nearest_grade(
    value_um: float,
    *,
    quantity: str,
    standard: str,
    module: float,
    diameter: float,
    face_width: float | None = None,
    teeth: int | None = None,
) -> int:
    """The coarsest whole grade whose published (rounded) tolerance is ≤ `value_um`.

    This is the grade a designer writes on the drawing for a budget of `value_um`: the
    cheapest grade that still keeps the quantity within the budget. A coarser grade would
    allow more than the budget; every finer grade also meets it but costs more. Rounded
    values are compared, since they are what the gear is inspected against.

    Beyond the grade range: if even the coarsest grade's tolerance is within the budget,
    the coarsest grade is returned (no grade of the standard is cheaper); if the finest
    grade's tolerance exceeds the budget, no grade meets it and `ValueError` is raised.

    **Arguments:**

    - `value_um`: the tolerance budget, µm (> 0, finite).
    - `quantity`, `standard`, `module`, `diameter`, `face_width`, `teeth`: as in
      `iso1328_tolerance`.

    **Returns:** the grade (int).
    """
    try:
        v = float(value_um)
    except (TypeError, ValueError):
        raise ValueError(f"value_um: expected a number (µm), got {value_um!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"value_um: a tolerance must be finite and > 0 µm, got {value_um!r}")
    base = _grade5(quantity, standard, module, diameter, face_width, teeth)
    lo, hi = GRADES[standard]
    for q in range(hi, lo - 1, -1):
        if round_tolerance(base * 2.0 ** ((q - 5) / 2.0)) <= v:
            return q
    finest = round_tolerance(base * 2.0 ** ((lo - 5) / 2.0))
    raise ValueError(
        f"{quantity} ≤ {v:g} µm is finer than ISO {standard}'s finest grade {lo} ({finest:g} µm for this gear); no grade meets it"
    )


def eccentricity_from_runout(F_r_um: ArrayLike) -> Float[Array, ...]:
    """Eccentricity (µm) from a radial run-out (µm): e = F_r / 2.

    Run-out is measured as the radial range of a probe over one turn, which an eccentric
    gear swings through twice its eccentricity, so e ≈ F_r / 2 (tolerances.md, "From
    tolerance to error magnitude"). Apply it to the run-out tolerance to get the largest
    eccentricity the tolerance allows.

    **Arguments:**

    - `F_r_um`: radial run-out, µm (≥ 0, finite when concrete; float or array).

    **Returns:** eccentricity, µm, with the shape of `F_r_um`.
    """
    if not is_traced(F_r_um):
        v = np.asarray(F_r_um, dtype=float)
        if not np.all(np.isfinite(v) & (v >= 0)):
            raise ValueError(f"F_r_um: a run-out must be finite and ≥ 0 µm, got {F_r_um!r}")
    return 0.5 * jnp.asarray(F_r_um, dtype=float)
