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
    """A sampled excitation and how it was made.

    Attributes
    ----------
    t : ndarray
        Sample times [s], uniform, from 0.
    v : ndarray
        Voltage [V].
    kind : str
        The generator: ``sweep``, ``tone``, ``square``, ``steps``, ``multisine`` or ``noise``.
    params : dict
        The generator's settings, named with their units (``f_start_Hz``, ``amplitude_V``, …).

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.tone(amplitude=2.0, frequency=1.0, duration=10.0, fs=1000.0)
    >>> sig.fs, sig.describe()["amplitude_V"]
    (1000.0, 2.0)
    """

    t: np.ndarray          # s
    v: np.ndarray          # V
    kind: str
    params: dict = field(default_factory=dict)

    @property
    def fs(self) -> float:
        """Sampling rate [Hz]."""
        return 1.0 / float(self.t[1] - self.t[0])

    def describe(self) -> dict:
        """``kind`` and ``params`` as plain values: the ``signal`` entry of a sidecar."""
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
    """A signal that starts from 0 V: multiplied by a raised-cosine ramp over its first seconds.

    A laboratory record starts at rest; a signal that starts at a non-zero voltage would imply
    that the strip had been held there forever.

    Parameters
    ----------
    sig : Signal
        The signal.
    duration : float
        Length of the ramp 0 → 1 [s], at least 0 and shorter than the signal; 0 returns
        ``sig`` unchanged.

    Returns
    -------
    Signal
        The faded signal; its ``params`` record ``fade_in_s``.

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.fade_in(signals.tone(1.0, 2.0, duration=5.0, fs=100.0, phase_deg=90), 1.0)
    >>> float(sig.v[0]), round(float(sig.v[100]), 6)
    (0.0, 1.0)
    """
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
    """A swept sine (chirp) from ``f_start`` to ``f_stop``, as in the thesis's experiments.

    Parameters
    ----------
    amplitude : float
        Amplitude [V] (the thesis: 2 V, i.e. 4 Vpp).
    f_start, f_stop : float
        Start and stop frequency [Hz], 0 < f_start < f_stop < fs/2.
    duration : float
        Length [s].
    fs : float
        Sampling rate [Hz].
    method : {"logarithmic", "linear"}
        How the frequency moves with time.
    offset : float
        Constant added [V].

    Returns
    -------
    Signal

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.sweep(amplitude=1.0, f_start=0.1, f_stop=20.0, duration=30.0, fs=100.0)
    >>> sig.t.size, sig.fs, sig.kind
    (3000, 100.0, 'sweep')
    """
    _check_band(f_start, f_stop, fs)
    if method not in ("linear", "logarithmic"):
        raise InputError("sweep method must be 'linear' or 'logarithmic'")
    t = _time(duration, fs)
    v = offset + amplitude * sps.chirp(t, f_start, duration, f_stop, method=method, phi=-90)
    return Signal(t, v, "sweep", dict(amplitude_V=amplitude, f_start_Hz=f_start, f_stop_Hz=f_stop,
                                      method=method, offset_V=offset, duration_s=duration, fs_Hz=fs))


def tone(amplitude: float = 2.0, frequency: float = 1.0, duration: float = 10.0, fs: float = 1000.0,
         phase_deg: float = 0.0, offset: float = 0.0) -> Signal:
    """A pure sine tone.

    Parameters
    ----------
    amplitude : float
        Amplitude [V].
    frequency : float
        Frequency [Hz], below fs/2.
    duration : float
        Length [s].
    fs : float
        Sampling rate [Hz].
    phase_deg : float
        Phase at t = 0 [°].
    offset : float
        Constant added [V].

    Returns
    -------
    Signal

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.tone(amplitude=2.0, frequency=1.0, duration=10.0, fs=1000.0)
    >>> round(float(sig.v.max()), 6)
    2.0
    """
    if not 0 < frequency < fs / 2:
        raise InputError(f"{arg('frequency')} {frequency:g} Hz must be positive and below the Nyquist frequency "
                         f"{fs / 2:g} Hz (half of {arg('fs')} {fs:g} Hz)")
    t = _time(duration, fs)
    v = offset + amplitude * np.sin(2 * np.pi * frequency * t + np.radians(phase_deg))
    return Signal(t, v, "tone", dict(amplitude_V=amplitude, frequency_Hz=frequency, phase_deg=phase_deg,
                                     offset_V=offset, duration_s=duration, fs_Hz=fs))


