"""A dependency-free progress bar for long runs (stderr)."""

from __future__ import annotations

import sys
import time


class ProgressBar:
    """Text progress bar; shown only when `enabled`. Use as a context manager."""

    def __init__(self, total: int, *, desc: str = "", enabled: bool = True, stream=None, unit: str = "samples"):
        self.total, self.desc, self.enabled, self.unit = total, desc, enabled, unit
        self.stream = stream if stream is not None else sys.stderr
        self.done = 0
        self.start = time.perf_counter()
        self._last = 0.0

    def __enter__(self):
        self._draw(force=True)
        return self

    def update(self, n: int) -> None:
        self.done = min(self.total, self.done + n)
        self._draw()

    def _draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        if not force and now - self._last < 0.1 and self.done < self.total:
            return
        self._last = now
        frac = self.done / self.total if self.total else 1.0
        width = 30
        fill = int(round(width * frac))
        elapsed = now - self.start
        rate = self.done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.done) / rate if rate > 0 else float("nan")
        msg = (f"\r{self.desc} [{'#' * fill}{'.' * (width - fill)}] {self.done:,}/{self.total:,} {self.unit} "
               f"{elapsed:5.1f}s elapsed" + (f", ~{eta:4.1f}s left" if self.done < self.total and rate > 0 else "   "))
        self.stream.write(msg)
        self.stream.flush()

    def __exit__(self, *exc):
        if self.enabled:
            self._draw(force=True)
            self.stream.write("\n")
            self.stream.flush()
        return False
