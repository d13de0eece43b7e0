"""A small memo for the model evaluations of a fit: the last few results, by key.

A finite-difference Jacobian evaluates the model at its centre and once per parameter; a
parameter fitted per RH level changes only the records or responses at that level, so the
others can be taken from the centre's evaluation.  The caller builds the key from everything
the result depends on (:meth:`physics.model.ActuatorModel.key_at`)."""
from __future__ import annotations

from typing import Callable, Hashable

import numpy as np

#: Results kept per memo: the centre of a finite-difference Jacobian outlives its columns ...
SIZE = 32
#: ... within this many bytes per memo [B] (a simulated hour-long record is megabytes).
MAX_BYTES = 16 << 20


def remembered(memo: dict, key: Hashable | None, compute: Callable[[], np.ndarray]) -> np.ndarray:
    """``memo[key]``, or ``compute()`` kept there (the oldest entries dropped beyond :data:`SIZE`
    results or :data:`MAX_BYTES`; the newest is always kept); ``key`` None: computed and not
    kept.  A kept array is made read-only, since later calls share it."""
    if key is None:
        return compute()
    out = memo.get(key)
    if out is None:
        out = compute()
        out.flags.writeable = False
        memo[key] = out
        while len(memo) > 1 and (len(memo) > SIZE or sum(v.nbytes for v in memo.values()) > MAX_BYTES):
            memo.pop(next(iter(memo)))
    return out
