"""One experiment as arrays: :class:`TimeSeries` and the checks every record passes.

A record holds uniformly sampled channels in stored units: ``time`` s, ``voltage`` V,
``deflection`` (the measured output: tip deflection in m, or the quantity named in
``meta["output"]``), ``rh`` %, ``current`` A, ``temperature`` °C.  The checks here
(finite values, strictly increasing and uniform time, RH within 0–100 %, a sampling rate
within :data:`~physics.limits.FS_RANGE_HZ`) are shared by the file reader (:mod:`physics.io.timeseries`),
the sensor model and records built in memory; every violation is an
:class:`~physics.errors.InputError` naming the record, the sample (or line) and the channel.
"""
from __future__ import annotations

import copy
import re
import warnings
from dataclasses import MISSING, dataclass, field, fields
from typing import Callable, Mapping

import numpy as np

from ..errors import InputError, InputNotice, arg
from ..limits import FS_RANGE_HZ
from .units import UnitError, parse_unit

#: Largest accepted deviation of a time step from the median step, relative to it.
UNIFORM_RTOL = 1e-2
#: Channels besides time.
CHANNELS = ("voltage", "deflection", "rh", "current", "temperature")
Locate = Callable[[int], str]
#: Magnitude bound of an output whose unit has no plausibility rule (any plant, any unit):
#: beyond it squares and sums overflow and every metric is meaningless.
GENERIC_LIMIT = 1e15
#: Quantities a record's inputs and time use; an output may not take these names.
RESERVED = ("time", "voltage", "rh", "current", "temperature")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9]*$")
_UNIT = re.compile(r"^[A-Za-z0-9%µΩ°/^*.()-]+$")


@dataclass(frozen=True)
class OutputQuantity:
    """What a record's output is: ``name`` (a word: ``deflection``, ``level``) and ``unit``
    (``m``, ``V``, ``mm``; a unit :func:`physics.io.units.parse_unit` reads, or any other word).

    The default is the tip deflection in metres.  Values are stored in ``unit``; the
    plausibility rule follows the quantity (:meth:`bounds`).  A record's file names its
    output column ``NAME_UNIT`` (``deflection_m``, ``level_V``)."""
    name: str = "deflection"
    unit: str = "m"

    def __post_init__(self):
        if not (isinstance(self.name, str) and _NAME.match(self.name)) or self.name in RESERVED:
            raise InputError(f"output name {self.name!r}: expected a word of letters and digits (e.g. level, "
                             f"deflection), not one of {', '.join(RESERVED)}")
        if not (isinstance(self.unit, str) and _UNIT.match(self.unit)):
            raise InputError(f"output unit {self.unit!r}: expected a unit such as m, mm, V, mV or 1")

    @classmethod
    def parse(cls, text: str) -> "OutputQuantity":
        """``"NAME:UNIT"`` (e.g. ``level:V``) → the quantity."""
        name, sep, unit = (s.strip() for s in str(text).partition(":"))
        if not sep or not name or not unit:
            raise InputError(f"output {text!r}: expected NAME:UNIT, e.g. level:V or deflection:mm")
        out = cls(name, unit)
        try:
            parse_unit(unit)
        except UnitError:     # any word may be a unit (counts, LSB): kept, but said aloud
            warnings.warn(InputNotice(f"output {text}: {unit!r} is not a unit eap knows (m, mm, V, mV, N, Pa, %, 1, "
                                      f"…): values are kept in it as they are, with no conversion — check the "
                                      "spelling (units are case-sensitive)"))
        return out

    @classmethod
    def from_dict(cls, d, where: str = "output") -> "OutputQuantity":
        """From ``{"name": ..., "unit": ...}`` (``None``: the default)."""
        if d is None:
            return cls()
        if not isinstance(d, dict) or not isinstance(d.get("name"), str) or not isinstance(d.get("unit"), str):
            raise InputError(f"{where}: expected a mapping with text keys name and unit (e.g. "
                             f"{{\"name\": \"level\", \"unit\": \"V\"}}), got {d!r}")
        return cls(d["name"], d["unit"])

    def to_dict(self) -> dict:
        return {"name": self.name, "unit": self.unit}

    @property
    def is_deflection(self) -> bool:
        """True for the tip deflection in metres (what the physics models predict)."""
        return self.name == "deflection" and self.unit == "m"

    @property
    def column(self) -> str:
        """The output's column name in a standard file."""
        return f"{self.name}_{self.unit}"

    def label(self, scale_to_mm: bool = False) -> str:
        """``"deflection [m]"`` (``[mm]`` when plotting metres in mm), for axes and tables."""
        unit = "mm" if scale_to_mm and self.unit == "m" else self.unit
        return f"{self.name} [{unit}]"

    def bounds(self) -> tuple[float, float, str]:
        """(low, high, description) of plausible values in :attr:`unit`: a tip deflection
        within ±1 m, a voltage-like output within ±1 kV, anything else within ±10¹⁵."""
        from .units import UnitError, parse_unit
        try:
            q = parse_unit(self.unit)
        except UnitError:
            q = None
        if q is not None and q.same_dimension(parse_unit("m")) and self.name == "deflection":
            lim = 1.0 / q.factor
            return -lim, lim, f"{self.unit} (tip deflection of a strip)"
        if q is not None and q.same_dimension(parse_unit("V")):
            lim = 1e3 / q.factor
            return -lim, lim, f"{self.unit} ({self.name}: a voltage-like output)"
        return -GENERIC_LIMIT, GENERIC_LIMIT, f"{self.unit} ({self.name}: larger values overflow the metrics)"


