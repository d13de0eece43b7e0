"""Single-threaded BLAS for the physics solvers.

All matrices in the solvers are small (tens to a few hundred rows); multithreaded
BLAS only adds overhead, and when the other cores are busy (training a network, CI)
OpenBLAS's spinning threads make a 1000×50 least-squares solve ~300× slower (measured:
0.29 s instead of 1 ms).  The public entry points therefore run under a one-thread limit.
"""
from __future__ import annotations

import functools

from threadpoolctl import threadpool_limits


def single_threaded(func):
    """Run ``func`` with BLAS limited to one thread (the previous setting is restored)."""
    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)
    return wrapper
