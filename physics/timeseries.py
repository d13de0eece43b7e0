"""Time-series records: one experiment (voltage in, tip deflection out) per file.

File format (``DATA_FORMAT.md``): a CSV with one row per sample and columns named
``quantity_unit``:

==============  ==================  ==================================
column          quantity            accepted units (stored as)
==============  ==================  ==================================
``time_*``      time                ``s``, ``ms``           (s)
``voltage_*``   applied voltage     ``V``, ``mV``           (V)
``deflection_*`` tip deflection     ``m``, ``mm``, ``um``   (m)
``rh_*``        relative humidity   ``pct``                 (%)
``current_*``   absorbed current    ``A``, ``mA``           (A)
``temperature_*`` ambient temp.     ``C``, ``K``            (°C)
==============  ==================  ==================================

Rules applied by :func:`read_timeseries` (every violation is an
:class:`~physics.errors.InputError` naming the file, the line or column and what was
expected):

* ``time``, ``voltage`` and (unless ``require_deflection=False``) ``deflection`` are
  required; a file without a time column needs ``fs=``.  Unknown columns are errors; a
  nameless, completely empty column (a trailing comma on every line) is ignored.
* Every value must be a finite number.  Time must be strictly increasing and uniform:
  each step may differ from the median step by at most :data:`UNIFORM_RTOL` (timestamps
  printed with few digits), otherwise the file is rejected unless ``resample=True``,
  which interpolates every channel linearly onto the median step and records it in
  ``meta["resampled"]``.
* Relative humidity comes, in this order of precedence, from an explicit ``rh=`` (always
  wins), the ``rh_pct`` column, or the key ``rh_pct`` of the sidecar; with none of them
  the file is rejected (never a silent default).  RH must lie within 0–100 %.
* Arbitrary files (e.g. public benchmarks with columns ``V1``, ``V2``) are read through an
  explicit column map ``{"voltage": "V1", "deflection": "V2"}`` whose columns hold values
  in the stored units above; only mapped columns are read, others are ignored.
* ``.mat`` files are read with :func:`scipy.io.loadmat`: variables named like the CSV
  columns, or through the column map; each must be a numeric vector.
* An optional sidecar ``NAME.yaml`` next to ``NAME.csv``/``NAME.mat`` (a YAML mapping:
  device, geometry, RH, excitation, sensor, provenance...) is read into ``meta``.

The table and sidecar helpers here are shared with :mod:`physics.frfdata`.
"""
from __future__ import annotations

import copy
import csv
import os
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable, Mapping

import numpy as np
import pandas as pd
import scipy.io
import yaml

from .errors import InputError
from .fileio import atomic_path
from .yamlio import load_yaml

#: Largest accepted deviation of a time step from the median step, relative to it.
UNIFORM_RTOL = 1e-2

#: quantity -> {unit: (scale, offset)}; stored value = scale * file value + offset.
TIMESERIES_UNITS: dict[str, dict[str, tuple[float, float]]] = {
    "time": {"s": (1.0, 0.0), "ms": (1e-3, 0.0)},
    "voltage": {"V": (1.0, 0.0), "mV": (1e-3, 0.0)},
    "deflection": {"m": (1.0, 0.0), "mm": (1e-3, 0.0), "um": (1e-6, 0.0)},
    "rh": {"pct": (1.0, 0.0)},
    "current": {"A": (1.0, 0.0), "mA": (1e-3, 0.0)},
    "temperature": {"C": (1.0, 0.0), "K": (1.0, -273.15)},
}
#: Unit each quantity is stored (and by default written) in.
STORED_UNITS = {"time": "s", "voltage": "V", "deflection": "m", "rh": "pct",
                "current": "A", "temperature": "C"}
CHANNELS = ("voltage", "deflection", "rh", "current", "temperature")
#: Plausible ranges (stored units) of columns named ``quantity_unit``: a value outside is
#: a unit or export error (a tip deflection of 1e300 m, a drive of 1 MV), not a measurement.
PLAUSIBLE = {"deflection": (-1.0, 1.0, "m (tip deflection of a strip)"),
             "voltage": (-1e3, 1e3, "V (drive voltage)"),
             "current": (-1e3, 1e3, "A (absorbed current)"),
             "temperature": (-273.15, 1e3, "°C (ambient temperature)")}
#: Magnitude bound of column-mapped values (arbitrary plants, any unit): beyond it squares
#: and sums overflow and every metric is meaningless.
MAPPED_LIMIT = 1e15
Locate = Callable[[int], str]


