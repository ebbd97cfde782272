"""Compiled programs kept on disk whole, so that a repeat run neither traces nor lowers them.

JAX's persistent compilation cache (`gearte.core.cache`) saves XLA's compilation, but every
process still traces the Python model into a program and lowers it before it can look the
program up: for the planetary Monte Carlo that is about 0.8 s of a 3 s repeat `gearte run`. The
program store keeps the compiled executable itself (`jax.experimental.serialize_executable`),
under a key computed without tracing, and loads it in about 0.15 s.

The key must change whenever the program could, because nothing checks the loaded program
against the model. It covers:

- the source of every gearte module (a digest of the package's ``*.py`` files), and the versions
  of Python, JAX, jaxlib, equinox and NumPy;
- every JAX configuration value (float64, the PRNG implementation, …) except the caches' own
  settings, ``XLA_FLAGS``, and the devices (platform, kind, id, process) and process count;
- the program's inputs: the pytree structure with every static value (equinox modules' static
  fields and every non-array leaf, by `repr`), and the shape, dtype and placement (sharding and
  devices) of every array leaf (array *values* are inputs of the program, not part of it).

Where it is used: the Monte Carlo engine's step (`gearte.monte_carlo`) and the gearte functions
decorated with `kept_jit` (an `eqx.filter_jit` that goes through the store: what a `gearte run` computes
besides the Monte Carlo, the sensitivities, a unit's TE trace, the drives' responses, the cycloid-pin reference
analyses and the optimisers of the study kinds). A program is kept only

- for the CPU (the CPU's LAPACK kernels are set up before a program is loaded, as lowering one
  would). In a several-process run (`jax.distributed`) each process keeps its own programs: the key
  covers the process's index, and a program computing on every process's devices is loaded onto the
  devices of its inputs' mesh, in that order. JAX's own cache serves only process 0 there (its key
  covers each process's local devices, and only process 0 writes it), so without the store the other
  processes would compile the study's programs on every run;
- when its key can be trusted: every pytree node class, and the class of every static value, comes
  from gearte, equinox, JAX, NumPy, Python's builtins or `fractions.Fraction` (the drives' exact
  frequencies; a user's own class could call code whose source the digest does not cover, or leave
  a value out of its `repr`),
  and no static value's `repr` hides its value (an object address ``at 0x…`` or a truncated
  array ``...``);
- on disk only when it does not call back into Python (a callback, equinox's run-time errors):
  such a program holds pointers into the process that compiled it, and stays in memory.

Otherwise the program is compiled as usual. The store compiles its own copies, never taking
one from JAX's cache (an executable JAX loaded from there cannot be serialised again on the CPU),
keeps every input of a program (no unused-input pruning), and one thread at a time loads or
compiles; a kept program that refuses its inputs is dropped, and the usual compilation answers for
its key for the rest of the process.

Files are ``<cache folder>/gearte-programs/<key>.program`` (written atomically; least recently
used ones deleted beyond `MAX_STORE_BYTES`); an unreadable file is compiled again and replaced.
Loading a program runs code from that file, as loading any cache of executables does: the folder
is the user's own. `gearte.enable_compilation_cache` turns the store on with JAX's cache
(``programs=False`` leaves it off); importing gearte leaves it off.
"""

from __future__ import annotations

import functools
import hashlib
import io
import os
import pickle
import re
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.core import Tracer

#: Size limit of the program store, bytes (least recently used programs are deleted beyond it).
MAX_STORE_BYTES = 512 * 2**20
#: Programs held in memory per process (a key's program is loaded or compiled once per process).
MEMORY_PROGRAMS = 32

_TRUSTED_MODULES = (
    "gearte",
    "equinox",
    "jax",
    "jaxlib",
    "numpy",
    "builtins",
    "collections",
    "fractions",
    "optimistix",
    "lineax",
    "diffrax",
)
_SUFFIX = ".program"


