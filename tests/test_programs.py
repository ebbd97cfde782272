"""The program store (gearte.core.programs): a kept program gives the values of a compiled one, bit for bit,
takes array values as inputs, and is only kept under a key that covers what it was compiled from."""

import dataclasses
import os
from fractions import Fraction
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
    # The RMS metric: these tests are about keeping and loading a program, and each of them compiles one afresh
    # (the store keeps what it compiled itself, not JAX's cached copy); the RMS program of this study compiles in
    # a third of the time of the exact-peak one.
    s = load_study("examples/planetary_wang2013_random.toml")
    return gearte.TEStudy(s.drive, s.errors, metric=gearte.RMS())


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


def test_a_structure_is_described_once(study, monkeypatch):
    # Describing a study's structure (its text: equinox formats every static field) takes milliseconds; a loop calls
    # one program on many trees of one structure (a budget's iterations), so each structure is described once.
    walked = []
    node_types = programs._node_types
    monkeypatch.setattr(programs, "_node_types", lambda treedef, found: walked.append(1) or node_types(treedef, found))
    monkeypatch.setattr(programs, "_STRUCTURES", {})
    key = programs.program_key("step", study, 64)
    nodes = len(walked)
    assert nodes > 10
    again = _scaled(study, 2.0)  # a new tree of the same structure (other array values)
    assert programs.program_key("step", again, 64) == key and len(walked) == nodes
    # The same key as a first description of that tree, and another static value is still another key.
    monkeypatch.setattr(programs, "_STRUCTURES", {})
    assert programs.program_key("step", again, 64) == key
    changed = jax.tree.map(lambda x: x, study)
    object.__setattr__(changed.errors, "specs", {**study.errors.specs, "sun_manufacturing": None})
    assert programs.program_key("step", changed, 64) not in (key, None)


class _Outside(eqx.Module):
    """A class from outside gearte: its code is not covered by the key."""

    study: gearte.TEStudy

    def __call__(self, key):
        return self.study(key)


class _Opaque:
    pass


class _Terse:
    """A class of another package whose repr leaves its value out."""

    def __init__(self, value):
        self.value = value

    def __repr__(self):
        return "Terse()"


def test_untrusted_inputs_are_not_kept(study, store_at):
    assert programs.program_key("step", _Outside(study)) is None
    assert programs.program_key("step", (study, _Opaque())) is None  # repr at 0x…: its value is hidden
    assert programs.program_key("step", (study, "a ... b")) is None  # a truncated repr could hide a value
    assert programs.program_key("step", (study, _Terse(1.0))) is None  # a class the key cannot see into
    assert programs.program_key("step", study, {"inner": (_Terse(1.0),)}) is None  # also inside static values
    assert programs.program_key("step", (study, np.float64(0.5), (1, "a"))) is not None  # NumPy and builtins
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


# ---------------------------------------------------------------- programs of any gearte function

_FRESH_PROCESS = """
import os, sys
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"  # a one-device program among two devices
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from gearte.core import programs
programs.enable_program_store(sys.argv[1])

def body(tree):
    a, b = tree
    return jnp.linalg.solve(a, b), jnp.linalg.cholesky(a), b  # LAPACK kernels, and an input handed back

a = jnp.asarray(np.eye(3) * 4.0 + 1.0)
b = jnp.asarray([1.0, 2.0, 3.0])
unused = jnp.ones(5)
run = programs.kept_program("lapack_test", lambda t: body(t[:2]), (a, b, unused), fallback=lambda t: body(t[:2]))
out = run((a, b, unused))
np.save(sys.argv[2], np.concatenate([np.ravel(np.asarray(x)) for x in out]))
store = programs.program_store()
print(store.loaded, store.saved, len(store.refused))
"""


def test_a_loaded_program_with_lapack_kernels_runs_in_a_fresh_process(tmp_path):
    # A process that loads a program calling LAPACK (a linear solve, a Cholesky factor) without having lowered
    # one itself used to crash: the kernels are set up before loading. Unused inputs and an input handed back
    # as an output are part of the test (both change how JAX calls a compiled program), and so are two
    # devices: the loaded program must run on the one it was compiled for, not refuse its inputs.
    import subprocess
    import sys

    script = tmp_path / "fresh.py"
    script.write_text(_FRESH_PROCESS)
    runs = []
    for i in range(2):
        p = subprocess.run(
            [sys.executable, str(script), str(tmp_path / "store"), str(tmp_path / f"{i}.npy")], capture_output=True, text=True
        )
        assert p.returncode == 0, p.stderr[-2000:]
        runs.append(p.stdout.split())
    assert runs == [["0", "1", "0"], ["1", "0", "0"]]  # compiled and kept, then loaded and run (none refused)
    np.testing.assert_array_equal(np.load(tmp_path / "0.npy"), np.load(tmp_path / "1.npy"))


def test_programs_that_call_the_host_stay_in_memory(store_at, tmp_path):
    store = store_at()

    def body(x):
        return eqx.error_if(x, x > 10.0, "too large") * 2.0  # a run-time check: a callback into this process

    x = jnp.ones(3)
    out = programs.kept_program("callback_test", body, x, fallback=body)(x)
    np.testing.assert_array_equal(out, 2.0 * np.ones(3))
    assert store.saved == 0 and not list((tmp_path / "programs").glob("*.program"))
    assert len(store._memory) == 1  # kept for this process
    np.testing.assert_array_equal(programs.kept_program("callback_test", body, x, fallback=body)(x), out)
    assert len(store._memory) == 1 and store.saved == 0


