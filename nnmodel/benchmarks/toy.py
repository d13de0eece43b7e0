"""Small known systems with exact answers, for tests and quick examples.

Each function returns a list of :class:`nnmodel.data.Experiment` in physical-looking units
(volts in, metres out) generated from a closed-form system, so a model's error against the
truth can be bounded without trusting any model's own output.
"""
from __future__ import annotations

import numpy as np
from scipy import signal

from ..data import Experiment

FS = 100.0
#: 2nd-order resonant discrete system (poles 0.75 +/- 0.37j, |p| = 0.84), DC gain 1
LIN2_B = (0.0, 0.25, 0.0)
LIN2_A = (1.0, -1.5, 0.7)
SCALE = 1e-3  # output scale: millimetres expressed in metres


def excitation(n: int, seed: int, rms: float = 1.0, pole: float = 0.6) -> np.ndarray:
    """Low-pass filtered Gaussian noise (V)."""
    rng = np.random.default_rng(seed)
    e = signal.lfilter([1.0 - pole], [1.0, -pole], rng.standard_normal(n))
    return rms * e / np.std(e)


def linear2(u: np.ndarray) -> np.ndarray:
    """Output (m) of the linear 2nd-order system for input ``u`` (V), starting at rest."""
    return SCALE * signal.lfilter(LIN2_B, LIN2_A, u)


def static_cubic(u: np.ndarray) -> np.ndarray:
    """Static nonlinearity y = (u + 0.5 u^3) * SCALE (no dynamics)."""
    return SCALE * (u + 0.5 * u ** 3)


def rh_gain(rh) -> np.ndarray:
    """Gain of the humidity-modulated system: 0.5 at 30 %RH rising to 1.5 at 90 %RH."""
    return 0.5 + (np.asarray(rh, float) - 30.0) / 60.0


def rh_system(u: np.ndarray, rh) -> np.ndarray:
    """First-order low-pass (pole 0.8) of the input, times a humidity-dependent gain."""
    x = signal.lfilter([0.2], [1.0, -0.8], u)
    return SCALE * rh_gain(rh) * x


def records(kind: str, n: int = 2000, seeds=(1,), rh_levels=(40.0, 60.0, 80.0), noise: float = 0.0):
    """Records of a toy system: ``kind`` in {"linear2", "cubic", "rh"}.  For "rh" one
    record per (seed, RH level)."""
    out = []
    for s in seeds:
        u = excitation(n, s)
        rng = np.random.default_rng(1000 + s)
        if kind == "rh":
            for rh in rh_levels:
                y = rh_system(u, rh)
                y = y + noise * SCALE * rng.standard_normal(n)
                out.append(Experiment(u, y, rh, FS, f"rh{rh:g}-s{s}"))
            continue
        y = linear2(u) if kind == "linear2" else static_cubic(u)
        y = y + noise * SCALE * rng.standard_normal(n)
        out.append(Experiment(u, y, None, FS, f"{kind}-s{s}"))
    return out
