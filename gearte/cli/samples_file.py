"""Per-sample values written to a ``.npy`` file chunk by chunk, never all held at once."""

from __future__ import annotations

from pathlib import Path

import numpy as np


class SamplesWriter:
    """A float64 ``.npy`` file of `n` values, filled in sample order by `write` (readable with `numpy.load`,
    also memory-mapped). `close` checks that every value came."""

    def __init__(self, path: str | Path, n: int):
        self.path, self.n, self.written = Path(path), int(n), 0
        self._f = open(self.path, "wb")
        np.lib.format.write_array_header_1_0(self._f, {"descr": np.dtype(np.float64).str, "fortran_order": False, "shape": (self.n,)})

    def write(self, values) -> None:
        v = np.ascontiguousarray(values, dtype=np.float64).ravel()
        if self.written + len(v) > self.n:
            raise ValueError(f"{self.path.name}: {self.written + len(v)} values for a file of {self.n}")
        self._f.write(v.tobytes())
        self.written += len(v)

    def close(self, *, complete: bool = True) -> None:
        """Close the file; with `complete`, check that all `n` values were written."""
        if not self._f.closed:
            self._f.close()
        if complete and self.written != self.n:
            raise ValueError(f"{self.path.name}: {self.written} of {self.n} values written")
