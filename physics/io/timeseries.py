"""Time-series records: one experiment (voltage in, measured output out) per file.

File format (``docs/reference/file-formats.md``): a CSV with one row per sample and columns named
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

* ``time``, ``voltage`` and (unless ``require_deflection=False``) the output are required;
  a file without a time column needs ``fs=``.  Unknown columns are errors; a nameless,
  completely empty column (a trailing comma on every line) is ignored.
* Every value must be a finite number and plausible for its quantity (a tip deflection
  within ±1 m, a drive within ±1 kV: a value beyond is a unit or export error).  Time must
  be strictly increasing and uniform: each step may differ from the median step by at most
  :data:`~physics.io.record.UNIFORM_RTOL` (timestamps printed with few digits), otherwise the
  file is rejected unless ``resample=True``, which interpolates every channel linearly
  onto the median step and records it in ``meta["resampled"]``.
* Relative humidity comes, in this order of precedence, from an explicit ``rh=`` (always
  wins), the ``rh_pct`` column, or the key ``rh_pct`` of the sidecar; with none of them
  the file is rejected (never a silent default).  RH must lie within 0–100 %.  A constant
  RH is stored once (a read-only view of one value), not as a record-long column.
* **The output.**  By default the output is the tip deflection (stored in m).  Another
  quantity is named with ``output=`` (:class:`~physics.io.record.OutputQuantity`, e.g.
  ``level:V``): its column in a standard file is ``level_V``, its values are stored in its
  unit and checked against the plausibility rule of that quantity.
* **Column maps** read other files (a lab's export, public benchmarks with columns ``V1``,
  ``V2``): ``{"voltage": "V1", "deflection": "V2"}``; only mapped columns are read.  An
  entry may carry the unit of its column, ``deflection=Tip (mm):mm``; without one, a unit
  in the column's header (``Tip (mm)``, ``Tip [mm]``) is used and said aloud (a
  :class:`~physics.errors.InputNotice`); without either, the values are in the stored
  unit (s, V, m, %, A, °C).  An output column in a unit that is not a length
  (``deflection=y:V``, a laser sensor's volts) makes the output that quantity, unless a
  sensor ``gain`` to metres is given (``"2.5mm/V"``).  A quantity or a column may appear
  only once in a map.
* ``.mat`` files are read with :func:`scipy.io.loadmat`: variables named like the CSV
  columns, or through the column map; each must be a numeric vector.
* An optional sidecar ``NAME.yaml`` next to ``NAME.csv``/``NAME.mat`` is read into
  ``meta`` (keys and units: :mod:`physics.io.sidecar`).
"""
from __future__ import annotations

import re
import warnings
from pathlib import Path
from typing import Mapping

import numpy as np

from .csvtable import check_input_path, iter_table, read_table, write_table
from ..errors import InputError, InputNotice, arg
from ..limits import MAX_DRIVE_V
from .record import (CHANNELS, DEFLECTION, UNIFORM_RTOL, OutputQuantity, TimeSeries,  # noqa: F401 (TimeSeries: public)
                     check_range, check_record)
from .sidecar import read_sidecar
from .units import UnitError, parse_unit

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
#: Plausible ranges (stored units): a value outside is a unit or export error (a tip
#: deflection of 1e300 m, a drive of 1 MV), not a measurement.  The output's rule is its
#: quantity's (:meth:`~physics.io.record.OutputQuantity.bounds`).
PLAUSIBLE = {"voltage": (-MAX_DRIVE_V, MAX_DRIVE_V, "V (drive voltage)"),
             "current": (-1e3, 1e3, "A (absorbed current)"),
             "temperature": (-273.15, 1e3, "°C (ambient temperature)")}
#: Other spellings of units in column maps and headers.
_UNIT_ALIASES = {"%": "pct", "%RH": "pct", "pct": "pct", "degC": "C", "°C": "C", "µm": "um", "μm": "um"}
_COLUMNS, _OUTPUT = arg("columns"), arg("output")   # how messages name the column map and the output
_HEADER_UNIT = re.compile(r"^(?P<name>.*?)\s*(?:\((?P<a>[^()]+)\)|\[(?P<b>[^\[\]]+)\])\s*$")


