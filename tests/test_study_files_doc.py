"""docs/study-files.md against the study-file readers: it cannot drift.

Every reader (the `[study]`, `[errors]` and study-kind readers of `gearte.cli.config`, and each drive's
`from_table`) reads its keys through `gearte.core.schema.Table`. Here every key a reader asks for
(`has`, `get` and the typed getters, present or not) is recorded while the example study files and
variants that take every branch (every law, rule, cost model) are read; the keys documented under each
table heading of the page must be exactly those.
"""

from __future__ import annotations

import re
import tomllib
from collections import defaultdict
from pathlib import Path

import pytest
import toy_drive

from gearte.cli.config import build_study
from gearte.core import schema
from gearte.drives import DRIVES

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "study-files.md"
#: Tables whose keys are names of error sources (or, for the top level, tables), not schema keys.
NAME_TABLES = {
    "study file",
    "[errors]",
    "[budget.costs]",
    "[budget.grades]",
    "[allocation.seed_rule]",
    "[budget] cost_model",
    "[budget.costs.NAME.costs_by_grade]",
}
ANGLE = r"(deg|rad|arcmin|arcsec)"


def _norm_table(where: str) -> str:
    where = re.sub(r"\s*#\d+( \([^)]*\))?$", "", where)
    where = re.sub(r"^\[errors\.[A-Za-z0-9_]+", "[errors.NAME", where)
    where = re.sub(r"^\[budget\.(costs|grades)\.[A-Za-z0-9_]+(\.costs_by_grade)?\]$", r"[budget.\1.NAME\2]", where)
    where = re.sub(r"^\[errors\.NAME\.value\.amplitude\]$", "[errors.NAME.value]", where)  # a pattern amplitude's own law
    return where


def _norm_key(table: str, key: str) -> str:
    if table == "[errors.NAME.value]":
        if re.fullmatch(rf"phase_{ANGLE}", key):
            return "phase_deg"
        return re.sub(rf"_{ANGLE}$", "_um", key)
    return key


def documented() -> dict[tuple[str | None, str], set[str]]:
    """(drive type or None, table) → the keys listed in the table under that heading."""
    out: dict[tuple[str | None, str], set[str]] = defaultdict(set)
    current = None
    for line in DOC.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^#{2,3} `(\[\[?[^`]+\]?\])`(?: \(type = \"([a-z0-9_]+)\"\))?", line)
        if m:
            current = (m.group(2), m.group(1))
            continue
        if current and line.startswith("| `"):
            first = line.split("|")[1]
            out[current] |= set(re.findall(r"`([A-Za-z0-9_]+)`", first))
    return out


def _variants() -> list[tuple[str, str]]:
    """Study files that take every branch of the readers: (drive type, TOML text)."""
    random = (ROOT / "examples" / "planetary_wang2013_random.toml").read_text(encoding="utf-8")
    sun = 'tolerance_um = 13\nmagnitude = { law = "fixed" }\nphase = { rule = "uniform" }'
    assert sun in random
    out = []
    for mag in (
        '{ law = "fixed", value_um = 3 }',
        '{ law = "fixed", fraction_of_tolerance = 0.5 }',
        '{ law = "uniform", low_um = 1 }',
        '{ law = "normal", mean_um = 5, std_um = 1 }',
        '{ law = "truncated_normal", mean_um = 5, std_um = 1, high_um = 9 }',
        '{ law = "rayleigh", scale_um = 4 }',
        '{ law = "rayleigh", scale_fraction = 0.5, truncate_at_tolerance = true }',
    ):
        for phase in (
            '{ rule = "uniform" }',
            '{ rule = "fixed", value_deg = 30 }',
            '{ rule = "relative", to = "beta_r", offset_rad = "pi/9" }',
        ):
            out.append(("planetary_2kh", random.replace(sun, f"tolerance_um = 13\nmagnitude = {mag}\nphase = {phase}")))
    budget = '\n[budget]\nsources = ["sun_manufacturing", "ring_manufacturing"]\n[[budget.constraints]]\nspec = 300.0\ntarget = 0.9\n'
    for cost in (
        'model = "reciprocal", a = 0.1, b = 2',
        'model = "power", exponent = 2',
        'model = "exponential", a = 0, b = 1, k = 0.1',
        'model = "grade_table", costs_by_grade = { "5" = 3.0, "6" = 2.0 }, quantity = "F_r", standard = "1328-1:2013", '
        "module_mm = 1.0, diameter_mm = 12.0, face_width_mm = 10.0",
    ):
        out.append(
            (
                "planetary_2kh",
                random
                + budget
                + "[budget.costs.sun_manufacturing]\n"
                + cost.replace(", ", "\n").replace('"5" = 3.0\n', '"5" = 3.0, ')
                + "\n",
            )
        )
    out.append(("planetary_2kh", random + '\n[budget]\nspec = 300.0\nconstraint = "mean_k_sigma"\ntarget = 3\n'))
    cycloid = (ROOT / "examples" / "cycloid_yao2001_modified.toml").read_text(encoding="utf-8")
    wheel = re.search(r"\[drive\.wheel\][^\[]*", cycloid)
    assert wheel
    out.append(
        (
            "cycloid_pin",
            cycloid.replace(wheel.group(0), "[drive.modification]\nshift_mm = -0.215\nequidistant_mm = 0.38\nrotation_arcsec = 5\n\n"),
        )
    )
    toy = toy_drive.STUDY
    value = 'value = { law = "uniform", half_width_um = 20, centre_um = 60 }'
    assert value in toy
    for law in (
        '{ law = "fixed", value_um = 50 }',
        '{ law = "uniform", low_um = 40, high_um = 80 }',
        '{ law = "normal", mean_um = 60, std_um = 5 }',
        '{ law = "truncated_normal", mean_um = 60, std_um = 5, low_um = 50, high_um = 70 }',
        '{ law = "rayleigh", scale_um = 5, truncate_at_um = 9 }',
    ):
        out.append(("toy_gear_pair", toy.replace(value, f"value = {law}")))
    out.append(
        (
            "toy_gear_pair",
            toy + '\n[errors.spacing]\nvalue = { law = "sinusoid", amplitude = { law = "uniform", low_um = 0, high_um = 5 }, '
            'phase = "uniform", order = 2 }\n[errors.index]\ntolerance_arcsec = 20\nvalue = { law = "random_angle" }\n',
        )
    )
    out.append(
        (
            "toy_gear_pair",
            toy + '\n[errors.spacing]\nvalue = { law = "sinusoid", amplitude_um = 3, phase_deg = 10 }\n'
            '[errors.index]\nvalue = { law = "uniform", half_width_arcsec = 20 }\n',
        )
    )
    return out


