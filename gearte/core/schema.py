"""Reading study-file tables: every key checked, every message naming the table, the key and the fix.

`Table` wraps one parsed TOML table and remembers which keys were read, so that a key
nobody read is refused with a "did you mean". Drives read their own ``[drive]`` table
with it (`AbstractDrive.from_table`), so each drive declares its own schema beside its
model; the command line reads the rest.
"""

from __future__ import annotations

import difflib
import math
import re
from pathlib import Path
from typing import Any


class ConfigError(ValueError):
    """A configuration file is invalid; the message names the field and the fix."""


#: The most samples of one study or study kind: sample i uses ``fold_in(key, i)`` with a 32-bit i.
MAX_SAMPLES = 2**32 - 1


class OptionError(ConfigError):
    """A command-line option or environment variable that overrides a configuration is invalid: its message names
    the option, not the file."""


_MISSING = object()


#: Largest magnitude of a value given in micrometres (a key ending in ``_um``): tolerances and errors of gear parts are
#: microns; 100 mm is beyond any of them, and far larger values overflow the statistics and plots.
MAX_MICROMETRES = 1e5


class Table:
    """A TOML table being read: tracks which keys were used, so leftovers are reported."""

    def __init__(self, data: Any, where: str, *, folder: Path | None = None):
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a table (key = value pairs), got {type(data).__name__}")
        self.data, self.where, self.used = data, where, set()
        #: Keys a reader asked about with `has` (optional keys): named with the used ones as allowed.
        self.asked: set[str] = set()
        #: The study file's folder (file names in the table are relative to it); None: the working directory.
        self.folder = folder

    def path(self, key: str, default: Any = _MISSING) -> Path:
        """A file name, relative to the study file's folder (`folder`); the file must exist."""
        v = self.string(key, default)
        p = Path(v)
        if not p.is_absolute() and self.folder is not None:
            p = self.folder / p
        if not p.is_file():
            self._fail(key, f"no file {str(p)!r}; give a path relative to the study file's folder")
        return p

    def _fail(self, key: str, msg: str):
        raise ConfigError(f"{self.where} {key}: {msg}")

    def has(self, key: str) -> bool:
        self.asked.add(key)
        return key in self.data

    def get(self, key: str, default: Any = _MISSING) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise ConfigError(f"{self.where}: missing required key `{key}`")
            return default
        return self.data[key]

    def string(self, key: str, default: Any = _MISSING, *, choices: tuple[str, ...] | None = None) -> str:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if not isinstance(v, str):
            self._fail(key, f"expected a string, got {v!r}")
        if choices is not None and v not in choices:
            hint = difflib.get_close_matches(v, choices, n=1)
            self._fail(
                key, f"must be one of {', '.join(repr(c) for c in choices)}, got {v!r}" + (f" (did you mean {hint[0]!r}?)" if hint else "")
            )
        return v

    def integer(self, key: str, default: Any = _MISSING, *, minimum: int | None = None, maximum: int | None = None) -> int:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, int):
            self._fail(key, f"expected a whole number, got {v!r}")
        if minimum is not None and v < minimum:
            self._fail(key, f"must be ≥ {minimum}, got {v}")
        if maximum is not None and v > maximum:
            self._fail(key, f"must be ≤ {maximum}, got {v}")
        return v

    def number(self, key: str, default: Any = _MISSING, *, minimum: float | None = None, positive: bool = False) -> float:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self._fail(key, f"expected a number, got {v!r}")
        v = float(v)
        if not math.isfinite(v):
            self._fail(key, f"must be a finite number, got {v}")
        if positive and not v > 0:
            self._fail(key, f"must be > 0, got {v:g}")
        if minimum is not None and v < minimum:
            self._fail(
                key, f"must be ≥ {minimum:g}, got {v:g}" + (" (tolerances and magnitudes cannot be negative)" if minimum == 0 else "")
            )
        if key.endswith("_um") and "_per_" not in key and abs(v) > MAX_MICROMETRES:
            self._fail(key, f"{v:g} µm is more than {MAX_MICROMETRES:,.0f} µm (100 mm): lengths ending in _um are micrometres")
        return v

    def boolean(self, key: str, default: Any = _MISSING) -> bool:
        v = self.get(key, default)
        if not isinstance(v, bool):
            self._fail(key, f"expected true or false, got {v!r}")
        return v

    def angle(self, stem: str, default: Any = _MISSING) -> float:
        """An angle given as `stem_deg` (number) or `stem_rad` (number, or a string like "7pi/9"); returns rad."""
        has_deg, has_rad = self.has(stem + "_deg"), self.has(stem + "_rad")
        if has_deg and has_rad:
            raise ConfigError(f"{self.where}: give `{stem}_deg` or `{stem}_rad`, not both")
        if has_deg:
            return math.radians(self.number(stem + "_deg"))
        if has_rad:
            v = self.get(stem + "_rad")
            if isinstance(v, str):
                return parse_angle(v, where=f"{self.where} {stem}_rad")
            return self.number(stem + "_rad")
        if default is _MISSING:
            raise ConfigError(f"{self.where}: missing `{stem}_deg` (degrees) or `{stem}_rad` (radians)")
        return default

    def table(self, key: str, default: Any = _MISSING) -> Table:
        v = self.get(key, default)
        if v is default and default is not _MISSING:
            return v
        where = f"{self.where[:-1]}.{key}]" if self.where.startswith("[") and self.where.endswith("]") else f"[{key}]"
        return Table(v, where, folder=self.folder)

    def finish(self) -> None:
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            k = unknown[0]
            allowed = sorted(self.used | self.asked)
            hint = difflib.get_close_matches(k, allowed, n=1)
            raise ConfigError(
                f"{self.where}: unknown key `{k}`"
                + (f" (did you mean `{hint[0]}`?)" if hint else "")
                + f"; allowed here: {', '.join(allowed)}"
            )


_ANGLE_RE = re.compile(r"^\s*([+-]?)\s*(\d+(?:\.\d*)?|\.\d+)?\s*\*?\s*(pi|π)?\s*(?:/\s*(\d+(?:\.\d*)?))?\s*$")


def parse_angle(text: str, *, where: str = "angle") -> float:
    """Read an angle in rad written like "7pi/9", "-pi/9", "0.5", "2*pi/3"."""
    m = _ANGLE_RE.match(text)
    if not m or (m.group(2) is None and m.group(3) is None):
        raise ConfigError(f"{where}: cannot read {text!r} as an angle in rad; write a number or a form like '7pi/9'")
    sign = -1.0 if m.group(1) == "-" else 1.0
    coef = float(m.group(2)) if m.group(2) else 1.0
    value = sign * coef * (math.pi if m.group(3) else 1.0)
    if m.group(4):
        den = float(m.group(4))
        if den == 0:
            raise ConfigError(f"{where}: division by zero in {text!r}")
        value /= den
    return value