def parse_header(name: str, units: Mapping[str, Mapping[str, object]],
                 where: Path, hint: str = "") -> tuple[str, str]:
    """Split a ``quantity_unit`` column name into (quantity, unit) and check both against
    ``units`` (quantity -> accepted units; a unitless quantity maps to ``{"": ...}``);
    ``hint`` ends the message of an unknown column (how to read other files)."""
    quantity, _, unit = name.partition("_")
    if quantity not in units:
        accepted = ", ".join(f"{q}_{u}" if u else q for q in units for u in units[q])
        raise InputError(f"{where}: unknown column {name!r}; expected columns named "
                         f"quantity_unit among: {accepted}{hint}")
    if unit not in units[quantity]:
        accepted = ", ".join(u or "(none)" for u in units[quantity])
        raise InputError(f"{where}: column {name!r}: cannot parse unit {unit or '(none)'!r} of "
                         f"{quantity}; accepted units: {accepted}")
    return quantity, unit



def header_unit(column: str) -> str | None:
    """The unit written in a column's header, ``Tip (mm)`` / ``Tip [mm]`` → ``mm`` (None when
    there is none, or when the brackets hold something that is not a unit: ``Sensor (raw)``)."""
    m = _HEADER_UNIT.match(column)
    if not m:
        return None
    unit = (m["a"] or m["b"]).strip()
    try:
        parse_unit(_UNIT_ALIASES.get(unit, unit).replace("pct", "%"))
    except UnitError:
        return None
    return unit


def unit_scale(quantity: str, unit: str) -> tuple[float, float] | None:
    """(scale, offset) from ``unit`` to the stored unit of ``quantity`` (time, voltage,
    deflection, rh, current, temperature); None when ``unit`` is not a unit of it."""
    unit = _UNIT_ALIASES.get(unit, unit)
    table = TIMESERIES_UNITS[quantity]
    if unit in table:
        return table[unit]
    if quantity in ("rh", "temperature"):
        return None
    try:
        q, ref = parse_unit(unit), parse_unit(STORED_UNITS[quantity])
    except UnitError:
        return None
    return (q.factor / ref.factor, 0.0) if q.same_dimension(ref) else None


def parse_gain(text: str) -> tuple[float, str]:
    """A sensor gain to metres, ``"2.5mm/V"`` → (2.5e-3, "V"): metres per unit of the
    output column, and that unit."""
    m = re.match(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S+)\s*$", str(text))
    if not m:
        raise InputError(f"sensor gain {text!r}: expected a number and a unit, e.g. 2.5mm/V")
    value, unit = float(m.group(1)), m.group(2)
    num, sep, den = unit.partition("/")
    scale = unit_scale("deflection", num) if sep else None
    if scale is None or not den or not np.isfinite(value) or value == 0:
        raise InputError(f"sensor gain {text!r}: expected a non-zero length per unit of the output column, "
                         "e.g. 2.5mm/V")
    return value * scale[0], den


def parse_column_map(text: str, output: OutputQuantity | None = None) -> dict[str, str]:
    """Parse ``"time=t,voltage=V1,deflection=Tip (mm):mm"`` into ``{"time": "t", ...}``
    (CLI form; a column's unit stays in the value and is read by :func:`read_timeseries`).
    Keys are stored quantities or the output (``output``, or its name); a quantity or a
    column given twice is an error."""
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
    channels: dict[str, str] = {}
    names: list[tuple[set[str], str]] = []   # (spellings of a column with or without its unit, quantity)
    for quantity, column in mapping.items():
        channel = _map_quantity(quantity, output)
        if channel in channels:
            raise InputError(f"column map {text!r}: {channels[channel]!r} and {quantity!r} both give the {channel}")
        channels[channel] = quantity
        spellings = {column, column.rpartition(":")[0].strip() or column}
        for other, q in names:
            if spellings & other:
                raise InputError(f"column map {text!r}: column {min(spellings & other)!r} is mapped to both {q} "
                                 f"and {quantity}; each column gives one quantity")
        names.append((spellings, quantity))
    return mapping


