"""Device parameter sets: loading, validation and SI conversion of device files.

A device file (YAML, see ``configs/devices/``) gives every value with its unit and
source::

    geometry:
      t_polymer: {value: 180, unit: um, source: "thesis §2.1, tNaf"}

Sections are the base sections of :mod:`physics.parameters` plus one section per
physical effect (named by the effect id) holding that effect's parameters and tables.
Unknown sections or keys, missing units, unparsable or incompatible units and values
outside the admissible range are rejected with a message naming the file and key.
"""
from __future__ import annotations

import difflib
import importlib.resources
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import InputError
from .io.yamlio import load_yaml
from .parameters import BASE_SECTIONS, ParamSpec, TableSpec
from .io.units import UnitError, to_si

SCHEMA = "eap-device/1"
_TOP_KEYS = {"schema", "name", "title", "reference", "reference_rh", "default_effects", "notes"}


def config_dir() -> Path:
    """Folder holding ``devices/``, ``datasets/`` and ``train/``: ``$EAP_CONFIG_DIR``, else the
    copy an installed wheel holds (``physics/configs``, put there by ``setup.py``), else the
    top-level ``configs/`` of the source checkout (an editable install or ``PYTHONPATH``)."""
    env = os.environ.get("EAP_CONFIG_DIR")
    if env:
        return Path(env)
    package = Path(str(importlib.resources.files("physics")))
    inside = package / "configs"
    return inside if inside.is_dir() else package.parent / "configs"


def available_devices() -> list[str]:
    """Names of the shipped device files (``configs/devices/NAME.yaml``), sorted.

    Examples
    --------
    >>> import physics
    >>> physics.available_devices()
    ['ip2c_pedot_water', 'ipmc_pt_eg']
    """
    d = config_dir() / "devices"
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


@dataclass(frozen=True)
class HumidityMap:
    """A parameter as a function of RH: ``factor(rh)`` multiplies the device's base value."""

    param: str
    rh: np.ndarray          # %
    values: np.ndarray      # SI, in the parameter's unit
    mode: str               # "ratio": values relative to the value at reference RH; "absolute"
    source: str = ""

    def factor(self, rh, base: float, reference_rh: float):
        v = np.interp(rh, self.rh, self.values)
        if self.mode == "ratio":
            return v / np.interp(reference_rh, self.rh, self.values)
        return v / base


@dataclass(frozen=True)
class Device:
    """A device: a validated parameter set in SI units, with its tables and sources.

    Immutable; :meth:`with_params` returns a changed copy.  Made by :func:`load_device`.

    Attributes
    ----------
    name, title : str
        The device's name and a one-line description.
    params : dict
        Every scalar parameter in SI units (``eap effects --device NAME`` lists them with
        their units): geometry (``L_total``, ``L_clamp``, ``width``, ``t_polymer``, m),
        electrical, chemical, electrode and mechanical values, and those of the effects.
    tables : mapping
        Tabulated data, e.g. the DMA curves of ``viscoelastic``.
    humidity_maps : mapping
        Parameters as functions of RH (thesis Table V for ``Y`` and ``kf``).
    sources : dict
        Where each value comes from (thesis table, equation, or identification).
    reference_rh : float
        The humidity the base values belong to [%].
    default_effects : tuple of str
        The effects ``"default"`` switches on.
    path : str or None
        The file it was read from.
    """

    name: str
    title: str
    params: Mapping[str, float]
    tables: Mapping[str, Mapping[str, np.ndarray]] = field(default_factory=dict)
    humidity_maps: Mapping[str, HumidityMap] = field(default_factory=dict)
    sources: Mapping[str, str] = field(default_factory=dict)
    reference_rh: float = 100.0
    default_effects: tuple[str, ...] = ()
    path: str | None = None

    def __getitem__(self, name: str) -> float:
        try:
            return self.params[name]
        except KeyError:
            raise InputError(f"device {self.name!r} has no parameter {name!r}") from None

    def has(self, name: str) -> bool:
        return name in self.params or name in self.tables

    def with_params(self, **values: float) -> "Device":
        """A copy with some parameters replaced.

        Parameters
        ----------
        **values : float
            New values in SI units, by parameter name; each is checked against its range.

        Returns
        -------
        Device

        Examples
        --------
        >>> import physics
        >>> longer = physics.load_device("ipmc_pt_eg").with_params(L_total=0.040)    # m
        >>> longer["L_total"]
        0.04
        """
        specs = all_param_specs()
        new = dict(self.params)
        for k, v in values.items():
            if k not in specs:
                raise InputError(f"unknown parameter {k!r}{_suggest(k, specs)}")
            new[k] = specs[k].check(float(v), f"device {self.name!r}")
        _check_lengths(new, f"device {self.name!r}")
        return replace(self, params=new)

    def describe(self) -> str:
        specs = all_param_specs()
        lines = [f"{self.name}: {self.title}"]
        for k, v in self.params.items():
            unit = specs[k].unit if k in specs else ""
            lines.append(f"  {k:16s} = {v:<12.5g} {unit:10s} {self.sources.get(k, '')}")
        return "\n".join(lines)


