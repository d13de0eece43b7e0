"""Realistic sensors for synthetic measurements.

Turns a noise-free simulated record into one that looks like the thesis set-up (De Luca
2014, ch. 2 §4.1): tip deflection from a laser triangulation sensor (Baumer OADM
12U6460/S35A), voltage and current through a 16-bit NI DAQ 6052E, temperature from an
LM35 and RH from a HIH-3610.  The defaults are assumed orders of magnitude for that
class of instruments (laser: µm-level noise and < 1 ms response time; DAQ: ±10 V
16-bit inputs), not values from the data sheets; set them from your own calibration.

Deflection channel, in order: first-order low-pass of the true deflection (sensor
bandwidth, bilinear discretisation), + offset, + random-walk drift, + white noise,
quantisation to ``deflection_step``, clipping to ``±deflection_range``.  Voltage and
current: white noise, then a DAQ of ``adc_bits`` over ``±range`` (quantisation step
``2 range / 2**adc_bits``, clipping).  RH and temperature: white noise, quantisation to
their resolution (RH clipped to 0–100 %).  Each channel draws from its own random
stream, so changing one channel's settings never changes another's noise.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ..errors import InputError
from .record import TimeSeries

_DAQ_LSB_10V = 20.0 / 2**16  # V, NI 6052E on its ±10 V range
_STREAMS = ("deflection", "drift", "voltage", "current", "rh", "temperature")


@dataclass(frozen=True)
class SensorModel:
    """Measurement chain settings (SI units; ``step``/``noise`` 0 and ``bandwidth``
    ``None`` switch a feature off, see :meth:`ideal`)."""
    deflection_noise: float = 1.0e-6          #: m, RMS white noise of the laser
    deflection_step: float = _DAQ_LSB_10V * 1e-3  #: m, DAQ step at 1 mm/V (0.31 µm)
    deflection_offset: float = 0.0            #: m, constant offset
    deflection_drift: float = 1.0e-6          #: m, std of the random-walk drift at record end
    deflection_range: float = 5.0e-3          #: m, ± measuring half-range (output clips)
    bandwidth: float | None = 400.0           #: Hz, first-order cut-off (~0.9 ms response)
    adc_bits: int | None = 16                 #: DAQ resolution for voltage and current
    voltage_range: float = 10.0               #: V, ± DAQ input range
    voltage_noise: float = 1.0e-4             #: V, RMS
    current_range: float = 0.1                #: A, ± full scale of the current channel
    current_noise: float = 2.0e-6             #: A, RMS
    rh_noise: float = 0.2                     #: %, RMS
    rh_step: float = 0.1                      #: %, resolution
    temperature_noise: float = 0.05           #: °C, RMS
    temperature_step: float = _DAQ_LSB_10V / 0.01  #: °C, DAQ step at 10 mV/°C (0.03 °C)

    def __post_init__(self):
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "adc_bits":
                ok = value is None or (isinstance(value, int) and 1 <= value <= 32)
                expected = "an integer 1–32 or None"
            elif f.name == "bandwidth":
                ok = value is None or (math.isfinite(value) and value > 0)
                expected = "a positive frequency in Hz or None"
            elif f.name.endswith("range"):
                ok = value > 0
                expected = "positive (may be inf)"
            elif f.name == "deflection_offset":
                ok = math.isfinite(value)
                expected = "finite"
            else:
                ok = math.isfinite(value) and value >= 0
                expected = "finite and >= 0"
            if not ok:
                raise InputError(f"sensor setting {f.name}={value!r} must be {expected}")
        if self.adc_bits is not None and not math.isfinite(self.voltage_range * self.current_range):
            raise InputError("sensor: a DAQ with adc_bits needs finite voltage_range and "
                             "current_range")

    @classmethod
    def ideal(cls) -> "SensorModel":
        """A perfect sensor: no noise, offset, drift, filtering, quantisation or clipping."""
        return cls(deflection_noise=0.0, deflection_step=0.0, deflection_drift=0.0,
                   deflection_range=math.inf, bandwidth=None, adc_bits=None,
                   voltage_range=math.inf, voltage_noise=0.0, current_range=math.inf,
                   current_noise=0.0, rh_noise=0.0, rh_step=0.0, temperature_noise=0.0,
                   temperature_step=0.0)

    def noise_floor(self) -> float:
        """Expected RMS (m) of measured minus sensor-filtered true deflection:
        sqrt(σ² + q²/12 + drift²/2).

        White noise σ, quantisation q (uniform-error model, valid when σ ≳ q/2 or the
        signal spans many steps) and the random walk, whose mean square over the record
        is drift²/2.  The constant offset and clipping are not included.
        """
        return math.sqrt(self.deflection_noise**2 + self.deflection_step**2 / 12
                         + self.deflection_drift**2 / 2)

    def apply(self, ts: TimeSeries, seed: int) -> TimeSeries:
        """A new record as these sensors would measure ``ts`` (left untouched).

        Deterministic for a given ``seed``; the settings, seed and number of clipped
        samples per channel are stored in ``meta["sensor"]``.  A record that already
        carries ``meta["sensor"]`` is a measurement and is refused.
        """
        where = ts.source or "time series"
        if "sensor" in ts.meta:
            raise InputError(f"{where}: already has sensor settings in its metadata "
                             "(a measurement); apply the sensor model to a noise-free record")
        rngs = dict(zip(_STREAMS, (np.random.default_rng(s) for s in
                                   np.random.SeedSequence(seed).spawn(len(_STREAMS)))))
        daq_step = {name: 0.0 if self.adc_bits is None else 2 * limit / 2**self.adc_bits
                    for name, limit in (("voltage", self.voltage_range),
                                        ("current", self.current_range))}
        chain = {  # channel: (noise, step, low, high); DAQ codes span [-range, range - step]
            "voltage": (self.voltage_noise, daq_step["voltage"], -self.voltage_range,
                        self.voltage_range - daq_step["voltage"]),
            "current": (self.current_noise, daq_step["current"], -self.current_range,
                        self.current_range - daq_step["current"]),
            "rh": (self.rh_noise, self.rh_step, 0.0, 100.0),
            "temperature": (self.temperature_noise, self.temperature_step, -math.inf, math.inf),
            "deflection": (self.deflection_noise, self.deflection_step, -self.deflection_range,
                           self.deflection_range),
        }
        out, clipped = {}, {}
        for name, (noise, step, lo, hi) in chain.items():
            x = getattr(ts, name)
            if x is None:
                continue
            if name == "deflection":
                x = self._lowpass(x, ts.fs) + self.deflection_offset \
                    + self._drift(x.size, rngs["drift"])
            out[name], clipped[name] = _measure(x, rngs[name], noise, step, lo, hi)
        # RH readings pinned at 0 or 100 % are physics, not a saturated sensor: no warning
        over_range = {k: v for k, v in clipped.items() if v and k != "rh"}
        if over_range:
            warnings.warn(f"{where}: sensor range exceeded, samples clipped: {over_range}", stacklevel=2)
        meta = copy.deepcopy(ts.meta)
        meta["sensor"] = {**dataclasses.asdict(self), "seed": int(seed),
                          "noise_floor_m": self.noise_floor(), "clipped_samples": clipped}
        return TimeSeries(time=ts.time.copy(), **out, meta=meta, source=ts.source)

    def _lowpass(self, x: np.ndarray, fs: float) -> np.ndarray:
        """First-order low-pass 1/(1 + s/(2π fc)), bilinear (Tustin) discretisation
        (frequency warped by about (π f/fs)²/3 relative: accurate for f ≪ fs/2), started
        in steady state at the first sample."""
        if self.bandwidth is None:
            return x
        b, a = signal.bilinear([1.0], [1.0 / (2 * np.pi * self.bandwidth), 1.0], fs)
        y, _ = signal.lfilter(b, a, x, zi=signal.lfilter_zi(b, a) * x[0])
        return y

    def _drift(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Random walk of n steps whose value at the last sample has std ``deflection_drift``."""
        if self.deflection_drift == 0:
            return np.zeros(n)
        return np.cumsum(rng.normal(0.0, self.deflection_drift / np.sqrt(n), n))


def _measure(x: np.ndarray, rng: np.random.Generator, noise: float, step: float,
             lo: float, hi: float) -> tuple[np.ndarray, int]:
    """x + white noise, quantised to ``step``, clipped to the largest representable
    values within [lo, hi]; returns the measurement and the number of clipped samples."""
    y = x + rng.normal(0.0, noise, x.size) if noise > 0 else x.copy()
    if step > 0:
        y = np.round(y / step) * step
        lo = np.ceil(lo / step) * step if math.isfinite(lo) else lo
        hi = np.floor(hi / step) * step if math.isfinite(hi) else hi
    n_clipped = int(np.count_nonzero((y < lo) | (y > hi)))
    return np.clip(y, lo, hi), n_clipped