def _map_quantity(quantity: str, output: OutputQuantity | None) -> str:
    """The channel a map key fills: a stored quantity, or the output (its name, or ``output``)."""
    if quantity in TIMESERIES_UNITS:
        return quantity
    if quantity == "output" or (output is not None and quantity == output.name):
        return "deflection"
    extra = f", {output.name}" if output is not None and output.name != "deflection" else ""
    raise InputError(f"column map: unknown quantity {quantity!r}; expected some of "
                     f"{', '.join(TIMESERIES_UNITS)}, output{extra}")


def _resolve_map(columns: Mapping[str, str], table, output, where: str) -> dict[str, tuple[str, str | None, str]]:
    """channel -> (column, unit or None, where the unit came from) of a column map."""
    out: dict[str, tuple[str, str | None, str]] = {}
    used: dict[str, str] = {}
    for quantity, text in columns.items():
        channel = _map_quantity(quantity, output)
        if channel in out:
            raise InputError(f"column map: {quantity!r} and another entry both give the {channel}; keep one")
        text = str(text)
        col, unit, how = text, None, ""
        if text not in table.columns and ":" in text:
            col, _, unit = (s.strip() for s in text.rpartition(":"))
            how = "the column map"
        if col not in table.columns:
            raise InputError(f"{where}: column {col!r} (mapped to {quantity}) is missing; the file has "
                             f"{', '.join(map(repr, table.columns))} — fix the map given with {_COLUMNS}")
        if col in used:
            raise InputError(f"{where}: column {col!r} is mapped to both {used[col]} and {quantity}; each column "
                             f"gives one quantity — fix {_COLUMNS}")
        used[col] = quantity
        said = header_unit(col)
        if unit is None and said is not None:
            unit, how = said, "its header"
        elif unit is not None and said is not None and said != unit:
            raise InputError(f"{where}: column {col!r} is mapped with unit {unit} but its header says {said}; "
                             f"correct the unit in {_COLUMNS}")
        out[channel] = (col, unit, how)
    return out


def _convert(table, channel: str, col: str, unit: str | None, how: str, output: OutputQuantity | None,
             gain, where: str) -> tuple[np.ndarray, OutputQuantity | None]:
    """Values of a mapped column in the stored unit of ``channel`` (and, for the output
    channel, the output quantity they are)."""
    label = f"column {col!r}"
    values = table.floats(col, label)
    if channel != "deflection":
        if unit is None:
            return values, None
        scale = unit_scale(channel, unit)
        if scale is None:
            raise InputError(f"{where}: {label} ({channel}) is in {unit!r} according to {how}, which is not a unit "
                             f"of {channel}; accepted: {', '.join(TIMESERIES_UNITS[channel])} and other "
                             f"units of {STORED_UNITS[channel]} — correct {_COLUMNS}")
        if how == "its header":
            warnings.warn(f"{where}: {label} read as {channel} in {unit} (the unit in its header)", InputNotice,
                          stacklevel=3)
        return (values * scale[0] + scale[1]) if scale != (1.0, 0.0) else values, None
    return _convert_output(values, label, unit, how, output, gain, where)


def _convert_output(values, label, unit, how, output, gain, where):
    """Values of the output column and the output quantity they are (module doc)."""
    if unit is None and output is not None:
        unit, how = output.unit, _OUTPUT
    if gain is not None:
        metres_per, per_unit = parse_gain(gain)
        if output is not None and output.name != "deflection":
            raise InputError(f"{where}: {label}: {_OUTPUT} {output.name}:{output.unit} and a sensor gain to metres "
                             f"contradict each other (the gain makes it the tip deflection in m, the declaration "
                             f"keeps it as {output.name} in {output.unit}); give one of them")
        if unit is None:
            raise InputError(f"{where}: {label}: a sensor gain needs the column's unit; give it in the column map, "
                             f"e.g. deflection=COLUMN:{per_unit}")
        if unit != per_unit:
            raise InputError(f"{where}: {label} is in {unit} but the sensor gain is per {per_unit}; give the gain "
                             f"per {unit}")
        warnings.warn(f"{where}: {label} read in {unit} × sensor gain {gain} → tip deflection in m", InputNotice,
                      stacklevel=4)
        return values * metres_per, DEFLECTION
    if unit is None:
        return values, DEFLECTION
    if output is None or output.name == "deflection":
        scale = unit_scale("deflection", unit)
        if scale is not None:   # a length: the tip deflection, stored in m
            if how == "its header":
                warnings.warn(f"{where}: {label} read as the tip deflection in {unit} (the unit in its header)",
                              InputNotice, stacklevel=4)
            return (values * scale[0] if scale != (1.0, 0.0) else values), DEFLECTION
    if output is not None and output.name != "deflection":
        q = 1.0 if unit == output.unit else _dimension_scale(unit, output.unit)
        if q is None:
            raise InputError(f"{where}: {label} is in {unit} according to {how}, but the output is "
                             f"{output.name} in {output.unit}; correct {_COLUMNS} or {_OUTPUT}")
        return (values * q if q != 1.0 else values), output
    try:
        parse_unit(unit)
        quantity = OutputQuantity("deflection", unit)
    except (InputError, UnitError):
        raise InputError(f"{where}: {label}: {unit!r} (from {how}) is not a unit this reader knows (m, mm, um, V, "
                         f"mV, …); correct {_COLUMNS}, or declare the output with {_OUTPUT} NAME:UNIT") from None
    warnings.warn(f"{where}: {label} is in {unit} according to {how}, not a length: the output is the deflection "
                  f"read in {unit} (give a sensor gain to metres to compare with a physics model)", InputNotice,
                  stacklevel=4)
    return values, quantity


