"""Experiments (input voltage, humidity, output) and training windows.

An :class:`Experiment` is the networks' view of one uniformly sampled record (a
:class:`physics.io.record.TimeSeries`, which it holds) in physical units: input voltage
``u`` (V), measured output ``y`` (tip deflection, m, or the dataset's output; ``None`` for an
input-only record), relative humidity ``rh`` (% per sample, or ``None`` when the model does
not use humidity) and the sampling rate ``fs`` (Hz).  Records slice like arrays
(``rec[100:200]``) as in deepSI, so splitting data never loses the sampling rate or the
humidity.

The window helpers cut records into the short sequences the models are trained on: each
window is ``n_init`` samples of measured history (used only to initialise the model state)
followed by ``horizon`` samples over which the model is simulated and scored.
"""
from __future__ import annotations

import copy
from typing import Iterable, Sequence

import numpy as np

from physics.errors import InputError
from physics.io.record import CHANNELS, TimeSeries, check_finite, check_range
# One definition of the fit metrics for the whole package (NRMSE = RMSE / std(y), fit % =
# 100 (1 - NRMSE)): physics.analysis.metrics, re-exported here for the neural-model code.
from physics.analysis.metrics import fit_percent, nrmse, rmse

__all__ = ["Experiment", "check_prediction_inputs", "check_records", "split_index", "split_records", "window_starts", "cut_windows",
           "rh_range", "rmse", "nrmse", "fit_percent"]


def check_fs(fs, where: str = "") -> float:
    """A sampling rate in Hz as a positive float, or an InputError naming ``where``."""
    pre = f"{where}: " if where else ""
    try:
        fs = float(fs)
    except (TypeError, ValueError):
        raise InputError(f"{pre}fs must be a number in Hz, got {fs!r}") from None
    if not np.isfinite(fs) or fs <= 0:
        raise InputError(f"{pre}fs must be a positive number of Hz, got {fs}")
    return fs


def _where(name: str) -> str:
    return f"record {name!r}"


def _sample(i: int) -> str:
    return f"sample {i}"


def check_voltage(u, where: str = "voltage") -> np.ndarray:
    """A voltage record (V) as a non-empty, finite 1-D float array, or an InputError."""
    u = np.asarray(u, dtype=float)
    if u.ndim != 1 or u.size == 0:
        raise InputError(f"{where} must be a non-empty 1-D array, got shape {u.shape}")
    check_finite(u, where, _sample, "voltage")
    return u


def _as_1d(x, what: str, name: str, n: int | None = None) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim != 1:
        raise InputError(f"record {name!r}: {what} must be a 1-D array, got shape {a.shape}")
    if n is not None and a.shape[0] != n:
        raise InputError(f"record {name!r}: {what} has {a.shape[0]} samples but the voltage has {n}")
    check_finite(a, _where(name), _sample, what)
    return a


def check_rh(rh, n: int, where: str) -> np.ndarray:
    """Relative humidity (%) as one finite value in 0-100 per sample (a constant is
    broadcast to ``n`` samples: a read-only view, not ``n`` copies), or an InputError
    naming ``where``."""
    rh = np.asarray(rh, dtype=float)
    if rh.ndim == 0:      # one value for every sample, stored once (a read-only view)
        rh = np.broadcast_to(float(rh), (n,))
    if rh.shape != (n,):
        raise InputError(f"{where}: rh must be a constant or have one value per voltage sample "
                         f"({n}), got shape {rh.shape}")
    check_finite(rh, where, _sample, "relative humidity rh")
    check_range(rh, 0.0, 100.0, where, _sample, "relative humidity rh", "% (relative humidity)")
    return rh


