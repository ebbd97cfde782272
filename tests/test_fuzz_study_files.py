"""Fuzzing the study-file reader: malformed values and structures for every registered drive's schema.

Each example study file (at least one per drive of `gearte.drives.registry.DRIVES`) is parsed, then
hypothesis mutates it: a value replaced by any TOML value (numbers out of range, NaN, ±inf, huge
integers, strings, booleans, dates, arrays, tables), a key deleted, renamed by a typo, or an unknown
key added, in any table or array of tables. The reader (`gearte.cli.config.load_study`, in-process)
must either accept the file or raise a `ConfigError` that names the file, the table and the key,
never another exception. A few mutated files also go through the real command (a subprocess):
exit status 2, a one-line message, no traceback, nothing written.

    pytest tests/test_fuzz_study_files.py -q          # the count of fuzzed cases is FUZZ_EXAMPLES × len(BASES)
"""

from __future__ import annotations

import copy
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gearte.cli import config
from gearte.cli.config import ConfigError, load_study, read_toml
from gearte.drives.registry import DRIVES

ROOT = Path(__file__).resolve().parents[1]
BASES = sorted((ROOT / "examples").glob("*.toml"))
FUZZ_EXAMPLES = 150  # per example file; derandomized, so every run tries the same files
NAME = "fuzzed.toml"


def test_every_registered_drive_has_a_fuzzed_example():
    types = {read_toml(p)["drive"]["type"] for p in BASES}
    assert types == set(DRIVES), f"drives without an example study file to fuzz: {set(DRIVES) - types}"