def all_param_specs() -> dict[str, ParamSpec]:
    out: dict[str, ParamSpec] = {}
    for sec in _sections().values():
        out.update({k: v for k, v in sec.items() if isinstance(v, ParamSpec)})
    return out


def _sections() -> dict[str, dict[str, ParamSpec | TableSpec]]:
    from .effects import EFFECTS  # effects declare their own parameters
    secs: dict[str, dict[str, ParamSpec | TableSpec]] = {k: dict(v) for k, v in BASE_SECTIONS.items()}
    for eff in EFFECTS.values():
        if eff.params or eff.tables:
            sec = secs.setdefault(eff.id, {})
            sec.update({p.name: p for p in eff.params})
            sec.update({t.name: t for t in eff.tables})
    return secs


def _suggest(key: str, known) -> str:
    close = difflib.get_close_matches(key, list(known), n=3)
    return f" (did you mean {', '.join(close)}?)" if close else f" (known: {', '.join(sorted(known))})"


def load_device(name_or_path: str | os.PathLike | Device) -> Device:
    """Load a device by name or from a device file.

    Parameters
    ----------
    name_or_path : str, path or Device
        A shipped device's name (see :func:`available_devices`), or the path of a device
        YAML file (``docs/reference/file-formats.md``); a :class:`Device` is returned as is.

    Returns
    -------
    Device
        Every value converted to SI and checked against its admissible range.

    Raises
    ------
    InputError
        An unknown name, a missing file, a value without a unit or out of range.

    Examples
    --------
    >>> import physics
    >>> dev = physics.load_device("ipmc_pt_eg")
    >>> print(f"L_total = {dev.params['L_total']:g} m, kf = {dev.params['kf']:g} N m/mol")
    L_total = 0.026 m, kf = 0.0041 N m/mol
    >>> dev.default_effects
    ('electrode_resistance', 'solvent_diffusion', 'viscoelastic', 'humidity')
    """
    if isinstance(name_or_path, Device):
        return name_or_path
    p = Path(name_or_path)
    if p.suffix not in (".yaml", ".yml"):
        cand = config_dir() / "devices" / f"{p.name}.yaml"
        if not cand.is_file():
            raise InputError(f"unknown device {str(name_or_path)!r}: not a YAML file and not one of "
                             f"{', '.join(available_devices()) or '(no devices found)'}")
        p = cand
    if not p.is_file():
        raise InputError(f"device file {p} does not exist")
    raw = load_yaml(p, "device file")
    return parse_device(raw, where=str(p))


def parse_device(raw: Any, where: str = "<device>") -> Device:
    """Validate a device mapping (as read from YAML) and convert it to SI."""
    if not isinstance(raw, dict):
        raise InputError(f"{where}: a device file must be a mapping of sections")
    if raw.get("schema", SCHEMA) != SCHEMA:
        raise InputError(f"{where}: schema {raw.get('schema')!r} is not supported (expected {SCHEMA!r})")
    sections = _sections()
    params: dict[str, float] = {}
    tables: dict[str, dict[str, np.ndarray]] = {}
    sources: dict[str, str] = {}
    maps: dict[str, HumidityMap] = {}
    for key, body in raw.items():
        if key in _TOP_KEYS:
            continue
        if key == "humidity_maps":
            maps = _parse_maps(body, where)
            continue
        if key not in sections:
            raise InputError(f"{where}: unknown section {key!r}"
                             f"{_suggest(key, list(sections) + sorted(_TOP_KEYS) + ['humidity_maps'])}")
        if not isinstance(body, dict):
            raise InputError(f"{where}: section {key!r} must be a mapping of parameters")
        for pname, entry in body.items():
            loc = f"{where}: {key}.{pname}"
            spec = sections[key].get(pname)
            if spec is None:
                raise InputError(f"{where}: unknown parameter {pname!r} in section {key!r}"
                                 f"{_suggest(pname, sections[key])}")
            if isinstance(spec, TableSpec):
                tables[pname], sources[pname] = _parse_table(spec, entry, loc)
            else:
                params[pname], sources[pname] = _parse_value(spec, entry, loc)
    for sec_name, sec in BASE_SECTIONS.items():
        missing = [k for k, s in sec.items() if not s.optional and k not in params]
        if missing:
            raise InputError(f"{where}: section {sec_name!r} is missing {', '.join(missing)}")
    _check_lengths(params, where)
    specs = all_param_specs()
    for m in maps.values():
        if m.param not in specs:
            raise InputError(f"{where}: humidity_maps.{m.param}: unknown parameter{_suggest(m.param, specs)}")
    ref_rh = 100.0
    if "reference_rh" in raw:
        ref_rh = _parse_value(ParamSpec("reference_rh", "pct", 0, 100, "reference RH"),
                              raw["reference_rh"], f"{where}: reference_rh")[0]
    dflt = raw.get("default_effects", []) or []
    from .effects import EFFECTS
    bad = [e for e in dflt if e not in EFFECTS]
    if bad:
        raise InputError(f"{where}: default_effects has unknown effect(s) {bad}; known: {sorted(EFFECTS)}")
    return Device(name=str(raw.get("name", Path(where).stem)), title=str(raw.get("title", "")),
                  params=params, tables=tables, humidity_maps=maps, sources=sources,
                  reference_rh=ref_rh, default_effects=tuple(dflt), path=where)