@programs.kept_jit
def _kept_example(a, n: int, *, scale: float = 2.0):
    return {"value": jnp.sum(a) * scale, "count": n, "same": a}


def test_kept_jit_is_filter_jit(store_at):
    a = jnp.arange(4.0)
    programs.disable_program_store()
    reference = _kept_example(a, 3, scale=0.5)
    store = store_at()
    got = _kept_example(a, 3, scale=0.5)
    assert got["count"] == 3 and float(got["value"]) == float(reference["value"]) == 3.0
    np.testing.assert_array_equal(got["same"], a)
    # A function of this test module: its source is not gearte's, so nothing is kept.
    assert store.saved == 0
    # Under a transformation it is equinox's filter_jit itself: gradients work.
    np.testing.assert_allclose(jax.grad(lambda x: _kept_example(x, 1)["value"])(a), 2.0 * np.ones(4))


def test_kept_jit_keeps_gearte_functions(store_at):
    from gearte.drives.cycloid_pin_contact import sweep

    s = load_study("examples/cycloid_yao2001_modified.toml")
    angles = np.linspace(0.0, 0.2, 5)
    programs.disable_program_store()
    reference = sweep(s.drive, s.drive.reference, angles, normal=False)
    store = store_at()
    got = sweep(s.drive, s.drive.reference, angles, normal=False)
    assert store.saved == 1
    for r, g in zip(jax.tree.leaves(reference), jax.tree.leaves(got), strict=True):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(r))


def test_environment_switch(monkeypatch, tmp_path):
    from gearte.core.cache import enable_compilation_cache, programs_wanted

    before = programs.program_store()
    try:
        for value, wanted in (("0", False), ("off", False), ("1", True), (" yes ", True)):
            monkeypatch.setenv("GEARTE_PROGRAM_STORE", value)
            assert programs_wanted() is wanted
        monkeypatch.setenv("GEARTE_PROGRAM_STORE", "0")
        programs.disable_program_store()
        enable_compilation_cache(tmp_path / "jax")
        assert programs.program_store() is None
        monkeypatch.setenv("GEARTE_PROGRAM_STORE", "1")
        enable_compilation_cache(tmp_path / "jax")
        store = programs.program_store()
        assert store is not None and store.folder == tmp_path / "jax" / "gearte-programs"
    finally:
        programs._STORE[0] = before
        enable_compilation_cache(os.environ["GEARTE_CACHE_DIR"], programs=False)


def test_a_program_that_refuses_its_inputs_is_dropped_for_good(store_at, tmp_path):
    store = store_at()
    x = jnp.arange(3.0)
    calls = []

    def body(x):
        return x * 2.0

    def fallback(x):
        calls.append(1)
        return body(x)

    np.testing.assert_array_equal(programs.kept_program("refusal_test", body, x, fallback=fallback)(x), 2.0 * np.arange(3.0))
    assert not calls and store.saved == 1
    (key,) = store._memory

    def refusing(*_):
        raise RuntimeError("refuses its inputs")

    store._memory[key].compiled = refusing  # what a program that no longer fits its inputs does
    np.testing.assert_array_equal(programs.kept_program("refusal_test", body, x, fallback=fallback)(x), 2.0 * np.arange(3.0))
    assert calls == [1] and key in store.refused and not list((tmp_path / "programs").glob("*.program"))
    # From then on the usual compilation answers at once: nothing compiled or kept again for that key.
    np.testing.assert_array_equal(programs.kept_program("refusal_test", body, x, fallback=fallback)(x), 2.0 * np.arange(3.0))
    assert calls == [1, 1] and store.saved == 1 and key not in store._memory


def test_a_repeat_run_loads_the_sensitivities_and_the_unit_s_trace(store_at):
    # `gearte run` computes the sensitivities (`pathwise_sensitivities`) and the TE trace of a unit
    # (`drive.trace`) as well as the Monte Carlo: the next process loads their programs too, tracing nothing.
    from trace_count import traces

    s = load_study("examples/planetary_wang2013_random.toml")
    errors = s.errors.sample(jax.random.key(7))

    def run():
        # RMS: its program compiles faster than the peak's, and the store compiles each program afresh here.
        sens = gearte.pathwise_sensitivities(s.drive, s.errors, gearte.RMS(), key=3, n_samples=6, chunk=3)["rms"]
        return [sens.mean, *jax.tree.leaves(sens.gradient)], s.drive.trace(errors)

    programs.disable_program_store()
    (grads, trace) = run()
    store = store_at()
    run()
    assert store.saved == 2
    programs._STORE[0] = None
    fresh = store_at()
    with traces() as seen:
        (grads_loaded, trace_loaded) = run()
    assert fresh.loaded == 2 and fresh.saved == 0
    assert seen["_chunk_grad"] == 0 and seen["_signal_and_extrema"] == 0, seen
    for a, b in zip(grads, grads_loaded, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(trace.te, trace_loaded.te)


def test_exact_frequencies_are_trusted_static_values():
    # A signal's frequencies are `fractions.Fraction`s (a harmonic drive's extrema take the signal): their repr
    # shows the whole value, so a program of them is kept, under a key that tells one frequency from another.
    x = jnp.ones(2)
    key = programs.program_key("f", (x, Fraction(7, 24)))
    assert key is not None
    assert key != programs.program_key("f", (x, Fraction(7, 25)))