class Experiment:
    """The networks' view of one uniformly sampled record, in physical units: input ``u``,
    output ``y``, humidity ``rh``, rate ``fs``, label ``name``.  The record itself is a
    :class:`physics.io.record.TimeSeries`, held as :attr:`ts`; the view stores nothing else
    (``u`` is its ``voltage``, ``y`` its ``deflection`` — the output, whatever its quantity —
    ``name`` its ``source``).

    Parameters
    ----------
    u : array (n,)
        Input voltage in V.
    y : array (n,) or None
        Measured output (tip deflection in m, or the dataset's output quantity: no
        plausibility rule of a deflection applies); ``None`` for an input-only record.
    rh : float, array (n,) or None
        Relative humidity in %: a constant is broadcast to every sample.  ``None`` means the
        record carries no humidity (a model trained on such records ignores humidity).
    fs : float
        Sampling rate in Hz (required; kept exactly).
    name : str
        Free label used in messages and reports.

    Values are checked with the rules of the file readers (:mod:`physics.io.timeseries`:
    finite numbers, RH within 0-100 %); the arrays are held without copying (time
    ``i / fs``).  :meth:`from_timeseries` makes the view of a record that exists already.
    """

    __slots__ = ("ts",)

    def __init__(self, u, y=None, rh=None, fs: float | None = None, name: str = ""):
        name = str(name)
        if fs is None:
            raise InputError(f"record {name!r}: the sampling rate fs (Hz) is required")
        fs = check_fs(fs, f"record {name!r}")
        u = _as_1d(u, "voltage u", name)
        n = u.shape[0]
        if n == 0:
            raise InputError(f"record {name!r}: empty record (no samples)")
        y = None if y is None else _as_1d(y, "output y", name, n)
        rh = None if rh is None else check_rh(rh, n, _where(name))
        self.ts = TimeSeries.prechecked(u, fs, deflection=y, rh=rh, source=name or None)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_timeseries(cls, ts, name: str | None = None) -> "Experiment":
        """The view of a record: a :class:`physics.io.record.TimeSeries` is held as it is (not
        copied; given a ``name`` other than its ``source``, a shallow copy labelled so, which
        shares its arrays).  Any other object with attributes ``voltage``, ``deflection`` (may
        be ``None``), ``rh`` (scalar, array or ``None``) and ``fs`` (duck-typed) is checked
        and held as a new record."""
        if isinstance(ts, TimeSeries):
            if name is not None and str(name) != (ts.source or ""):
                ts = copy.copy(ts)
                ts.source = str(name) or None
            return cls._of(ts)
        for attr in ("voltage", "fs"):
            if not hasattr(ts, attr):
                raise InputError(f"{type(ts).__name__} has no attribute {attr!r}; expected a time "
                                 "series with time, voltage, deflection, rh and fs")
        if name is None:
            name = str(getattr(ts, "name", "") or getattr(ts, "source", "") or "")
        return cls(ts.voltage, getattr(ts, "deflection", None), getattr(ts, "rh", None),
                   ts.fs, name)

    @classmethod
    def _of(cls, ts) -> "Experiment":
        """The view of ``ts`` as it is (no check, no copy)."""
        view = object.__new__(cls)
        view.ts = ts
        return view

    # ------------------------------------------------------------------ the record's channels
    @property
    def u(self) -> np.ndarray:
        """Input voltage (V), shape (n,)."""
        return self.ts.voltage

    @property
    def y(self) -> np.ndarray | None:
        """Measured output, shape (n,), or None for an input-only record."""
        return self.ts.deflection

    @property
    def rh(self) -> np.ndarray | None:
        """Relative humidity (%) per sample, or None."""
        return self.ts.rh

    @property
    def fs(self) -> float:
        """Sampling rate (Hz)."""
        return self.ts.fs

    @property
    def name(self) -> str:
        """Label used in messages and reports."""
        return self.ts.source or ""

    # ------------------------------------------------------------------ array-like behaviour
    def __len__(self) -> int:
        return int(self.ts.voltage.shape[0])

    def __getitem__(self, item) -> "Experiment":
        if not isinstance(item, slice):
            raise TypeError("records slice only with a slice, e.g. rec[100:200]")
        if item.step not in (None, 1):
            raise InputError("slicing a record with a step would change its sampling rate; "
                             "resample explicitly instead")
        ts = self.ts
        cut = {c: a[item] for c in ("time",) + CHANNELS if (a := getattr(ts, c)) is not None}
        if cut["voltage"].shape[0] == 0:
            raise InputError(f"record {self.name!r}: empty record (no samples)")
        return Experiment._of(TimeSeries.prechecked(cut.pop("voltage"), self.fs, **cut, meta=ts.meta,
                                                    source=ts.source, output=ts.output))

    def __repr__(self) -> str:
        rh = "no RH" if self.rh is None else f"RH {self.rh.min():g}-{self.rh.max():g} %"
        return (f"Experiment({self.name!r}, {len(self)} samples at {self.fs:g} Hz, "
                f"{'with' if self.y is not None else 'no'} output, {rh})")

    @property
    def time(self) -> np.ndarray:
        """Sample times in s, starting at 0."""
        return np.arange(len(self)) / self.fs

    @property
    def duration(self) -> float:
        return len(self) / self.fs

    def to_timeseries(self):
        """The record this view holds (:attr:`ts`, a :class:`physics.io.record.TimeSeries`;
        ``y`` is its ``deflection``, its output)."""
        return self.ts

    def split(self, fraction: float) -> tuple["Experiment", "Experiment"]:
        """Split at ``fraction`` of the length: ``(first part, last part)``."""
        k = int(round(len(self) * float(fraction)))
        return self[:k], self[k:]


