"""Measurement input: time series and FRF files, record names, RH levels and the RH given to a model."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import InputError, arg
from ..io.frfdata import FRFData, read_frf
from ..io.csvtable import csv_header
from ..io.record import DEFLECTION
from ..io.timeseries import TimeSeries, read_timeseries

#: the shortest time record a model is compared with [samples]: an FRF estimate and time
#: metrics over a few periods
MIN_SAMPLES = 32


def is_frf_file(path) -> bool:
    """True when a CSV's header has a ``freq_Hz`` column (a frequency-response file)."""
    p = Path(path)
    if p.suffix.lower() != ".csv" or not p.is_file():
        return False
    return "freq_hz" in [h.lower() for h in csv_header(p)]


def load_measurements(items: Iterable, *, rh: float | None = None, columns: dict | None = None,
                      fs: float | None = None, resample: bool = False, output=None,
                      gain: str | None = None) -> list[TimeSeries | FRFData]:
    """Measurements from paths (time-series ``.csv``/``.mat`` or FRF ``.csv``, told apart by
    the ``freq_Hz`` column) or ready :class:`TimeSeries`/:class:`FRFData` objects, checked by
    :func:`check_measurements` against the output a model predicts.

    ``rh`` [%] for records without RH; ``columns``/``fs``/``output``/``gain`` as in
    :func:`physics.io.timeseries.read_timeseries` (time series only); ``output``: what the
    model predicts (an :class:`~physics.io.record.OutputQuantity`; default the tip deflection in m)."""
    if fs is not None and not fs > 0:
        raise InputError(f"{arg('fs_Hz', 'fs')} {fs!r}: the sampling rate must be a positive number of Hz")
    out: list[TimeSeries | FRFData] = []
    for item in items:
        if isinstance(item, (TimeSeries, FRFData)):
            out.append(item)
            continue
        if not isinstance(item, (str, Path)):
            raise InputError(f"measurement {item!r}: expected a file path, a TimeSeries or an FRFData")
        if not Path(item).exists():
            raise InputError(f"measurement file {item} not found")
        if is_frf_file(item):
            frf = read_frf(item)
            if frf.rh is None and rh is not None:
                frf = replace(frf, rh=float(rh))
            out.append(frf)
        else:
            out.append(read_timeseries(item, columns=columns, fs=fs, rh=rh, resample=resample,
                                       output=None if output is None or output.is_deflection else output, gain=gain))
    if not out:
        raise InputError("no measurement given: pass at least one time-series or FRF file")
    check_measurements(out, output or DEFLECTION)
    return out


def check_measurements(ms: Sequence, output=None) -> None:
    """Refuse time records a model cannot be compared with: fewer than :data:`MIN_SAMPLES`
    samples, a constant output, an output other than ``output`` (what the model predicts;
    ``None``: not checked), a sidecar geometry (it would be silently ignored).  Run by
    :func:`load_measurements` and by :func:`~physics.compare.compare` on what it is given."""
    for k, m in enumerate(ms):
        if not isinstance(m, TimeSeries):
            continue
        where = source_name(m, k)
        if m.n < MIN_SAMPLES:
            raise InputError(f"{where}: {m.n} samples; comparing a model with a record needs at least "
                             f"{MIN_SAMPLES} (an FRF estimate and time metrics over a few periods)")
        if output is not None and m.output != output:
            raise InputError(f"{where}: the measured output is {m.output.label()} but the model predicts "
                             f"{output.label()}" + (f" — give {arg('sensor_gain', 'gain')} (e.g. 2.5mm/V) to "
                                                    "convert it to metres" if output.is_deflection else ""))
        if m.deflection is not None and np.ptp(m.deflection) == 0:
            raise InputError(f"{where}: the measured {m.output.name} is constant ({float(m.deflection[0]):g}); "
                             f"there is nothing to compare — check the column ({arg('columns')}) or the record")
        if isinstance(m.meta, dict) and "geometry" in m.meta:
            raise InputError(f"{Path(where).with_suffix('.yaml')}: geometry: the sidecar's geometry is not "
                             "applied to the model (it would be silently ignored); put it in a device YAML (copy "
                             "configs/devices/*.yaml, edit geometry:) and give that file as the model's device, "
                             "then remove the geometry block from the sidecar")


def source_name(m, k: int) -> str:
    """The file a measurement came from, or ``record k`` for one built in memory."""
    return str(m.source) if getattr(m, "source", None) else f"record {k}"


def mean_rh(m, where: str) -> float:
    """Mean RH [%] of a record (an FRF without RH is an error naming it)."""
    rh = m.rh
    if rh is None:
        raise InputError(f"{where}: no relative humidity; add an rh_pct column or give the RH with {arg('rh')}")
    return float(np.mean(rh))


def cluster_rh(values: Sequence[float], tolerance: float = 1.0) -> list[float]:
    """Group RH values [%] into humidity levels and label each by its nominal value.

    Sorted values closer than ``tolerance`` [%] (a hygrometer's tolerance) to the previous
    one join its group; a group is labelled by its mean rounded to whole percent (to 0.1 %
    when ``tolerance`` is below 0.5 %, or when whole percents would merge two groups), so
    that 59.7 % and 60.2 % are "60 %", never 59.95 or 60.0003.  Returns the label of each
    input value; the value a model is evaluated at stays each record's own RH."""
    vals = np.asarray(values, dtype=float)
    order = np.argsort(vals)
    groups: list[list[int]] = []
    for i in order:
        if groups and vals[i] - vals[groups[-1][-1]] <= tolerance:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    means = [float(np.mean(vals[g])) for g in groups]
    step = 1.0 if tolerance >= 0.5 else 0.1
    labels = [round(m / step) * step for m in means]
    if len(set(labels)) < len(labels):
        labels = [round(m, 1) for m in means]
    level = np.empty(vals.size)
    for g, lab in zip(groups, labels):
        level[g] = round(lab, 1)
    return level.tolist()


def model_rh(rh: np.ndarray, fs: float, tolerance: float = 2.5, window_s: float = 10.0,
             step: float = 0.5):
    """The RH [%] given to a model for a record's RH channel.

    A hygrometer's jitter is not a humidity change, and a time solver would restart its
    mechanics at every new RH value: the channel is smoothed by a moving mean over
    ``window_s`` [s]; when the smoothed RH spans no more than ``tolerance`` [%] the record's
    median is used (robust to a sensor clipped at 100 %), otherwise the smoothed series
    rounded to ``step`` [%] (RH changes slowly compared with the mechanics)."""
    rh = np.asarray(rh, dtype=float)
    if not np.all(np.isfinite(rh)):           # a running sum would carry one gap to the record's end
        raise InputError(f"the RH channel has {int(np.sum(~np.isfinite(rh)))} non-finite value(s); "
                         "give finite RH values in % (fill or cut the gaps)")
    if rh.size and rh.min() == rh.max():      # one value (a constant channel): no smoothing to do
        return float(rh[0])
    n = min(max(1, int(round(window_s * fs))), rh.size)
    pad = n // 2
    ref = float(rh[0])                        # running sums of the departures stay small
    c = np.concatenate([[0.0], np.cumsum(np.pad(rh - ref, (pad, n - 1 - pad), mode="edge"))])
    smooth = ref + (c[n:] - c[:-n]) / n       # the centred moving mean, O(len) whatever the window
    if np.ptp(smooth) <= tolerance:
        return float(np.median(rh))
    return np.clip(np.round(smooth / step) * step, 0.0, 100.0)
