"""Results folders written atomically, and interrupts that always end a run cleanly.

A run or a comparison writes into a hidden temporary sibling of its results folder and
renames it into place only when everything is written: a failed or interrupted run leaves
either the previous complete result or nothing. gearte replaces only folders it wrote
itself (recognised by their `summary.json` or `comparison.json`, whose `files` lists everything
gearte wrote there); it refuses a non-empty folder holding anything else, the current folder,
and any folder holding an input.

Ctrl-C (SIGINT) and SIGTERM raise `KeyboardInterrupt` wherever Python code is running, and
are also remembered: an interrupt that Python cannot raise (one that lands in a garbage-
collector callback, as JAX registers, is "ignored" by Python) or that a library swallows
still stops the run at its next phase, and always before its result is renamed into place
(`commit_point`).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import socket
import sys
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

#: The file that marks a results folder: its `files` key lists every file gearte wrote there.
MARKERS = ("summary.json", "comparison.json")
#: What gearte writes into its results folders (recognises folders written before `files` was recorded).
_LEGACY_SUFFIXES = (".png", ".md", ".json", ".npz")


class OutputError(ValueError):
    """The results folder (``--out``) cannot be used; the message names it and the fix."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM: the run stops; `signum` is the signal (SIGINT when pressed at a terminal)."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _State:
    received: int | None = None  # the first signal received, kept until `reset`
    deferring: int = 0  # inside a critical section: remember, raise at its end


def _handler(signum, frame):
    del frame
    if _State.received is None:
        _State.received = signum
    if _State.deferring == 0:
        raise Interrupted(signum)


def _quiet_unraisable(previous):
    """A `sys.unraisablehook` that drops interrupts (remembered by the handler) and passes on the rest."""

    def hook(unraisable):
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            return
        previous(unraisable)

    hook.gearte = True  # pyright: ignore[reportFunctionMemberAccess]
    return hook


def install_interrupt_handlers() -> None:
    """Route SIGINT and SIGTERM to `_handler` (main thread only; a no-op elsewhere)."""
    if not getattr(sys.unraisablehook, "gearte", False):
        sys.unraisablehook = _quiet_unraisable(sys.unraisablehook)
    try:
        signal.signal(signal.SIGINT, _handler)
        signal.signal(signal.SIGTERM, _handler)
    except ValueError:  # not the main thread
        pass


def interrupt_received() -> int | None:
    """The signal received since the last `reset_interrupts` (None if none)."""
    return _State.received


def reset_interrupts() -> None:
    _State.received = None
    _State.deferring = 0


def commit_point() -> None:
    """Raise `Interrupted` if an interrupt arrived at any time, even one a library swallowed."""
    if _State.received is not None:
        raise Interrupted(_State.received)


@contextlib.contextmanager
def deferred_interrupts(*, raise_after: bool = True) -> Iterator[None]:
    """A critical section (renames, clean-up): an interrupt inside it is remembered, never raised half-way;
    it is raised when the section ends (unless `raise_after` is False: then `commit_point` or the caller sees it)."""
    _State.deferring += 1
    try:
        yield
    finally:
        _State.deferring -= 1
    if raise_after and _State.deferring == 0:
        commit_point()


@contextlib.contextmanager
def sigterm_as_interrupt():
    """SIGINT and SIGTERM raise `Interrupted` inside the block (previous handlers restored after it)."""
    try:
        previous = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
        install_interrupt_handlers()
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous[0])
        signal.signal(signal.SIGTERM, previous[1])


# ---------------------------------------------------------------- results folders


def _written_by_gearte(path: Path) -> bool:
    """Whether the folder `path` holds only what gearte wrote there (so replacing it deletes nothing else)."""
    entries = list(path.iterdir())
    if not entries:
        return True
    for name in MARKERS:
        marker = path / name
        if not marker.is_file():
            continue
        try:
            head = json.loads(marker.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return False
        if not isinstance(head, dict):
            return False
        files = head.get("files")
        if isinstance(files, list):
            return all(e.name in files and e.is_file() and not e.is_symlink() for e in entries)
        # Written before `files` was recorded: a gearte summary (or comparison), and only files gearte writes.
        if "gearte_version" in head or {"runs", "metric", "unit"} <= set(head):
            return all(e.is_file() and not e.is_symlink() and e.suffix in _LEGACY_SUFFIXES for e in entries)
        return False
    return False


def written_files(folder: Path, *also: str) -> list[str]:
    """The names of the files in `folder`, with `also` (the marker about to be written): its `files` entry."""
    return sorted({p.name for p in folder.iterdir() if not p.name.endswith(".tmp")} | set(also))


def _inside(a: Path, b: Path) -> bool:
    """Whether `a` is `b` or inside it (both resolved)."""
    return a == b or b in a.parents


def check_output(out: str | Path, *, inputs: Iterable[str | Path] = (), option: str = "--out") -> Path:
    """Check a results folder before anything is computed; returns it resolved, or raises `OutputError`.

    Refused: an existing file or a link; a mount point; a path below a file; the current folder or one holding it;
    a folder that is, holds or lies inside one of `inputs`; a non-empty folder gearte did not write;
    a place where no folder can be created.
    """
    given = str(out)
    if not given.strip():
        raise OutputError(f"{option}: empty; name the results folder, e.g. {option} results/my_study")
    path = Path(os.path.abspath(given))
    if path.is_symlink():
        raise OutputError(f"{option} {given}: is a symbolic link; give the folder itself")
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError) as e:
        raise OutputError(f"{option} {given}: cannot be resolved ({e})") from None
    if resolved.exists() and not resolved.is_dir():
        raise OutputError(f"{option} {given}: is an existing file, not a folder; choose another {option}")
    if resolved.is_dir() and os.path.ismount(resolved):
        raise OutputError(
            f"{option} {given}: is a mount point, which cannot be replaced (gearte writes a new results folder beside "
            f"the old one and renames it): name a sub-folder, e.g. {option} {Path(given) / 'results'}"
        )
    for parent in resolved.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(f"{option} {given}: {parent} is a file, so no folder can be made below it; choose another {option}")
            try:  # a real probe: permissions, read-only and special file systems
                os.rmdir(tempfile.mkdtemp(prefix=".gearte-probe-", dir=parent))
            except OSError as e:
                raise OutputError(f"{option} {given}: cannot write in {parent} ({e.strerror}); choose another {option}") from None
            break
    if resolved.parent == resolved:
        raise OutputError(f"{option} {given}: is the root folder; name a new folder for the results")
    cwd = Path.cwd().resolve()
    if _inside(cwd, resolved):
        raise OutputError(
            f"{option} {given}: is the current folder (or holds it); gearte replaces the whole results folder, "
            f"so name a new sub-folder, e.g. {option} {Path(given) / 'results'}"
        )
    for x in inputs:
        xi = Path(x).resolve()
        if _inside(xi, resolved) or _inside(resolved, xi):
            raise OutputError(f"{option} {given}: is, holds or lies inside the input {x}; write the results elsewhere")
    if resolved.is_dir() and not _written_by_gearte(resolved):
        raise OutputError(
            f"{option} {given}: a folder with files gearte did not write; gearte replaces only its own results folders "
            f"(never deleting other files): choose a new or empty folder, e.g. {option} {Path(given) / 'results'}"
        )
    return resolved


