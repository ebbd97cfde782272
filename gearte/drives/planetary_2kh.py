"""2K-H planetary train: eccentricity errors → transmission error.

Source: Wang, Chen, Li, Chen (2013), "Coupling compensation of transmission error
for planetary gear", Trans. CSAM 44(8):287-292, sections 1-2, Table 2.

Each eccentricity, projected on a line of action (LOA), gives an equivalent mesh
error ``±E sin((ω_member − ω_c) t + phase terms)``, because every LOA is fixed in
the carrier. The sun–planet (external, e_w) and ring–planet (internal, e_n) mesh
errors of one planet path move the output by

    r_bs δ_s + r_br δ_r − (r_bs + r_br) δ_c = −(e_w + e_n)        (µm → mm: × 10⁻³)

with δ the small rotations of sun, ring and carrier and r_b the base radii. With the
input and the fixed member at δ = 0 this gives the output error; for sun input,
carrier output and ring fixed it is the paper's ``Δθ_sc = (e_w + e_n)/(2 a cos α)``
(eq. 9's prefactor 1/(48000 cos π/9) for Table 1).

Kinematics are computed from the tooth counts (Willis), so the planet terms of the
paper's example are at |ω_p − ω_c| = 7/24 ω_s, not the 11/24 printed in its eq. (9)
(see `wang2013.eq9_drive` for the literal equation).
"""

from __future__ import annotations

import abc
import math
from collections.abc import Mapping, Sequence
from fractions import Fraction
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..core.schema import ConfigError, Table
from ..core.signal import Components
from ..core.units import ARCSEC_PER_RAD
from ..core.validate import as_float, as_int, check_option
from .planet_layout import check_assembly, check_planet_count, smallest_spacing
from .planet_layout import planet_angles as planet_angles_of
from .protocol import AbstractSinusoidalDrive, Eccentricity, SourceSpec

MEMBERS = ("sun", "carrier", "ring")


class AbstractPlanetCoupling(eqx.Module):
    """How the planets' paths combine into the output error of a `Planetary2KH`: the output error is the mean of
    the paths of the planets that `paths` names, each path with its own planet's errors and its own position η_i."""

    #: The coupling's name in study files (``[drive] coupling = …``).
    name: ClassVar[str]
    #: What the report says of the coupling.
    description: ClassVar[str]

    @abc.abstractmethod
    def paths(self, n_planets: int) -> range:
        """The planets (0 = planet 1) whose paths set the output."""


class SinglePath(AbstractPlanetCoupling):
    """Every planet behaves like planet 1, and planet 1's path alone sets the output (Wang et al. 2013's
    assumption). Study files: ``coupling = "single_path"``."""

    name: ClassVar[str] = "single_path"
    description: ClassVar[str] = "single path: planet 1's path alone (the paper's assumption)"

    def paths(self, n_planets: int) -> range:
        del n_planets
        return range(1)


class LoadSharing(AbstractPlanetCoupling):
    """The planets share the load equally (a floating member, or equal mesh compliances): the output error is the
    mean of the N planets' path errors, so equally spaced planets cancel the first harmonic of the sun's and the
    ring's eccentricities. Study files: ``coupling = "load_sharing"``."""

    name: ClassVar[str] = "load_sharing"
    description: ClassVar[str] = "equal load sharing: mean of the N planet paths"

    def paths(self, n_planets: int) -> range:
        return range(n_planets)


#: The couplings by their names in study files.
COUPLINGS: dict[str, type[AbstractPlanetCoupling]] = {c.name: c for c in (SinglePath, LoadSharing)}

#: Error sources of the 2K-H model, their phase symbols in the paper, and whether one per planet.
SOURCES = {
    "sun_manufacturing": ("beta_s", False),
    "planet_manufacturing": ("beta_p", True),
    "ring_manufacturing": ("beta_r", False),
    "sun_assembly": ("gamma_s", False),
    "planet_assembly": ("gamma_p", True),
    "carrier_assembly": ("gamma_c", False),
}


_as_int = as_int


def _as_float(name: str, value, *, positive: bool = False) -> float:
    return as_float(name, value, positive=positive)