@functools.cache
def _source_digest() -> str:
    """A digest of every gearte source file (path and content)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


@functools.cache
def _versions() -> tuple[str, ...]:
    from importlib.metadata import version

    return (sys.version, jax.__version__, version("jaxlib"), eqx.__version__, np.__version__)


def _environment() -> str:
    """Everything outside the program's inputs that can change the compiled program."""
    versions = _versions()
    config = sorted((k, repr(v)) for k, v in jax.config.values.items() if "compilation_cache" not in k and "persistent_cache" not in k)
    devices = [(d.platform, d.device_kind, d.id, d.process_index) for d in jax.devices()]
    return repr((_source_digest(), versions, config, os.environ.get("XLA_FLAGS", ""), devices, jax.process_count(), jax.process_index()))


def _value_types(value: Any, found: set[type]) -> set[type]:
    """The types of `value` and, through tuples, lists, sets and dicts, of what it holds."""
    found.add(type(value))
    if isinstance(value, dict):
        for k, v in value.items():
            _value_types(k, found)
            _value_types(v, found)
    elif isinstance(value, (tuple, list, set, frozenset)):
        for v in value:
            _value_types(v, found)
    return found


def _node_types(treedef, found: set[type]) -> set[type]:
    """The classes of a pytree's nodes and of their static data (equinox modules' static fields)."""
    data = treedef.node_data()
    if data is not None:
        found.add(data[0])
        _value_types(data[1], found)
    for child in treedef.children():
        _node_types(child, found)
    return found


#: A tree structure's text and node types, by structure: its text takes milliseconds (equinox formats every
#: module's static fields), and a loop calls the same program on many trees of one structure.
_STRUCTURES: dict[Any, tuple[str, frozenset[type]]] = {}


def _structure(treedef) -> tuple[str, frozenset[type]]:
    """``str(treedef)`` and the classes of its nodes and static data (`_node_types`), once per structure.
    Structures are told apart as `jax.jit` tells them apart (equal and of equal hash: the same compiled
    program); one whose static data cannot be hashed or compared is described afresh each time."""
    try:
        return _STRUCTURES[treedef]
    except KeyError:
        pass
    except Exception:  # unhashable or incomparable static data
        return str(treedef), frozenset(_node_types(treedef, set()))
    info = (str(treedef), frozenset(_node_types(treedef, set())))
    if len(_STRUCTURES) >= 256:
        _STRUCTURES.clear()
    _STRUCTURES[treedef] = info
    return info


def program_key(name: str, tree: Any, *static: Any) -> str | None:
    """The store's key of program `name` for inputs `tree` (a pytree: arrays are inputs, everything else is
    part of the program) and further `static` values; None when the key cannot be trusted (module notes)."""
    leaves, treedef = jax.tree.flatten(tree)
    structure, node_types = _structure(treedef)
    types = set(node_types)
    for leaf in leaves:
        if not eqx.is_array(leaf):
            _value_types(leaf, types)
    _value_types(static, types)
    for t in types:  # a class of another package could hide a value from its repr, or run code the digest misses
        if (getattr(t, "__module__", "") or "").split(".")[0] not in _TRUSTED_MODULES:
            return None
    parts = [name, _environment(), structure, repr(static)]
    for leaf in leaves:
        if eqx.is_array(leaf):
            aval = jax.typeof(leaf)
            sharding = getattr(leaf, "sharding", None)  # a compiled program expects its inputs where they were
            place = "host" if sharding is None else f"{sharding!r} on {sorted(d.id for d in sharding.device_set)}"
            parts.append(f"array {aval.str_short()} weak={getattr(aval, 'weak_type', False)} {place}")
        else:
            parts.append(f"{type(leaf).__module__}.{type(leaf).__qualname__} {leaf!r}")
    text = "\n".join(parts)
    if " at 0x" in text or "..." in text:
        return None
    return hashlib.sha256(text.encode()).hexdigest()


