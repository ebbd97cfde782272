"""Equations of motion of the helical 2K-H stage, non-dimensionalised: ε q'' + Ĉ q' + K̂ q + Gᵀ f(G q + gap(τ), …) = F̂.

Every elastic element is a spring along a *projection* g (a row over the 6·(3+N) coordinates): its
deflection is gᵀq. A contact at point p with unit direction n (the force on member A; B feels −n)
has g = [−(n, (p − o_A)×n / R_A) on A, +(n, (p − o_B)×n / R_B) on B] — the linear coordinate
transform of Zhang, Chen & Wang's eqs. 9-10 with translations, tilts and rotations (u = R θ)
projected on the contact normal; the same rule gives the support and planet-bearing springs.
Mesh slices act at the pitch point of their slice (the lumped-parameter assumption).

Units: q in µm (the length scale b_c = 1 µm), forces N, stiffness N/µm, masses kg (a rotation
coordinate u = R θ has mass I/R²). Time is measured in mesh periods T_m: τ = t/T_m. Dividing by the
mean external mesh stiffness k_ref = c_γ b gives the dimensionless mass ε = 10⁻⁶ M/(T_m² k_ref)
and damping Ĉ = C/(T_m k_ref) — the paper's mass and stiffness ratios. The frame turns with the
carrier; its centripetal and gyroscopic terms (ω_c² a ≈ 2 m/s² at 22 rpm, a constant load) are left out.

Damping: each support spring has c = 2ζ√(k m_eff), m_eff = 1/(gᵀM⁻¹g) the mass it sees; each mesh
c = 2ζ_m √(k̄ m_eff) with its mean stiffness k̄, shared by its pairs in proportion to their stiffness.
The mesh force of a pair is k w max_ℓ(x) + c w max_ℓ′(x) ẋ with x = gᵀq + gap the compression,
w the contact weight, and max_ℓ(x) = ½(x + (x⁴ + 16ℓ⁴)^¼) a smooth max(0, x) (ℓ = `contact_smoothing`,
µm): unilateral contact (a relieved or crowned pair that lifts off carries nothing), convex and
infinitely differentiable, so the integrator keeps its order and gradients stay finite. Its error
max_ℓ(x) − max(0, x) is ℓ at x = 0 and at most 2ℓ⁴/|x|³ elsewhere (3e-12 µm for a pair compressed by
40 µm at ℓ = 0.02 µm); it costs two square roots, where the softplus ℓ log(1 + e^{x/ℓ}) cost an
exponential and a logarithm, 2.5 × as much on the CPU (fluctuations of the example agree with the
softplus law's within 2.3e-4 µm, a tenth of the integration error).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core import linalg
from .helical_geometry import Geometry, HelicalStage, geometry
from .helical_modifications import StageModifications
from .helical_stiffness import AbstractStiffnessModel, SlicedMeshes, SlicedStiffness, check_stiffness_model, pair_range, slice_centres
from .planetary_2kh import SOURCES, member_speeds
from .protocol import Eccentricity, SourceSpec

CARRIER, RING, SUN = 0, 1, 2


def _smooth_max(x, ell):
    """max_ℓ(x) = ½(x + (x⁴ + 16ℓ⁴)^¼) and its slope ½(1 + x³/(x⁴ + 16ℓ⁴)^¾) from two square roots (an exponential and a
    logarithm cost 2.5 × as much here), with z = x/ℓ and r = (z⁴ + 16)^¼ for the derivatives."""
    z = x / ell
    z2 = z * z
    r2 = jnp.sqrt(z2 * z2 + 16.0)
    r = jnp.sqrt(r2)
    return 0.5 * (z + r), 0.5 * (1.0 + z * z2 / (r * r2)), z, r


@jax.custom_jvp
def contact_force(x, xd, w, k, c, ell):
    """Force of a unilateral mesh pair of compression `x` (µm), compression rate `xd`, weight `w`, stiffness `k`,
    damping `c`: k w max_ℓ(x) + c w max_ℓ′(x) ẋ, ℓ = `ell` (the module docstring); arrays broadcast together.

    Its derivatives are written out (`jax.custom_jvp`) and their values kept once computed (an optimisation barrier):
    differentiated by JAX, the law's derivative is an expression that XLA recomputes inside every fused kernel of a
    gradient through the ODE solve that needs it (the reverse pass of the wind-turbine example went from 6.5 to 4.5
    forward solves with this rule; the values are the same to rounding, tests compare them)."""
    return _law(x, xd, w, k, c, ell)[0]


def _law(x, xd, w, k, c, ell):
    """The force, and what its derivatives are made of: (force, elastic ℓ max_ℓ(x), viscous max_ℓ′(x) ẋ, max_ℓ(x), its
    slope, z, r); one formula for the value with and without derivatives, so that both are the same to the bit."""
    smooth_max, slope, z, r = _smooth_max(x, ell)
    elastic, viscous = ell * smooth_max, slope * xd
    return w * (k * elastic + c * viscous), elastic, viscous, smooth_max, slope, z, r


@contact_force.defjvp
def _contact_force_jvp(primals, tangents):
    x, xd, w, k, c, ell = primals
    dx, dxd, dw, dk, dc, dell = tangents
    out, elastic, viscous, smooth_max, slope, z, r = _law(x, xd, w, k, c, ell)
    # d slope/dz = 24 z²/r⁷ (r⁴ = z⁴ + 16): the curvature of max_ℓ, per µm of x.
    r2 = r * r
    curvature = 24.0 * z * z / (r * r2 * r2 * r2) / ell
    d_x = w * (k * slope + c * curvature * xd)
    d_xd = c * w * slope
    d_w = k * elastic + c * viscous
    d_x, d_xd, d_w = jax.lax.optimization_barrier((d_x, d_xd, d_w))
    # ∂/∂ℓ: ℓ max_ℓ(x) → max_ℓ − z slope; slope → −curvature z.
    d_ell = w * (k * (smooth_max - z * slope) - c * curvature * z * xd)
    return out, d_x * dx + d_xd * dxd + d_w * dw + w * (elastic * dk + viscous * dc) + d_ell * dell


class MeshedSystem(eqx.Module):
    """A mechanical system with constant supports and unilateral, time-varying mesh springs (dimensionless).

    - `mass` (D,): ε; `stiffness`, `damping` (D, D): K̂, Ĉ of the supports; `load` (D,): F̂, µm.
    - `projection` (S, D): the springs' projections g; `pair_stiffness`, `pair_damping` (S,): k̂, ĉ of one
      pair of full weight in each; `excitation`: τ ↦ (gap (S, J) µm, weight (S, J)).
    - `contact_smoothing`: ℓ, µm.
    """

    mass: Float[Array, " d"]
    stiffness: Float[Array, "d d"]
    damping: Float[Array, "d d"]
    load: Float[Array, " d"]
    projection: Float[Array, "s d"]
    pair_stiffness: Float[Array, " s"]
    pair_damping: Float[Array, " s"]
    excitation: Callable[[Array], tuple[Array, Array]]
    contact_smoothing: Float[Array, ""]

    def pair_forces(self, tau, q, v) -> Float[Array, "s j"]:
        """Dimensionless force of every pair (× k_ref b_c = N)."""
        (gap, w), (gap_dot, _) = jax.jvp(self.excitation, (tau,), (jnp.ones_like(tau),))
        x = (self.projection @ q)[:, None] + gap
        xd = (self.projection @ v)[:, None] + gap_dot
        return contact_force(x, xd, w, self.pair_stiffness[:, None], self.pair_damping[:, None], self.contact_smoothing)

    def vector_field(self, tau, y, args=None):
        """diffrax vector field of the state y = (q, q')."""
        del args
        # Jitted: a solve calls it at every stage of the Runge–Kutta step it unrolls, and jitted it is traced (and
        # differentiated) once per solve instead of at each call.
        return _vector_field(self, tau, y)

    def _field(self, tau, y):
        q, v = jnp.split(y, 2)
        f = jnp.sum(self.pair_forces(tau, q, v), axis=-1)
        acc = (self.load - self.stiffness @ q - self.damping @ v - self.projection.T @ f) / self.mass
        return jnp.concatenate([v, acc])

    def linear_stiffness(self, tau) -> Float[Array, "d d"]:
        """K̂(τ) with every pair in contact (no lift-off)."""
        _, w = self.excitation(tau)
        k = self.pair_stiffness * jnp.sum(w, axis=-1)
        return self.stiffness + (self.projection.T * k) @ self.projection

    def static(self, tau, *, newton_steps: int = 0) -> Float[Array, " d"]:
        """Quasi-static q at τ: K̂(τ) q = F̂ − Gᵀ(k̂ w gap) with every pair in contact, then `newton_steps`
        Newton iterations on the unilateral contact law (no velocity)."""
        gap, w = self.excitation(tau)
        rhs = self.load - self.projection.T @ (self.pair_stiffness * jnp.sum(w * gap, axis=-1))
        # K̂ and the Newton Jacobian are symmetric positive definite (supports, springs, a contact law that never
        # softens): gearte.core.linalg, whose solves cannot hang a batch on several CPU devices as LAPACK's can.
        q = linalg.solve_spd(self.linear_stiffness(tau), rhs[:, None])[:, 0]

        def residual(q):
            f = jnp.sum(self.pair_forces(tau, q, jnp.zeros_like(q)), axis=-1)
            return self.stiffness @ q + self.projection.T @ f - self.load

        for _ in range(newton_steps):
            q = q - linalg.solve_spd(jax.jacfwd(residual)(q), residual(q)[:, None])[:, 0]
        return q


@eqx.filter_jit
def _vector_field(system: MeshedSystem, tau, y):
    return system._field(tau, y)


class LOAErrors(eqx.Module):
    """Eccentricity errors as displacement excitation along the contact normal (µm, > 0 adds material), every mesh, at τ.

    The same sources, phases and frequencies as `Planetary2KH` (Wang et al. 2013, Table 2) for carrier
    input, ring fixed: e_w (sun–planet) and e_n (planet–ring) of each planet, which are displacements along the
    *transverse* line of action; e = −e_w, −e_n there. An eccentricity moves a gear in its transverse plane, and a
    transverse displacement δ along the base tangent closes a helical mesh by δ cos β_b along its normal: the
    excitation is e cos β_b, so that with rigid meshes the sun turns by Planetary2KH's output error (a
    spur model; its TE is that of the transverse line of action).
    """

    errors: dict
    planet_angles: Float[Array, " n"]
    pressure_angle: Float[Array, ""]
    cos_base_helix: Float[Array, ""]
    frequencies: tuple[tuple[str, float], ...] = eqx.field(static=True)
    carrier_turns_per_mesh: float = eqx.field(static=True)

    def __call__(self, tau) -> Float[Array, " m"]:
        theta = 2 * jnp.pi * self.carrier_turns_per_mesh * tau  # carrier (input) angle, rad
        e, f, a = self.errors, dict(self.frequencies), self.pressure_angle
        eta = self.planet_angles - self.planet_angles[0]

        def s(source, i_planet, offset):
            ecc = e[source]
            mag = ecc.magnitude if i_planet else ecc.magnitude[0]
            ph = ecc.phase if i_planet else ecc.phase[0]
            return mag * jnp.sin(f[source] * theta + ph + offset)

        e_w = (
            -s("sun_manufacturing", False, a - eta)
            - s("planet_manufacturing", True, a)
            - s("sun_assembly", False, a - eta)
            + s("planet_assembly", True, a)
            + s("carrier_assembly", False, a - eta)
        )
        e_n = s("planet_manufacturing", True, -a) + s("ring_manufacturing", False, -a - eta) + s("planet_assembly", True, -a)
        e_n = e_n + s("carrier_assembly", False, -a - eta)
        return jnp.concatenate([-e_w, -e_n]) * self.cos_base_helix


def error_sources(n_planets: int) -> dict[str, SourceSpec]:
    """The eccentricity sources of the stage (those of `Planetary2KH`), by name."""
    return dict(_error_sources(int(n_planets)))


@functools.lru_cache(maxsize=16)
def _error_sources(n_planets: int) -> dict[str, SourceSpec]:
    """`error_sources`, built once per planet count (callers get a copy of the dict; `SourceSpec` is immutable)."""
    return {
        name: SourceSpec(name, "eccentricity", shape=(n_planets if per_planet else 1,), symbol=sym, description=name.replace("_", " "))
        for name, (sym, per_planet) in SOURCES.items()
    }


def loa_errors(stage: HelicalStage, geom: Geometry, errors: Mapping[str, Eccentricity]) -> LOAErrors:
    """The `LOAErrors` of `errors` (names as `error_sources`; missing sources are zero)."""
    specs = error_sources(stage.n_planets)
    unknown = sorted(set(errors) - set(specs))
    if unknown:
        raise ValueError(f"errors: unknown sources {unknown}; the stage's sources are {list(specs)}")
    full = {}
    for name, spec in specs.items():
        ecc = errors.get(name, Eccentricity(0.0, 0.0))
        if not isinstance(ecc, Eccentricity):
            raise ValueError(f"errors[{name!r}]: give an Eccentricity(magnitude_um, phase_rad)")
        full[name] = Eccentricity(jnp.broadcast_to(ecc.magnitude, spec.shape), jnp.broadcast_to(ecc.phase, spec.shape))
    w = member_speeds(stage.z_sun, stage.z_ring, input="carrier", fixed="ring")
    w_planet = w["carrier"] - (w["sun"] - w["carrier"]) * stage.z_sun / stage.z_planet
    rel = {"sun": w["sun"] - w["carrier"], "planet": w_planet - w["carrier"], "ring": w["ring"] - w["carrier"]}
    freq = {
        "sun_manufacturing": rel["sun"],
        "planet_manufacturing": rel["planet"],
        "ring_manufacturing": rel["ring"],
        "sun_assembly": -w["carrier"],
        "planet_assembly": 0,
        "carrier_assembly": -w["carrier"],
    }
    return LOAErrors(
        full,
        stage.planet_angles,
        geom.transverse_pressure_angle,
        jnp.cos(geom.base_helix_angle),
        tuple((k, float(v)) for k, v in freq.items()),
        1.0 / stage.z_ring,
    )


class StageLayout(eqx.Module):
    """Where the springs of a stage act: member origins and reference radii, mesh normals and points."""

    origin: Float[Array, "b 3"]
    radius: Float[Array, " b"]
    normal: Float[Array, "m 3"]
    pitch_point: Float[Array, "m 3"]
    members: tuple[tuple[int, int], ...] = eqx.field(static=True)


def layout(stage: HelicalStage, geom: Geometry) -> StageLayout:
    """Origins (carrier, ring, sun at 0; planets at a·(cos Ψ, sin Ψ)), reference radii (a, r_b) and, per mesh,
    the contact normal (force on sun / ring) and the transverse pitch point (module docstring of `helical_geometry`)."""
    psi = stage.planet_angles
    n = stage.n_planets
    a, rb, r = geom.centre_distance, geom.base_radius, geom.radius
    at, bb, hs = geom.transverse_pressure_angle, geom.base_helix_angle, float(stage.sun_hand)
    zeros = jnp.zeros(n)
    planets = jnp.stack([a * jnp.cos(psi), a * jnp.sin(psi), zeros], axis=-1)
    origin = jnp.concatenate([jnp.zeros((3, 3)), planets])
    radius = jnp.concatenate([jnp.stack([a, rb[2], rb[0]]), rb[1] * jnp.ones(n)])

    def normal(phi, hand):
        return jnp.stack([-jnp.sin(phi) * jnp.cos(bb), jnp.cos(phi) * jnp.cos(bb), -hand * jnp.sin(bb) * jnp.ones_like(phi)], axis=-1)

    normals = jnp.concatenate([normal(psi + at, hs), normal(psi - at, -hs)])
    points = jnp.concatenate(
        [jnp.stack([r[0] * jnp.cos(psi), r[0] * jnp.sin(psi), zeros], -1), jnp.stack([r[2] * jnp.cos(psi), r[2] * jnp.sin(psi), zeros], -1)]
    )
    members = tuple((SUN, 3 + i) for i in range(n)) + tuple((RING, 3 + i) for i in range(n))
    return StageLayout(origin, radius, normals, points, members)


def contact_projections(lay: StageLayout, points: Float[Array, "m k 3"]) -> Float[Array, "m k d"]:
    """Projections g of the contacts of every mesh m at `points` (mm) along the mesh's normal: member A (sun or
    ring, pushed along +normal) and planet B, g = [−(n, (p − o_A)×n / R_A) on A, +(n, (p − o_B)×n / R_B) on B]."""
    n_members = lay.origin.shape[0]
    a_idx = jnp.asarray([a for a, _ in lay.members])
    b_idx = jnp.asarray([b for _, b in lay.members])
    normal = jnp.broadcast_to(lay.normal[:, None, :], points.shape)

    def block(idx):
        arm = points - lay.origin[idx][:, None, :]
        return jnp.concatenate([normal, jnp.cross(arm, normal) / lay.radius[idx][:, None, None]], axis=-1)

    one_a = jax.nn.one_hot(a_idx, n_members)
    one_b = jax.nn.one_hot(b_idx, n_members)
    g = -jnp.einsum("mb,mkc->mkbc", one_a, block(a_idx)) + jnp.einsum("mb,mkc->mkbc", one_b, block(b_idx))
    return g.reshape(points.shape[0], points.shape[1], 6 * n_members)


def support_projections(stage: HelicalStage, lay: StageLayout) -> tuple[Float[Array, "p d"], Float[Array, " p"], Float[Array, " p"]]:
    """Projections, stiffness (N/µm or N·m/rad) and damping ratios of every support and planet-bearing spring."""
    n = stage.n_planets
    d = stage.n_dof
    # Carrier, ring, sun to the housing: translations as they are, tilts and torsion u/R = θ.
    scale = jnp.concatenate([jnp.concatenate([jnp.ones(3), jnp.ones(3) / lay.radius[i]]) for i in range(3)])
    ground = jnp.eye(18, d) * scale[:, None]
    # Planet bearings: planet centre minus the carrier's point under it, radial / tangential / axial; tilts.
    psi = stage.planet_angles
    zeros, ones = jnp.zeros(n), jnp.ones(n)
    dirs = jnp.stack(
        [
            jnp.stack([jnp.cos(psi), jnp.sin(psi), zeros], -1),
            jnp.stack([-jnp.sin(psi), jnp.cos(psi), zeros], -1),
            jnp.stack([zeros, zeros, ones], -1),
        ],
        axis=1,
    )  # (n, 3 directions, 3)
    arm = jnp.cross(lay.origin[3:, None, :], dirs) / lay.radius[CARRIER]
    one = jnp.eye(n)
    planet_t = jnp.einsum("ip,ijc->ijpc", one, jnp.concatenate([dirs, jnp.zeros_like(dirs)], -1)).reshape(n, 3, 6 * n)
    carrier_t = -jnp.concatenate([dirs, arm], -1)
    trans = jnp.concatenate([carrier_t, jnp.zeros((n, 3, 12)), planet_t], -1)
    tilt_local = jnp.zeros((n, 2, 6)).at[:, 0, 3].set(1.0).at[:, 1, 4].set(1.0)
    planet_r = jnp.einsum("ip,ijc->ijpc", one, tilt_local / lay.radius[3:, None, None]).reshape(n, 2, 6 * n)
    carrier_r = -tilt_local / lay.radius[CARRIER]
    tilt = jnp.concatenate([carrier_r, jnp.zeros((n, 2, 12)), planet_r], -1)
    bearing = jnp.concatenate([trans, tilt], axis=1).reshape(5 * n, d)
    kp = jnp.tile(stage.support_stiffness[3, :5], n)
    zp = jnp.tile(stage.support_damping_ratio[3, :5], n)
    rows = jnp.concatenate([ground, bearing])
    k = jnp.concatenate([stage.support_stiffness[:3].reshape(-1), kp])
    zeta = jnp.concatenate([stage.support_damping_ratio[:3].reshape(-1), zp])
    return rows, k, zeta


def physical_mass(stage: HelicalStage, lay: StageLayout) -> Float[Array, " d"]:
    """Generalised masses, kg (a rotation coordinate u = R θ: I/R², R in m)."""
    kind = np.minimum(np.arange(3 + stage.n_planets), 3)
    r_m = lay.radius * 1e-3
    m, ip, it = stage.mass[kind], stage.polar_inertia[kind], stage.tilt_inertia[kind]
    return jnp.stack([m, m, m, it / r_m**2, it / r_m**2, ip / r_m**2], axis=-1).reshape(-1)


def _damping(g, k, zeta, inv_mass):
    m_eff = 1.0 / jnp.sum(g * g * inv_mass, axis=-1)
    return 2.0 * zeta * jnp.sqrt(k * m_eff)


class StageSystem(eqx.Module):
    """A stage's `MeshedSystem` with what its outputs need: the mid-face projections of the meshes, the
    scales (mesh period T_m s, k_ref N/µm) and the layout."""

    system: MeshedSystem
    mid_projection: Float[Array, "m d"]
    mesh_period: Float[Array, ""]
    reference_stiffness: Float[Array, ""]
    geometry: Geometry
    layout: StageLayout


def stage_system(
    stage: HelicalStage,
    modifications: StageModifications,
    errors: Mapping[str, Eccentricity] | None = None,
    *,
    n_slices: int = 8,
    stiffness_model: AbstractStiffnessModel = SlicedStiffness(),
    contact_smoothing: float = 0.02,
    pairs: tuple[int, int] | None = None,
) -> StageSystem:
    """Assemble the dimensionless equations of motion of `stage` with `modifications` and eccentricity `errors`.

    **Arguments:**

    - `n_slices`: K, slices across the face width.
    - `stiffness_model`: an `AbstractStiffnessModel` (`gearte.drives.helical_stiffness`): `SlicedStiffness()`
      (time-varying, helical overlap included), `TransverseStiffness()` (every slice in phase) or
      `MeanStiffness()` (constant c_γ b).
    - `contact_smoothing`: ℓ of the smooth unilateral contact, µm.
    - `pairs`: the tooth-pair index range (computed from the geometry when None: give it when the
      geometry is traced).
    """
    check_stiffness_model("stiffness_model", stiffness_model)
    geom = geometry(stage)
    lay = layout(stage, geom)
    d = stage.n_dof
    if pairs is None:
        pairs = pair_range(geom, float(stage.face_width), n_slices)
    mass = physical_mass(stage, lay)
    inv_mass = 1.0 / (1e-6 * mass)
    g_sup, k_sup, z_sup = support_projections(stage, lay)
    c_sup = _damping(g_sup, k_sup, z_sup, inv_mass)
    k0 = (g_sup.T * k_sup) @ g_sup
    c0 = (g_sup.T * c_sup) @ g_sup
    z = slice_centres(stage.face_width, n_slices)
    n_mesh = 2 * stage.n_planets

    z_mid = jnp.concatenate([jnp.zeros(1), z])
    points = lay.pitch_point[:, None, :] + z_mid[None, :, None] * jnp.asarray([0.0, 0.0, 1.0])
    g_all = contact_projections(lay, points)
    g_mid = g_all[:, 0]
    g_slices = g_all[:, 1:].reshape(n_mesh * n_slices, d)
    kind = np.repeat([0, 1], stage.n_planets)
    k_mean = stage.mesh_stiffness[kind] * stage.face_width  # N/µm
    c_mesh = _damping(g_mid, k_mean, stage.mesh_damping_ratio[kind], inv_mass)
    eps_alpha = geom.contact_ratio[kind]
    k_pair = jnp.repeat(k_mean / (eps_alpha * n_slices), n_slices)
    c_pair = jnp.repeat(c_mesh / (eps_alpha * n_slices), n_slices)
    load = jnp.zeros(d).at[5].set(1e3 * stage.carrier_torque / lay.radius[CARRIER])  # N·mm / mm = N
    exc_errors = loa_errors(stage, geom, errors) if errors else None
    excitation = SlicedMeshes(stage, geom, modifications, exc_errors, n_slices=n_slices, pairs=pairs, stiffness_model=stiffness_model)
    tm = geom.mesh_period
    k_ref = k_mean[0]
    system = MeshedSystem(
        mass=1e-6 * mass / (tm**2 * k_ref),
        stiffness=k0 / k_ref,
        damping=c0 / (tm * k_ref),
        load=load / k_ref,
        projection=g_slices,
        pair_stiffness=k_pair / k_ref,
        pair_damping=c_pair / (tm * k_ref),
        excitation=excitation,
        contact_smoothing=jnp.asarray(contact_smoothing, dtype=float),
    )
    return StageSystem(system, g_mid, tm, k_ref, geom, lay)


def natural_frequencies(sys: StageSystem) -> Float[Array, " d"]:
    """Undamped natural frequencies (Hz) about the mean mesh stiffness (every pair in contact at τ = 0)."""
    s = sys.system
    k = s.linear_stiffness(jnp.asarray(0.0))
    scale = 1.0 / jnp.sqrt(s.mass)
    lam = jnp.linalg.eigvalsh(scale[:, None] * k * scale[None, :])
    return jnp.sqrt(jnp.maximum(lam, 0.0)) / (2 * jnp.pi * sys.mesh_period)
