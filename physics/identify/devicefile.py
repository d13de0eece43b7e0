"""Writing identified values back as a device file (units and sources kept)."""
from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from pathlib import Path

import numpy as np
import yaml

from ..device import Device, HumidityMap, all_param_specs, parse_device
from ..errors import InputError, ModelError
from ..io.units import to_si
from .free_parameters import _section_of, switchable
from .result import IdentificationResult




def _from_si(value: float, unit: str, spec_unit: str) -> float:
    a = to_si(0.0, unit, spec_unit)
    b = to_si(1.0, unit, spec_unit)
    return (value - a) / (b - a)


def _num(v: float, digits: int = 7) -> float:
    return float(f"{v:.{digits}g}")


def device_to_raw(device: Device) -> dict:
    """A device file mapping (schema eap-device/1) that loads back to ``device``: the
    original file's entries (units, sources, notes) where the values agree, SI entries
    for everything that differs or is missing."""
    from ..effects import EFFECTS
    specs = all_param_specs()
    section = _section_of()
    raw: dict = {}
    dev0 = None
    if device.path and Path(device.path).suffix in (".yaml", ".yml") and Path(device.path).is_file():
        raw = yaml.safe_load(Path(device.path).read_text(encoding="utf-8")) or {}
        try:
            dev0 = parse_device(raw, where=device.path)
        except InputError:
            raw, dev0 = {}, None
    raw.setdefault("schema", "eap-device/1")
    raw["name"] = device.name
    if device.title:
        raw["title"] = device.title
    if dev0 is None or dev0.reference_rh != device.reference_rh:
        raw["reference_rh"] = {"value": device.reference_rh, "unit": "pct", "source": ""}
    if device.default_effects:
        raw["default_effects"] = list(device.default_effects)
    for k, v in device.params.items():
        if dev0 is not None and k in dev0.params and dev0.params[k] == v:
            continue
        sec = section[k]
        entry = (raw.get(sec) or {}).get(k)
        unit = entry["unit"] if isinstance(entry, dict) and entry.get("unit") else specs[k].unit
        raw.setdefault(sec, {})[k] = {"value": _num(_from_si(v, str(unit), specs[k].unit)), "unit": unit,
                                      "source": device.sources.get(k, "")}
    table_section = {t.name: eff.id for eff in EFFECTS.values() for t in eff.tables}
    table_specs = {t.name: t for eff in EFFECTS.values() for t in eff.tables}
    for name, cols in device.tables.items():
        if dev0 is not None and name in dev0.tables and all(
                np.array_equal(dev0.tables[name][c], cols[c]) for c in cols):
            continue
        spec = table_specs[name]
        raw.setdefault(table_section[name], {})[name] = {
            "source": device.sources.get(name, ""),
            **{c: {"values": [_num(x) for x in np.asarray(cols[c]).tolist()], "unit": spec.columns[c]} for c in cols}}
    maps = {}
    for name, m in device.humidity_maps.items():
        old = (raw.get("humidity_maps") or {}).get(name)
        if dev0 is not None and name in dev0.humidity_maps and _maps_equal(dev0.humidity_maps[name], m) and old:
            maps[name] = old
            continue
        maps[name] = {"mode": m.mode, "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                      "values": {"values": [_num(x) for x in m.values.tolist()], "unit": specs[name].unit},
                      "source": m.source}
    if maps:
        raw["humidity_maps"] = maps
    else:
        raw.pop("humidity_maps", None)
    return raw


def _maps_equal(a: HumidityMap, b: HumidityMap) -> bool:
    return a.mode == b.mode and np.array_equal(a.rh, b.rh) and np.array_equal(a.values, b.values)