def _paths(obj, prefix=()):
    """Every place in the parsed file: (path, container, key) for each value of each table and array."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield prefix + (k,)
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            if isinstance(v, (dict, list)):
                yield prefix + (i,)
                yield from _paths(v, prefix + (i,))


def _tables(obj, prefix=()):
    """Every table (dict) in the parsed file, by path."""
    if isinstance(obj, dict):
        yield prefix
        for k, v in obj.items():
            yield from _tables(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _tables(v, prefix + (i,))


def _at(raw, path):
    for p in path:
        raw = raw[p]
    return raw


scalars = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 1, 2, 3, 2**31, 2**32 - 1, 2**32, 2**63, -(2**63)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, -1.0, 1e-300, 1e300, math.nan, math.inf, -math.inf]),
    st.text(max_size=10),
    st.sampled_from(["", "uniform", "fixed", "pi/0", "7pi/9", "rayleigh", "peak", "planetary_2kh", "cycloid_pin", "harmonic"]),
    st.booleans(),
    st.dates(),
    st.datetimes(),
    st.times(),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6,
)
key_names = st.one_of(st.text(min_size=1, max_size=12), st.sampled_from(["type", "law", "value_um", "samples", "z", "phase", "magnitude"]))


@st.composite
def mutated(draw, base_raw):
    raw = copy.deepcopy(base_raw)
    kind = draw(st.sampled_from(["replace", "delete", "typo", "add"]))
    if kind == "add":
        table = draw(st.sampled_from(list(_tables(raw))))
        key = draw(key_names)
        target = _at(raw, table)
        if key in target:
            kind = "replace"
            path = table + (key,)
        else:
            target[key] = draw(values)
            return raw, kind, table, key
    paths = list(_paths(raw))
    path = draw(st.sampled_from(paths))
    parent, key = _at(raw, path[:-1]), path[-1]
    if kind == "replace":
        parent[key] = draw(values)
    elif isinstance(parent, list):  # deleting or renaming an array entry: drop it
        del parent[key]
        kind = "delete"
    elif kind == "delete":
        del parent[key]
    else:
        k = str(key)
        i = draw(st.integers(0, len(k)))
        new = k[:i] + draw(st.sampled_from(["_", "x", "s", ""])) + k[i + 1 :]
        if not new or new in parent:
            new = k + "_"
        parent[new] = parent.pop(key)
        key = new
    return raw, kind, path[:-1], key


def _names(table_path) -> list[str]:
    """The names a message may use for the table at `table_path` (or any table above it)."""
    keys = [str(p) for p in table_path if not isinstance(p, int)]
    names = ["study file"] + [f"[{'.'.join(keys[:i])}]" for i in range(1, len(keys) + 1)]
    return names + keys


def _check(raw, kind, table_path, key, monkeypatch):
    monkeypatch.setattr(config, "read_toml", lambda path: raw)
    try:
        load_study(NAME)
    except ConfigError as e:
        msg = str(e)
        assert msg.startswith(f"{NAME}: "), msg
        assert re.search(r"\[[^\]]+\]|study file", msg), f"no table named: {msg}"
        named = [str(key)] + _names(table_path)
        assert any(n in msg for n in named), f"{kind} {'.'.join(map(str, table_path))} / {key!r}: message names neither: {msg}"
        assert "Traceback" not in msg, msg
    # Anything other than a ConfigError propagates and fails the test.


@pytest.mark.parametrize("base", BASES, ids=lambda p: p.stem)
def test_fuzzed_study_files_are_accepted_or_refused_naming_file_table_and_key(base, monkeypatch):
    base_raw = read_toml(base)

    @settings(
        max_examples=FUZZ_EXAMPLES,
        derandomize=True,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large],
    )
    @given(mutated(base_raw))
    def fuzz(case):
        _check(*case, monkeypatch)

    fuzz()


# Counts that size arrays, each at 2³¹ (a value the fuzzing draws): refused by a message naming the key, before any
# array or list of that length is made (each of these once exhausted memory instead: a 16 GiB table of pin-space
# errors, a list of 2³² planet angles, a 32 GiB design matrix).
OVERSIZED_COUNTS = [
    ("cycloid_yao2001_modified", ("drive", "z_lobes"), "z_lobes"),
    ("planetary_wang2013_budget", ("drive", "n_planets"), "n_planets"),
    ("planetary_wang2013_doe", ("doe", "design", "center_points"), "center_points"),
]


@pytest.mark.parametrize("stem,path,key", OVERSIZED_COUNTS, ids=[k for _, _, k in OVERSIZED_COUNTS])
def test_oversized_counts_are_refused_naming_the_key(stem, path, key, monkeypatch):
    raw = read_toml(ROOT / "examples" / f"{stem}.toml")
    _at(raw, path[:-1])[path[-1]] = 2**31
    monkeypatch.setattr(config, "read_toml", lambda p: raw)
    with pytest.raises(ConfigError, match=key):
        load_study(NAME)


# A few mutated files through the real command: exit status 2, one message, no traceback, nothing written.
CLI_CASES = {
    "a date for a tolerance": ("planetary_wang2013_random", "tolerance_um = 13", "tolerance_um = 2024-01-01"),
    "drive type misspelt": ("harmonic_liu", 'type = "harmonic"', 'type = "harmonik"'),
    "NaN radius": ("cycloid_yao2001_modified", "pin_radius_mm = 13.5 ", "pin_radius_mm = nan "),
}


def test_command_line_contract_on_fuzzed_files(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    procs = {}
    for n, (case, (stem, old, new)) in enumerate(sorted(CLI_CASES.items())):
        text = (ROOT / "examples" / f"{stem}.toml").read_text(encoding="utf-8")
        assert old in text, old
        folder = tmp_path / str(n)
        folder.mkdir()
        cfg = folder / "bad.toml"
        cfg.write_text(text.replace(old, new, 1), encoding="utf-8")
        cmd = [
            sys.executable,
            "-c",
            "import sys, gearte_command; sys.exit(gearte_command.main())",
            "run",
            str(cfg),
            "--out",
            str(folder / "out"),
        ]
        procs[case] = (cfg, subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=folder))
    for case, (cfg, p) in procs.items():
        stdout, stderr = p.communicate(timeout=120)
        assert p.returncode == 2, (case, stderr)
        assert "Traceback" not in stderr and stdout == "", (case, stderr)
        assert stderr.startswith(f"gearte: error in config: {cfg}: ") and stderr.count("\n") == 1, (case, stderr)
        assert sorted(x.name for x in cfg.parent.iterdir()) == ["bad.toml"], case


@settings(max_examples=100, derandomize=True, deadline=None, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.one_of(
        st.binary(max_size=64),
        st.builds(
            lambda t, i, b: t[:i] + b + t[i:], st.just(BASES[0].read_bytes()), st.integers(0, 400), st.binary(min_size=1, max_size=4)
        ),
    )
)
def test_fuzzed_bytes_are_refused_naming_the_file(tmp_path_factory, data):
    """Any bytes: a study file that is not UTF-8 TOML text, or not a study, is a ConfigError naming the file."""
    path = tmp_path_factory.getbasetemp() / "bytes.toml"
    path.write_bytes(data)
    try:
        load_study(path)
    except ConfigError as e:
        assert str(e).startswith(f"{path}: "), str(e)