@pytest.fixture(scope="module")
def probed() -> dict[tuple[str, str], set[str]]:
    rec: dict[tuple[str, str], set[str]] = defaultdict(set)
    current = {"type": ""}
    has, get = schema.Table.has, schema.Table.get

    def rec_has(self, key):
        rec[(current["type"], _norm_table(self.where))].add(key)
        return has(self, key)

    def rec_get(self, key, *a, **k):
        rec[(current["type"], _norm_table(self.where))].add(key)
        return get(self, key, *a, **k)

    files = [(tomllib.loads(p.read_text(encoding="utf-8")), str(p)) for p in sorted((ROOT / "examples").glob("*.toml"))]
    files += [(tomllib.loads(text), f"variant {i}") for i, (_, text) in enumerate(_variants())]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(schema.Table, "has", rec_has)
        mp.setattr(schema.Table, "get", rec_get)
        mp.setitem(DRIVES, "toy_gear_pair", toy_drive.ToyGearPair)
        for raw, name in files:
            current["type"] = raw["drive"]["type"]
            build_study(raw, name)
    # [drive.reference] (cycloid-pin) names its keys after the error sources, like [errors].
    return {
        (t, w): {_norm_key(w, k) for k in keys}
        for (t, w), keys in rec.items()
        if w not in NAME_TABLES and not w.startswith("[drive.reference")
    }


def test_every_key_a_reader_asks_for_is_documented_and_every_documented_key_is_read(probed):
    doc = documented()
    drive_tables = {w for (t, w) in doc if t is not None}
    checked = set()
    for (dtype, where), keys in sorted(probed.items()):
        if dtype == "toy_gear_pair" and (where in drive_tables or where.startswith(("[drive", "[[drive"))):
            continue  # the test drive's own [drive] table is not part of the page
        key = (dtype if where in drive_tables or where.startswith(("[drive", "[[drive")) else None, where)
        assert key in doc, f"docs/study-files.md has no section for {where}" + (f' (type = "{dtype}")' if key[0] else "")
        missing = keys - doc[key]
        assert not missing, f"{where}{' (' + dtype + ')' if key[0] else ''}: keys read but not documented: {sorted(missing)}"
        checked.add(key)
    # Generic tables collect keys over every drive; each documented key must be asked for by some reader.
    generic: dict[str, set[str]] = defaultdict(set)
    for (_, where), keys in probed.items():
        generic[where] |= keys
    for (dtype, where), keys in doc.items():
        read = probed.get((dtype, where), set()) if dtype is not None else generic.get(where, set())
        extra = keys - read
        assert not extra, f"{where}{' (' + dtype + ')' if dtype else ''}: documented but no reader asks for {sorted(extra)}"


def test_every_registered_drive_has_a_section():
    sections = {t for (t, _) in documented() if t is not None}
    assert set(DRIVES) <= sections, sorted(set(DRIVES) - sections)


def test_reference_table_names_every_angle_source_with_its_unit():
    """[drive.reference] (cycloid-pin) takes its keys from the error sources, each with the unit suffix of
    `unit_of`: the page names every angle source, whose suffix (arcsec) is not the lengths' um."""
    from gearte.drives.cycloid_pin_geometry import ANGLE_FIELDS
    from gearte.drives.cycloid_pin_table import unit_of

    text = DOC.read_text(encoding="utf-8")
    section = text.split("### `[drive.reference]`", 1)[1].split("\n### ", 1)[0]
    assert {unit_of(f) for f in ANGLE_FIELDS} == {"arcsec"}
    assert "`NAME_arcsec`" in section and "`NAME_um`" in section and "`NAME_deg`" in section
    missing = [f for f in ANGLE_FIELDS if f"`{f}`" not in section]
    assert not missing, f"docs/study-files.md, [drive.reference]: angle sources not named: {missing}"