#: Errors of writing to a full or failing disk (`atomic_output_dir` names the results folder for them).
_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS)


@contextlib.contextmanager
def atomic_output_dir(path: str | Path, *, inputs: Iterable[str | Path] = (), option: str = "--out") -> Iterator[Path]:
    """Yield a temporary folder beside `path`; when the block ends normally it replaces `path` (after
    `check_output`), when it fails or is interrupted it is removed with any parent folders created for it.

    Enter it before computing: a results folder that cannot be written is refused before any work.
    """
    path = check_output(path, inputs=inputs, option=option)
    created: list[Path] = []
    with deferred_interrupts(raise_after=False):
        for parent in reversed(path.parents):
            if not parent.exists():
                try:
                    parent.mkdir()
                except OSError as e:
                    _remove_created(created)
                    raise OutputError(f"{option} {path}: cannot create {parent} ({e.strerror}); choose another {option}") from None
                created.append(parent)
        _clear_stale(path)
        try:
            tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-{_owner()}-", dir=path.parent))
        except OSError as e:
            _remove_created(created)
            raise OutputError(f"{option} {path}: cannot write in {path.parent} ({e.strerror}); choose another {option}") from None
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it private; results are ordinary folders
    writing = True  # the block's own work (computing, writing into tmp); then the replacement of `path`
    try:
        commit_point()
        yield tmp
        writing = False
        commit_point()
        with deferred_interrupts(raise_after=False):
            check_output(path, inputs=inputs, option=option)  # still ours to replace
            old = None
            if path.exists():
                old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-{_owner()}-", dir=path.parent))
                try:
                    os.rename(path, old / "previous")
                except OSError as e:
                    old.rmdir()
                    raise OutputError(f"{option} {path}: cannot be replaced ({e.strerror}); choose another {option}") from None
            try:
                os.rename(tmp, path)
            except OSError:
                if old is not None:
                    os.rename(old / "previous", path)
                    old.rmdir()
                raise
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)
    except BaseException as e:
        with deferred_interrupts(raise_after=False):
            shutil.rmtree(tmp, ignore_errors=True)
            _remove_created(created)
        if (
            writing
            and isinstance(e, OSError)
            and e.errno in _FULL
            and _inside(Path(os.path.abspath(e.filename)) if e.filename else tmp, tmp)
        ):
            # the disk filled (or failed) under the new results: name the results folder
            raise OutputError(
                f"{option} {path}: {e.strerror or e} while writing the results; nothing was replaced (free space, or "
                f"choose another {option})"
            ) from None
        raise


def _host() -> str:
    """This host's name as the working folders carry it (no dashes: a dash ends the name there)."""
    return socket.gethostname().replace("-", "_")


def _owner() -> str:
    """This process, as the working folders beside a results folder name it: ``PID@HOST``."""
    return f"{os.getpid()}@{_host()}"


def _clear_stale(path: Path) -> None:
    """Remove the working folders a killed run (SIGKILL, a power cut) left beside `path`: its new results
    (``.NAME.partial-PID@HOST-…``) and, where it had moved the previous result aside (``.NAME.old-PID@HOST-…``), that
    result is put back if `path` is missing, else removed. Only folders of this host whose process is gone."""
    host = _host()
    for kind in ("old", "partial"):  # the previous result first: it may be put back
        for p in sorted(path.parent.glob(f".{path.name}.{kind}-*@{host}-*")):
            pid = p.name[len(f".{path.name}.{kind}-") :].partition("@")[0]
            if not pid.isdigit() or _alive(int(pid)):
                continue
            with contextlib.suppress(OSError):
                if kind == "old" and (p / "previous").is_dir() and not path.exists():
                    os.rename(p / "previous", path)
                shutil.rmtree(p)


def _alive(pid: int) -> bool:
    if os.name == "nt":  # os.kill would end the process there: the folders are left to the user
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # it exists (another user's)
    return True


def _remove_created(created: list[Path]) -> None:
    for p in reversed(created):
        with contextlib.suppress(OSError):
            p.rmdir()


def write_json(path: Path, obj) -> None:
    """Write JSON via a temporary file and rename."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)
