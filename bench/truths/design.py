"""Records as a lab designs them, and the instruments that measure them.

Excitations (voltage [V] sampled at ``fs``):

* :func:`multisine` — odd-random-phase multisine with lines from 0.05 Hz up to ``f_hi`` on a
  logarithmic selection of the harmonics of 1/period (period 20 s: 0.05 Hz resolution), the
  record holding whole periods; scaled to a peak of ``amplitude``;
* :func:`step` — rest, a step held for a long time, release and a long hold at zero;
* :func:`log_sweep` — a logarithmic swept sine (Farina's exponential chirp);
* :func:`square` — rest, then a bipolar square wave (a pulse train).

:class:`Plan` lists the records of a family (kind, amplitude factor, nominal RH);
:func:`measure` adds what a laser triangulation sensor and a capacitive hygrometer add.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def multisine(amplitude: float, fs: float, duration: float, rng, *, period: float = 20.0, f_lo: float = 0.05,
              f_hi: float = 20.0, per_decade: int = 12, fade: float = 2.0) -> np.ndarray:
    """Multisine of peak ``amplitude`` [V]: harmonics k/period, log-spaced (``per_decade``
    lines a decade, each harmonic used once) from ``f_lo`` to ``f_hi``, random phases; faded in
    over the first ``fade`` s (raised cosine) so that the drive starts from 0 V."""
    k_lo, k_hi = max(1, round(f_lo * period)), int(f_hi * period)
    ks = np.unique(np.round(np.geomspace(k_lo, k_hi, int(per_decade * math.log10(k_hi / k_lo)) + 1)).astype(int))
    t = np.arange(int(round(duration * fs))) / fs
    ph = rng.uniform(0, 2 * np.pi, ks.size)
    v = np.zeros_like(t)
    for k, p in zip(ks, ph):
        v += np.cos(2 * np.pi * k / period * t + p)
    v = amplitude * v / np.max(np.abs(v))
    ramp = t < fade
    v[ramp] *= 0.5 * (1 - np.cos(np.pi * t[ramp] / fade))
    return v


def step(amplitude: float, fs: float, duration: float, *, rest: float = 2.0, hold: float = 25.0) -> np.ndarray:
    """``rest`` s at 0 V, ``hold`` s at ``amplitude``, then 0 V to the end."""
    t = np.arange(int(round(duration * fs))) / fs
    return np.where((t >= rest) & (t < rest + hold), amplitude, 0.0)


def square(amplitude: float, fs: float, duration: float, *, rest: float = 2.0, period: float = 10.0) -> np.ndarray:
    """``rest`` s at 0 V, then +``amplitude`` and −``amplitude`` for half a ``period`` [s] each."""
    t = np.arange(int(round(duration * fs))) / fs
    phase = np.mod(t - rest, period) < period / 2
    return np.where(t < rest, 0.0, np.where(phase, amplitude, -amplitude))


def log_sweep(amplitude: float, fs: float, duration: float, f0: float = 0.1, f1: float = 50.0) -> np.ndarray:
    """Exponential chirp from ``f0`` to ``f1`` [Hz] over ``duration`` [s], starting at 0 V."""
    t = np.arange(int(round(duration * fs))) / fs
    r = math.log(f1 / f0)
    return amplitude * np.sin(2 * np.pi * f0 * duration / r * (np.exp(t * r / duration) - 1.0))


@dataclass(frozen=True)
class Plan:
    """One record: ``kind`` (multisine, step, sweep, square), amplitude factor, nominal RH [%],
    length [s] (None: the family's)."""

    kind: str
    scale: float
    rh: float
    duration: float | None = None

    def length(self, default: float) -> float:
        """The record's length [s]."""
        return default if self.duration is None else self.duration

    def name(self, k: int, amp: float) -> str:
        return f"{k + 1:02d}_{self.kind}_{amp * self.scale:.3g}V_RH{self.rh:g}"

    def voltage(self, amp: float, fs: float, duration: float, rng) -> np.ndarray:
        a = amp * self.scale
        if self.kind == "multisine":
            return multisine(a, fs, duration, rng)
        if self.kind == "step":
            return step(a, fs, duration)
        if self.kind == "sweep":
            return log_sweep(a, fs, duration)
        if self.kind == "square":
            return square(a, fs, duration)
        raise ValueError(f"unknown record kind {self.kind!r}")

    def describe(self, amp: float, fs: float, duration: float) -> dict:
        """What a lab's sidecar says about the excitation."""
        a = amp * self.scale
        if self.kind == "multisine":
            return {"kind": "multisine", "period_s": 20.0, "periods": int(duration // 20), "f_start_Hz": 0.05,
                    "f_stop_Hz": 20.0, "fs_Hz": fs, "duration_s": duration, "amplitude_V": a}
        if self.kind == "step":
            return {"kind": "steps", "fs_Hz": fs, "duration_s": duration, "amplitude_V": a}
        if self.kind == "square":
            return {"kind": "square", "period_s": 10.0, "fs_Hz": fs, "duration_s": duration, "amplitude_V": a}
        return {"kind": "sweep", "f_start_Hz": 0.1, "f_stop_Hz": 50.0, "fs_Hz": fs, "duration_s": duration,
                "amplitude_V": a}


def measure(y: np.ndarray, rng, *, noise: float, step_m: float, offset: float) -> np.ndarray:
    """What a laser triangulation sensor records of the deflection ``y`` [m]: white noise of
    RMS ``noise``, an offset, quantisation to ``step_m``."""
    m = y + offset + noise * rng.standard_normal(y.size)
    return np.round(m / step_m) * step_m


def hygrometer(rh_true: float, n: int, rng, *, jitter: float = 0.3, step_pct: float = 0.1) -> np.ndarray:
    """A capacitive hygrometer's RH column: the true level, a slow wobble and white jitter of
    about ±``jitter`` %, quantised to ``step_pct``."""
    x = np.linspace(0, 1, n)
    wob = 0.5 * jitter * np.sin(2 * np.pi * (x * rng.uniform(0.5, 2.0) + rng.uniform()))
    rh = rh_true + wob + 0.5 * jitter * rng.uniform(-1, 1, n)
    return np.round(rh / step_pct) * step_pct


def fft_filter(x: np.ndarray, fs: float, response, *, pad_s: float = 60.0) -> np.ndarray:
    """``x`` (starting from rest) through the linear system whose frequency response is
    ``response(f)`` (f [Hz] ≥ 0, a callable returning complex values), by a zero-padded FFT
    (linear, not circular, convolution while the response decays within ``pad_s`` s)."""
    n = x.size
    nfft = 1 << int(math.ceil(math.log2(n + int(pad_s * fs))))
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    h = response(f)
    return np.fft.irfft(np.fft.rfft(x, nfft) * h, nfft)[:n]
