"""A drive written the way a new drive is added to gearte: this one file (model, schema, metric, trace)
plus one registry line (the tests put it in `gearte.drives.DRIVES`, as `registry.py` would).

A spur gear pair with an eccentric pinion and an eccentric gear and a backlash, computed on a grid
of input angles (an `AbstractGridDrive`): the output angle error at input angle θ is

    Δθ(θ) = (e₁ sin(θ + φ₁) + e₂ sin(θ/i + φ₂)) · 10⁻³ / r_b2      (rad; e in µm, r_b2 in mm)

plus a mean tooth-spacing term at the mesh frequency and a constant index error; the lost motion is the backlash j (µm, a signed deviation about its nominal) over r_b2 plus
the peak-to-peak of Δθ, since the backlash opens on top of the kinematic error.
"""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp
import numpy as np

import gearte
from gearte.core.schema import Table
from gearte.drives import Trace


class GridPeakToPeak(gearte.AbstractMetric):
    name: ClassVar[str] = "peak_to_peak"
    label: ClassVar[str] = "peak-to-peak Δθ on the grid"
    quantity: ClassVar = "angle"

    def __call__(self, drive, response):
        return jnp.max(response["te"]) - jnp.min(response["te"])

    def describe(self) -> str:
        return "peak-to-peak of Δθ on the input-angle grid"


class LostMotion(gearte.AbstractMetric):
    name: ClassVar[str] = "lost_motion"
    label: ClassVar[str] = "lost motion"
    quantity: ClassVar = "angle"

    def __call__(self, drive, response):
        return response["backlash"] + jnp.max(response["te"]) - jnp.min(response["te"])

    def describe(self) -> str:
        return "backlash over the base radius plus the peak-to-peak kinematic error"


class ToyGearPair(gearte.AbstractGridDrive):
    type_name: ClassVar[str] = "toy_gear_pair"
    z1: int
    z2: int
    base_radius: float
    points: int

    def __init__(self, z1: int = 20, z2: int = 60, *, base_radius: float = 28.2, points: int = 720):
        self.z1, self.z2, self.base_radius, self.points = z1, z2, float(base_radius), points

    @property
    def error_sources(self):
        return {
            "pinion": gearte.SourceSpec("pinion", "eccentricity", symbol="φ_1"),
            "gear": gearte.SourceSpec("gear", "eccentricity", symbol="φ_2"),
            "backlash": gearte.SourceSpec("backlash", "deviation", shape=(), tolerance=20.0),
            "spacing": gearte.SourceSpec("spacing", "deviation", shape=(self.z1,), description="pinion tooth spacing errors, µm"),
            "index": gearte.SourceSpec("index", "deviation", shape=(), unit="rad", description="output index error, rad"),
        }

    def input_angles(self):
        # One output revolution: the pattern of both eccentricities repeats after i input revolutions.
        revs = self.z2 // math.gcd(self.z1, self.z2)
        return jnp.linspace(0.0, 2 * math.pi * revs, self.points * revs, endpoint=False)

    def response(self, errors):
        e = self.checked(errors)
        th = self.input_angles()
        i = self.z2 / self.z1
        te = (
            e["pinion"].magnitude[0] * jnp.sin(th + e["pinion"].phase[0])
            + e["gear"].magnitude[0] * jnp.sin(th / i + e["gear"].phase[0])
            + jnp.mean(e["spacing"]) * jnp.sin(self.z1 * th)
        ) * 1e-3 / self.base_radius + e["index"]
        return {"te": te, "backlash": e["backlash"] * 1e-3 / self.base_radius}

    @property
    def metrics(self):
        return {"peak_to_peak": GridPeakToPeak(), "lost_motion": LostMotion()}

    def accuracy(self) -> str:
        return f"on a grid of {self.points} points per input revolution (≤ {1 - math.cos(math.pi / self.points):.1e} relative)"

    def trace(self, errors) -> Trace:
        te = np.asarray(self.response(errors)["te"])
        th = np.asarray(self.input_angles())
        return Trace(
            theta=th,
            te=te,
            span_revs=str(self.z2 // math.gcd(self.z1, self.z2)),
            max=float(te.max()),
            min=float(te.min()),
            theta_max=float(th[te.argmax()]),
            theta_min=float(th[te.argmin()]),
        )

    @classmethod
    def from_table(cls, table: Table) -> ToyGearPair:
        return cls(
            table.integer("z1", minimum=3),
            table.integer("z2", minimum=3),
            base_radius=table.number("base_radius_mm", positive=True),
            points=table.integer("points_per_rev", 720, minimum=16),
        )


STUDY = """
[study]
name = "toy"
samples = 256
seed = 5
metric = "lost_motion"

[drive]
type = "toy_gear_pair"
z1 = 20
z2 = 60
base_radius_mm = 28.2
points_per_rev = 64

[errors.pinion]
tolerance_um = 10
magnitude = { law = "rayleigh", scale_fraction = 0.5, truncate_at_tolerance = true }
phase = { rule = "uniform" }

[errors.gear]
tolerance_um = 16
magnitude = { law = "rayleigh", scale_fraction = 0.5, truncate_at_tolerance = true }
phase = { rule = "uniform" }

[errors.backlash]
tolerance_um = 20
value = { law = "uniform", half_width_um = 20, centre_um = 60 }
"""
