"""Drives by their study-file name (``[drive] type``): a new drive adds one line here.

`DRIVES` maps each name to the drive's class, and imports the drive's module when the class is first asked
for: a study of one drive imports that drive only (its names, ``set(DRIVES)``, import nothing). The
contract test checks that every entry's class has the entry's name as its `type_name`.
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator, MutableMapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .protocol import AbstractDrive

#: Name → ``module:class`` of each registered drive, in the order the registry lists them.
_WHERE = {
    "planetary_2kh": ".planetary_2kh:Planetary2KH",
    "explicit": ".explicit:ExplicitDrive",
    "harmonic": ".harmonic:HarmonicDrive",
    "cycloid_pin": ".cycloid_pin:CycloidPin",
    "rv_khv": ".rv_khv:RVKHV",
    "helical_planetary": ".helical_drive:HelicalPlanetaryDrive",
}


class DriveRegistry(MutableMapping[str, "type[AbstractDrive]"]):
    """Drive classes by study-file name, each drive's module imported when its class is first asked for. A drive
    registered by assignment (``DRIVES[name] = cls``) is held as given."""

    def __init__(self, where: dict[str, str]):
        self._where = dict(where)
        self._classes: dict[str, type[AbstractDrive]] = {}

    def __getitem__(self, name: str) -> type[AbstractDrive]:
        if name not in self._classes:
            module, _, cls = self._where[name].partition(":")  # KeyError: not a registered drive
            self._classes[name] = getattr(importlib.import_module(module, __package__), cls)
        return self._classes[name]

    def __setitem__(self, name: str, cls: type[AbstractDrive]) -> None:
        self._where[name] = f"{cls.__module__}:{cls.__qualname__}"
        self._classes[name] = cls

    def __delitem__(self, name: str) -> None:
        del self._where[name]
        self._classes.pop(name, None)

    def __contains__(self, name: object) -> bool:  # a name's presence imports nothing
        return name in self._where

    def __iter__(self) -> Iterator[str]:
        return iter(self._where)

    def __len__(self) -> int:
        return len(self._where)

    def __repr__(self) -> str:
        return f"DriveRegistry({sorted(self._where)})"


DRIVES: DriveRegistry = DriveRegistry(_WHERE)
