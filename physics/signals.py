"""Excitation signals (voltages in V, times in s, frequencies in Hz).

Each generator returns a :class:`Signal` with the sampled record and a description of
how it was made (recorded in every output file).  Random signals take a ``seed``.
Thesis experiments: swept sine 4 Vpp (amplitude 2 V) over 0.1–50 Hz (IP2C) or 1–50 Hz
(IPMC), pure tones 4 Vpp at 0.2, 1, 10 and 26 Hz, square wave T_on 20 s / T_off 80 s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from .errors import InputError, arg


@dataclass
class Signal:
    t: np.ndarray          # s
    v: np.ndarray          # V
    kind: str
    params: dict = field(default_factory=dict)

    @property
    def fs(self) -> float:
        return 1.0 / float(self.t[1] - self.t[0])

    def describe(self) -> dict:
        return {"kind": self.kind, **{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                      for k, v in self.params.items()}}


def _time(duration: float, fs: float) -> np.ndarray:
    if not (duration > 0 and fs > 0):
        raise InputError("duration [s] and sampling rate fs [Hz] must be positive")
    n = int(round(duration * fs))
    if n < 3:
        raise InputError(f"duration × fs gives {n} samples; need at least 3")
    return np.arange(n) / fs


def _check_band(f0: float, f1: float, fs: float):
    if not (0 < f0 < f1):
        raise InputError(f"need 0 < {arg('f_start')} < {arg('f_stop')}, got {f0:g}, {f1:g} Hz")
    if f1 >= fs / 2:
        raise InputError(f"{arg('f_stop')} {f1:g} Hz must be below the Nyquist frequency {fs / 2:g} Hz (half of "
                         f"{arg('fs')} {fs:g} Hz)")


def fade_in(sig: Signal, duration: float) -> Signal:
    """``sig`` multiplied by a raised-cosine ramp 0 → 1 over its first ``duration`` seconds,
    so that the record starts at 0 V, from rest, as a laboratory record does (a signal that
    starts at a non-zero voltage would otherwise imply that the actuator had been held
    there forever).  ``duration = 0`` returns ``sig`` unchanged."""
    duration = float(duration)
    if not (0.0 <= duration < sig.t[-1]):
        raise InputError(f"fade-in duration must be at least 0 s and shorter than the signal "
                         f"({sig.t[-1]:g} s), got {duration:g} s")
    if duration == 0.0:
        return sig
    w = 0.5 - 0.5 * np.cos(np.pi * np.clip(sig.t / duration, 0.0, 1.0))
    return Signal(sig.t, sig.v * w, sig.kind, {**sig.params, "fade_in_s": duration})


def sweep(amplitude: float = 2.0, f_start: float = 0.1, f_stop: float = 50.0, duration: float = 100.0,
          fs: float = 1000.0, method: str = "logarithmic", offset: float = 0.0) -> Signal:
    """Swept sine (chirp) from f_start to f_stop, linear or logarithmic in frequency."""
    _check_band(f_start, f_stop, fs)
    if method not in ("linear", "logarithmic"):
        raise InputError("sweep method must be 'linear' or 'logarithmic'")
    t = _time(duration, fs)
    v = offset + amplitude * sps.chirp(t, f_start, duration, f_stop, method=method, phi=-90)
    return Signal(t, v, "sweep", dict(amplitude_V=amplitude, f_start_Hz=f_start, f_stop_Hz=f_stop,
                                      method=method, offset_V=offset, duration_s=duration, fs_Hz=fs))


def tone(amplitude: float = 2.0, frequency: float = 1.0, duration: float = 10.0, fs: float = 1000.0,
         phase_deg: float = 0.0, offset: float = 0.0) -> Signal:
    """Pure sine tone."""
    if not 0 < frequency < fs / 2:
        raise InputError(f"{arg('frequency')} {frequency:g} Hz must be positive and below the Nyquist frequency "
                         f"{fs / 2:g} Hz (half of {arg('fs')} {fs:g} Hz)")
    t = _time(duration, fs)
    v = offset + amplitude * np.sin(2 * np.pi * frequency * t + np.radians(phase_deg))
    return Signal(t, v, "tone", dict(amplitude_V=amplitude, frequency_Hz=frequency, phase_deg=phase_deg,
                                     offset_V=offset, duration_s=duration, fs_Hz=fs))


def square(amplitude: float = 2.0, t_on: float = 20.0, t_off: float = 80.0, cycles: int = 1,
           fs: float = 100.0, rise_time: float | None = None, bipolar: bool = False) -> Signal:
    """Square pulses: ``amplitude`` for t_on, 0 (or −amplitude if ``bipolar``) for t_off, repeated
    ``cycles`` times; edges are linear ramps of ``rise_time`` (default: one sample)."""
    if t_on <= 0 or t_off < 0 or cycles < 1:
        raise InputError("need t_on > 0, t_off >= 0 and at least one cycle")
    period = t_on + t_off
    t = _time(period * cycles, fs)
    rt = 1.0 / fs if rise_time is None else float(rise_time)
    if rt <= 0 or rt > min(t_on, t_off if t_off > 0 else t_on):
        raise InputError("rise_time must be positive and shorter than t_on and t_off")
    ph = np.mod(t, period)
    up = np.clip(ph / rt, 0.0, 1.0)
    down = np.clip((ph - t_on) / rt, 0.0, 1.0)
    low = -amplitude if bipolar else 0.0
    v = low + (amplitude - low) * (up - down)
    return Signal(t, v, "square", dict(amplitude_V=amplitude, t_on_s=t_on, t_off_s=t_off, cycles=cycles,
                                       rise_time_s=rt, bipolar=bipolar, fs_Hz=fs))


def steps(times, levels, duration: float, fs: float = 1000.0, rise_time: float | None = None) -> Signal:
    """Piecewise-constant voltage: ``levels[i]`` from ``times[i]`` (s); 0 before the first."""
    times, levels = np.asarray(times, dtype=float), np.asarray(levels, dtype=float)
    if times.shape != levels.shape or times.ndim != 1 or np.any(np.diff(times) <= 0):
        raise InputError("steps: times must increase strictly and match levels one to one")
    t = _time(duration, fs)
    rt = 1.0 / fs if rise_time is None else float(rise_time)
    v = np.zeros_like(t)
    prev = 0.0
    for ti, lv in zip(times, levels):
        v += (lv - prev) * np.clip((t - ti) / rt, 0.0, 1.0)
        prev = lv
    return Signal(t, v, "steps", dict(times_s=times, levels_V=levels, rise_time_s=rt, duration_s=duration,
                                      fs_Hz=fs))


def multisine(rms: float = 0.5, f_start: float = 0.1, f_stop: float = 50.0, period: float = 20.0,
              periods: int = 1, fs: float = 1000.0, phases: str = "random", odd_only: bool = False,
              seed: int = 0) -> Signal:
    """Multisine with equal amplitudes on the lines k/period within the band; ``phases`` is
    ``random`` (uniform, seeded) or ``schroeder`` (low crest factor; Schroeder 1970)."""
    _check_band(f_start, f_stop, fs)
    k = np.arange(int(np.ceil(f_start * period)), int(np.floor(f_stop * period)) + 1)
    k = k[k > 0]
    if odd_only:
        k = k[k % 2 == 1]
    if k.size == 0:
        raise InputError(f"no frequency line k/{period:g} s lies in {f_start:g}–{f_stop:g} Hz")
    if phases == "random":
        ph = np.random.default_rng(seed).uniform(0, 2 * np.pi, k.size)
    elif phases == "schroeder":
        ph = -np.pi * np.arange(1, k.size + 1) * np.arange(k.size) / k.size
    else:
        raise InputError("phases must be 'random' or 'schroeder'")
    t = _time(period * periods, fs)
    v = np.zeros_like(t)
    for kk, p in zip(k, ph):
        v += np.cos(2 * np.pi * kk / period * t + p)
    v *= rms / np.sqrt(k.size / 2.0)
    return Signal(t, v, "multisine", dict(rms_V=rms, f_start_Hz=f_start, f_stop_Hz=f_stop, period_s=period,
                                          periods=periods, phases=phases, odd_only=odd_only, seed=seed,
                                          lines=int(k.size), fs_Hz=fs))


def noise(rms: float = 0.5, f_start: float = 0.1, f_stop: float = 50.0, duration: float = 100.0,
          fs: float = 1000.0, seed: int = 0) -> Signal:
    """Band-limited Gaussian noise: white noise band-passed in the frequency domain to
    [f_start, f_stop] (brick wall), scaled to ``rms``."""
    _check_band(f_start, f_stop, fs)
    t = _time(duration, fs)
    rng = np.random.default_rng(seed)
    X = np.fft.rfft(rng.standard_normal(t.size))
    f = np.fft.rfftfreq(t.size, 1 / fs)
    X[(f < f_start) | (f > f_stop)] = 0.0
    v = np.fft.irfft(X, n=t.size)
    v *= rms / np.std(v)
    return Signal(t, v, "noise", dict(rms_V=rms, f_start_Hz=f_start, f_stop_Hz=f_stop, duration_s=duration,
                                      fs_Hz=fs, seed=seed))


GENERATORS = {"sweep": sweep, "tone": tone, "square": square, "steps": steps, "multisine": multisine,
              "noise": noise}
