"""Sidecars: the optional ``NAME.yaml`` next to a record ``NAME.csv`` (or ``NAME.mat``).

A sidecar is a YAML mapping (read by :func:`physics.io.yamlio.load_yaml`: at most 1 MiB, no
aliases, no key twice, shallow nesting).  The keys the package reads, with their units:

==================  ===========================================================================
key                 meaning
==================  ===========================================================================
``rh_pct``          relative humidity of the record [%], 0–100 (when the file has no RH column)
``signal`` /        the excitation: a mapping with ``kind`` (text: ``sweep``, ``multisine``,
``excitation``      ``noise``, ``square``, ``tone``, ``steps``, or your own word) and, where they
                    apply, ``f_start_Hz``, ``f_stop_Hz``, ``frequency_Hz``, ``period_s``,
                    ``duration_s``, ``fs_Hz`` (positive numbers) and ``periods`` (whole number ≥ 1)
``sensor``          the displacement sensor: free text (``laser triangulation, Keyence LK-G``) or
                    a mapping of the settings below; every other key is kept as metadata
``geometry``        refused by compare / identify / diagnose: geometry belongs in a device YAML
``device``,         free text, kept as metadata
``description``, …
==================  ===========================================================================

Sensor settings (stored in SI under the name on the left; a common spelling with its unit
is accepted and converted, and a value may be a number or text with a unit, ``1 kHz``):

========================  =====  ====================================================
stored as                 unit   also accepted
========================  =====  ====================================================
``bandwidth``             Hz     ``bandwidth_Hz``, ``bandwidth_kHz``, ``cutoff_Hz``, …
``deflection_noise``      m      ``noise_rms_um``, ``noise_um``, ``noise_rms_m``, …
``deflection_step``       m      ``resolution_um``, ``resolution_nm``, ``step_um``, …
``deflection_range``      m      ``range_mm`` (± half-range), …
``deflection_offset``     m      ``offset_mm``, …
``deflection_drift``      m      ``drift_um``, …
``noise_floor_m``         m      ``noise_floor_um``, …; when absent it is computed from the
                                 noise and resolution given: √(σ² + q²/12)
``adc_bits``, ``voltage_range``, ``voltage_noise``, ``current_range``, ``current_noise``,
``rh_noise``, ``rh_step``, ``temperature_noise``, ``temperature_step``: as in
:class:`physics.io.sensor.SensorModel` (V, A, %, °C)
``model``, ``type``,      text   free text (kept)
``description``, …
========================  =====  ====================================================

:func:`read_sidecar` returns the mapping with the sensor settings in their stored names
and SI units, so that every reader (compare's sensor bandwidth, the diagnosis's noise
floor, ``eap dataset``) sees one spelling; each fault is an
:class:`~physics.errors.InputError` naming the sidecar and the key.
"""
from __future__ import annotations

import math
import re
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..errors import InputError
from .fileio import check_regular
from .sensor import SensorModel
from .units import UnitError, parse_unit
from .yamlio import load_yaml

#: Stored sensor settings with common spellings (before the unit suffix) and their SI unit.
SENSOR_ALIASES: dict[str, tuple[tuple[str, ...], str]] = {
    "bandwidth": (("bandwidth", "cutoff", "cut_off", "f_cutoff", "fc"), "Hz"),
    "deflection_noise": (("deflection_noise", "noise_rms", "rms_noise", "noise"), "m"),
    "deflection_step": (("deflection_step", "resolution", "step"), "m"),
    "deflection_range": (("deflection_range", "range", "half_range"), "m"),
    "deflection_offset": (("deflection_offset", "offset"), "m"),
    "deflection_drift": (("deflection_drift", "drift"), "m"),
    "noise_floor_m": (("noise_floor",), "m"),
}
#: Largest length [m] a sensor setting of a tip deflection may state (noise, step, range,
#: offset, drift): a strip is centimetres long; beyond is a unit error (and squares overflow).
MAX_SENSOR_M = 1.0
#: Sidecar keys of the signal description that must be positive numbers.
POSITIVE_SIGNAL_KEYS = ("period_s", "duration_s", "fs_Hz", "f_start_Hz", "f_stop_Hz", "frequency_Hz")
_TINY = float(np.finfo(float).tiny)
_NUMBER_UNIT = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


def read_sidecar(path: Path) -> dict:
    """Metadata of the optional sidecar ``NAME.yaml`` next to ``path`` ({} if absent),
    normalised (sensor settings in stored names and SI) and checked (:func:`check_sidecar`)."""
    side = Path(path).with_suffix(".yaml")
    check_regular(side, f"the sidecar of {Path(path).name}")
    if not side.is_file():
        return {}
    meta = load_yaml(side, "sidecar")
    if meta is None:
        return {}
    if not isinstance(meta, dict):
        raise InputError(f"{side}: expected a mapping of metadata keys, got {type(meta).__name__}")
    if "sensor" in meta:
        meta["sensor"] = normalise_sensor(meta["sensor"], side)
    check_sidecar(meta, side)
    return meta


def _number(value, key: str, side, lo=-math.inf, hi=math.inf, allow_none=False) -> None:
    if value is None and allow_none:
        return
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) \
            or not lo <= value <= hi:
        rng = " > 0" if lo == _TINY else "" if (lo, hi) == (-math.inf, math.inf) else f" within {lo:g}–{hi:g}"
        raise InputError(f"{side}: {key}: {value!r} is not valid; expected a finite number{rng}")