def _dimension_scale(unit: str, to: str) -> float | None:
    try:
        a, b = parse_unit(unit), parse_unit(to)
    except UnitError:
        return None
    return a.factor / b.factor if a.same_dimension(b) else None


def _standard_columns(table, p: Path, output: OutputQuantity | None):
    """Channels of a file with standard ``quantity_unit`` headers: values (stored units),
    labels, the output quantity (another output than the deflection: ``NAME_UNIT``, in
    its unit or one of the same dimension)."""
    other = output is not None and output.name != "deflection"
    values, labels, found = {}, {}, {}
    quantity_out = output if other else DEFLECTION
    for name in table.columns:
        head, _, unit = name.partition("_")
        if other and head == output.name:
            q = 1.0 if unit == output.unit else _dimension_scale(unit, output.unit)
            if q is None:
                raise InputError(f"{p}: column {name!r}: {unit!r} is not a unit of the output {output.name} "
                                 f"({output.unit}); name it {output.column}")
            quantity, scale = "deflection", (q, 0.0)
        else:
            quantity, unit = parse_header(name, TIMESERIES_UNITS, p, (f" or the output {output.column}" if other else "")
                                          + f"; read other files with a column map, e.g. {_COLUMNS} time=t,voltage=u")
            if other and quantity == "deflection":
                raise InputError(f"{p}: column {name!r}: the output here is {output.name} ({output.column}), not "
                                 f"the deflection; name the column {output.column} or map it with {_COLUMNS} "
                                 f"{output.name}=COLUMN")
            scale = TIMESERIES_UNITS[quantity][unit]
        if quantity in found:
            raise InputError(f"{p}: columns {found[quantity]!r} and {name!r} both give {quantity}; keep one")
        found[quantity] = name
        labels[quantity] = f"column {name!r}"
        values[quantity] = table.floats(name)
        if scale != (1.0, 0.0):
            values[quantity] = values[quantity] * scale[0] + scale[1]
    return values, labels, quantity_out


def _output_arg(output, columns) -> OutputQuantity | None:
    if isinstance(output, str):
        output = OutputQuantity.parse(output)
    if output is not None and output.name == "deflection" and unit_scale("deflection", output.unit) is None \
            and columns is None:
        raise InputError(f"output {output.name}:{output.unit}: a deflection read in {output.unit} needs a column "
                         "map (deflection=COLUMN:UNIT)")
    return output


