"""Time-varying mesh stiffness of helical meshes by slices across the face width.

The face width b is cut into K slices of width Δz = b/K. In slice k (centre z_k from mid face) the
tooth pairs j of a mesh sit on the transverse path of contact at

    u_kj(τ) = u_P + p_bt (τ + φ_m) + z_k tan β_b − j p_bt,     τ in mesh periods,

(u from the start of the path, u_P the pitch point, φ_m the mesh's phase, `helical_geometry.mesh_phases`):
a helical contact line is a straight line inclined at β_b on the plane of action, so across the
face it sweeps the path of contact. A pair carries load where 0 ≤ u ≤ g_α. Over the slice, u spans
[u_kj − w/2, u_kj + w/2] with w = Δz tan β_b, and the pair's weight is the fraction of that span on
the path (the exact integral of the contact-line length over the slice: continuous and piecewise
linear in time, so the right-hand side has no jumps). Each pair in each slice is a spring of
stiffness c_γ b / (ε_α K) × weight, so the mean mesh stiffness is c_γ b (ISO 6336-1's mean mesh
stiffness per unit face width, c_γα), and the stiffness varies as the total contact-line length
does: rectangular single/double alternation for spur gears (w → 0), smoothed by the overlap ε_β of
helical gears, and constant when ε_β is whole. A slice model rather than a Fourier series of the
alternation: it handles the overlap ratio by construction, and the same slices carry the crowning
(a load distribution across the face) and the profile relief of each pair.

How the stiffness varies is an option object, as optimistix passes a solver: `SlicedStiffness` (the
above, the default), `TransverseStiffness` (every slice in phase: the rectangular single/double-contact
alternation of a spur pair, ε_α only, smoothed over the slice span), `MeanStiffness` (one pair per
slice at the pitch point with weight ε_α: constant stiffness c_γ b) and `SinglePairStiffness` (the sliced
model with each pair stiffest at mid path and softer towards tip and root, ISO 6336-1's c' at its maximum),
subclasses of `AbstractStiffnessModel`.
"""

import abc
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

if TYPE_CHECKING:  # equinox's workaround for pyright#4965 (`equinox.AbstractClassVar`'s docstring)
    from typing import ClassVar as AbstractClassVar
else:
    from equinox import AbstractClassVar

from .helical_geometry import Geometry, HelicalStage, lead_mismatch_gap, mesh_phases
from .helical_modifications import PathRelief, StageModifications, crowning


def slice_centres(face_width, n_slices: int) -> Float[Array, " k"]:
    """Centres of `n_slices` equal slices of the face, mm from mid face."""
    k = jnp.arange(n_slices, dtype=float)
    return (k + 0.5) / n_slices * face_width - face_width / 2


def contact_fraction(u, half_span, path_length):
    """Fraction of [u − half_span, u + half_span] that lies on [0, path_length]."""
    lo = jnp.maximum(u - half_span, 0.0)
    hi = jnp.minimum(u + half_span, path_length)
    return jnp.clip(hi - lo, 0.0, 2 * half_span) / (2 * half_span)


def pair_range(geom: Geometry, face_width: float, n_slices: int) -> tuple[int, int]:
    """Tooth-pair indices j (lo, hi) that can be on the path of contact of some slice (concrete geometry).

    Pair j of a slice sits at u = b − j p_bt, b ∈ [0, p_bt) (`SlicedMeshes`), and has weight only while
    u ∈ (−s, g + s), s = the slice's half span: so j > −(g + s)/p_bt and j < 1 + s/p_bt. The other pairs
    would always have weight 0 and only cost evaluations of the contact law.
    """
    pbt = float(geom.base_pitch)
    s = max(float(face_width) / n_slices * math.tan(float(geom.base_helix_angle)), 1e-3 * pbt) / 2  # SlicedMeshes.half_span
    g = float(jnp.max(geom.path_length))
    lo = math.floor(-(g + s) / pbt) + 1
    hi = math.ceil(1 + s / pbt)
    return lo, hi