#: The default output: the tip deflection in metres.
DEFLECTION = OutputQuantity()


@dataclass
class TimeSeries:
    """One uniformly sampled experiment.

    Units: ``time`` s (uniform, strictly increasing), ``voltage`` V, ``deflection`` the
    measured output in ``output.unit`` (by default the tip deflection in m), ``rh`` % per
    sample, ``current`` A, ``temperature`` °C.  Optional channels are ``None``.  ``meta``
    holds the sidecar metadata, ``source`` the file read from (or the record's label),
    ``rate_hz`` the sampling rate the time base was made from, kept exactly (``None``: the
    rate follows from ``time``).  Construction validates lengths and values (same rules as
    the file reader); :meth:`prechecked` holds channels a caller has already checked.
    """
    time: np.ndarray
    voltage: np.ndarray
    deflection: np.ndarray | None = None
    rh: np.ndarray | None = None
    current: np.ndarray | None = None
    temperature: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    source: str | None = None
    output: OutputQuantity = DEFLECTION
    rate_hz: float | None = None

    def __post_init__(self):
        where = self.source or "time series"
        arrays = {}
        for name in ("time",) + CHANNELS:
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=float)
            if arr.ndim != 1:
                raise InputError(f"{where}: {name} must be a 1-D array, got shape {arr.shape}")
            arrays[name] = arr
        if arrays["time"].size < 2:
            raise InputError(f"{where}: needs at least 2 samples, got {arrays['time'].size}")
        for name, arr in arrays.items():
            if arr.size != arrays["time"].size:
                raise InputError(f"{where}: {name} has {arr.size} samples but time has "
                                 f"{arrays['time'].size}")
        check_record(arrays, where, lambda i: f"sample {i}")
        for name, arr in arrays.items():
            setattr(self, name, arr)
        if self.rate_hz is not None:
            from_time = (self.n - 1) / float(self.time[-1] - self.time[0])
            if not abs(float(self.rate_hz) - from_time) <= UNIFORM_RTOL * from_time:
                raise InputError(f"{where}: rate_hz {self.rate_hz!r} Hz does not match its time column "
                                 f"({from_time:.6g} Hz)")
            self.rate_hz = float(self.rate_hz)

    @classmethod
    def prechecked(cls, voltage: np.ndarray, fs: float, *, time: np.ndarray | None = None,
                   **values) -> "TimeSeries":
        """A record at the rate ``fs`` (Hz, kept exactly as :attr:`rate_hz`) holding channels
        its caller has already checked — 1-D float arrays of one length (one sample or more),
        finite, RH within 0–100 %, ``fs`` positive — as they are: nothing is copied or
        checked again.  ``time`` defaults to ``i / fs``; ``values`` are other fields
        (``deflection``, ``rh``, ``source``, ``meta``, ``output``, …).

        For views that check their inputs with messages of their own
        (:class:`nnmodel.data.Experiment`); a record from anything else goes through the
        constructor, which checks it.  The plausibility of the output (a tip deflection
        within ±1 m) is a rule of the file readers and applies to neither."""
        names = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise TypeError(f"TimeSeries has no field {', '.join(unknown)}")
        ts = object.__new__(cls)
        for f in fields(cls):
            setattr(ts, f.name, f.default_factory() if f.default_factory is not MISSING else f.default)
        for name, value in values.items():
            setattr(ts, name, value)
        ts.voltage, ts.rate_hz = voltage, float(fs)
        ts.time = np.arange(voltage.shape[0]) / ts.rate_hz if time is None else time
        return ts

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.time.size)

    @property
    def fs(self) -> float:
        """Sampling frequency (Hz): :attr:`rate_hz` when the record was made at a given rate,
        else from the mean step."""
        if self.rate_hz is not None:
            return self.rate_hz
        return (self.n - 1) / float(self.time[-1] - self.time[0])

    @property
    def duration(self) -> float:
        """Record length n/fs (s): the span covered by n sample periods."""
        return self.n / self.fs

    def slice(self, i0: int, i1: int) -> "TimeSeries":
        """Samples ``i0:i1`` of every channel as an independent record."""
        return self._map(lambda a: a[i0:i1].copy())

    def copy(self) -> "TimeSeries":
        """Deep copy (arrays and metadata)."""
        return self._map(np.copy)

    def _map(self, fn) -> "TimeSeries":
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        for name in ("time",) + CHANNELS:
            if kw[name] is not None:
                kw[name] = fn(kw[name])
        kw["meta"] = copy.deepcopy(self.meta)
        return TimeSeries(**kw)