# --------------------------------------------------------------------------- records

@dataclass
class TimeSeries:
    """One uniformly sampled experiment.

    Units: ``time`` s (uniform, strictly increasing), ``voltage`` V, ``deflection`` m
    (tip), ``rh`` % per sample, ``current`` A, ``temperature`` °C.  Optional channels are
    ``None``.  ``meta`` holds the sidecar metadata, ``source`` the file read from.
    Construction validates lengths and values (same rules as the file reader).
    """
    time: np.ndarray
    voltage: np.ndarray
    deflection: np.ndarray | None = None
    rh: np.ndarray | None = None
    current: np.ndarray | None = None
    temperature: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    source: str | None = None

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

    @property
    def n(self) -> int:
        """Number of samples."""
        return int(self.time.size)

    @property
    def fs(self) -> float:
        """Sampling frequency (Hz) from the mean step."""
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
    dev = np.abs(dt - step) / step
    bad = np.flatnonzero(dev > UNIFORM_RTOL)
    if not bad.size:
        return arrays, None
    if not resample:
        i = bad[0] + 1
        raise InputError(f"{where}, {locate(i)}, {label['time']}: step {float(dt[i - 1])!r} s differs from the "
                         f"median step {step!r} s by {100 * dev[i - 1]:.3g} % (more than "
                         f"{100 * UNIFORM_RTOL:g} %); sampling must be uniform, or pass --resample "
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


# --------------------------------------------------------------------------- tables

@dataclass
class Table:
    """Columns of a CSV or .mat file before unit conversion.

    ``columns`` maps each name (file order) to its raw values (CSV: text; .mat: array),
    ``locate(i)`` names the line (CSV) or element (.mat) of value ``i``.
    """
    path: Path
    columns: dict[str, np.ndarray]
    locate: Locate

    def floats(self, name: str, label: str | None = None) -> np.ndarray:
        """Column ``name`` as finite floats; errors name line/element and column."""
        raw = self.columns[name]
        label = label or f"column {name!r}"
        if raw.dtype.kind in "biuf":
            values = raw.astype(float, copy=False)
        else:
            values = pd.to_numeric(pd.Series(raw), errors="coerce").to_numpy(dtype=float)
            i = next((i for i in np.flatnonzero(np.isnan(values))
                      if raw[i].strip().lower() != "nan"), None)
            if i is not None:
                text = raw[i].strip()
                what = "empty cell" if not text else f"{text!r} is not a number"
                raise InputError(f"{self.path}, {self.locate(i)}, column {name!r}: {what}; "
                                 "expected a finite number")
        check_finite(values, str(self.path), self.locate, label)
        return values


def check_input_path(path, suffixes: tuple[str, ...]) -> Path:
    """``path`` as a :class:`Path` after checking that it is an existing file with one of
    ``suffixes`` (lower case, with the dot)."""
    p = Path(path)
    if p.suffix.lower() not in suffixes:
        raise InputError(f"{p}: unsupported file type {p.suffix or '(no extension)'!r}; "
                         f"expected {' or '.join(suffixes)}")
    if not p.is_file():
        raise InputError(f"{p}: file not found")
    return p


#: Field separators recognised in a CSV header line, in order of preference.
DELIMITERS = (",", ";", "\t", "|")
#: Encodings tried in turn: UTF-8 (with or without BOM), then Latin-1 (never fails).
ENCODINGS = ("utf-8-sig", "latin-1")


def sniff_dialect(path: Path) -> tuple[str, str, str]:
    """(encoding, delimiter, decimal mark) of a CSV from its first 64 kB.

    The delimiter is the separator most frequent in the header line (comma, semicolon,
    tab, bar; runs of blanks if none); a decimal comma is recognised when the separator
    is not a comma and data cells look like ``1,5``.
    """
    with path.open("rb") as fh:
        head = fh.read(1 << 16)
    if b"\x00" in head or re.search(rb"[\x01-\x08\x0e-\x1a]", head):
        raise InputError(f"{path}: not a UTF-8 text file (binary content); expected a CSV")
    try:
        text, encoding = head.decode("utf-8-sig"), "utf-8-sig"
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 4:  # not merely a multi-byte character cut at the chunk end
            text, encoding = head.decode("latin-1"), "latin-1"
        else:
            text, encoding = head[:exc.start].decode("utf-8-sig"), "utf-8-sig"
    lines = text.splitlines()
    header = lines[0] if lines else ""
    counts = {d: header.count(d) for d in DELIMITERS}
    delim = max(DELIMITERS, key=lambda d: counts[d]) if any(counts.values()) else \
        (r"\s+" if len(header.split()) > 1 else ",")
    decimal = "."
    if delim != ",":
        body = "\n".join(lines[1:50])
        if re.search(r"\d,\d", body) and not re.search(r"\d\.\d", body):
            decimal = ","
    return encoding, delim, decimal


def csv_header(path: Path) -> list[str]:
    """Column names of a CSV's header line (dialect sniffed as by :func:`read_table`)."""
    encoding, delim, _ = sniff_dialect(path)
    with open(path, encoding=encoding, newline="") as fh:
        header_line = fh.readline()
    if delim == r"\s+":
        return header_line.split()
    return [n.strip() for n in next(csv.reader([header_line], delimiter=delim), [])]


def read_table(path: Path) -> Table:
    """Read a CSV (header line of names) or .mat file into a :class:`Table`.

    CSV dialects are sniffed (:func:`sniff_dialect`): comma, semicolon, tab or blank
    separated, decimal point or comma, UTF-8 (BOM allowed) or Latin-1, LF or CRLF.  Numeric
    files are parsed straight to floats (8 bytes per value); a file with a non-numeric,
    empty or NaN cell is re-read as text to name the line and column.
    """
    if path.suffix.lower() == ".mat":
        return _read_mat(path)
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file; expected a header line of column names "
                         "followed by data rows")
    encoding, delim, decimal = sniff_dialect(path)
    names = csv_header(path)
    if not any(names):
        raise InputError(f"{path}: empty file; expected a header line of column names "
                         "followed by data rows")
    opts = dict(sep=delim, header=None, skiprows=1, names=list(range(len(names))), decimal=decimal,
                encoding=encoding, skip_blank_lines=False, engine="c")
    try:
        try:  # in chunks: the parser's buffers stay small; peak ≈ 2 × the values
            chunks = [c.to_numpy() for c in pd.read_csv(path, dtype=float, chunksize=1 << 18, **opts)]
            values = np.concatenate(chunks) if chunks else np.empty((0, len(names)))
            del chunks
            if values.size and np.isnan(values).any():
                nonblank = np.flatnonzero(~np.isnan(values).all(axis=1))
                end = nonblank[-1] + 1 if nonblank.size else 0
                if np.isnan(values[:end]).any() or end == 0:
                    raise ValueError("NaN or empty cell")
                values = values[:end]
            raw = None
        except ValueError:
            df = pd.read_csv(path, dtype=str, keep_default_na=False, **opts)
            raw = df.to_numpy(dtype=object).copy()
    except pd.errors.EmptyDataError:
        raise InputError(f"{path}: empty file; the header is not followed by any data row") from None
    except pd.errors.ParserError as exc:
        raise InputError(f"{path}: cannot be parsed as CSV ({' '.join(str(exc).split())}); "
                         f"every line must have the {len(names)} fields of the header "
                         f"(separator {delim!r})") from None
    if raw is not None:
        raw[pd.isna(raw)] = ""
        end = raw.shape[0]
        while end and not any(str(v).strip() for v in raw[end - 1]):
            end -= 1  # drop trailing blank lines
        values = raw[:end]
        if decimal == ",":
            values = np.vectorize(lambda v: str(v).replace(",", "."), otypes=[object])(values) \
                if values.size else values
    if values.shape[0] == 0:
        raise InputError(f"{path}: empty file; the header is not followed by any data row")
    columns: dict[str, np.ndarray] = {}
    for k, name in enumerate(names):
        col = np.ascontiguousarray(values[:, k]) if raw is None else values[:, k].astype(str)
        if not name:
            if (np.isnan(col).all() if raw is None else (np.char.strip(col) == "").all()):
                continue  # trailing separator: nameless, empty column
            raise InputError(f"{path}: column {k + 1} has data but no name in the header")
        if name in columns:
            raise InputError(f"{path}: column {name!r} appears twice in the header")
        columns[name] = col
    return Table(path, columns, lambda i: f"line {i + 2}")