def square(amplitude: float = 2.0, t_on: float = 20.0, t_off: float = 80.0, cycles: int = 1,
           fs: float = 100.0, rise_time: float | None = None, bipolar: bool = False) -> Signal:
    """Square pulses: ``amplitude`` for ``t_on``, then 0 (or −amplitude) for ``t_off``, repeated.

    Parameters
    ----------
    amplitude : float
        Pulse height [V].
    t_on, t_off : float
        Time on and time off per cycle [s] (the thesis: 20 s and 80 s).
    cycles : int
        Number of cycles, at least 1.
    fs : float
        Sampling rate [Hz].
    rise_time : float, optional
        Length of the linear edges [s] (default: one sample).
    bipolar : bool
        Off at −amplitude instead of 0 V.

    Returns
    -------
    Signal

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.square(amplitude=1.0, t_on=10.0, t_off=20.0, cycles=1, fs=100.0)
    >>> float(sig.v[500]), float(sig.v[2500]), float(sig.t[-1])
    (1.0, 0.0, 29.99)
    """
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
    """A piecewise-constant voltage: ``levels[i]`` from ``times[i]`` on, 0 V before the first.

    Parameters
    ----------
    times : array_like
        Step times [s], strictly increasing.
    levels : array_like
        Voltage after each step [V], one per time.
    duration : float
        Length [s].
    fs : float
        Sampling rate [Hz].
    rise_time : float, optional
        Length of the linear edges [s] (default: one sample).

    Returns
    -------
    Signal

    Examples
    --------
    >>> from physics import signals
    >>> sig = signals.steps([1.0, 3.0], [0.5, -0.5], duration=5.0, fs=10.0)
    >>> sig.v[[0, 20, 40]].tolist()
    [0.0, 0.5, -0.5]
    """
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
    """A multisine: equal amplitudes on every line k/period within the band.

    Parameters
    ----------
    rms : float
        RMS value [V].
    f_start, f_stop : float
        Band [Hz], below fs/2.
    period : float
        Period [s]: the lines are spaced 1/period Hz apart.
    periods : int
        Number of periods.
    fs : float
        Sampling rate [Hz].
    phases : {"random", "schroeder"}
        Random phases (uniform, from ``seed``) or Schroeder's (a low crest factor; Schroeder 1970).
    odd_only : bool
        Only odd lines (even lines then show nonlinear distortion).
    seed : int
        Seed of the random phases.

    Returns
    -------
    Signal
        Its ``params`` record the number of ``lines``.

    Examples
    --------
    >>> import numpy as np
    >>> from physics import signals
    >>> sig = signals.multisine(rms=0.5, f_start=0.1, f_stop=10.0, period=20.0, fs=100.0)
    >>> sig.params["lines"], round(float(np.sqrt(np.mean(sig.v ** 2))), 3)
    (199, 0.5)
    """
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
    """Band-limited Gaussian noise: white noise cut to the band in the frequency domain.

    Parameters
    ----------
    rms : float
        RMS value [V].
    f_start, f_stop : float
        Band [Hz] (brick-wall edges), below fs/2.
    duration : float
        Length [s].
    fs : float
        Sampling rate [Hz].
    seed : int
        Seed of the noise.

    Returns
    -------
    Signal

    Examples
    --------
    >>> from physics import signals
    >>> a = signals.noise(rms=0.5, f_start=0.1, f_stop=20.0, duration=10.0, fs=100.0, seed=1)
    >>> b = signals.noise(rms=0.5, f_start=0.1, f_stop=20.0, duration=10.0, fs=100.0, seed=1)
    >>> bool((a.v == b.v).all()), round(float(a.v.std()), 6)
    (True, 0.5)
    """
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
