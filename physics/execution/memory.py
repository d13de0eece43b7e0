"""Handing memory a long record's pieces used back to the system.

A record of 10⁷ samples is processed in pieces of ~10⁶ (the network's free run, the time
solver, spectra in parts).  glibc serves a buffer of a few MB from its heap once one of
that size has been freed (its mmap threshold rises with the largest freed block, up to
32 MB), and keeps freed heap pages for reuse: after a piecewise run ~8 bytes per sample
stay resident although nothing uses them.  :func:`release_free_memory` returns them
(``malloc_trim``); elsewhere (macOS, musl, Windows) it does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util

_trim = None


def release_free_memory() -> None:
    """Return the C heap's free pages to the system (glibc ``malloc_trim(0)``); a no-op
    where the C library has no such call."""
    global _trim
    if _trim is None:
        try:
            _trim = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
            _trim.argtypes, _trim.restype = [ctypes.c_size_t], ctypes.c_int
        except (OSError, AttributeError):
            _trim = False
    if _trim:
        _trim(0)
