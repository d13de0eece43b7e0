"""Progress bars on stderr for long computations, drawn by tqdm (installed with Lightning).

Shown only where a person watches: stderr is a terminal, or ``force`` is given; disabled,
a bar costs nothing but the counting.
"""
from __future__ import annotations

import sys


class Progress:
    """``with Progress(total, "simulating") as bar: bar.update(n)``; silent when disabled
    or when stderr is not a terminal and ``force`` is False."""

    def __init__(self, total: int, label: str, enabled: bool = True, force: bool = False):
        from tqdm import tqdm
        self.total, self.label = max(int(total), 1), label
        self.enabled = enabled and (force or sys.stderr.isatty())
        self._bar = tqdm(total=self.total, desc=label, disable=not self.enabled, file=sys.stderr,
                         mininterval=0.2, dynamic_ncols=True)

    def __enter__(self):
        return self

    def update(self, n: int = 1):
        self._bar.update(n)

    def __exit__(self, *exc):
        self._bar.close()
        return False