def check_record(arrays: dict[str, np.ndarray], where: str, locate: Locate,
                 labels: Mapping[str, str] | None = None, *,
                 resample: bool = False) -> tuple[dict[str, np.ndarray], dict | None]:
    """Validate the channels of a record (stored units) and return them, resampled if
    asked for and needed, with the resampling record (or ``None``).

    ``where`` names the file, ``locate(i)`` the position of sample ``i``, ``labels`` the
    column of each quantity (default: the quantity name).
    """
    label = {name: name for name in arrays} | dict(labels or {})
    for name, arr in arrays.items():
        check_finite(arr, where, locate, label[name])
    t = arrays["time"]
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = bad[0] + 1
        raise InputError(f"{where}, {locate(i)}, {label['time']}: {float(t[i])!r} s is not after the previous "
                         f"{float(t[i - 1])!r} s; time must be strictly increasing")
    if "rh" in arrays:
        check_range(arrays["rh"], 0.0, 100.0, where, locate, label["rh"], "% (relative humidity)")
    step = float(np.median(dt))
    lo, hi = FS_RANGE_HZ
    if not lo <= 1.0 / step <= hi:
        raise InputError(f"{where}, {label['time']}: time step {step!r} s is a sampling rate of {1.0 / step:.3g} Hz, "
                         f"outside {lo:g}–{hi:g} Hz; check the time column's unit (s or ms) or {arg('fs_Hz', 'fs')}")
    dev = dt - step                      # |dt − step| / step, in place (long records: one array)
    np.abs(dev, out=dev)
    dev /= step
    bad = np.flatnonzero(dev > UNIFORM_RTOL)
    if not bad.size:
        return arrays, None
    if not resample:
        i = bad[0] + 1
        raise InputError(f"{where}, {locate(i)}, {label['time']}: step {float(dt[i - 1])!r} s differs from the "
                         f"median step {step!r} s by {100 * dev[i - 1]:.3g} % (more than "
                         f"{100 * UNIFORM_RTOL:g} %); sampling must be uniform, or pass {arg('resample')} "
                         "to interpolate onto the median step")
    new_t = t[0] + step * np.arange(int(np.floor((t[-1] - t[0]) / step * (1 + 1e-12))) + 1)
    out = {name: np.interp(new_t, t, arr) for name, arr in arrays.items()}
    out["time"] = new_t
    info = {"method": "linear interpolation onto the median step", "step_s": step,
            "samples_before": int(t.size), "samples_after": int(new_t.size),
            "max_step_deviation": float(dev.max())}
    return out, info


def check_finite(arr: np.ndarray, where: str, locate: Locate, name: str) -> None:
    """Raise naming the first NaN or infinite value of ``arr``."""
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise InputError(f"{where}, {locate(bad[0])}, {name}: value {float(arr[bad[0]])!r} is not "
                         "finite; expected a finite number")


def check_range(arr: np.ndarray, lo: float, hi: float, where: str, locate: Locate,
                name: str, unit: str) -> None:
    """Raise naming the first value of ``arr`` outside ``[lo, hi]``."""
    bad = np.flatnonzero((arr < lo) | (arr > hi))
    if bad.size:
        raise InputError(f"{where}, {locate(bad[0])}, {name}: value {float(arr[bad[0]])!r} is "
                         f"outside {lo:g}–{hi:g} {unit}")

