"""What the bearings' clearance polygons cost in TE: the tolerance example's units with every bearing clearance taken
as a polygon of 64 faces (gearte's default) against the same units with 1,024 faces (docs/rv.md, "Equilibrium"). The
median error falls about 4× with each doubling of the faces (64 → 128 below), so the reference's own is near 1e-4″.

Each face count (`[drive.model] bearing_faces`, `RVKHV(bearing_faces=...)`) runs in a fresh interpreter, with the
solver's iteration limit raised for the many faces of the reference. Not a speed benchmark: it checks a
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
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ARCSEC_PER_RAD = 3600 * 180 / math.pi

CHILD = """
import json, re, sys
import jax
import numpy as np
jax.config.update("jax_enable_x64", True)
import gearte.drives.rv_khv_equilibrium as eq
eq.MAX_STEPS = 20000  # more faces, more of them to walk over (the limit is a module constant, read when traced)
from gearte.cli.config import load_study
faces, units, path, tmp = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
text = open(path).read()
text = re.sub(r"(\\[drive\\.model\\][^\\n]*\\n)", lambda m: m.group(1) + f"bearing_faces = {faces}\\n", text, count=1)
open(tmp, "w").write(text)
st = load_study(tmp)
assert st.drive.bearing_faces == faces
te, steps = [], []
for u in range(units):
    r = st.drive.response(st.errors.sample(jax.random.key(u)))
    te.append(np.asarray(r.te).tolist()); steps.append(float(np.mean(np.asarray(r.steps))))
print(json.dumps({"te": te, "steps": steps}))
"""


def run(faces: int, units: int, study: Path) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        args = [str(faces), str(units), str(study), str(Path(tmp) / study.name)]
        out = subprocess.run([sys.executable, "-c", CHILD, *args], capture_output=True, text=True, check=True)
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