def _si(value, unit: str, si_unit: str, key: str, side):
    """``value`` (a number, or text ``"1 kHz"``) in ``unit`` converted to ``si_unit``."""
    if isinstance(value, str):
        m = _NUMBER_UNIT.match(value)
        if not m:
            raise InputError(f"{side}: sensor.{key}: {value!r} is not a number with an optional unit")
        value, text_unit = float(m.group(1)), m.group(2)
        if text_unit:
            if unit != si_unit:
                raise InputError(f"{side}: sensor.{key}: the key already says the unit ({unit}); give a number")
            unit = text_unit
    if value is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return value   # left for check_sidecar to name
    try:
        q, ref = parse_unit(unit), parse_unit(si_unit)
    except UnitError as exc:
        raise InputError(f"{side}: sensor.{key}: {exc}; expected a unit of {si_unit}") from None
    if not q.same_dimension(ref):
        raise InputError(f"{side}: sensor.{key}: unit {unit!r} is not a unit of {si_unit}")
    out = float(value) * q.factor / ref.factor
    if si_unit == "m" and not abs(out) <= MAX_SENSOR_M:
        raise InputError(f"{side}: sensor.{key}: {value:g} {unit} is {out:.3g} m; a sensor setting of the tip "
                         f"deflection lies within ±{MAX_SENSOR_M:g} m (a unit error?)")
    return out


def _canonical(key: str) -> tuple[str, str] | None:
    """(stored name, unit written in the key) of a sensor key, or None if it is not a setting."""
    pairs = sorted(((alias, name) for name, (aliases, _) in SENSOR_ALIASES.items() for alias in (name,) + aliases),
                   key=lambda p: -len(p[0]))
    for alias, name in pairs:   # the longest spelling first: noise_floor_um is not noise + "floor_um"
        if key == alias:
            return name, SENSOR_ALIASES[name][1]
        if key.startswith(alias + "_"):
            return name, key[len(alias) + 1:]
    return None


def normalise_sensor(sensor, side) -> dict:
    """A sidecar's ``sensor`` entry as a mapping of stored settings (SI) plus free metadata;
    free text becomes ``{"description": text}``."""
    if sensor is None:
        return {}
    if isinstance(sensor, str):
        return {"description": sensor}
    if not isinstance(sensor, dict):
        raise InputError(f"{side}: sensor: expected a description (text) or a mapping of sensor settings "
                         f"(e.g. bandwidth_Hz, noise_rms_um), got {sensor!r}")
    out: dict = {}
    for key, value in sensor.items():
        key = str(key)
        found = _canonical(key)
        if found is None:
            out[key] = value
            continue
        name, unit = found
        if name in out:
            raise InputError(f"{side}: sensor: {key} and another key both give {name}; keep one")
        out[name] = _si(value, unit, SENSOR_ALIASES[name][1], key, side)
    if "noise_floor_m" not in out and isinstance(out.get("deflection_noise"), (int, float)):
        step = out.get("deflection_step") if isinstance(out.get("deflection_step"), (int, float)) else 0.0
        out["noise_floor_m"] = math.hypot(float(out["deflection_noise"]), float(step) / math.sqrt(12))
    return out


def check_sidecar(meta: dict, side: Path) -> None:
    """Check the sidecar keys the package reads (types, units, ranges); errors name the
    file and the key."""
    if "rh_pct" in meta:
        _number(meta["rh_pct"], "rh_pct", side, 0.0, 100.0)
    for section in ("signal", "excitation"):
        sig = meta.get(section)
        if sig is None:
            continue
        if not isinstance(sig, dict):
            raise InputError(f"{side}: {section}: expected a mapping (kind, frequencies...), got {sig!r}")
        if "kind" in sig and not (isinstance(sig["kind"], str) and sig["kind"].strip()):
            raise InputError(f"{side}: {section}.kind: {sig['kind']!r} is not valid; expected the excitation's "
                             "name as text, e.g. sweep, multisine, noise, square")
        for key in POSITIVE_SIGNAL_KEYS:
            if key in sig:
                _number(sig[key], f"{section}.{key}", side, _TINY)
        if "periods" in sig and (isinstance(sig["periods"], bool) or not isinstance(sig["periods"], int)
                                 or sig["periods"] < 1):
            raise InputError(f"{side}: {section}.periods: {sig['periods']!r} is not valid; expected a "
                             "whole number of periods ≥ 1")
    sensor = meta.get("sensor")
    if sensor is None:
        return
    if not isinstance(sensor, dict):
        raise InputError(f"{side}: sensor: expected a mapping of sensor settings, got {sensor!r}")
    known = {f.name for f in fields(SensorModel)}
    for key in sorted(known & set(sensor)):
        lo, hi = (-MAX_SENSOR_M, MAX_SENSOR_M) if key.startswith("deflection_") else (-math.inf, math.inf)
        _number(sensor[key], f"sensor.{key}", side, lo, hi, allow_none=key in ("bandwidth", "adc_bits"))
    try:
        SensorModel(**{k: sensor[k] for k in known & set(sensor)})
    except InputError as exc:
        raise InputError(f"{side}: {exc}") from None
    if "noise_floor_m" in sensor:
        _number(sensor["noise_floor_m"], "sensor.noise_floor_m", side, 0.0, MAX_SENSOR_M)
