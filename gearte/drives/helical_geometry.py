"""Helical 2K-H stage: parameters and geometry (members, lines of action, contact ratios, mesh phasing).

The dynamic model (`gearte.drives.helical_equations`) is written in a frame that turns with the
carrier; carrier input, sun output, ring fixed (Zhang, Chen & Wang: the wind-turbine low-speed stage).
Members, in the order of the generalised coordinates q = (q_c, q_r, q_s, q_1 … q_N): carrier, ring,
sun, planets; each has q_i = (x, y, z, u_x, u_y, u_z), µm, where u = R_i·θ is a rotation times the
member's reference radius R_i (carrier: centre distance a; gears: base radius), so every
coordinate is a length, as in the source paper.

Conventions (derived here; the paper's equations 9-10 were lost in extraction):

- z is the common axis; planet n sits at angle Ψ_n; rotations are positive counter-clockwise
  seen from +z. The carrier turns counter-clockwise; the sun, the output, turns the same way, faster.
- The contact force on the sun (pushed by planet n) lies along
  n_s = t(φ_s) cos β_b − h_s ẑ sin β_b with t(φ) = (−sin φ, cos φ, 0), φ_s = Ψ_n + α_t; on the ring
  along n_r = t(φ_r) cos β_b − h_r ẑ sin β_b, φ_r = Ψ_n − α_t, h = ±1 the hand (right = +1) of the
  sun / ring. Both give the gear a counter-clockwise torque, and push the planet away from the
  member it meshes with (separating force). The planet's axial forces from its two meshes cancel.
- Gears are standard (no profile shift, addendum 1·m_n, tooth thickness half the pitch) with
  z_ring = z_sun + 2 z_planet, so the working pitch circles are the reference circles.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.validate import as_float, as_int
from .planet_layout import check_assembly, check_planet_count, smallest_spacing
from .planet_layout import planet_angles as planet_angles_of

MEMBERS = ("carrier", "ring", "sun", "planet")
DIRECTIONS = ("x", "y", "z", "u_x", "u_y", "u_z")


def _array(name: str, value, shape: tuple[int, ...], *, positive: bool = False, nonnegative: bool = False, unit: str = "") -> Array:
    arr = np.asarray(value, dtype=np.float64) if not hasattr(value, "aval") else value
    if hasattr(arr, "aval"):  # traced or JAX array: taken as it is (built inside gearte, e.g. under vmap)
        return jnp.broadcast_to(jnp.asarray(arr, dtype=float), shape)
    if arr.shape not in ((), shape):
        raise ValueError(f"{name}: expected a number or an array of shape {shape} ({unit}), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    if positive and not np.all(arr > 0):
        raise ValueError(f"{name}: must be > 0 {unit}, got {value!r}")
    if nonnegative and not np.all(arr >= 0):
        raise ValueError(f"{name}: must be ≥ 0 {unit}, got {value!r}")
    return jnp.broadcast_to(jnp.asarray(arr, dtype=float), shape)


class HelicalStage(eqx.Module):
    """A helical 2K-H planetary stage (carrier input, sun output, ring fixed): geometry, masses, supports, load.

    **Arguments:**

    - `z_sun`, `z_planet`, `z_ring`: tooth counts (standard gears: z_ring = z_sun + 2·z_planet).
    - `normal_module`: m_n, mm.
    - `normal_pressure_angle`: α_n, rad.
    - `helix_angle`: β at the reference circle, rad (0 < β < 45°).
    - `face_width`: b, mm (common to both meshes).
    - `n_planets`: N; `planet_angles`: Ψ_n, rad (default equally spaced from 0; each must satisfy
      the assembly condition (z_sun + z_ring)·Ψ_n/2π whole).
    - `sun_hand`: "right" or "left" (planets the other hand, ring the planets' hand).
    - `mass`: kg, per member (carrier, ring, sun, planet), shape (4,).
    - `polar_inertia`, `tilt_inertia`: kg·m² about the axis and about a diameter, shape (4,).
    - `support_stiffness`: shape (4, 6), per member and direction (x, y, z, u_x, u_y, u_z): N/µm for
      translations, N·m/rad for tilts and torsion. Carrier, ring, sun: to the housing (the sun's
      torsion is its output shaft, held at its far end by the load; the carrier's is usually 0:
      the input torque is applied to it). Planet: its bearing to the carrier (the planet's spin
      entry is ignored: it turns freely).
    - `support_damping_ratio`: ζ of each support spring, shape (4, 6) or a number.
    - `mesh_stiffness`: c_γ, N/(mm·µm): mean mesh stiffness per unit face width (ISO 6336-1 c_γα),
      external (sun–planet) and internal (planet–ring), shape (2,).
    - `mesh_damping_ratio`: ζ of the meshes, shape (2,) or a number.
    - `carrier_torque`: input torque, N·m; `carrier_speed`: input speed, rpm.
    - `lead_mismatch`: F_βy, µm, external and internal, shape (2,) or a number: the effective
      helix-slope mismatch of each mesh under load after running-in (ISO 6336-1 F_βy: helix slope
      deviations plus the misalignment of the gear axes and their deflection), a gap that grows
      linearly across the face, + F_βy/2 at one end and − F_βy/2 at the other (`lead_mismatch_gap`).
      0 by default (ideal leads).
    """

    z_sun: int = eqx.field(static=True)
    z_planet: int = eqx.field(static=True)
    z_ring: int = eqx.field(static=True)
    n_planets: int = eqx.field(static=True)
    sun_hand: int = eqx.field(static=True)
    normal_module: Float[Array, ""]
    normal_pressure_angle: Float[Array, ""]
    helix_angle: Float[Array, ""]
    face_width: Float[Array, ""]
    planet_angles: Float[Array, " n"]
    mass: Float[Array, " 4"]
    polar_inertia: Float[Array, " 4"]
    tilt_inertia: Float[Array, " 4"]
    support_stiffness: Float[Array, "4 6"]
    support_damping_ratio: Float[Array, "4 6"]
    mesh_stiffness: Float[Array, " 2"]
    mesh_damping_ratio: Float[Array, " 2"]
    carrier_torque: Float[Array, ""]
    carrier_speed: Float[Array, ""]
    lead_mismatch: Float[Array, " 2"]

    def __init__(
        self,
        z_sun: int,
        z_planet: int,
        z_ring: int,
        *,
        normal_module: float,
        normal_pressure_angle: float = math.radians(20.0),
        helix_angle: float,
        face_width: float,
        n_planets: int = 3,
        planet_angles: Sequence[float] | None = None,
        sun_hand: str = "right",
        mass: Any,
        polar_inertia: Any,
        tilt_inertia: Any,
        support_stiffness: Any,
        support_damping_ratio: Any = 0.05,
        mesh_stiffness: Any = 20.0,
        mesh_damping_ratio: Any = 0.07,
        carrier_torque: float,
        carrier_speed: float,
        lead_mismatch: Any = 0.0,
    ):
        zs = as_int("z_sun", z_sun, minimum=6)
        zp = as_int("z_planet", z_planet, minimum=6)
        zr = as_int("z_ring", z_ring, minimum=zs + 2)
        n = as_int("n_planets", n_planets, minimum=1)
        if zr != zs + 2 * zp:
            raise ValueError(f"tooth counts: standard gears need z_ring = z_sun + 2·z_planet ({zs + 2 * zp}), got {zr}")
        beta = as_float("helix_angle", helix_angle, nonnegative=True, hint="rad")
        if not beta < math.radians(45):
            raise ValueError(f"helix_angle: {math.degrees(beta):g}° is not a helix angle (give rad; 8° = {math.radians(8):.6f})")
        alpha = as_float("normal_pressure_angle", normal_pressure_angle, positive=True, hint="rad")
        if not alpha < math.radians(45):
            raise ValueError(f"normal_pressure_angle: {math.degrees(alpha):g}° is not a pressure angle (give rad)")
        if sun_hand not in ("right", "left"):
            raise ValueError(f"sun_hand: 'right' or 'left', got {sun_hand!r}")
        mn = as_float("normal_module", normal_module, positive=True, hint="mm")
        # Neighbouring planets must not clash: planet tip circles (standard addendum m_n) within the distance of their
        # centres, 2 a sin(ΔΨ/2), a = m_t (z_sun + z_planet)/2, m_t = m_n / cos β. The count first, before a list of n
        # angles is made.
        a = mn / math.cos(beta) * (zs + zp) / 2
        tip = mn / math.cos(beta) * zp + 2 * mn
        check_planet_count(n, a, tip, z_sun=zs, z_planet=zp)
        angles = planet_angles_of(planet_angles, n)
        check_assembly(angles, zs, zr, equally_spaced=planet_angles is None)
        if n > 1 and (spacing := smallest_spacing(angles, a)) <= tip:
            raise ValueError(
                f"n_planets: planets clash: {n} planets of {zp} teeth around a {zs}-tooth sun, their centres "
                f"{spacing:.1f} mm apart, have tip circles of {tip:.1f} mm diameter"
            )
        self.z_sun, self.z_planet, self.z_ring, self.n_planets = zs, zp, zr, n
        self.sun_hand = 1 if sun_hand == "right" else -1
        self.normal_module = jnp.asarray(mn)
        self.normal_pressure_angle = jnp.asarray(alpha)
        self.helix_angle = jnp.asarray(beta)
        self.face_width = jnp.asarray(as_float("face_width", face_width, positive=True, hint="mm"))
        self.planet_angles = jnp.asarray(angles, dtype=float)
        self.mass = _array("mass", mass, (4,), positive=True, unit="kg")
        self.polar_inertia = _array("polar_inertia", polar_inertia, (4,), positive=True, unit="kg·m²")
        self.tilt_inertia = _array("tilt_inertia", tilt_inertia, (4,), positive=True, unit="kg·m²")
        self.support_stiffness = _array("support_stiffness", support_stiffness, (4, 6), nonnegative=True, unit="N/µm, N·m/rad")
        self.support_damping_ratio = _array("support_damping_ratio", support_damping_ratio, (4, 6), nonnegative=True)
        self.mesh_stiffness = _array("mesh_stiffness", mesh_stiffness, (2,), positive=True, unit="N/(mm·µm)")
        self.mesh_damping_ratio = _array("mesh_damping_ratio", mesh_damping_ratio, (2,), nonnegative=True)
        self.carrier_torque = jnp.asarray(as_float("carrier_torque", carrier_torque, hint="N·m"))
        self.carrier_speed = jnp.asarray(as_float("carrier_speed", carrier_speed, positive=True, hint="rpm"))
        self.lead_mismatch = _array("lead_mismatch", lead_mismatch, (2,), nonnegative=True, unit="µm")

    @property
    def n_dof(self) -> int:
        """Number of generalised coordinates, 6·(3 + N)."""
        return 6 * (3 + self.n_planets)

    @property
    def ratio(self) -> float:
        """Speed ratio carrier → sun, 1 + z_ring/z_sun (the sun turns faster)."""
        return 1.0 + self.z_ring / self.z_sun


class Geometry(eqx.Module):
    """Derived geometry of a `HelicalStage` (mm, rad); index 0 = external (sun–planet), 1 = internal (planet–ring).

    - `transverse_module`, `transverse_pressure_angle` α_t, `base_helix_angle` β_b.
    - `radius`: reference (= working) pitch radii (sun, planet, ring); `base_radius`; `tip_radius`
      (the ring's is its internal tip circle); `centre_distance` a.
    - `base_pitch`: transverse base pitch p_bt, mm.
    - `path_length`: length of the transverse path of contact g_α, per mesh; `contact_ratio`
      ε_α = g_α/p_bt; `overlap_ratio` ε_β = b sin β / (π m_n).
    - `pitch_point`: distance along the path of contact from its start (u = 0) to the pitch point;
      the path starts at the sun's tip (external: the planet drives the sun in the carrier's frame)
      and at the planet's tip (internal: the ring drives the planet).
    - `mesh_period`: s; `mesh_frequency`: Hz (z_ring × carrier speed).
    """

    transverse_module: Float[Array, ""]
    transverse_pressure_angle: Float[Array, ""]
    base_helix_angle: Float[Array, ""]
    radius: Float[Array, " 3"]
    base_radius: Float[Array, " 3"]
    tip_radius: Float[Array, " 3"]
    centre_distance: Float[Array, ""]
    base_pitch: Float[Array, ""]
    path_length: Float[Array, " 2"]
    contact_ratio: Float[Array, " 2"]
    overlap_ratio: Float[Array, ""]
    pitch_point: Float[Array, " 2"]
    mesh_period: Float[Array, ""]
    mesh_frequency: Float[Array, ""]


def geometry(stage: HelicalStage) -> Geometry:
    """The derived geometry of `stage` (standard involute helical gears, ISO 21771 relations)."""
    mn, an, beta = stage.normal_module, stage.normal_pressure_angle, stage.helix_angle
    mt = mn / jnp.cos(beta)
    at = jnp.arctan(jnp.tan(an) / jnp.cos(beta))
    bb = jnp.arctan(jnp.tan(beta) * jnp.cos(at))
    z = jnp.asarray([stage.z_sun, stage.z_planet, stage.z_ring], dtype=float)
    r = mt * z / 2
    rb = r * jnp.cos(at)
    ra = r + jnp.asarray([1.0, 1.0, -1.0]) * mn
    a = r[0] + r[1]
    roll_tip = jnp.sqrt(ra**2 - rb**2)  # roll length of each tip circle on its own base circle
    g_ext = roll_tip[0] + roll_tip[1] - a * jnp.sin(at)
    g_int = roll_tip[1] - roll_tip[2] + a * jnp.sin(at)
    pbt = jnp.pi * mt * jnp.cos(at)
    path = jnp.stack([g_ext, g_int])
    pitch_point = jnp.stack([roll_tip[0] - r[0] * jnp.sin(at), roll_tip[1] - r[1] * jnp.sin(at)])
    f_mesh = stage.z_ring * stage.carrier_speed / 60.0
    return Geometry(
        transverse_module=mt,
        transverse_pressure_angle=at,
        base_helix_angle=bb,
        radius=r,
        base_radius=rb,
        tip_radius=ra,
        centre_distance=a,
        base_pitch=pbt,
        path_length=path,
        contact_ratio=path / pbt,
        overlap_ratio=stage.face_width * jnp.sin(beta) / (jnp.pi * mn),
        pitch_point=pitch_point,
        mesh_period=1.0 / f_mesh,
        mesh_frequency=f_mesh,
    )


def mesh_phases(stage: HelicalStage) -> tuple[Float[Array, " n"], Float[Array, " n"]]:
    """Phase of every mesh, in base pitches (fraction of a mesh period), planet by planet: (external, internal).

    Planet n's sun mesh is in the state planet 1's was in z_sun·Ψ_n/2π mesh periods earlier (the sun
    turns counter-clockwise relative to the carrier), its ring mesh in the state planet 1's will be
    in z_ring·Ψ_n/2π periods (the ring turns clockwise) — Parker & Lin (2004). Within one planet, the
    ring mesh is at its pitch point when the sun mesh is at its own, or half a base pitch later when
    z_planet is even (the planet's two flanks are half a pitch apart on its pitch circle).
    """
    psi = stage.planet_angles - stage.planet_angles[0]
    ext = -stage.z_sun * psi / (2 * jnp.pi)
    internal = stage.z_ring * psi / (2 * jnp.pi) + (0.5 if stage.z_planet % 2 == 0 else 0.0)
    return jnp.mod(ext, 1.0), jnp.mod(internal, 1.0)


def iso6336_mesh_stiffness(stage: HelicalStage) -> tuple[Float[Array, " 2"], Float[Array, " 2"]]:
    """Single stiffness c' and mean mesh stiffness c_γα, N/(mm·µm), of the external and internal meshes by
    ISO 6336-1 method B: c'_th = 1/q' (q' from the virtual tooth counts; an internal mesh takes
    z_n2 = ∞), c' = c'_th C_M C_R C_B cos β with C_M = 0.8, C_R = C_B = 1 (solid gears, standard basic
    rack, no profile shift), c_γα = c' (0.75 ε_α + 0.25)."""
    geom = geometry(stage)
    cos_bb, beta = jnp.cos(geom.base_helix_angle), stage.helix_angle
    zn = jnp.asarray([stage.z_sun, stage.z_planet], dtype=float) / (cos_bb**2 * jnp.cos(beta))
    q_ext = 0.04723 + 0.15551 / zn[0] + 0.25791 / zn[1]
    q_int = 0.04723 + 0.15551 / zn[1]
    c_single = 0.8 * jnp.cos(beta) / jnp.stack([q_ext, q_int])
    return c_single, c_single * (0.75 * geom.contact_ratio + 0.25)


def lead_mismatch_gap(lead_mismatch, z, face_width):
    """Gap excitation (µm, added to the compression) of a lead mismatch F_βy at `z` mm from mid face:
    F_βy z / b, linear across the face from −F_βy/2 to +F_βy/2 (the flanks first touch at the + end)."""
    return lead_mismatch * z / face_width


def iso6336_lead_mismatch(*, f_ma: float, f_sh: float = 0.0, case_hardened: bool = True) -> float:
    """Effective helix-slope mismatch F_βy, µm, of ISO 6336-1 (the K_Hβ initial equivalent misalignment):
    F_βx = 1.33 f_sh + f_ma (f_sh: mismatch from the deformation of shafts and gear bodies under load,
    f_ma: manufacturing and assembly mismatch, µm), less the running-in allowance y_β: 0.15 F_βx, at
    most 6 µm, for case-hardened gears; 0.15 F_βx without the limit otherwise (σ_Hlim ≈ 2100 N/mm²)."""
    for name, v in (("f_ma", f_ma), ("f_sh", f_sh)):
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"iso6336_lead_mismatch: {name} must be ≥ 0 µm, got {v!r}")
    f_bx = 1.33 * f_sh + f_ma
    y_b = min(0.15 * f_bx, 6.0) if case_hardened else 0.15 * f_bx
    return f_bx - y_b