def _check_lengths(params: Mapping[str, float], where: str) -> None:
    """The strip must bend: its total length exceeds the length held in the clamp."""
    L, Lc = params.get("L_total"), params.get("L_clamp")
    if L is not None and Lc is not None and not L > Lc:
        raise InputError(f"{where}: L_total {L:g} m is not longer than L_clamp {Lc:g} m; the free (bending) length "
                         "L_total − L_clamp must be positive")


def _parse_value(spec: ParamSpec, entry: Any, loc: str) -> tuple[float, str]:
    if not isinstance(entry, dict) or "value" not in entry:
        raise InputError(f"{loc}: expected a mapping {{value: ..., unit: ..., source: ...}}, got {entry!r}")
    unknown = set(entry) - {"value", "unit", "source", "note"}
    if unknown:
        raise InputError(f"{loc}: unknown key(s) {sorted(unknown)}; allowed: value, unit, source, note")
    if "unit" not in entry or entry["unit"] in (None, ""):
        raise InputError(f"{loc}: missing unit (expected something compatible with {spec.unit!r})")
    try:
        value = float(entry["value"])
    except (TypeError, ValueError):
        raise InputError(f"{loc}: value {entry['value']!r} is not a number") from None
    if not np.isfinite(value):
        raise InputError(f"{loc}: value must be finite")
    try:
        si = to_si(value, str(entry["unit"]), spec.unit)
    except UnitError as exc:
        raise InputError(f"{loc}: {exc}") from None
    return spec.check(si, loc), str(entry.get("source", ""))


def _parse_column(entry: Any, unit: str, loc: str) -> np.ndarray:
    if not isinstance(entry, dict) or "values" not in entry or "unit" not in entry:
        raise InputError(f"{loc}: expected {{values: [...], unit: ...}}")
    try:
        vals = np.asarray(entry["values"], dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{loc}: values must be a list of numbers") from None
    if vals.ndim != 1 or vals.size < 2 or not np.all(np.isfinite(vals)):
        raise InputError(f"{loc}: values must be a list of at least 2 finite numbers")
    try:
        return to_si(vals, str(entry["unit"]), unit)
    except UnitError as exc:
        raise InputError(f"{loc}: {exc}") from None


def _parse_table(spec: TableSpec, entry: Any, loc: str) -> tuple[dict[str, np.ndarray], str]:
    if not isinstance(entry, dict):
        raise InputError(f"{loc}: a table is a mapping of columns {list(spec.columns)} and a source")
    unknown = set(entry) - set(spec.columns) - {"source", "note"}
    if unknown:
        raise InputError(f"{loc}: unknown column(s) {sorted(unknown)}; expected {list(spec.columns)}")
    cols = {}
    for c, unit in spec.columns.items():
        if c not in entry:
            raise InputError(f"{loc}: missing column {c!r} (unit compatible with {unit!r})")
        cols[c] = _parse_column(entry[c], unit, f"{loc}.{c}")
    n = {v.size for v in cols.values()}
    if len(n) != 1:
        raise InputError(f"{loc}: columns have different lengths")
    first = next(iter(cols.values()))
    if np.any(np.diff(first) <= 0):
        raise InputError(f"{loc}: the first column ({next(iter(cols))}) must be strictly increasing")
    return cols, str(entry.get("source", ""))


def _parse_maps(body: Any, where: str) -> dict[str, HumidityMap]:
    if not isinstance(body, dict):
        raise InputError(f"{where}: humidity_maps must map parameter names to tables")
    out = {}
    for pname, entry in body.items():
        loc = f"{where}: humidity_maps.{pname}"
        if not isinstance(entry, dict):
            raise InputError(f"{loc}: expected {{rh: ..., values: ..., mode: ratio|absolute, source: ...}}")
        unknown = set(entry) - {"rh", "values", "mode", "source", "note"}
        if unknown:
            raise InputError(f"{loc}: unknown key(s) {sorted(unknown)}")
        mode = entry.get("mode", "absolute")
        if mode not in ("ratio", "absolute"):
            raise InputError(f"{loc}: mode must be 'ratio' or 'absolute', got {mode!r}")
        specs = all_param_specs()
        if pname not in specs:
            raise InputError(f"{loc}: unknown parameter{_suggest(pname, specs)}")
        rh = _parse_column(entry.get("rh"), "pct", f"{loc}.rh")
        if np.any(np.diff(rh) <= 0) or rh[0] < 0 or rh[-1] > 100:
            raise InputError(f"{loc}.rh: RH must increase strictly within 0–100 %")
        vals = _parse_column(entry.get("values"), specs[pname].unit, f"{loc}.values")
        if vals.size != rh.size:
            raise InputError(f"{loc}: rh and values have different lengths")
        if np.any(vals <= 0):
            raise InputError(f"{loc}.values: humidity-mapped values must be positive")
        out[pname] = HumidityMap(pname, rh, vals, mode, str(entry.get("source", "")))
    return out