def _read_mat(path: Path) -> Table:
    try:
        data = scipy.io.loadmat(path)
    except NotImplementedError:
        raise InputError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; save with "
                         "-v7 or export a CSV") from None
    except Exception as exc:  # scipy raises various types for corrupt files
        raise InputError(f"{path}: cannot be read as a MATLAB file ({exc})") from None
    columns = {}
    for name, value in data.items():
        if name.startswith("__"):
            continue
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf" or arr.ndim > 2 or (arr.ndim == 2 and min(arr.shape) != 1):
            raise InputError(f"{path}: variable {name!r} must be a real numeric vector, got "
                             f"{arr.dtype} array of shape {arr.shape}")
        columns[name] = arr.ravel()
    if not columns or all(c.size == 0 for c in columns.values()):
        raise InputError(f"{path}: empty file; expected vectors named like the CSV columns")
    return Table(path, columns, lambda i: f"element {i + 1}")


def parse_header(name: str, units: Mapping[str, Mapping[str, object]],
                 where: Path) -> tuple[str, str]:
    """Split a ``quantity_unit`` column name into (quantity, unit) and check both against
    ``units`` (quantity -> accepted units; a unitless quantity maps to ``{"": ...}``)."""
    quantity, _, unit = name.partition("_")
    if quantity not in units:
        accepted = ", ".join(f"{q}_{u}" if u else q for q in units for u in units[q])
        raise InputError(f"{where}: unknown column {name!r}; expected columns named "
                         f"quantity_unit among: {accepted} (use a column map for other files)")
    if unit not in units[quantity]:
        accepted = ", ".join(u or "(none)" for u in units[quantity])
        raise InputError(f"{where}: column {name!r}: cannot parse unit {unit or '(none)'!r} of "
                         f"{quantity}; accepted units: {accepted}")
    return quantity, unit


