"""Threads and seeds: how a network runs on a shared CPU, reproducibly."""
from __future__ import annotations

import contextlib
import random

import numpy as np
import torch

__all__ = ["torch_threads", "seed_all"]


@contextlib.contextmanager
def torch_threads(n: int | None):
    """Temporarily limit torch intra-op threads and BLAS threads to ``n`` (None: leave).

    The networks here are small: on a shared 2-core machine one thread is several times
    faster than two (measured: 14 s vs 94 s for two NARX epochs on Silverbox while other
    jobs ran), because waiting threads spin against the other processes."""
    if not n:
        yield
        return
    from threadpoolctl import threadpool_limits  # a scikit-learn dependency

    old = torch.get_num_threads()
    torch.set_num_threads(int(n))
    try:
        with threadpool_limits(limits=int(n), user_api="blas"):
            yield
    finally:
        torch.set_num_threads(old)


def seed_all(seed: int) -> None:
    """Seed Python, numpy and torch (same seed -> same initial weights and batches)."""
    random.seed(seed)
    np.random.seed(seed % (2 ** 32))
    torch.manual_seed(seed)