def _channels_of(table, p: Path, meta: dict, *, columns, fs, rh, require_deflection, output, gain, first: int = 0):
    """(values in stored units, labels, output quantity) of the rows of ``table`` (rows
    ``first``… of the file), with time, RH and plausibility as the module doc says."""
    where = str(p)
    if columns is not None:
        values, labels, quantity_out = {}, {}, DEFLECTION
        for channel, (col, unit, how) in _resolve_map(columns, table, output, where).items():
            labels[channel] = f"column {col!r} ({channel if channel != 'deflection' else 'output'})"
            values[channel], q = _convert(table, channel, col, unit, how, output, gain, where)
            quantity_out = q or quantity_out
    else:
        if gain is not None:
            raise InputError(f"{where}: a sensor gain applies to a mapped output column; give a column map")
        values, labels, quantity_out = _standard_columns(table, p, output)
    for quantity, arr in values.items():
        if quantity == "deflection":
            lo, hi, what = quantity_out.bounds()
            hint = (f"; if the output is another quantity or unit, say so with {_OUTPUT} NAME:UNIT (e.g. "
                    f"{_OUTPUT} level:V) or a unit in {_COLUMNS} (deflection=COLUMN:V)") if quantity_out.is_deflection \
                else ""
            check_range(arr, lo, hi, where, table.locate, labels[quantity], what + hint)
        elif quantity in PLAUSIBLE:
            lo, hi, what = PLAUSIBLE[quantity]
            check_range(arr, lo, hi, where, table.locate, labels[quantity], what)
    if "voltage" not in values:
        raise InputError(f"{where}: missing column voltage_V (voltage in {', '.join(TIMESERIES_UNITS['voltage'])})"
                         + (" or a column map entry" if columns is not None else ""))
    if require_deflection and "deflection" not in values:
        want = quantity_out.column if output is not None else "deflection_m (deflection in m, mm or um)"
        raise InputError(f"{where}: missing column {want}"
                         + (" or a column map entry" if columns is not None else ""))
    n = values["voltage"].size
    if fs is not None:
        if "time" in values:
            raise InputError(f"{where}: has a time column, so a sampling rate must not be given too")
        if not np.isfinite(fs) or fs <= 0:
            raise InputError(f"{where}: sampling rate {arg('fs_Hz', 'fs')} {fs!r} must be a positive number")
        values["time"] = (first + np.arange(n)) / float(fs)
    elif "time" not in values:
        raise InputError(f"{where}: missing column time_s (time in s or ms); give the "
                         f"sampling rate with {arg('fs_Hz', 'fs')} for a file without a time column")
    if "rh" in values and meta.get("rh_pct") is not None and rh is None:
        col_rh = float(np.mean(values["rh"]))
        if abs(col_rh - float(meta["rh_pct"])) > 5.0:
            raise InputError(f"{where}: the sidecar {p.with_suffix('.yaml').name} says rh_pct={meta['rh_pct']!r} "
                             f"but the {labels['rh']} averages {col_rh:.3g} %; correct one of them (or give "
                             f"{arg('rh')} to override both)")
    if rh is not None:
        if not np.isfinite(rh) or not 0.0 <= rh <= 100.0:
            raise InputError(f"{where}: relative humidity rh={rh!r} must lie within 0–100 %")
        values["rh"] = _constant(float(rh), n)
    elif "rh" not in values:
        side_rh = meta.get("rh_pct")
        if side_rh is None:
            raise InputError(f"{where}: no relative humidity: add an rh_pct column, the key "
                             f"rh_pct to the sidecar, or give the RH with {arg('rh')}")
        values["rh"] = _constant(float(side_rh), n)
    elif values["rh"].size and values["rh"].min() == values["rh"].max():
        values["rh"] = _constant(float(values["rh"][0]), n)
    return values, labels, quantity_out


def _constant(value: float, n: int) -> np.ndarray:
    """``n`` samples of ``value`` stored once: a read-only view (``np.broadcast_to``), as a
    record's RH usually is; a long record then holds its varying channels only."""
    return np.broadcast_to(np.float64(value), (n,))


def read_timeseries(path, *, columns: dict[str, str] | None = None, fs: float | None = None,
                    rh: float | None = None, require_deflection: bool = True, resample: bool = False,
                    output: OutputQuantity | str | None = None, gain: str | None = None) -> TimeSeries:
    """Read a time-series record (``.csv`` or ``.mat``) following ``docs/reference/file-formats.md``.

    ``columns`` maps quantities to the file's columns (with optional units, module doc);
    ``fs`` (Hz) gives the time base of a file without a time column; ``rh`` (%) is the
    relative humidity when the file has no ``rh_pct`` column (it wins over the column and
    the sidecar); ``resample`` allows non-uniform time; ``output`` names the measured
    output (default: the tip deflection in m; ``"level:V"``); ``gain`` converts an output
    column in another unit to metres (``"2.5mm/V"``).
    """
    output = _output_arg(output, columns)
    p = check_input_path(path, (".csv", ".mat"))
    table = read_table(p)
    meta = read_sidecar(p)
    values, labels, quantity_out = _channels_of(table, p, meta, columns=columns, fs=fs, rh=rh, output=output,
                                                require_deflection=require_deflection, gain=gain)
    locate = table.locate
    del table                        # columns not kept (a constant RH, unmapped ones) are freed here
    if values["voltage"].size < 2:
        raise InputError(f"{p}: needs at least 2 samples, got {values['voltage'].size}")
    values, info = check_record(values, str(p), locate, labels, resample=resample)
    if info is not None:
        meta["resampled"] = info
    return TimeSeries(**values, meta=meta, source=str(p), output=quantity_out)