def read_sidecar(path: Path) -> dict:
    """Metadata of the optional sidecar ``NAME.yaml`` next to ``path`` ({} if absent),
    checked by :func:`check_sidecar`."""
    side = path.with_suffix(".yaml")
    if not side.is_file():
        return {}
    meta = load_yaml(side, "sidecar")
    if meta is None:
        return {}
    if not isinstance(meta, dict):
        raise InputError(f"{side}: expected a mapping of metadata keys, got {type(meta).__name__}")
    check_sidecar(meta, side)
    return meta


_TINY = float(np.finfo(float).tiny)
#: Sidecar keys of the signal description that must be positive numbers.
_POSITIVE_SIGNAL_KEYS = ("period_s", "duration_s", "fs_Hz", "f_start_Hz", "f_stop_Hz", "frequency_Hz")


def check_sidecar(meta: dict, side: Path) -> None:
    """Check the sidecar keys the package reads (types, units, ranges); errors name the
    file and the key."""
    def number(value, key, lo=-np.inf, hi=np.inf, allow_none=False):
        if value is None and allow_none:
            return
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) \
                or not lo <= value <= hi:
            rng = " > 0" if lo == _TINY else "" if (lo, hi) == (-np.inf, np.inf) else f" within {lo:g}–{hi:g}"
            raise InputError(f"{side}: {key}: {value!r} is not valid; expected a finite number{rng}")

    if "rh_pct" in meta:
        number(meta["rh_pct"], "rh_pct", 0.0, 100.0)
    for section in ("signal", "excitation"):
        sig = meta.get(section)
        if sig is None:
            continue
        if not isinstance(sig, dict):
            raise InputError(f"{side}: {section}: expected a mapping (kind, frequencies...), got {sig!r}")
        for key in _POSITIVE_SIGNAL_KEYS:
            if key in sig:
                number(sig[key], f"{section}.{key}", _TINY)
        if "periods" in sig and (isinstance(sig["periods"], bool) or not isinstance(sig["periods"], int)
                                 or sig["periods"] < 1):
            raise InputError(f"{side}: {section}.periods: {sig['periods']!r} is not valid; expected a "
                             "whole number of periods ≥ 1")
    sensor = meta.get("sensor")
    if sensor is not None:
        if not isinstance(sensor, dict):
            raise InputError(f"{side}: sensor: expected a mapping of sensor settings, got {sensor!r}")
        from .sensor import SensorModel
        known = {f.name for f in fields(SensorModel)}
        for key in known & set(sensor):
            number(sensor[key], f"sensor.{key}", allow_none=key in ("bandwidth", "adc_bits"))
        try:
            SensorModel(**{k: sensor[k] for k in known & set(sensor)})
        except InputError as exc:
            raise InputError(f"{side}: {exc}") from None
        for key in ("noise_floor_m",):
            if key in sensor:
                number(sensor[key], f"sensor.{key}", 0.0)