@functools.cache
def _prepare_kernels() -> None:
    """Set up the CPU's LAPACK kernels, as lowering a linear-algebra operation does: a loaded program calls
    them directly, and before this set-up they point nowhere (a process that loads a program with a Cholesky
    factor or a linear solve without having lowered one itself would crash)."""
    jax.jit(jnp.linalg.cholesky).lower(np.eye(2))


def _equinox_missing() -> Any:
    """equinox's marker of a module without wrapper fields in its flattened form (compared by identity when
    a module is rebuilt, so a pickled structure must get the marker itself back, not a copy)."""
    from equinox._module._flatten import MISSING

    return MISSING


class _Pickler(pickle.Pickler):
    def reducer_override(self, obj):  # pyright: ignore[reportIncompatibleMethodOverride]
        if type(obj).__name__ == "_Missing" and obj is _equinox_missing():
            return (_equinox_missing, ())
        return NotImplemented


class _Program:
    """A compiled program of a flat list of input arrays, and how its outputs are rebuilt: the structure of
    their arrays and the outputs' other values (those a trace fixes)."""

    def __init__(self, compiled: Any, out_treedef: Any, out_static: Any, *, lapack: bool):
        self.compiled, self.out_treedef, self.out_static = compiled, out_treedef, out_static
        self.lapack = lapack  # calls LAPACK kernels (`_prepare_kernels` before it is loaded)

    def __call__(self, leaves: list, *args: Any) -> Any:
        return eqx.combine(jax.tree.unflatten(self.out_treedef, self.compiled(leaves, *args)), self.out_static)


class ProgramStore:
    """Compiled programs on disk in `folder`, and those of this process in memory."""

    def __init__(self, folder: str | os.PathLike[str], *, max_bytes: int = MAX_STORE_BYTES):
        self.folder = Path(folder)
        self.max_bytes = int(max_bytes)
        self._memory: dict[str, Any] = {}
        self.refused: set[str] = set()  # keys whose program refused its inputs: compiled as usual from then on
        self.loaded = 0  # programs read from disk by this process
        self.saved = 0  # programs written to disk by this process

    def _path(self, key: str) -> Path:
        return self.folder / f"{key}{_SUFFIX}"

    def load(self, key: str) -> Any | None:
        """The compiled program of `key`, or None when none is kept (or its file cannot be read)."""
        if key in self._memory:
            return self._memory[key]
        path = self._path(key)
        try:
            payload = path.read_bytes()
        except OSError:
            return None
        try:
            from jax.experimental import serialize_executable

            blob, in_tree, out_tree, device_ids, lapack, out_treedef, out_static = pickle.loads(payload)
            if lapack:
                _prepare_kernels()
            by_id = {d.id: d for d in jax.devices()}
            devices = [by_id[i] for i in device_ids]  # the program's own devices, in its order (default: all of them)
            loaded = serialize_executable.deserialize_and_load(blob, in_tree, out_tree, execution_devices=devices)
            compiled = _Program(loaded, out_treedef, out_static, lapack=lapack)
        except Exception:  # a damaged or foreign file: compile again (and replace it)
            return None
        try:
            os.utime(path)  # recently used
        except OSError:
            pass
        self.loaded += 1
        self._remember(key, compiled)
        return compiled

    def save(self, key: str, program: _Program, *, disk: bool = True) -> None:
        """Keep `program` under `key` (in memory always; with `disk`, on disk too when it can be written)."""
        self._remember(key, program)
        if not disk:
            return
        try:
            from jax.experimental import serialize_executable

            with io.BytesIO() as buffer:
                device_ids = _device_ids(program.compiled)
                if device_ids is None:
                    return
                blob, in_tree, out_tree = serialize_executable.serialize(program.compiled)
                record = (blob, in_tree, out_tree, device_ids, program.lapack, program.out_treedef, program.out_static)
                _Pickler(buffer).dump(record)
                payload = buffer.getvalue()
        except Exception:  # a program JAX cannot serialise (or outputs pickle cannot keep): kept in memory only
            return
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.folder, suffix=".tmp")
            with os.fdopen(fd, "wb") as f:
                f.write(payload)
            os.replace(tmp, self._path(key))  # atomic: a reader sees the whole file or none
        except OSError:
            return
        self.saved += 1
        self._evict()

    def refuse(self, key: str) -> None:
        """Drop the program of `key`, from memory and from disk, and keep none for it in this process."""
        self.refused.add(key)
        self._memory.pop(key, None)
        try:
            self._path(key).unlink(missing_ok=True)
        except OSError:
            pass

    def _remember(self, key: str, compiled: Any) -> None:
        self._memory[key] = compiled
        while len(self._memory) > MEMORY_PROGRAMS:
            self._memory.pop(next(iter(self._memory)))

    def _evict(self) -> None:
        try:
            files = sorted(self.folder.glob(f"*{_SUFFIX}"), key=lambda p: p.stat().st_mtime)
            total = sum(p.stat().st_size for p in files)
            for p in files[:-1]:  # never the newest
                if total <= self.max_bytes:
                    break
                total -= p.stat().st_size
                p.unlink(missing_ok=True)
        except OSError:
            pass