def identified_device_raw(result: IdentificationResult, *, name: str | None = None,
                          date: str | None = None) -> dict:
    """The fitted device as a device-file mapping: identified values with units, a source
    "identified by eap identify from FILES on DATE" and a note with the standard error."""
    prob, fit = result.problem, result.fit
    date = date or _dt.date.today().isoformat()
    files = ", ".join(Path(s).name for s in result.sources)
    src = f"identified by eap identify from {files} on {date}"
    specs = all_param_specs()
    section = _section_of()
    base = prob.device
    new_name = name or f"{base.name}_identified"
    dev = dataclasses.replace(result.device, name=new_name,
                              title=(f"{base.title} — identified" if base.title else new_name),
                              default_effects=switchable(prob.effects))
    # dataclass equality of HumidityMap with arrays is ambiguous: compare explicitly
    raw = device_to_raw(dataclasses.replace(dev, humidity_maps={}))
    raw.pop("humidity_maps", None)
    old_raw_maps = {}
    if base.path and Path(base.path).is_file():
        old_raw_maps = (yaml.safe_load(Path(base.path).read_text(encoding="utf-8")) or {}).get("humidity_maps") or {}
    maps = {}
    for mname, m in dev.humidity_maps.items():
        if mname in prob.per_rh:
            idx = [i for i, p in enumerate(prob.params) if p.name == mname]
            old_vals = (old_raw_maps.get(mname) or {}).get("values")
            unit = str(old_vals["unit"]) if isinstance(old_vals, dict) and old_vals.get("unit") else specs[mname].unit
            conv = lambda v: _from_si(v, unit, specs[mname].unit)  # noqa: E731
            se = ", ".join(f"RH {prob.params[i].rh:g} %: ±{conv(fit.std_error[i]) - conv(0.0):.3g}" for i in idx)
            maps[mname] = {"mode": "absolute", "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                           "values": {"values": [_num(conv(x)) for x in m.values.tolist()], "unit": unit},
                           "source": f"{src} ({fit.method}; one value per RH level)",
                           "note": f"standard errors (1 sigma, {unit}): {se}"}
        elif mname in base.humidity_maps and _maps_equal(base.humidity_maps[mname], m) and mname in old_raw_maps:
            maps[mname] = old_raw_maps[mname]
        else:
            maps[mname] = {"mode": m.mode, "rh": {"values": [_num(x) for x in m.rh.tolist()], "unit": "pct"},
                           "values": {"values": [_num(x) for x in m.values.tolist()], "unit": specs[mname].unit},
                           "source": m.source}
    if maps:
        raw["humidity_maps"] = maps
    for i, p in enumerate(prob.params):
        if p.rh is not None:
            continue
        sec = section[p.name]
        entry = raw[sec][p.name] if p.name in raw.get(sec, {}) else {}
        unit = entry.get("unit") or p.unit
        val = _from_si(float(fit.theta[i]), str(unit), p.unit)
        se = _from_si(float(fit.std_error[i]), str(unit), p.unit) - _from_si(0.0, str(unit), p.unit) \
            if np.isfinite(fit.std_error[i]) else math.inf
        if result.kept_start:
            raw.setdefault(sec, {})[p.name] = {
                "value": _num(_from_si(p.initial, str(unit), p.unit)), "unit": unit,
                "source": f"start value kept by eap identify on {date} (the fit was worse than its start)",
                "note": f"rejected fitted value {_num(val, 6)} {unit}"}
            continue
        raw.setdefault(sec, {})[p.name] = {
            "value": _num(val), "unit": unit, "source": f"{src} ({fit.method})",
            "note": (f"standard error {se:.3g} {unit} ({100 * fit.rel_std_error[i]:.3g} %), start value "
                     f"{_num(_from_si(p.initial, str(unit), p.unit), 6)} {unit}") if math.isfinite(se)
            else "standard error: not determined (see the identification report)"}
    notes = list(raw.get("notes") or [])
    if result.kept_start:
        notes.append(f"WARNING ({date}): {result.check['message']}")
    notes.append(f"{src}: free {', '.join(prob.free) or '-'}"
                 + (f", per RH {', '.join(prob.per_rh)} at {', '.join(f'{x:g}' for x in prob.levels)} %" if prob.per_rh else "")
                 + f"; method {fit.method}; effects {', '.join(prob.effects)}; J_err {result.j_err_initial:.4g} -> "
                 f"{fit.j_err:.4g} m/V")
    raw["notes"] = notes
    raw["name"] = new_name
    raw["title"] = dev.title
    raw["default_effects"] = list(dev.default_effects)
    # self-check: the file must load back to the fitted parameters
    back = parse_device(raw, where=f"<identified device {new_name}>")
    for k, v in dev.params.items():
        if not math.isclose(back.params.get(k, math.nan), v, rel_tol=2e-6, abs_tol=1e-300):
            raise ModelError(f"internal error: identified device does not load back: {k} = {back.params.get(k)} "
                             f"instead of {v}")
    return raw


class _DeviceDumper(yaml.SafeDumper):
    """Device-file layout of ``configs/devices``: ``{value: ..., unit: ..., source: ...}``
    entries and short lists of numbers on one line."""


def _is_scalar(v) -> bool:
    return not isinstance(v, (dict, list, tuple))


def _repr_map(dumper, data):
    flow = set(data) <= {"value", "unit", "source", "note", "values"} and all(
        _is_scalar(v) or (isinstance(v, list) and all(_is_scalar(x) for x in v)) for v in data.values())
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=flow)


def _repr_seq(dumper, data):
    flow = all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in data) or \
        all(isinstance(x, str) and len(x) < 40 for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_DeviceDumper.add_representer(dict, _repr_map)
_DeviceDumper.add_representer(list, _repr_seq)


def write_device(result: IdentificationResult, path, *, name: str | None = None, date: str | None = None,
                 protect=()) -> Path:
    """Write the fitted device file atomically (never over an input in ``protect``)."""
    from ..io.fileio import write_text
    raw = identified_device_raw(result, name=name, date=date)
    warn = f"# WARNING: {result.check['message']}\n" if result.kept_start else ""
    header = (warn + f"# {raw['name']}: written by eap identify on {date or _dt.date.today().isoformat()}.\n"
              f"# Loads with physics.load_device(path) / eap ... --device {Path(path).name}\n")
    text = header + yaml.dump(raw, Dumper=_DeviceDumper, sort_keys=False, allow_unicode=True, width=110)
    return write_text(path, text, protect=tuple(protect))


# ============================================================================ report