def write_table(columns: dict[str, np.ndarray], meta: dict, path, *, overwrite: bool,
                protect) -> Path:
    """Atomically write ``columns`` as CSV (shortest round-trip float repr) to ``path``
    (``.csv``) and ``meta`` to the sidecar ``NAME.yaml`` (removing a stale sidecar when
    ``meta`` is empty).  Inputs in ``protect`` (and their sidecars) are never targets."""
    target = Path(path)
    if target.suffix.lower() != ".csv":
        raise InputError(f"{target}: output must be a .csv file")
    side = target.with_suffix(".yaml")
    protect = tuple(Path(p) for p in protect)
    protect = protect + tuple(p.with_suffix(".yaml") for p in protect)
    for p in (target, side):  # check both before writing either
        if any(p.resolve() == q.resolve() for q in protect):
            raise InputError(f"refusing to overwrite the input file {p}; choose another output path")
        if p.exists() and not overwrite:
            raise InputError(f"{p} already exists; choose another output path or pass --overwrite")
    if meta:
        text = yaml.safe_dump(plain(meta), sort_keys=False, allow_unicode=True)
        with atomic_path(side, overwrite=True) as tmp:
            tmp.write_text(text, encoding="utf-8")
    elif side.exists():
        side.unlink()
    with atomic_path(target, overwrite=True) as tmp:
        pd.DataFrame(columns).to_csv(tmp, index=False, lineterminator="\n")
    return target


def plain(obj, key: str = "meta"):
    """``obj`` converted to plain YAML/JSON types (numpy scalars and arrays, tuples, paths)."""
    if isinstance(obj, dict):
        return {str(k): plain(v, f"{key}.{k}") for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v, f"{key}[{i}]") for i, v in enumerate(obj)]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist(), key)
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, os.PathLike):
        return str(obj)
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    raise InputError(f"{key}: cannot store a {type(obj).__name__} in metadata; use numbers, "
                     "strings, lists or mappings")


# --------------------------------------------------------------------------- read / write

def parse_column_map(text: str) -> dict[str, str]:
    """Parse ``"time=t,voltage=V1,deflection=V2"`` into ``{"time": "t", ...}`` (CLI form)."""
    mapping: dict[str, str] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        quantity, sep, column = (s.strip() for s in item.partition("="))
        if not sep or not quantity or not column:
            raise InputError(f"column map {text!r}: item {item!r} must look like "
                             "quantity=column, e.g. voltage=V1")
        if quantity in mapping:
            raise InputError(f"column map {text!r}: {quantity!r} is given twice")
        mapping[quantity] = column
    if not mapping:
        raise InputError(f"column map {text!r} is empty; expected e.g. voltage=V1,deflection=V2")
    _check_column_map(mapping)
    return mapping


def _check_column_map(mapping: Mapping[str, str]) -> None:
    unknown = sorted(set(mapping) - set(TIMESERIES_UNITS))
    if unknown:
        raise InputError(f"column map: unknown quantity {unknown[0]!r}; expected some of "
                         f"{', '.join(TIMESERIES_UNITS)}")