def read_timeseries_pieces(path, *, rows: int = 1 << 20, columns: dict[str, str] | None = None,
                           fs: float | None = None, rh: float | None = None, require_deflection: bool = True,
                           output: OutputQuantity | str | None = None, gain: str | None = None):
    """A CSV record as consecutive :class:`TimeSeries` pieces of about ``rows`` samples,
    each checked as :func:`read_timeseries` checks a record, the time uniform across pieces
    too (every step within :data:`~physics.io.record.UNIFORM_RTOL` of the first piece's median
    step); no resampling.  For records longer than memory; the pieces share ``meta``."""
    output = _output_arg(output, columns)
    p = check_input_path(path, (".csv",))
    meta = read_sidecar(p)
    kw = dict(columns=columns, fs=fs, rh=rh, require_deflection=require_deflection, output=output, gain=gain)
    step = last = None
    first = 0
    for table in iter_table(p, rows):
        values, labels, quantity_out = _channels_of(table, p, meta, first=first, **kw)
        first += values["voltage"].size
        if values["voltage"].size < 2:
            raise InputError(f"{p}: needs at least 2 samples, got {values['voltage'].size}")
        locate = table.locate
        values, _ = check_record(values, str(p), locate, labels)
        t = values["time"]
        here = float(np.median(np.diff(t)))
        if step is None:
            step = here
        elif abs(here - step) > UNIFORM_RTOL * step or abs(t[0] - last - step) > UNIFORM_RTOL * step:
            bad = t[0] - last if abs(t[0] - last - step) > UNIFORM_RTOL * step else here
            raise InputError(f"{p}, {locate(0)}, {labels['time']}: step {bad!r} s differs from the step "
                             f"{step!r} s of the first lines by more than {100 * UNIFORM_RTOL:g} %; sampling must "
                             "be uniform (resample the file first)")
        last = float(t[-1])
        yield TimeSeries(**values, meta=meta, source=str(p), output=quantity_out)


def columns_of(ts: TimeSeries, units: dict[str, str] | None = None) -> dict[str, np.ndarray]:
    """The CSV columns of ``ts`` (``quantity_unit`` headers, the output column named after
    ``ts.output``); ``units`` chooses the unit per quantity (default: stored units; not for an
    output other than the deflection)."""
    units = dict(units or {})
    for quantity, unit in units.items():
        parse_header(f"{quantity}_{unit}", TIMESERIES_UNITS, Path(ts.source or "record"))
    cols = {}
    for quantity in ("time",) + CHANNELS:
        arr = getattr(ts, quantity)
        if arr is None:
            continue
        if quantity == "deflection" and not ts.output.is_deflection:
            cols[ts.output.column] = arr
            continue
        unit = units.get(quantity, STORED_UNITS[quantity])
        scale, offset = TIMESERIES_UNITS[quantity][unit]
        cols[f"{quantity}_{unit}"] = (arr - offset) / scale if (scale, offset) != (1.0, 0.0) else arr
    return cols


def write_timeseries(ts: TimeSeries, path, *, units: dict[str, str] | None = None,
                     overwrite: bool = False, protect=()) -> Path:
    """Write ``ts`` atomically as CSV (:func:`columns_of`, full float precision) plus the
    sidecar ``NAME.yaml`` when ``ts.meta`` is non-empty; ``protect`` lists input files that
    must never be overwritten."""
    return write_table(columns_of(ts, units), ts.meta, path, overwrite=overwrite, protect=protect)