def _device_ids(compiled: Any) -> list[int] | None:
    """The ids of the devices `compiled` runs on, in the order of its device assignment (what loading it needs).

    In one process: the process's own devices of the executable. In a several-process run: the devices of its
    inputs' mesh (every process's), or None when no input is laid out on a mesh spanning the processes; such a
    program is kept in memory only.
    """
    if jax.process_count() == 1:
        return [d.id for d in compiled.runtime_executable().local_devices()]
    for sharding in jax.tree.leaves(compiled.input_shardings):
        mesh = sharding.mesh.devices if isinstance(sharding, jax.sharding.NamedSharding) else None
        if mesh is not None and len(sharding.device_set) == jax.device_count():
            return [d.id for d in np.asarray(mesh).flat]
    return None


#: A call of the host from a compiled program (`jax.pure_callback`, `jax.debug.callback`, equinox's `error_if`).
_HOST_CALLBACK = re.compile(r"custom_call @\w*callback")
#: A compiler option at XLA's default value: it changes no code, only the key of JAX's cache (`_compile_fresh`).
_OWN_KEY = {"xla_embed_ir_in_executable": False}
_NEVER = 1e12  # s: a minimum compile time no compilation reaches


def _compile_fresh(lowered) -> Any:
    """`lowered` compiled by XLA, not loaded from JAX's persistent cache.

    An executable JAX loaded from its cache cannot be serialised again on the CPU (it keeps no code
    for its kernels: the copy would fail at its first run, "Function … not found"), so the store
    keeps only executables it compiled. The option `_OWN_KEY` gives the compilation a key of JAX's
    cache that JAX never writes (its minimum compile time is out of reach during the call), so the
    cache never answers it.
    """
    before = jax.config.values["jax_persistent_cache_min_compile_time_secs"]
    jax.config.update("jax_persistent_cache_min_compile_time_secs", _NEVER)
    try:
        return lowered.compile(compiler_options=_OWN_KEY)
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", before)


_STORE: list[ProgramStore | None] = [None]
_LOCK = threading.RLock()


def enable_program_store(folder: str | os.PathLike[str]) -> ProgramStore:
    """Keep compiled programs in `folder` from now on (see the module notes); returns the store."""
    store = _STORE[0]
    if store is None or store.folder != Path(folder):
        store = ProgramStore(folder)
        _STORE[0] = store
    return store


def disable_program_store() -> None:
    """Stop keeping and loading programs (what is on disk stays)."""
    _STORE[0] = None


def program_store() -> ProgramStore | None:
    """The store in use, or None when programs are not kept."""
    return _STORE[0]