def read_timeseries(path, *, columns: dict[str, str] | None = None, fs: float | None = None,
                    rh: float | None = None, require_deflection: bool = True,
                    resample: bool = False) -> TimeSeries:
    """Read a time-series record (``.csv`` or ``.mat``) following ``DATA_FORMAT.md``.

    ``columns`` maps quantities to the file's columns (values in stored units: s, V, m,
    %, A, °C); ``fs`` (Hz) gives the time base of a file without a time column; ``rh``
    (%) is the relative humidity when the file has no ``rh_pct`` column (it wins over the
    column and the sidecar); ``resample`` allows non-uniform time (see module doc).
    """
    p = check_input_path(path, (".csv", ".mat"))
    table = read_table(p)
    where = str(p)
    values: dict[str, np.ndarray] = {}
    labels: dict[str, str] = {}
    if columns is not None:
        _check_column_map(columns)
        for quantity, col in columns.items():
            if col not in table.columns:
                raise InputError(f"{where}: column {col!r} (mapped to {quantity}) is missing; "
                                 f"the file has {', '.join(map(repr, table.columns))}")
            labels[quantity] = f"column {col!r} ({quantity})"
            values[quantity] = table.floats(col, labels[quantity])
    else:
        found: dict[str, str] = {}
        for name in table.columns:
            quantity, unit = parse_header(name, TIMESERIES_UNITS, p)
            if quantity in found:
                raise InputError(f"{where}: columns {found[quantity]!r} and {name!r} both "
                                 f"give {quantity}; keep one")
            found[quantity] = name
            labels[quantity] = f"column {name!r}"
            scale, offset = TIMESERIES_UNITS[quantity][unit]
            values[quantity] = table.floats(name)
            if (scale, offset) != (1.0, 0.0):
                values[quantity] = values[quantity] * scale + offset
    for quantity, arr in values.items():
        if columns is None and quantity in PLAUSIBLE:
            lo, hi, what = PLAUSIBLE[quantity]
        elif quantity in ("voltage", "deflection", "current"):
            lo, hi, what = -MAPPED_LIMIT, MAPPED_LIMIT, "(mapped column; larger values overflow the metrics)"
        else:
            continue
        check_range(arr, lo, hi, where, table.locate, labels[quantity], what)
    required = ["voltage"] + (["deflection"] if require_deflection else [])
    for quantity in required:
        if quantity not in values:
            raise InputError(f"{where}: missing column {quantity}_{STORED_UNITS[quantity]} "
                             f"({quantity} in {', '.join(TIMESERIES_UNITS[quantity])})"
                             + (" or a column map entry" if columns is not None else ""))
    n = values["voltage"].size
    if fs is not None:
        if "time" in values:
            raise InputError(f"{where}: has a time column, so a sampling rate must not be given too")
        if not np.isfinite(fs) or fs <= 0:
            raise InputError(f"{where}: sampling rate --fs-Hz {fs!r} must be a positive number")
        values["time"] = np.arange(n) / float(fs)
    elif "time" not in values:
        raise InputError(f"{where}: missing column time_s (time in s or ms); give the "
                         "sampling rate with --fs-Hz for a file without a time column")
    if n < 2:
        raise InputError(f"{where}: needs at least 2 samples, got {n}")
    meta = read_sidecar(p)
    if "rh" in values and meta.get("rh_pct") is not None and rh is None:
        col_rh = float(np.mean(values["rh"]))
        if abs(col_rh - float(meta["rh_pct"])) > 5.0:
            raise InputError(f"{where}: the sidecar {p.with_suffix('.yaml').name} says rh_pct={meta['rh_pct']!r} "
                             f"but the {labels['rh']} averages {col_rh:.3g} %; correct one of them (or give "
                             "--rh to override both)")
    if rh is not None:
        if not np.isfinite(rh) or not 0.0 <= rh <= 100.0:
            raise InputError(f"{where}: relative humidity rh={rh!r} must lie within 0–100 %")
        values["rh"] = np.full(n, float(rh))
    elif "rh" not in values:
        side_rh = meta.get("rh_pct")
        if side_rh is None:
            raise InputError(f"{where}: no relative humidity: add an rh_pct column, the key "
                             "rh_pct to the sidecar, or give the RH with --rh")
        if isinstance(side_rh, bool) or not isinstance(side_rh, (int, float)) \
                or not 0.0 <= side_rh <= 100.0:
            raise InputError(f"{p.with_suffix('.yaml')}: rh_pct={side_rh!r} must be a number "
                             "within 0–100 %")
        values["rh"] = np.full(n, float(side_rh))
    values, info = check_record(values, where, table.locate, labels, resample=resample)
    if info is not None:
        meta["resampled"] = info
    return TimeSeries(**values, meta=meta, source=where)


def write_timeseries(ts: TimeSeries, path, *, units: dict[str, str] | None = None,
                     overwrite: bool = False, protect=()) -> Path:
    """Write ``ts`` atomically as CSV (``quantity_unit`` headers, full float precision)
    plus the sidecar ``NAME.yaml`` when ``ts.meta`` is non-empty.

    ``units`` chooses the unit per quantity (default: stored units); ``protect`` lists
    input files that must never be overwritten.
    """
    units = dict(units or {})
    for quantity, unit in units.items():
        parse_header(f"{quantity}_{unit}", TIMESERIES_UNITS, Path(path))
    cols = {}
    for quantity in ("time",) + CHANNELS:
        arr = getattr(ts, quantity)
        if arr is None:
            continue
        unit = units.get(quantity, STORED_UNITS[quantity])
        scale, offset = TIMESERIES_UNITS[quantity][unit]
        cols[f"{quantity}_{unit}"] = (arr - offset) / scale
    return write_table(cols, ts.meta, path, overwrite=overwrite, protect=protect)
