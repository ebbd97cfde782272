"""What the bearings' clearance polygons cost in TE: the tolerance example's units with every bearing clearance taken
as a polygon of 64 faces (gearte's model) against the same units with 1,024 faces, a reference within 0.0012″ of the
circle's limit (docs/rv.md, "Equilibrium").

Each face count runs in a fresh interpreter, where `gearte.drives.rv_khv_equilibrium`'s face tables are rebuilt
before the first solve is traced (the count is a module constant, not an option). Not a speed benchmark: it checks a
result and prints the error's median, 99th percentile and maximum over every angle and both loads, and the Newton
iterations per solve of each face count.

    python benchmarks/rv_polygon_accuracy.py            # 3 units, 97 angles × 2 loads, under a minute
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ARCSEC_PER_RAD = 3600 * 180 / math.pi

CHILD = """
import json, math, sys
import jax
import numpy as np
jax.config.update("jax_enable_x64", True)
import gearte.drives.rv_khv_equilibrium as eq
faces, units = int(sys.argv[1]), int(sys.argv[2])
angles = 2 * math.pi * np.arange(faces) / faces
eq.BEARING_FACES = faces
eq.FACE_NORMALS = np.stack([np.cos(angles), np.sin(angles)], axis=1)
n = eq.FACE_NORMALS
eq._FACE_OUTER = np.stack([n[:, 0] ** 2, n[:, 0] * n[:, 1], n[:, 1] ** 2], axis=1)
eq.MAX_STEPS = 20000  # more faces, more of them to walk over
from gearte.cli.config import load_study
st = load_study(sys.argv[3])
te, steps = [], []
for u in range(units):
    r = st.drive.response(st.errors.sample(jax.random.key(u)))
    te.append(np.asarray(r.te).tolist()); steps.append(float(np.mean(np.asarray(r.steps))))
print(json.dumps({"te": te, "steps": steps}))
"""


def run(faces: int, units: int, study: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(faces), str(units), str(study)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--units", type=int, default=3)
    ap.add_argument("--faces", type=int, nargs="+", default=[64, 128])
    ap.add_argument("--reference", type=int, default=1024)
    ap.add_argument("--study", type=Path, default=ROOT / "examples" / "rv_robot_joint_tolerances.toml")
    a = ap.parse_args()
    ref = run(a.reference, a.units, a.study)
    ref_te = np.asarray(ref["te"]) * ARCSEC_PER_RAD
    print(f"reference: {a.reference} faces, {np.mean(ref['steps']):.1f} Newton iterations per solve")
    print("| faces | median error (″) | P99 (″) | max (″) | iterations per solve |")
    print("|---|---|---|---|---|")
    for m in a.faces:
        got = run(m, a.units, a.study)
        err = np.abs(np.asarray(got["te"]) * ARCSEC_PER_RAD - ref_te)
        print(f"| {m} | {np.median(err):.4f} | {np.percentile(err, 99):.3f} | {err.max():.3f} | {np.mean(got['steps']):.1f} |")


if __name__ == "__main__":
    main()