def _load_or_compile(store: ProgramStore, key: str, body, treedef, fixed, leaves, args) -> _Program:
    program = store.load(key)
    if program is not None:
        return program
    traced: dict[str, Any] = {}

    def flat(leaves, *args):
        out = body(eqx.combine(jax.tree.unflatten(treedef, leaves), fixed), *args)
        out_arrays, traced["static"] = eqx.partition(out, eqx.is_array)
        arrays, traced["treedef"] = jax.tree.flatten(out_arrays)
        return arrays

    lowered = jax.jit(flat, keep_unused=True).lower(leaves, *args)  # every input the key describes, none pruned
    text = lowered.as_text()
    program = _Program(_compile_fresh(lowered), traced["treedef"], traced["static"], lapack="lapack" in text)
    # A program that calls back into Python (equinox's run-time errors, callbacks) holds pointers to this
    # process's functions: kept in memory, never on disk (another process would jump to nowhere).
    store.save(key, program, disk=_HOST_CALLBACK.search(text) is None)
    return program


def kept_program(
    name: str, body: Callable[..., Any], tree: Any, *args: Any, static: tuple = (), fallback: Callable[..., Any]
) -> Callable[..., Any]:
    """``body(tree, *args)`` compiled, from the program store when it holds it.

    `tree`'s array leaves and `args` (arrays) are the program's inputs; every other value in `tree`
    and `static` is part of it. Returns a function of ``(tree, *args)`` (same structure, same array
    shapes, dtypes and placements): the kept program, or `fallback` (the same computation compiled
    as usual) when no store is in use or the key cannot be trusted. A kept program that refuses its
    inputs when called is dropped, and `fallback` answers.
    """
    store = _STORE[0]
    # CPU only (the kernels set up above); in a several-process run, one program per process (its key).
    if store is None or jax.default_backend() != "cpu":
        return fallback
    key = program_key(name, (tree, args), *static)
    if key is None or key in store.refused:
        return fallback
    dynamic, fixed = eqx.partition(tree, eqx.is_array)
    leaves, treedef = jax.tree.flatten(dynamic)
    with _LOCK:  # one thread at a time loads or compiles (XLA's loading of executables is not thread-safe)
        program = _load_or_compile(store, key, body, treedef, fixed, leaves, args)
    last = [tree, leaves]  # the input arrays of the last tree (a caller calls again with the same tree)

    def run(tree, *args):
        if key not in store.refused:
            if tree is not last[0]:
                last[:] = [tree, jax.tree.leaves(eqx.filter(tree, eqx.is_array))]
            try:
                return program(last[1], *args)
            except Exception:  # e.g. inputs placed otherwise than the key said: never the user's concern
                store.refuse(key)
        return fallback(tree, *args)

    return run


def kept_jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """`eqx.filter_jit(fn)` whose compiled programs the program store keeps, for gearte's own module-level
    functions: called with concrete values while a store is in use, a repeat run loads the program instead
    of tracing `fn`; otherwise (no store, called under a trace or a transformation such as `jax.grad`, or a
    key that cannot be trusted) it is `eqx.filter_jit(fn)` itself."""
    jitted = eqx.filter_jit(fn)
    name = f"{fn.__module__}.{fn.__qualname__}"
    own = fn.__module__.split(".")[0] == "gearte" and "<locals>" not in fn.__qualname__ and not getattr(fn, "__closure__", None)

    def body(tree):
        args, kwargs = tree
        return fn(*args, **kwargs)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if own and _STORE[0] is not None:
            tree = (args, kwargs)
            if not any(isinstance(x, Tracer) for x in jax.tree.leaves(tree)):
                return kept_program(name, body, tree, fallback=lambda tree: jitted(*tree[0], **tree[1]))(tree)
        return jitted(*args, **kwargs)

    return call


__all__ = (
    "MAX_STORE_BYTES",
    "ProgramStore",
    "disable_program_store",
    "enable_program_store",
    "kept_jit",
    "kept_program",
    "program_key",
    "program_store",
)
