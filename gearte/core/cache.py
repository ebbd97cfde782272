"""JAX's persistent compilation cache for gearte: where it lives, and turning it on.

Most of the time of a first `gearte run` is XLA compiling the study's programs; JAX can keep
compiled programs on disk and load them the next time the same program is compiled (its key
covers the program, the JAX and XLA versions, the device and the compiler options, so a stale
entry is never used). The `gearte` command turns the cache on by default, so that a second run
of a study compiles nothing; ``gearte run … --no-compile-cache`` or the environment variable
``GEARTE_COMPILATION_CACHE=0`` turns it off. The test suite shares the same cache.

JAX's cache still traces and lowers every program before it looks it up; gearte's program store
(`gearte.core.programs`, in the cache folder's ``gearte-programs`` subfolder) also keeps the
Monte Carlo's compiled programs (and the cycloid-pin reference analyses) whole, so a repeat run
skips that too. ``GEARTE_PROGRAM_STORE=0`` turns the store off alone (the test suite does).

Importing gearte changes no global state: a library user who wants the caches calls
`enable_compilation_cache` once (it sets JAX's ``jax_compilation_cache_dir`` and turns on the
program store).

Where (`default_cache_dir`): ``$GEARTE_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/gearte/jax``,
else ``~/.cache/gearte/jax`` (``%LOCALAPPDATA%\\gearte\\jax`` on Windows). The folder holds only
compiled programs: deleting it is always safe. It is kept under `MAX_SIZE_BYTES` (least recently
used entries go first).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: Size limit of the cache folder, bytes (JAX evicts the least recently used entries beyond it).
MAX_SIZE_BYTES = 2 * 2**30

_OFF = {"0", "off", "no", "false"}


def default_cache_dir() -> Path:
    """The compilation cache folder gearte uses (see the module notes for the order of the choices)."""
    if os.environ.get("GEARTE_CACHE_DIR"):
        return Path(os.environ["GEARTE_CACHE_DIR"]).expanduser()
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "gearte" / "jax"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base).expanduser() / "gearte" / "jax"


def cache_wanted() -> bool:
    """False when the environment turns the cache off (``GEARTE_COMPILATION_CACHE=0``, ``off``, ``no`` or ``false``)."""
    return os.environ.get("GEARTE_COMPILATION_CACHE", "1").strip().lower() not in _OFF


def programs_wanted() -> bool:
    """False when the environment turns the program store off (``GEARTE_PROGRAM_STORE=0``, ``off``, ``no`` or
    ``false``; JAX's cache stays on). Worth it where gearte's source changes between runs, as in its own
    test suite: every change of the source compiles the kept programs again, from scratch."""
    return os.environ.get("GEARTE_PROGRAM_STORE", "1").strip().lower() not in _OFF


def enable_compilation_cache(path: str | os.PathLike[str] | None = None, *, programs: bool | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache in `path` (default `default_cache_dir()`).

    Every compiled program is kept, however short its compilation (a study compiles many small
    ones). With `programs` (default: unless ``GEARTE_PROGRAM_STORE=0``, `programs_wanted`), gearte's
    program store is turned on too, in the folder's ``gearte-programs`` subfolder
    (`gearte.core.programs`). Returns the folder, or None when it cannot be created or written (the
    caches then stay off and gearte runs as without them).
    """
    if programs is None:
        programs = programs_wanted()
    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        if not os.access(folder, os.W_OK):
            return None
    except OSError:
        return None
    import jax  # here, so that importing this module (the command line does) does not import JAX

    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    jax.config.update("jax_compilation_cache_max_size", MAX_SIZE_BYTES)
    if programs:
        from .programs import enable_program_store

        enable_program_store(folder / "gearte-programs")
    return folder


__all__ = ("MAX_SIZE_BYTES", "cache_wanted", "default_cache_dir", "enable_compilation_cache", "programs_wanted")
