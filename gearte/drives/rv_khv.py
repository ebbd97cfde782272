"""RV (K-H-V) reducer: Hidaka's equivalent-error model with floating parts (Hidaka et al. 1994).

Source: T. Hidaka, H. Wang, T. Ishida et al. (1994), "Rotational transmission error of K-H-V
planetary gears with cycloid gear, 1st report: analytical method", Trans. JSME C 60(570):645-653.

**The drive.** Stage 1: an involute sun (input, z_s teeth) meshes with N = 2 or 3 planets
(z_g teeth), each fixed on a crankshaft; the cranks sit on a circle of radius r_c (the stage's
centre distance) in the carrier (the output). Stage 2: each crank's two eccentrics (eccentricity a,
180° apart) carry two cycloid discs (one disc is allowed, for checks), which mesh with z_p pins in
the fixed ring (z_c = z_p − 1 lobes). With the ring fixed the reduction ratio is
i = 1 + z_p z_g / z_s: the carrier turns θ_o = θ_in / i, the eccentrics (and planets) −z_c θ_o.

**The model** (Hidaka et al. 1994, secs. 3–4). Every part is a rigid body in the plane: sun (x, y),
cranks (x, y, θ), discs (x, y, θ), carrier (x, y, θ), 20 coordinates for 3 cranks and 2 discs, in
the fixed frame centred on the ring (angles CCW from +x; crank 1 and disc 1's eccentric point
along +y at θ_o = 0). Every contact is a spring along its line of action carrying an equivalent
error (`gearte.drives.rv_khv_contacts`):

- sun–planet meshes: both flanks, unilateral, along the two lines of action at the pressure
  angle; equivalent error −j_n/2 (normal backlash j_n) plus the sun's and planet's eccentricities
  (run-outs, turning with their gears) projected on the line;
- disc–pin contacts: unilateral, each pin on its own flank, the equivalent error from the exact
  rotation to contact of the cycloid-pin model (`gearte.drives.cycloid_pin`, its geometry and
  error objects: pin-circle and pin radii, per-pin positions, the pin-circle eccentricity, every
  modification and form-grinding error of each disc);
- crank–disc bearings (each crank in each disc), crank–carrier bearings and the carrier's main
  bearing: dead zones of their radial clearances, with the crank eccentricity and angular phase
  errors of each crank and the crank-hole position errors in the discs and in the carrier.

The input (sun rotation) is held and a small torque acts on the carrier, in one direction and then
the other. The equilibrium is the minimum of the convex contact potential
(`gearte.drives.rv_khv_equilibrium`), taken in the **rigid limit** (the elastic part removed
exactly for the set of closed contacts), so results do not depend on the load or the
stiffnesses. **TE** = θ_o − θ_in / i (Hidaka et al. 1994, sec. 2.2), the carrier's small rotation,
under the forward (+, CCW) and the reverse load; **lost motion** = TE(+) − TE(−), the hysteresis
between the two load directions at vanishing load (the catalogue's figure).

Units: geometry in mm, errors in µm (rad for angles), angles in rad inside; reports in ″ and ′.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..core.metrics import AbstractMetric, Quantity
from ..core.precision import require_x64
from ..core.programs import kept_jit
from ..core.schema import ConfigError
from ..core.solution import RESULTS
from ..core.units import ARCSEC_PER_RAD, TWO_PI
from ..core.validate import as_float, as_int
from .cycloid_pin import CycloidPin
from .cycloid_pin_geometry import CycloidModification
from .protocol import AbstractGridDrive, AbstractStudyContext, Eccentricity, SourceSpec, StudyOutputs, Trace
from .rv_khv_contacts import DEFLECTION_MM, REGULARISATION_PER_MM, check_deflection, dof_count, output_index, rv_system, translations
from .rv_khv_equilibrium import BEARING_FACES, MAX_BEARING_FACES, solve

if TYPE_CHECKING:
    from ..core.schema import Table


class RVResponse(eqx.Module):
    """The equilibrium of the reducer at every output angle of the grid, under both load directions.

    - `output_angle`: θ_o (rad), the grid; the input angle is i θ_o.
    - `te`: TE (rad) in the rigid limit, shape (2, p): [forward (+) load, reverse (−) load].
    - `te_loaded`: TE (rad) under the small load itself (the rigid TE plus the elastic deflection).
    - `force`: force in every unilateral contact (2, p, m): the pins of disc 1, of disc 2, then both
      flanks of each mesh (units of stiffness × mm; > 0: carrying load).
    - `result`: the solve's result code per angle and direction (2, p); `steps`: its Newton iterations.
    """

    output_angle: Float[Array, " p"]
    te: Float[Array, "2 p"]
    te_loaded: Float[Array, "2 p"]
    force: Float[Array, "2 p m"]
    result: RESULTS
    steps: Array


class RVLostMotion(AbstractMetric):
    """Lost motion: TE(+) − TE(−) in the rigid limit, its maximum over the grid (rad)."""

    name: ClassVar[str] = "lost_motion"
    label: ClassVar[str] = "lost motion, max over the output revolution"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcmin"

    def __call__(self, drive: Any, response: RVResponse) -> Float[Array, ""]:
        del drive
        return jnp.max(response.te[0] - response.te[1])

    def describe(self) -> str:
        return "lost motion = output rotation between the forward and the reverse load with the input held, max over the grid"


class RVPeakToPeak(AbstractMetric):
    """Peak-to-peak TE under the forward load over the grid (rad)."""

    name: ClassVar[str] = "peak_to_peak"
    label: ClassVar[str] = "TE p-p (forward load)"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcsec"

    def __call__(self, drive: Any, response: RVResponse) -> Float[Array, ""]:
        del drive
        return jnp.max(response.te[0]) - jnp.min(response.te[0])

    def describe(self) -> str:
        return "peak-to-peak of TE = θ_o − θ_in/i under the forward load over the output revolution's grid"


class RVPeakToPeakReverse(AbstractMetric):
    """Peak-to-peak TE under the reverse load over the grid (rad)."""

    name: ClassVar[str] = "peak_to_peak_reverse"
    label: ClassVar[str] = "TE p-p (reverse load)"
    quantity: ClassVar[Quantity] = "angle"
    report_unit: ClassVar[str | None] = "arcsec"

    def __call__(self, drive: Any, response: RVResponse) -> Float[Array, ""]:
        del drive
        return jnp.max(response.te[1]) - jnp.min(response.te[1])

    def describe(self) -> str:
        return "peak-to-peak of TE under the reverse load over the output revolution's grid"


METRICS: tuple[type[AbstractMetric], ...] = (RVLostMotion, RVPeakToPeak, RVPeakToPeakReverse)

#: (kind, shape key, unit, symbol, description) of every error source; shapes: "" scalar, "N" per crank,
#: "D" per disc, "zp" per pin, "Dzc" per disc and tooth space (disc 1's spaces, then disc 2's), "DN" per disc and crank.
SOURCES = {
    "pin_circle_radius": ("deviation", "", "µm", "ΔR′", "pin-circle radius error"),
    "pin_radius": ("deviation", "", "µm", "Δr′", "pin (sleeve contact surface) radius error"),
    "pin_tangential": ("deviation", "zp", "µm", "δ_j", "tangential position error of each pin"),
    "pin_radial": ("deviation", "zp", "µm", "δr_j", "radial position error of each pin"),
    "pin_circle_eccentricity": ("eccentricity", "1", "µm", "e_p", "pin-circle eccentricity in the housing"),
    "disc_dressing_x": ("deviation", "D", "µm", "δX_4", "dresser error along X_4, each disc"),
    "disc_dressing_y": ("deviation", "D", "µm", "δY_4", "dresser error along Y_4, each disc"),
    "disc_infeed": ("deviation", "Dzc", "µm", "ΔY_4(n)", "infeed error of each tooth space of each disc"),
    "disc_indexing": ("deviation", "Dzc", "rad", "Δβ(n)", "indexing error of each tooth space of each disc"),
    "disc_setup": ("eccentricity", "D", "µm", "ΔA", "blank set-up eccentricity of each disc"),
    "disc_mandrel": ("eccentricity", "D", "µm", "ΔB", "mandrel run-out of each disc"),
    "crank_eccentricity": ("deviation", "N", "µm", "ΔA′_i", "eccentricity error of each crank"),
    "crank_phase": ("deviation", "N", "rad", "γ_i", "angular phase error of each crank's eccentrics"),
    "carrier_hole": ("eccentricity", "N", "µm", "h_i", "crank-hole position error in the carrier (phase from radial)"),
    "disc_hole": ("eccentricity", "DN", "µm", "h_di", "crank-hole position error in each disc (phase from radial)"),
    "crank_disc_clearance": ("deviation", "", "µm", "c_cd", "crank–disc bearing radial clearance, from nominal"),
    "crank_carrier_clearance": ("deviation", "", "µm", "c_cc", "crank–carrier bearing radial clearance, from nominal"),
    "main_bearing_clearance": ("deviation", "", "µm", "c_m", "carrier main-bearing radial clearance, from nominal"),
    "backlash": ("deviation", "", "µm", "j_n", "normal backlash of the sun–planet meshes, from nominal"),
    "sun_eccentricity": ("eccentricity", "1", "µm", "e_s", "sun eccentricity (run-out), turning with the sun"),
    "planet_eccentricity": ("eccentricity", "N", "µm", "e_g", "eccentricity of each planet, turning with it"),
    "planet_assembly": (
        "deviation",
        "N",
        "rad",
        "φ_g",
        "assembly phase of each planet on its crank (whole teeth: 2π k / z_g), added to its eccentricity's phase",
    ),
}


class RVKHV(AbstractGridDrive):
    """A two-stage RV (K-H-V) reducer (Hidaka et al. 1994); see the module notes for the model.

    **Arguments:**

    - `z_pins`: z_p, pins in the ring (discs have z_p − 1 lobes).
    - `pin_circle_radius`, `pin_radius`, `eccentricity`: R, r, a (mm) of the cycloid stage.
    - `z_sun`, `z_planet`: teeth of the sun and of each planet.
    - `crank_circle_radius`: r_c, mm: radius of the crank centres (the stage-1 centre distance).
    - `cranks`: N = 2 or 3; `discs`: 1 or 2 (default 3 and 2).
    - `pressure_angle`: of the stage-1 meshes, rad (default 20°).
    - `modification`: the discs' profile modification (`CycloidModification`, default none).
    - `backlash_mm`, `crank_disc_clearance_mm`, `crank_carrier_clearance_mm`, `main_bearing_clearance_mm`:
      nominal normal backlash of the meshes and radial clearances of the bearings (mm, ≥ 0; default 0); the
      error sources of the same names are deviations from these.
    - `points`: output angles of the grid over one output revolution (default 360).
    - `trace_points`: output angles of the report's TE curve (default 2 × `points`).
    - `deflection_mm`: the elastic deflection scale of the small load (default 1e-10 mm; 1e-13 to 1e-5 mm accepted,
      `rv_khv_contacts.DEFLECTION_RANGE_MM`). The rigid-limit results
      do not depend on it inside a window: it must be small enough that the load does not move the weak modes of
      preloaded parts (about 1e-5 of the pin stiffness) across a change of contact state, and large enough for the
      Newton iteration to resolve it against the preload's forces (docs/rv.md, "Size of the small load").
    - `pin_stiffness`, `mesh_stiffness`, `bearing_stiffness`: relative stiffnesses (default 1).
    - `regularisation`: μ / k_pin for floating parts (default `REGULARISATION_PER_MM` × `deflection_mm`: 1e-13 at the
      default load). Tied to the load, its force μ |q − q₀| stays the same small fraction of the load whatever the
      load's size.
    - `bearing_faces`: faces of the polygon that stands for every bearing's clearance circle (default 64; at
      least 8, at most `rv_khv_equilibrium.MAX_BEARING_FACES`). On the tolerance example the 64-gon's TE is within
      0.025″ of 1,024 faces at the median solve and 0.15″ at the 99th percentile; 128 faces give 0.006″ and 0.10″
      for half again as many Newton iterations
      (docs/rv.md, "Equilibrium").
    """

    z_pins: int = eqx.field(static=True)
    z_sun: int = eqx.field(static=True)
    z_planet: int = eqx.field(static=True)
    cranks: int = eqx.field(static=True)
    discs: int = eqx.field(static=True)
    points: int = eqx.field(static=True)
    trace_points: int = eqx.field(static=True)
    bearing_faces: int = eqx.field(static=True)
    stage: CycloidPin
    crank_circle_radius: Float[Array, ""]
    pressure_angle: Float[Array, ""]
    backlash_mm: Float[Array, ""]
    crank_disc_clearance_mm: Float[Array, ""]
    crank_carrier_clearance_mm: Float[Array, ""]
    main_bearing_clearance_mm: Float[Array, ""]
    deflection_mm: Float[Array, ""]
    pin_stiffness: Float[Array, ""]
    mesh_stiffness: Float[Array, ""]
    bearing_stiffness: Float[Array, ""]
    regularisation: Float[Array, ""]

    type_name: ClassVar[str] = "rv_khv"
    linear: ClassVar[bool] = False

    def __init__(
        self,
        z_pins: int,
        *,
        pin_circle_radius: float,
        pin_radius: float,
        eccentricity: float,
        z_sun: int,
        z_planet: int,
        crank_circle_radius: float,
        cranks: int = 3,
        discs: int = 2,
        pressure_angle: float = math.radians(20.0),
        modification: CycloidModification | None = None,
        backlash_mm: float = 0.0,
        crank_disc_clearance_mm: float = 0.0,
        crank_carrier_clearance_mm: float = 0.0,
        main_bearing_clearance_mm: float = 0.0,
        points: int = 360,
        trace_points: int | None = None,
        deflection_mm: float = DEFLECTION_MM,
        pin_stiffness: float = 1.0,
        mesh_stiffness: float = 1.0,
        bearing_stiffness: float = 1.0,
        regularisation: float | None = None,
        bearing_faces: int = BEARING_FACES,
    ):
        self.stage = CycloidPin(
            z_pins, pin_circle_radius=pin_circle_radius, pin_radius=pin_radius, eccentricity=eccentricity, modification=modification
        )
        self.z_pins = self.stage.z_pins
        self.z_sun = as_int("z_sun", z_sun, minimum=6)
        self.z_planet = as_int("z_planet", z_planet, minimum=6)
        self.cranks = as_int("cranks", cranks, minimum=2)
        if self.cranks > 3:
            raise ValueError(f"cranks: an RV reducer has 2 or 3 crankshafts, got {self.cranks}")
        self.discs = as_int("discs", discs, minimum=1)
        if self.discs > 2:
            raise ValueError(f"discs: give 2 discs (eccentrics 180° apart) or 1 (for checks), got {self.discs}")
        rc = as_float("crank_circle_radius", crank_circle_radius, positive=True)
        a, R, r = float(self.stage.eccentricity), float(self.stage.pin_circle_radius), float(self.stage.pin_radius)
        if not rc + a < R - r:
            raise ValueError(
                f"crank_circle_radius: the cranks (r_c = {rc:g} mm) must sit inside the pin circle (R − r − a = {R - r - a:g} mm)"
            )
        pa = as_float("pressure_angle", pressure_angle, positive=True)
        if not pa < math.pi / 4:
            raise ValueError(f"pressure_angle: {pa:g} rad is not a gear pressure angle (give it in rad, below π/4)")
        self.crank_circle_radius = jnp.asarray(rc, dtype=float)
        self.pressure_angle = jnp.asarray(pa, dtype=float)
        for name, v in (
            ("backlash_mm", backlash_mm),
            ("crank_disc_clearance_mm", crank_disc_clearance_mm),
            ("crank_carrier_clearance_mm", crank_carrier_clearance_mm),
            ("main_bearing_clearance_mm", main_bearing_clearance_mm),
        ):
            setattr(self, name, jnp.asarray(as_float(name, v, nonnegative=True, hint="a clearance is ≥ 0 mm"), dtype=float))
        self.points = as_int("points", points, minimum=1)
        self.trace_points = 2 * self.points if trace_points is None else as_int("trace_points", trace_points, minimum=2)
        self.deflection_mm = jnp.asarray(check_deflection(as_float("deflection_mm", deflection_mm, positive=True)), dtype=float)
        for name, v in (("pin_stiffness", pin_stiffness), ("mesh_stiffness", mesh_stiffness), ("bearing_stiffness", bearing_stiffness)):
            setattr(self, name, jnp.asarray(as_float(name, v, positive=True), dtype=float))
        if regularisation is None:
            regularisation = REGULARISATION_PER_MM * float(self.deflection_mm)
        self.regularisation = jnp.asarray(as_float("regularisation", regularisation, positive=True), dtype=float)
        self.bearing_faces = as_int("bearing_faces", bearing_faces, minimum=8)
        if self.bearing_faces > MAX_BEARING_FACES:
            raise ValueError(
                f"bearing_faces: {self.bearing_faces:,} faces, more than {MAX_BEARING_FACES:,}; the default {BEARING_FACES} is "
                "within 0.03″ of 1,024 faces at the median solve (docs/rv.md)"
            )

    @property
    def ratio(self) -> float:
        """Reduction ratio i = 1 + z_p z_g / z_s (ring fixed, input sun, output carrier)."""
        return 1.0 + self.z_pins * self.z_planet / self.z_sun

    def describe(self) -> list[tuple[str, str]]:
        return [
            ("pins z_p / lobes z_c", f"{self.z_pins} / {self.z_pins - 1}"),
            ("sun z_s / planets z_g", f"{self.z_sun} / {self.z_planet}"),
            ("ratio i = 1 + z_p z_g / z_s", f"{self.ratio:.6g}"),
            ("cranks N / discs", f"{self.cranks} / {self.discs}"),
            (
                "pin circle R, pin r, eccentricity a",
                f"{float(self.stage.pin_circle_radius):g}, {float(self.stage.pin_radius):g}, {float(self.stage.eccentricity):g} mm",
            ),
            ("crank circle r_c", f"{float(self.crank_circle_radius):g} mm"),
            ("nominal backlash j_n", f"{float(self.backlash_mm) * 1e3:g} µm"),
            (
                "nominal clearances crank–disc / crank–carrier / main",
                f"{float(self.crank_disc_clearance_mm) * 1e3:g} / "
                f"{float(self.crank_carrier_clearance_mm) * 1e3:g} / {float(self.main_bearing_clearance_mm) * 1e3:g} µm",
            ),
            (
                "profile modification (shift, equidistant, rotation)",
                f"{float(self.stage.modification.shift):+g} mm, "
                f"{float(self.stage.modification.equidistant):+g} mm, {float(self.stage.modification.rotation) * ARCSEC_PER_RAD:g}″",
            ),
        ]

    # ------------------------------------------------------------ the drive protocol

    @property
    def error_sources(self) -> dict[str, SourceSpec]:
        return dict(_error_sources(self.cranks, self.discs, self.z_pins))

    def output_angles(self, points: int | None = None) -> Float[Array, " p"]:
        """Output angles θ_o of the grid over one output revolution (rad)."""
        p = self.points if points is None else points
        return jnp.arange(p, dtype=float) * (TWO_PI / p)

    def input_angles(self) -> Float[Array, " p"]:
        """The input angles i θ_o of the grid (rad)."""
        return self.ratio * self.output_angles()

    def errors(self, errors: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """`errors` (source name → value; names left out are 0) checked and broadcast to the declared shapes."""
        full = self.zero_errors()
        if errors is not None:
            unknown = sorted(set(errors) - set(full))
            if unknown:
                raise ValueError(f"errors: unknown error source(s) {unknown}; the sources are {list(full)}")
            full.update(errors)
        return self.checked(full)

    def response(self, errors: Mapping[str, Any] | None) -> RVResponse:
        """The equilibrium at every output angle of the grid, both load directions (`RVResponse`)."""
        require_x64()
        return _response_jit(self, self.errors(errors), self.output_angles())

    def solve_at(self, errors: Mapping[str, Any] | None, output_angles) -> RVResponse:
        """As `response`, at the given output angles θ_o (rad)."""
        require_x64()
        return _response_jit(self, self.errors(errors), jnp.asarray(output_angles, dtype=float).reshape(-1))

    @property
    def metrics(self) -> dict[str, AbstractMetric]:
        return {m.name: m() for m in METRICS}

    def trace(self, errors: Mapping[str, Any] | None) -> Trace:
        """TE under the forward load over one output revolution (`trace_points` angles), against the input angle."""
        th_o = self.output_angles(self.trace_points)
        r = self.solve_at(errors, th_o)
        te = np.asarray(r.te[0])
        theta = np.asarray(th_o) * self.ratio
        return Trace.of_grid(theta, te, f"{self.ratio:g}")

    @classmethod
    def from_table(cls, table: Table) -> RVKHV:
        """``[drive] type = "rv_khv"``: see `gearte.drives.rv_khv_table`."""
        from .rv_khv_table import drive_arguments

        kwargs = drive_arguments(table)
        try:
            return cls(**kwargs)
        except ValueError as e:
            raise ConfigError(f"{table.where} {e}") from None

    def accuracy(self) -> str:
        return (
            f"taken on a grid of {self.points} output angles over one output revolution ({self.points} × 2 equilibrium "
            "solves), not between them; each solve is Newton's method on the contact potential (bearing clearances as "
            f"{self.bearing_faces}-gons, within {1 / math.cos(math.pi / self.bearing_faces) - 1:.1e} of the clearance; on "
            "the tolerance example the 64-gon's TE is within 0.025″ of 1,024-gons at the median solve and 0.15″ at the "
            "99th percentile, 128 faces' within 0.006″ and 0.10″) until the step lands on the minimum, then the elastic "
            "part removed exactly for the closed contacts (the rigid limit); result codes per solve"
        )

    def solved(self, response: RVResponse) -> Array:
        """Whether every equilibrium solve of `response` (every angle, both loads) succeeded."""
        return jnp.all(response.result == RESULTS.successful)

    def bytes_per_sample(self) -> int:
        m = self.discs * self.z_pins + 2 * self.cranks
        n = 5 + 3 * (self.cranks + self.discs)
        return 8 * 2 * self.points * (m * n * 6 + self.bearing_faces * self.z_pins * self.discs)

    def sample_outputs(self, errors, response: RVResponse) -> dict[str, Array]:
        """Per sample: TE p-p (both directions), lost motion (max and min over the grid), and the fraction of solves
        that succeeded."""
        del errors
        te = response.te
        return {
            "te_pp": jnp.max(te[0]) - jnp.min(te[0]),
            "te_pp_reverse": jnp.max(te[1]) - jnp.min(te[1]),
            "lost_motion": jnp.max(te[0] - te[1]),
            "lost_motion_min": jnp.min(te[0] - te[1]),
            "solved": jnp.mean((response.result == RESULTS.successful).astype(float)),
        }

    def study_outputs(self, context: AbstractStudyContext) -> StudyOutputs:
        """The typical unit's TE under both loads, its spectrum and contact map, and the Monte Carlo of the per-sample
        outputs, with their plots and report (see `gearte.drives.rv_khv_outputs`)."""
        from .rv_khv_outputs import study_outputs

        return study_outputs(self, context)


@functools.lru_cache(maxsize=64)
def _error_sources(cranks: int, discs: int, z_pins: int) -> dict[str, SourceSpec]:
    """`RVKHV.error_sources` of a reducer with these counts, built once (a study asks for them many times; callers get
    a copy of the dict, and `SourceSpec` is immutable)."""
    zc = z_pins - 1
    shapes = {"": (), "1": (1,), "N": (cranks,), "D": (discs,), "zp": (z_pins,), "Dzc": (discs * zc,), "DN": (discs * cranks,)}
    return {
        name: SourceSpec(name, kind, shape=shapes[shape], unit=unit, symbol=symbol, description=text)  # pyright: ignore[reportArgumentType]
        for name, (kind, shape, unit, symbol, text) in SOURCES.items()
    }


def grid_walk(z_c: int, p: int) -> np.ndarray:
    """The order of a uniform grid of p output angles (index k at θ₀ + 2π k / p) that `solve_order` takes: indices k,
    k + s, k + 2s, … (mod p, in gcd(s, p) cycles) with the one step s whose neighbours differ least in the output
    angle θ_o, the eccentrics' phase z_c θ_o and the pins' phase z_p θ_o = (z_c + 1) θ_o together (the sum of the
    three differences, each wrapped to ±π); of two steps as good, the one that advances the eccentrics' phase least.
    The drive turned by a pin pitch is the same drive but for its errors, so where the grid holds that turn (p a
    multiple of z_p) the walk goes a pin pitch at a time; on the example's 97 angles it is the eccentrics' phase
    order."""
    if p < 3:
        return np.arange(p)

    def wrapped(x: float) -> float:
        return abs((x + math.pi) % TWO_PI - math.pi)

    def cost(s: int) -> float:
        d = TWO_PI * s / p
        return round(wrapped(d) + wrapped(z_c * d) + wrapped((z_c + 1) * d), 9)

    s = min(range(1, p), key=lambda s: (cost(s), (z_c * s) % p, s))
    g = math.gcd(s, p)
    return np.asarray([(k0 + s * j) % p for k0 in range(g) for j in range(p // g)])


def solve_order(z_c: int, thetas: Float[Array, " p"]) -> Array:
    """The order in which `RVKHV.response` solves the output angles `thetas` (rad), each solve starting from the one
    before (`_response_jit`). On a uniform grid over the revolution (the drive's own grids), `grid_walk`. Other
    angles: by the eccentrics' phase z_c θ_o mod 2π, in g = gcd(z_c, p) sectors of the revolution."""
    p = thetas.shape[0]
    g = math.gcd(z_c, p)
    sector = jnp.floor(jnp.mod(thetas, TWO_PI) / (TWO_PI / g) + 1e-9)  # 1e-9: an angle on a sector's edge opens it
    by_phase = jnp.argsort(jnp.mod(z_c * thetas, TWO_PI) + TWO_PI * sector)
    if p < 3:
        return by_phase
    off = thetas - thetas[0] - (TWO_PI / p) * jnp.arange(p, dtype=thetas.dtype)
    uniform = jnp.all(jnp.abs(jnp.mod(off + math.pi, TWO_PI) - math.pi) <= 1e-9)
    return jnp.where(uniform, jnp.asarray(grid_walk(z_c, p), dtype=by_phase.dtype), by_phase)


@kept_jit
def _response_jit(drive: RVKHV, err, thetas) -> RVResponse:
    """Both load directions. Each solve starts from the solution at the previous angle in `solve_order`, where the
    contact states of neighbours are alike (a `lax.scan`), turned with the drive: every body's small translation
    turned by the output's turn between the two angles, its rotation kept. On the drive's grids the order is
    `grid_walk`: on the example's 97 angles the order of the eccentrics' phase (z_c θ_o mod 2π); on 360 angles a pin
    pitch at a time, where the drive turned is the same drive but for its errors. 16 units of the tolerance example,
    Newton iterations per solve on average: 360 angles 13.7 (22.0 with the start not turned, 42.1 in the phase's
    order taken in the three sectors of 120° that gcd(z_c, 360) = 3 makes); 97 angles 24.2 (29.1 not turned).

    The two directions share each angle's contacts (the load's sign enters the load vector alone): one system per
    angle, its two solves batched (values identical to building the system for each direction; tracing the
    response takes about 1 s less). The systems of every angle are built at once, vectorised, before the walk
    (about 15 MB per unit at 360 angles): built one at a time inside it, the same 16 units at 360 angles took
    0.154-0.161 s per unit instead of 0.132-0.136 (alternating; TE within 2e-13 rad)."""
    i = output_index(drive)
    L = drive.stage.pin_circle_radius
    n = dof_count(drive.cranks, drive.discs)
    order = solve_order(drive.z_pins - 1, thetas)
    back = jnp.argsort(order)
    signs = jnp.asarray([1.0, -1.0])
    x = translations(drive.cranks, drive.discs)

    def turned(q, angle):
        c, s = jnp.cos(angle), jnp.sin(angle)
        u, v = q[:, x], q[:, x + 1]
        return q.at[:, x].set(c * u - s * v).at[:, x + 1].set(s * u + c * v)

    def step(carry, angle):
        theta_o, s = angle
        q_before, theta_before = carry
        q0 = turned(q_before, theta_o - theta_before)

        def direction(sign, q):
            eq = solve(eqx.tree_at(lambda t: t.f, s, sign * s.f), q)
            return eq.q, (eq.q_rigid[i] / L, eq.q[i] / L, eq.force, eq.result, eq.steps)

        q, out = jax.vmap(direction)(signs, q0)
        return (q, theta_o), out

    ordered = thetas[order]
    systems = jax.vmap(lambda theta_o: rv_system(drive, err, theta_o, 1.0))(ordered)
    _, out = jax.lax.scan(step, (jnp.zeros((2, n), dtype=thetas.dtype), ordered[0]), (ordered, systems))
    te, tl, force, result, steps = jax.tree.map(lambda x: jnp.swapaxes(x, 0, 1)[:, back], out)
    return RVResponse(thetas, te, tl, force, result, steps)


__all__ = (
    "METRICS",
    "RVKHV",
    "SOURCES",
    "Eccentricity",
    "RVLostMotion",
    "RVPeakToPeak",
    "RVPeakToPeakReverse",
    "RVResponse",
    "grid_walk",
    "solve_order",
)