def member_speeds(z_sun: int, z_ring: int, *, input: str, fixed: str) -> dict[str, Fraction]:
    """Exact speeds of sun, carrier and ring for unit input speed (Willis: z_s ω_s + z_r ω_r = (z_s + z_r) ω_c)."""
    free = next(m for m in MEMBERS if m not in (input, fixed))
    w = {input: Fraction(1), fixed: Fraction(0)}
    if free == "carrier":
        w["carrier"] = (z_sun * w["sun"] + z_ring * w["ring"]) / (z_sun + z_ring)
    elif free == "sun":
        w["sun"] = ((z_sun + z_ring) * w["carrier"] - z_ring * w["ring"]) / z_sun
    else:
        w["ring"] = ((z_sun + z_ring) * w["carrier"] - z_sun * w["sun"]) / z_ring
    return w


class Planetary2KH(AbstractSinusoidalDrive):
    """2K-H planetary train with eccentricity errors (Wang et al. 2013).

    **Arguments:**

    - `z_sun`, `z_planet`, `z_ring`: tooth counts.
    - `module`: module, mm (equal for both meshes).
    - `pressure_angle`: standard pressure angle α₀, rad (default 20°).
    - `n_planets`: number of planets.
    - `planet_angles`: planet positions, rad (default equally spaced from 0);
      η_i = position of planet i − position of planet 1.
    - `centre_distance`: working centre distance, mm, for profile-shifted gears; if
      omitted the gears are standard and ``z_ring = z_sun + 2 z_planet`` is required.
    - `input`, `output`, `fixed`: members, each one of "sun", "carrier", "ring".
    - `coupling`: `SinglePath()` (the default) — every planet behaves like planet 1 and
      planet 1's path alone sets the output (the paper's assumption); or `LoadSharing()` —
      the planets share the load equally (floating member or equal mesh compliance), so
      the output error is the mean of the N path errors, each with its own planet's
      errors and its own η_i (equally spaced planets then cancel the first harmonic
      of the sun and ring eccentricities).
    """

    z_sun: int
    z_planet: int
    z_ring: int
    n_planets: int
    module: Float[Array, ""]
    pressure_angle: Float[Array, ""]
    working_angle_external: Float[Array, ""]
    working_angle_internal: Float[Array, ""]
    planet_angles: Float[Array, " n"]
    input: str
    output: str
    fixed: str
    coupling: AbstractPlanetCoupling

    def __init__(
        self,
        z_sun: int,
        z_planet: int,
        z_ring: int,
        *,
        module: float,
        pressure_angle: float = math.radians(20.0),
        n_planets: int = 3,
        planet_angles: Sequence[float] | None = None,
        centre_distance: float | None = None,
        input: str = "sun",
        output: str = "carrier",
        fixed: str = "ring",
        coupling: AbstractPlanetCoupling = SinglePath(),
    ):
        zs = _as_int("z_sun", z_sun, minimum=3)
        zp = _as_int("z_planet", z_planet, minimum=3)
        zr = _as_int("z_ring", z_ring, minimum=zs + 1)
        n = _as_int("n_planets", n_planets, minimum=1)
        m = _as_float("module", module, positive=True)
        a0 = _as_float("pressure_angle", pressure_angle, positive=True)
        if not a0 < math.radians(45):
            raise ValueError(f"pressure_angle: {math.degrees(a0):g}° is not a gear pressure angle (give rad; 20° = {math.radians(20):.6f})")
        if {input, output, fixed} != set(MEMBERS):
            raise ValueError(
                f"input, output, fixed must be sun, carrier and ring in some order, got input={input!r}, output={output!r}, fixed={fixed!r}"
            )
        coupling = check_option("coupling", coupling, AbstractPlanetCoupling, COUPLINGS)
        if centre_distance is None:
            if zr != zs + 2 * zp:
                raise ValueError(
                    f"tooth counts: standard gears need z_ring = z_sun + 2·z_planet ({zs} + 2·{zp} = {zs + 2 * zp}), got z_ring = {zr}; "
                    "fix the counts or give centre_distance (mm) for profile-shifted gears"
                )
            aw = an = a0
            a = m * (zs + zp) / 2
        else:
            a = _as_float("centre_distance", centre_distance, positive=True)
            cw = m * (zs + zp) * math.cos(a0) / (2 * a)
            cn = m * (zr - zp) * math.cos(a0) / (2 * a)
            if not (0 < cw < 1 and 0 < cn < 1):
                raise ValueError(f"centre_distance: {a} mm gives no valid working pressure angle for these tooth counts and module")
            aw, an = math.acos(cw), math.acos(cn)
        # Neighbouring planets must not clash (tip circles, standard addendum = m): the count, then the angles.
        check_planet_count(n, a, m * (zp + 2), z_sun=zs, z_planet=zp)
        angles = planet_angles_of(planet_angles, n)
        check_assembly(angles, zs, zr, equally_spaced=planet_angles is None)
        if n > 1 and smallest_spacing(angles, a) <= m * (zp + 2):
            raise ValueError(f"planets clash: {n} planets of {zp} teeth do not fit around a {zs}-tooth sun (planet tip circles overlap)")
        self.z_sun, self.z_planet, self.z_ring, self.n_planets = zs, zp, zr, n
        self.module = jnp.asarray(m)
        self.pressure_angle = jnp.asarray(a0)
        self.working_angle_external = jnp.asarray(aw)
        self.working_angle_internal = jnp.asarray(an)
        self.planet_angles = jnp.asarray(angles)
        self.input, self.output, self.fixed, self.coupling = input, output, fixed, coupling

    type_name: ClassVar[str] = "planetary_2kh"

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        return {
            name: SourceSpec(
                name,
                "eccentricity",
                shape=(self.n_planets if per_planet else 1,),
                symbol=sym,
                description=name.replace("_", " ") + " eccentricity" + (", one per planet" if per_planet else ""),
            )
            for name, (sym, per_planet) in SOURCES.items()
        }

    @classmethod
    def from_table(cls, table: Table) -> Planetary2KH:
        """``[drive] type = "planetary_2kh"``: z_sun, z_planet, z_ring, module_mm, n_planets; optional
        pressure_angle_deg/_rad (20°), planet_angles_deg/_rad, centre_distance_mm, input ("sun"),
        output ("carrier"), fixed ("ring"), coupling ("single_path" or "load_sharing")."""
        t = table
        angles = None
        if t.has("planet_angles_deg") or t.has("planet_angles_rad"):
            key = "planet_angles_deg" if t.has("planet_angles_deg") else "planet_angles_rad"
            raw = t.get(key)
            if not isinstance(raw, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in raw):
                raise ConfigError(f"{t.where} {key}: expected a list of numbers")
            angles = [math.radians(x) if key.endswith("deg") else float(x) for x in raw]
        centre = t.number("centre_distance_mm", None, positive=True) if t.has("centre_distance_mm") else None
        kwargs: dict[str, Any] = dict(
            module=t.number("module_mm", positive=True),
            pressure_angle=t.angle("pressure_angle", math.radians(20.0)),
            n_planets=t.integer("n_planets", minimum=1),
            planet_angles=angles,
            centre_distance=centre,
            input=t.string("input", "sun", choices=MEMBERS),
            output=t.string("output", "carrier", choices=MEMBERS),
            fixed=t.string("fixed", "ring", choices=MEMBERS),
            coupling=COUPLINGS[t.string("coupling", "single_path", choices=tuple(COUPLINGS))](),
        )
        zs, zp, zr = (t.integer(k, minimum=1) for k in ("z_sun", "z_planet", "z_ring"))
        try:
            return cls(zs, zp, zr, **kwargs)
        except ValueError as e:
            raise ConfigError(f"{t.where}: {e}") from None

    @property
    def speeds(self) -> dict[str, Fraction]:
        """Exact speeds of sun, carrier, ring and planet for unit input speed."""
        w = member_speeds(self.z_sun, self.z_ring, input=self.input, fixed=self.fixed)
        w["planet"] = w["carrier"] - Fraction(self.z_sun, self.z_planet) * (w["sun"] - w["carrier"])
        return w

    @property
    def ratio(self) -> Fraction:
        """Transmission ratio input speed / output speed."""
        return 1 / self.speeds[self.output]

    def source_frequencies(self) -> dict[str, Fraction]:
        """Frequency of each source on the lines of action, as a multiple of the input speed."""
        w = self.speeds
        rel = {k: w[k] - w["carrier"] for k in ("sun", "planet", "ring")}
        return {
            "sun_manufacturing": rel["sun"],
            "planet_manufacturing": rel["planet"],
            "ring_manufacturing": rel["ring"],
            "sun_assembly": -w["carrier"],
            "planet_assembly": Fraction(0),
            "carrier_assembly": -w["carrier"],
        }

    def _gain(self) -> Float[Array, ""]:
        """Output rotation per µm of (e_w + e_n), rad/µm."""
        rb_s = self.module * self.z_sun * jnp.cos(self.pressure_angle) / 2
        rb_r = self.module * self.z_ring * jnp.cos(self.pressure_angle) / 2
        per_mm = {"carrier": 1 / (rb_s + rb_r), "ring": -1 / rb_r, "sun": -1 / rb_s}[self.output]
        return 1e-3 * per_mm

    def components(self, errors: Mapping[str, Eccentricity]) -> Components:
        """TE components at the output (seed Table 2, every planet path as the coupling mode says)."""
        e = self.checked(errors)
        f = self.source_frequencies()
        aw, an = self.working_angle_external, self.working_angle_internal
        paths = self.coupling.paths(self.n_planets)
        weight = 1.0 / len(paths)
        g = self._gain() * weight
        amp, phase, gain, freq, labels = [], [], [], [], []

        def term(label, source, i, sign, freq_, extra):
            amp.append(e[source].magnitude[i])
            phase.append(e[source].phase[i] + extra)
            gain.append(sign * g)
            freq.append(freq_)
            labels.append(label)

        for i in paths:
            eta = self.planet_angles[i] - self.planet_angles[0]
            p = f"planet {i + 1}: "
            # Seed Table 2; e_w terms carry +α_w, e_n terms −α_n, fixed-frame sources −η_i.
            term(p + "sun manufacturing (e_w)", "sun_manufacturing", 0, -1.0, f["sun_manufacturing"], aw - eta)
            term(p + "planet manufacturing (e_w)", "planet_manufacturing", i, -1.0, f["planet_manufacturing"], aw)
            term(p + "planet manufacturing (e_n)", "planet_manufacturing", i, 1.0, f["planet_manufacturing"], -an)
            term(p + "ring manufacturing (e_n)", "ring_manufacturing", 0, 1.0, f["ring_manufacturing"], -an - eta)
            term(p + "sun assembly (e_w)", "sun_assembly", 0, -1.0, f["sun_assembly"], aw - eta)
            term(p + "planet assembly (e_w)", "planet_assembly", i, 1.0, f["planet_assembly"], aw)
            term(p + "planet assembly (e_n)", "planet_assembly", i, 1.0, f["planet_assembly"], -an)
            term(p + "carrier assembly (e_w)", "carrier_assembly", 0, 1.0, f["carrier_assembly"], aw - eta)
            term(p + "carrier assembly (e_n)", "carrier_assembly", 0, 1.0, f["carrier_assembly"], -an - eta)
        return Components(jnp.stack(amp, axis=-1), jnp.stack(phase, axis=-1), freq, gain=jnp.stack(gain, axis=-1), labels=labels)

    def describe(self) -> list[tuple[str, str]]:
        w = self.speeds
        rows = [
            ("drive", "2K-H planetary (Wang et al. 2013)"),
            ("tooth counts z_sun / z_planet / z_ring", f"{self.z_sun} / {self.z_planet} / {self.z_ring}"),
            ("module", f"{float(self.module):g} mm"),
            ("pressure angle α₀", f"{math.degrees(float(self.pressure_angle)):.6g}°"),
            (
                "working pressure angles α_w (sun–planet) / α_n (ring–planet)",
                f"{math.degrees(float(self.working_angle_external)):.6g}° / {math.degrees(float(self.working_angle_internal)):.6g}°",
            ),
            ("planets", f"{self.n_planets} at " + ", ".join(f"{math.degrees(float(x)):.6g}°" for x in self.planet_angles)),
            ("configuration", f"{self.input} input, {self.output} output, {self.fixed} fixed"),
            ("ratio i (input/output)", f"{self.ratio}" if self.ratio.denominator == 1 else f"{self.ratio} = {float(self.ratio):.6g}"),
            ("speeds (× input): sun, carrier, ring, planet", ", ".join(f"{w[k]}" for k in ("sun", "carrier", "ring", "planet"))),
            ("planet coupling", self.coupling.description),
            ("output error per µm of (e_w + e_n)", f"{float(self._gain()) * ARCSEC_PER_RAD:.6g}″/µm"),
        ]
        rows += [(f"frequency of {k} on the LOA (× input speed)", str(v)) for k, v in self.source_frequencies().items()]
        return rows