def check_prediction_inputs(u, rh, y, y_name: str, rh_trained: tuple | None):
    """Inputs of a prediction in physical units as arrays ``(u, rh or None, y or None)``.

    ``rh_trained``: the RH range (%) seen in training by a model that takes humidity (it
    then needs ``rh``, and warns outside that range), None for a model without humidity
    (``rh`` is then ignored with a warning)."""
    import warnings

    u = check_voltage(u)
    n = u.size
    if rh_trained is not None:
        lo, hi = rh_trained
        if rh is None:
            raise InputError(f"this model takes relative humidity as an input (trained on "
                             f"{lo:g}-{hi:g} %RH); pass rh= (a constant or one value per sample)")
        rh = check_rh(rh, n, "prediction input")
        tol = 1e-9 * max(1.0, hi)
        if rh.min() < lo - tol or rh.max() > hi + tol:
            warnings.warn(f"relative humidity {rh.min():g}-{rh.max():g} % is outside the range "
                          f"seen in training ({lo:g}-{hi:g} %RH): the model extrapolates and "
                          "its predictions are not validated there", RuntimeWarning, stacklevel=4)
    elif rh is not None:
        warnings.warn("this model was trained without humidity; the rh argument is ignored",
                      RuntimeWarning, stacklevel=4)
        rh = None
    if y is not None:
        y = np.asarray(y, dtype=float)
        if y.ndim != 1:
            raise InputError(f"{y_name} must be a 1-D array, got shape {y.shape}")
        check_finite(y, "prediction input", _sample, y_name)
    return u, rh, y

# ---------------------------------------------------------------------- record lists
def check_records(records: Sequence[Experiment | TimeSeries] | Experiment | TimeSeries,
                  what: str = "training", need_y: bool = True) -> list[Experiment]:
    """Validate a list of records for fitting: same sampling rate, outputs present and
    humidity either on every record or on none.  Returns the list as views (a
    :class:`~physics.io.record.TimeSeries` given becomes :meth:`Experiment.from_timeseries`)."""
    if isinstance(records, (Experiment, TimeSeries)):
        records = [records]
    records = [Experiment.from_timeseries(r) if isinstance(r, TimeSeries) else r for r in records or []]
    if not records:
        raise InputError(f"no {what} records given")
    for r in records:
        if not isinstance(r, Experiment):
            raise InputError(f"{what} data must be nnmodel.data.Experiment objects, got {type(r).__name__}")
        if need_y and r.y is None:
            raise InputError(f"{what} record {r.name!r} has no measured output y")
    fs = records[0].fs
    for r in records[1:]:
        if abs(r.fs - fs) > 1e-9 * fs:
            raise InputError(f"{what} records have different sampling rates ({fs:g} Hz and "
                             f"{r.fs:g} Hz in {r.name!r}); resample them to one rate first")
    has_rh = {r.rh is not None for r in records}
    if len(has_rh) > 1:
        raise InputError(f"some {what} records carry relative humidity and some do not; "
                         "give RH for every record or for none")
    return records


def rh_range(records: Iterable[Experiment]) -> tuple[float, float] | None:
    """(min, max) RH over records, or None if they carry no humidity."""
    vals = [(r.rh.min(), r.rh.max()) for r in records if r.rh is not None]
    if not vals:
        return None
    return float(min(v[0] for v in vals)), float(max(v[1] for v in vals))


def split_index(n: int, val_fraction: float, min_len: int = 1) -> int | None:
    """Where a record of ``n`` samples is cut to hold out its last ``val_fraction`` for
    validation, or None when either part would be shorter than ``min_len``."""
    if not 0 <= val_fraction < 1:
        raise InputError(f"val_fraction must be in [0, 1), got {val_fraction}")
    k = int(round(n * (1 - val_fraction)))
    if val_fraction > 0 and n - k >= min_len and k >= min_len:
        return k
    return None


def split_records(records: Sequence[Experiment], val_fraction: float,
                  min_len: int = 1) -> tuple[list[Experiment], list[Experiment]]:
    """Hold out the last ``val_fraction`` of every record (at least ``min_len`` samples on
    each side) for validation.  Records too short to split stay in training."""
    train, val = [], []
    for r in records:
        k = split_index(len(r), val_fraction, min_len)
        if k is not None:
            train.append(r[:k])
            val.append(r[k:])
        else:
            train.append(r)
    return train, val


# ---------------------------------------------------------------------- windows
def window_starts(n: int, length: int, stride: int) -> np.ndarray:
    """Start indices of windows of ``length`` samples every ``stride`` samples in a
    sequence of ``n`` samples; the last window ends exactly at ``n`` when possible."""
    if length > n:
        return np.zeros(0, dtype=np.int64)
    stride = max(1, int(stride))
    starts = np.arange(0, n - length + 1, stride, dtype=np.int64)
    if starts[-1] != n - length:
        starts = np.append(starts, n - length)
    return starts


def cut_windows(records: Sequence[Experiment], n_init: int, horizon: int, stride: int) -> dict:
    """Cut records into windows of ``n_init`` history + ``horizon`` simulated samples.

    Returns a dict of arrays of shape (n_windows, n_init + horizon): ``u``, ``y`` and, if
    the records carry humidity, ``rh``.
    """
    L = n_init + horizon
    out = {"u": [], "y": [], "rh": []}
    for r in records:
        starts = window_starts(len(r), L, stride)
        if starts.size == 0:
            continue
        idx = starts[:, None] + np.arange(L)[None, :]
        out["u"].append(r.u[idx])
        out["y"].append(r.y[idx])
        if r.rh is not None:
            out["rh"].append(r.rh[idx])
    if not out["u"]:
        raise InputError(f"every record is shorter than one training window ({L} samples)")
    res = {k: np.concatenate(v) for k, v in out.items() if v}
    return res
