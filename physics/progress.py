"""A minimal progress bar on stderr for long computations (no dependency)."""
from __future__ import annotations

import sys
import time


class Progress:
    """``with Progress(total, "simulating") as bar: bar.update(n)``; silent when disabled
    or when stderr is not a terminal and ``force`` is False."""

    def __init__(self, total: int, label: str, enabled: bool = True, force: bool = False):
        self.total, self.label = max(int(total), 1), label
        self.enabled = enabled and (force or sys.stderr.isatty())
        self.done, self._t0, self._last = 0, time.perf_counter(), 0.0

    def __enter__(self):
        return self

    def update(self, n: int = 1):
        self.done = min(self.total, self.done + n)
        now = time.perf_counter()
        if self.enabled and (now - self._last > 0.2 or self.done == self.total):
            self._last = now
            frac = self.done / self.total
            bar = "#" * int(30 * frac)
            eta = (now - self._t0) * (1 - frac) / frac if frac > 0 else 0.0
            sys.stderr.write(f"\r{self.label}: [{bar:<30s}] {100 * frac:5.1f} %  eta {eta:5.1f} s")
            sys.stderr.flush()

    def __exit__(self, *exc):
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()
        return False
