"""The program store (gearte.core.programs): a kept program gives the values of a compiled one, bit for bit,
takes array values as inputs, and is only kept under a key that covers what it was compiled from."""

import dataclasses
import os
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gearte
from gearte.cli.config import load_study
from gearte.core import programs
from gearte.studies.errors import ErrorModel, ErrorSource
from gearte.studies.laws import Fixed

N, BLOCK = 300, 64


@pytest.fixture(scope="module")
def study():
    s = load_study("examples/planetary_wang2013_random.toml")
    return gearte.TEStudy(s.drive, s.errors, metric=gearte.Peak())


@pytest.fixture
def store_at(tmp_path):
    """Use a store in a folder of its own for one test, then the one the suite had."""
    before = programs.program_store()
    yield lambda: programs.enable_program_store(tmp_path / "programs")
    programs._STORE[0] = before


def _values(study, **kw):
    return gearte.monte_carlo(study, key=5, n_samples=N, block_size=BLOCK, **kw).values


def _scaled(study, factor: float):
    """The study with the sun's manufacturing eccentricity (a fixed magnitude, an array) scaled."""
    src = dict(study.errors.sources)
    s = src["sun_manufacturing"]
    assert isinstance(s.magnitude, Fixed)
    src["sun_manufacturing"] = ErrorSource(Fixed(jnp.asarray(s.magnitude.value) * factor), s.phase)
    return gearte.TEStudy(study.drive, ErrorModel(src, study.errors.specs), metric=study.metric)


def test_kept_program_is_bit_identical_and_loads_in_a_new_process_store(study, store_at, tmp_path):
    programs.disable_program_store()
    reference = _values(study)
    store = store_at()
    np.testing.assert_array_equal(_values(study), reference)
    assert store.saved == 1 and store.loaded == 0
    assert len(list((tmp_path / "programs").glob("*.program"))) == 1
    # A fresh store on the same folder is what the next process sees: it loads, compiles nothing.
    programs._STORE[0] = None
    fresh = store_at()
    assert fresh is not store
    np.testing.assert_array_equal(_values(study), reference)
    assert fresh.loaded == 1 and fresh.saved == 0
    # Without the file, the program is compiled again (JAX's own cache now holds it: the store must not keep
    # the copy JAX loads from there, which cannot run once serialised again) and kept, and it runs.
    (path,) = (tmp_path / "programs").glob("*.program")
    path.unlink()
    programs._STORE[0] = None
    store_at()
    np.testing.assert_array_equal(_values(study), reference)
    programs._STORE[0] = None
    again = store_at()
    np.testing.assert_array_equal(_values(study), reference)
    assert again.loaded == 1


def test_array_values_are_inputs_of_the_kept_program(study, store_at):
    # Two studies that differ only in an array's value share one program, and each gets its own values.
    programs.disable_program_store()
    references = [_values(_scaled(study, f)) for f in (1.0, 3.0)]
    assert not np.allclose(references[0], references[1])
    store = store_at()
    for f, ref in zip((1.0, 3.0), references):
        np.testing.assert_array_equal(_values(_scaled(study, f)), ref)
    assert store.saved == 1


def test_key_covers_static_values_source_and_block(study, monkeypatch):
    key = programs.program_key("step", study, 64)
    assert key == programs.program_key("step", study, 64)
    assert key != programs.program_key("step", study, 128)
    assert key != programs.program_key("other", study, 64)
    assert key == programs.program_key("step", _scaled(study, 2.0), 64)  # an array's value is an input
    # A static value (an equinox static field: a source's spec) is part of the key.
    specs = dict(study.errors.specs)
    specs["sun_manufacturing"] = dataclasses.replace(specs["sun_manufacturing"], description="changed")
    changed = jax.tree.map(lambda x: x, study)  # new nodes; an equinox static field is set on the copy alone
    object.__setattr__(changed.errors, "specs", specs)
    assert study.errors.specs["sun_manufacturing"].description != "changed"
    assert programs.program_key("step", changed, 64) != key
    # A Python float leaf is part of the program, to its last bit.
    assert programs.program_key("step", (study, 0.1), 64) != programs.program_key("step", (study, 0.1 + 2**-55), 64)
    # Another source of gearte is another program.
    monkeypatch.setattr(programs, "_source_digest", lambda: "another source")
    assert programs.program_key("step", study, 64) != key


class _Outside(eqx.Module):
    """A class from outside gearte: its code is not covered by the key."""

    study: gearte.TEStudy

    def __call__(self, key):
        return self.study(key)


class _Opaque:
    pass


def test_untrusted_inputs_are_not_kept(study, store_at):
    assert programs.program_key("step", _Outside(study)) is None
    assert programs.program_key("step", (study, _Opaque())) is None  # repr at 0x…: its value is hidden
    assert programs.program_key("step", (study, "a ... b")) is None  # a truncated repr could hide a value
    programs.disable_program_store()
    reference = _values(_Outside(study))
    store = store_at()
    np.testing.assert_array_equal(_values(_Outside(study)), reference)
    assert store.saved == 0 and store.loaded == 0


def test_damaged_file_is_compiled_again_and_replaced(study, store_at, tmp_path):
    programs.disable_program_store()
    reference = _values(study)
    store_at()
    _values(study)
    (path,) = (tmp_path / "programs").glob("*.program")
    path.write_bytes(b"not a program")
    programs._STORE[0] = None
    fresh = store_at()
    np.testing.assert_array_equal(_values(study), reference)
    assert fresh.loaded == 0 and fresh.saved == 1 and path.stat().st_size > 1000


def test_least_recently_used_programs_go_beyond_the_size_limit(tmp_path):
    store = programs.ProgramStore(tmp_path, max_bytes=2500)
    for i, t in enumerate((100, 300, 200)):
        p = tmp_path / f"{i}.program"
        p.write_bytes(b"x" * 1000)
        os.utime(p, (t, t))
    store._evict()
    assert sorted(p.name for p in tmp_path.glob("*.program")) == ["1.program", "2.program"]


def test_readme_states_the_store_size():
    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    assert f"at most {programs.MAX_STORE_BYTES // 2**20} MiB" in readme