class AbstractStiffnessModel(eqx.Module):
    """How the mesh stiffness of a `SlicedMeshes` varies over a mesh period.

    A model places the tooth pairs of every slice on the path of contact and weighs them; a pair of
    weight w is a spring of c_γ b w / (ε_α K). Class variable: `name`, the model's name in parameter
    files (``stiffness_model = "slices"``) and reports.
    """

    name: AbstractClassVar[str]

    @abc.abstractmethod
    def contacts(self, meshes: "SlicedMeshes", tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        """Position u (mm from the start of the path of contact) and contact weight of every pair
        j of every slice k of every mesh m of `meshes`, at τ (mesh periods)."""


def _pairs_on_path(meshes: "SlicedMeshes", tau, lead_shift) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
    """Pairs travelling along the path of contact, slice k shifted by `lead_shift[k]` (mm); weight: the
    fraction of the slice's span on the path (module docstring)."""
    j = jnp.arange(meshes.pairs[0], meshes.pairs[1], dtype=float)
    pbt = meshes.base_pitch
    lead = meshes.pitch_point[:, None] + pbt * (tau + meshes.phase[:, None]) + lead_shift[None, :]
    base = jnp.mod(lead, pbt)
    u = base[..., None] - j * pbt
    w = contact_fraction(u, meshes.half_span, meshes.path_length[:, None, None])
    return u, w


class SlicedStiffness(AbstractStiffnessModel):
    """Time-varying stiffness with the helical overlap: slice k's contact lines lead by z_k tan β_b (the default)."""

    name: ClassVar[str] = "slices"

    def contacts(self, meshes: "SlicedMeshes", tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        return _pairs_on_path(meshes, tau, meshes.lead_shift)


class TransverseStiffness(AbstractStiffnessModel):
    """Every slice in phase (no lead shift): the rectangular single/double-contact alternation of a spur pair,
    ε_α only, smoothed over the slice span ±Δz tan β_b/2."""

    name: ClassVar[str] = "transverse"

    def contacts(self, meshes: "SlicedMeshes", tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        return _pairs_on_path(meshes, tau, jnp.zeros_like(meshes.lead_shift))


class MeanStiffness(AbstractStiffnessModel):
    """Constant stiffness c_γ b: one pair per slice at the pitch point, of weight ε_α."""

    name: ClassVar[str] = "mean"

    def contacts(self, meshes: "SlicedMeshes", tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        u = jnp.broadcast_to(meshes.pitch_point[:, None, None], (meshes.phase.shape[0], meshes.n_slices, 1))
        return u, jnp.broadcast_to(meshes.contact_ratio[:, None, None], u.shape)


class SinglePairStiffness(AbstractStiffnessModel):
    """The sliced model with a single pair's stiffness varying along its path of contact: a pair at u weighs
    (1 − c x²)/(1 − c/3), x = 2u/g_α − 1, so it is stiffest at mid path, (1 − c) of that at the tip and root, and its
    mean over the path (hence the mean mesh stiffness c_γ b) is unchanged.

    `end_drop` c: None (the default) takes c = 0.75 (1 − 1/ε_α) per mesh, the parabola whose maximum is ISO 6336-1's
    single stiffness c' when the mean mesh stiffness is c_γα = c' (0.75 ε_α + 0.25) (the parabolic shape is gearte's
    assumption; ISO gives the two values, not the shape): c = 0.28 and 0.35 for the wind-turbine stage's external
    (ε_α = 1.59) and internal (1.87) meshes. A number in [0, 1) sets c for every mesh."""

    name: ClassVar[str] = "single_pair"
    end_drop: float | Array | None = None

    def __check_init__(self):
        c = self.end_drop
        if c is not None and (isinstance(c, bool) or not isinstance(c, (int, float, jax.Array, np.ndarray, np.number))):
            raise ValueError(f"SinglePairStiffness.end_drop: a fraction in [0, 1) of the mid-path stiffness or None, got {c!r}")
        if isinstance(c, (int, float, np.ndarray, np.number)) and not np.all(
            (np.asarray(c) >= 0.0) & (np.asarray(c) < 1.0)
        ):  # (an array, e.g. traced, is the caller's to check)
            raise ValueError(f"SinglePairStiffness.end_drop: a fraction in [0, 1) of the mid-path stiffness, got {c!r}")

    def drop(self, meshes: "SlicedMeshes") -> Float[Array, " m"]:
        """c of every mesh (differentiable in a given `end_drop`)."""
        if self.end_drop is None:
            return 0.75 * (1.0 - 1.0 / meshes.contact_ratio)
        return jnp.broadcast_to(jnp.asarray(self.end_drop, dtype=meshes.contact_ratio.dtype), meshes.contact_ratio.shape)

    def contacts(self, meshes: "SlicedMeshes", tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        u, w = _pairs_on_path(meshes, tau, meshes.lead_shift)
        g = meshes.path_length[:, None, None]
        c = self.drop(meshes)[:, None, None]
        x = 2.0 * jnp.clip(u, 0.0, g) / g - 1.0
        return u, w * (1.0 - c * x * x) / (1.0 - c / 3.0)


#: The stiffness models, in the order error messages list them.
STIFFNESS_MODELS: tuple[type[AbstractStiffnessModel], ...] = (SlicedStiffness, TransverseStiffness, MeanStiffness, SinglePairStiffness)


def check_stiffness_model(argument: str, model) -> AbstractStiffnessModel:
    """`model` if it is an `AbstractStiffnessModel`, else a ValueError naming `argument` and the classes to use."""
    if isinstance(model, AbstractStiffnessModel):
        return model
    classes = ", ".join(f"{c.__name__}()" for c in STIFFNESS_MODELS)
    hint = ""
    if isinstance(model, str):
        named = [c for c in STIFFNESS_MODELS if c.name == model]
        hint = f" (use {named[0].__name__}(); names are for parameter files)" if named else ""
    raise ValueError(f"{argument}: give a stiffness model object, one of {classes}, got {model!r}{hint}")


class SlicedMeshes(eqx.Module):
    """Gap excitation and contact weights of every tooth pair in every slice of every mesh.

    Meshes are ordered sun–planet 1 … N, then planet–ring 1 … N. Calling it at τ (mesh periods)
    returns ``(gap, weight)``, each of shape (2N·K, J): `gap` (µm) is the excitation added to the
    members' approach along the contact normal (LOA errors plus the lead mismatch minus the
    modification), `weight` the pair's contact weight (0 … 1; ε_α for `MeanStiffness`'s one pair).
    `stiffness_model` (an `AbstractStiffnessModel`, `SlicedStiffness()` by default) places and weighs the pairs.
    """

    path_length: Float[Array, " m"]
    pitch_point: Float[Array, " m"]
    phase: Float[Array, " m"]
    base_pitch: Float[Array, ""]
    lead_shift: Float[Array, " k"]
    half_span: Float[Array, ""]
    contact_ratio: Float[Array, " m"]
    crowning: Float[Array, "m k"]
    mismatch: Float[Array, "m k"]
    modifications: StageModifications
    relief: PathRelief
    errors: Callable[[Array], Array] | None
    stiffness_model: AbstractStiffnessModel
    n_planets: int = eqx.field(static=True)
    n_slices: int = eqx.field(static=True)
    pairs: tuple[int, int] = eqx.field(static=True)

    def __init__(
        self,
        stage: HelicalStage,
        geom: Geometry,
        modifications: StageModifications,
        errors,
        *,
        n_slices: int,
        pairs: tuple[int, int],
        stiffness_model: AbstractStiffnessModel = SlicedStiffness(),
    ):
        self.stiffness_model = check_stiffness_model("stiffness_model", stiffness_model)
        n = stage.n_planets
        ones = jnp.ones(n)
        ext_phase, int_phase = mesh_phases(stage)
        z = slice_centres(stage.face_width, n_slices)
        self.path_length = jnp.concatenate([geom.path_length[0] * ones, geom.path_length[1] * ones])
        self.pitch_point = jnp.concatenate([geom.pitch_point[0] * ones, geom.pitch_point[1] * ones])
        self.phase = jnp.concatenate([ext_phase, int_phase])
        self.contact_ratio = jnp.concatenate([geom.contact_ratio[0] * ones, geom.contact_ratio[1] * ones])
        self.base_pitch = geom.base_pitch
        self.lead_shift = z * jnp.tan(geom.base_helix_angle)
        self.half_span = jnp.maximum(stage.face_width / n_slices * jnp.tan(geom.base_helix_angle), 1e-3 * geom.base_pitch) / 2
        m = modifications
        c_ext = crowning(m.sun, m.planet_sun_flank, z, stage.face_width)
        c_int = crowning(m.planet_ring_flank, m.ring, z, stage.face_width)
        self.crowning = jnp.concatenate([jnp.broadcast_to(c_ext, (n, n_slices)), jnp.broadcast_to(c_int, (n, n_slices))])
        mismatch = lead_mismatch_gap(stage.lead_mismatch[:, None], z[None, :], stage.face_width)  # (2, K)
        self.mismatch = jnp.concatenate([jnp.broadcast_to(mismatch[0], (n, n_slices)), jnp.broadcast_to(mismatch[1], (n, n_slices))])
        self.modifications = modifications
        # The profile reliefs of every mesh as arrays (`flank_pair_relief` of each mesh's flanks, all meshes at once).
        flanks = [(m.sun, m.planet_sun_flank)] * n + [(m.planet_ring_flank, m.ring)] * n
        self.relief = PathRelief(flanks, self.path_length, geom.base_pitch)
        self.errors = errors
        self.n_planets, self.n_slices, self.pairs = n, n_slices, pairs

    def positions(self, tau) -> tuple[Float[Array, "m k j"], Float[Array, "m k j"]]:
        """Position u (mm) on the path of contact and contact weight of every pair, at τ (mesh periods), as the
        stiffness model places them (`AbstractStiffnessModel.contacts`)."""
        return self.stiffness_model.contacts(self, tau)

    def __call__(self, tau) -> tuple[Float[Array, "s j"], Float[Array, "s j"]]:
        u, w = self.positions(tau)
        h = self.relief(u, self.path_length) + self.crowning[..., None]
        gap = self.mismatch[..., None] - h
        if self.errors is not None:
            gap = gap + self.errors(tau)[:, None, None]
        s = gap.shape[0] * gap.shape[1]
        return gap.reshape(s, -1), w.reshape(s, -1)
