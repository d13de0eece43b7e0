"""Normalisation shared by every network: the affine scale of each channel, learned in
``fit`` and saved with the weights, and the normalised record the training code sees."""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .core import SequenceCore

__all__ = ["Normalized", "Seq"]


class Normalized(nn.Module):
    """A core plus the affine normalisation of each channel (stored as buffers, so it is
    saved with the weights); ``n_mem``: memory channels, each with its own scale."""

    def __init__(self, core: SequenceCore, n_mem: int = 0):
        super().__init__()
        self.core = core
        for name in ("u", "y", "rh"):
            self.register_buffer(f"{name}_mean", torch.zeros((), dtype=torch.float64))
            self.register_buffer(f"{name}_std", torch.ones((), dtype=torch.float64))
        if n_mem:  # scale of each memory filter's output (they shrink with the time constant)
            self.register_buffer("mem_std", torch.ones(int(n_mem), dtype=torch.float64))

    def set_stats(self, records, use_rh: bool) -> None:
        """Mean and standard deviation of the voltage, the output and (``use_rh``) the RH."""
        def stats(x):
            m, s = float(np.mean(x)), float(np.std(x))
            if not np.isfinite(s) or s <= 1e-12 * max(1.0, abs(m)):
                s = 1.0  # a constant channel: centre it, do not blow it up
            return m, s
        u = np.concatenate([r.u for r in records])
        y = np.concatenate([r.y for r in records])
        for name, x in (("u", u), ("y", y)):
            m, s = stats(x)
            getattr(self, f"{name}_mean").fill_(m)
            getattr(self, f"{name}_std").fill_(s)
        if use_rh:
            m, s = stats(np.concatenate([r.rh for r in records]))
            self.rh_mean.fill_(m)
            self.rh_std.fill_(s)

    def stat(self, name: str) -> tuple[float, float]:
        return float(getattr(self, f"{name}_mean")), float(getattr(self, f"{name}_std"))

    def norm(self, name: str, x: np.ndarray) -> np.ndarray:
        m, s = self.stat(name)
        return (np.asarray(x, float) - m) / s

    def denorm(self, name: str, x: np.ndarray) -> np.ndarray:
        m, s = self.stat(name)
        return np.asarray(x, float) * s + m


class Seq:
    """A normalised record used by the training code: ``u`` (n, input channels), ``y``
    (n,), ``rh`` (n, RH channels) or None."""

    __slots__ = ("u", "y", "rh")

    def __init__(self, u, y, rh):
        self.u, self.y, self.rh = u, y, rh

    def __len__(self):
        return len(self.u)

    def __getitem__(self, sl: slice) -> "Seq":
        return Seq(self.u[sl], self.y[sl], None if self.rh is None else self.rh[sl])
