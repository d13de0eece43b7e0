"""Free parameters: names, starting values, bounds and log/linear scaling."""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..device import all_param_specs
from ..errors import InputError, arg
from ..parameters import BASE_SECTIONS
from ..io.units import to_si
from .settings import DEFAULT_DECADES




def hint(name: str, effects) -> str:
    """Why parameter ``name`` may not act in a model with ``effects``: the effects that use it
    (their ``params``/``requires``), the effect whose parameter takes its role over (its
    diagnosis spec's ``roles``), per-RH fits (``per_rh``) and the effects' own ``hints``
    ({parameter: sentence}) — everything read from the effect modules."""
    from ..effects import EFFECTS
    on = set(effects)
    parts = [c.hints[name] for c in EFFECTS.values() if name in (getattr(c, "hints", None) or {})]
    owners = [e for e, c in EFFECTS.items() if any(q.name == name for q in c.params) or name in c.requires]
    if owners and not on & set(owners):
        parts.append(f"{name} is used only with {' or '.join(owners)}")
    for e, c in EFFECTS.items():
        spec = c.diagnosis or {}
        for role, (param, _) in spec.get("roles", {}).items():
            if param == name and e not in on:
                parts.append(f"{name} takes over the {role} only with {e}")
            elif param != name and e in on and name in _BASE_ROLES.get(role, ()):
                parts.append(f"with {e} on, {param} takes over the {role} from {name}")
        if name in spec.get("per_rh", ()):
            parts.append(f"with {e} it can be fitted once per RH level (per_rh)")
    return "; ".join(dict.fromkeys(parts))


#: The base's own parameters of each role (before an effect takes it over).
_BASE_ROLES = {"gain": ("kf",), "stiffness": ("Y",)}


def switchable(ids) -> tuple[str, ...]:
    """The effects of ``ids`` that can be switched off: all but the model's core (a stage
    default that carries an id, always on)."""
    from ..effects import CORE
    return tuple(e for e in ids if e not in CORE)


def held_per_rh(device, free: Sequence[str], per_rh: Sequence[str], levels: Sequence[float],
                rh: float) -> tuple:
    """(device, free, per_rh, notes): the shared parameters of ``free`` that ``device`` holds per
    RH — an absolute humidity map, as ``identify --per-rh`` writes it, leaves no shared value to
    fit — fitted once per RH level when the records span two or more ``levels``, else given
    the map's value at ``rh`` [%] as their shared value (the map dropped).  ``identify`` and
    ``diagnose`` both read such a file this way."""
    import dataclasses
    free, per, notes = list(free), list(per_rh), []
    for name in [n for n in free if n in device.humidity_maps and device.humidity_maps[n].mode == "absolute"]:
        free.remove(name)
        if len(levels) >= 2:
            if name not in per:
                per.append(name)
            notes.append(f"{name} is held per RH by the device (an absolute humidity map): fitted once per RH level")
        else:
            m = device.humidity_maps[name]
            v = float(np.interp(rh, m.rh, m.values))
            device = dataclasses.replace(device.with_params(**{name: v}),
                                         humidity_maps={k: x for k, x in device.humidity_maps.items() if k != name})
            free.append(name)
            notes.append(f"{name} is held per RH by the device (an absolute humidity map); one RH level: its value "
                         f"there ({v:.4g}) is the start of the shared value")
    return device, free, per, notes


class IdentifiabilityWarning(UserWarning):
    """A parameter is not (or poorly) determined by the data."""


# ============================================================================ parameters


def _section_of() -> dict[str, str]:
    from ..effects import EFFECTS
    out = {}
    for sec, specs in BASE_SECTIONS.items():
        for k in specs:
            out[k] = sec
    for eff in EFFECTS.values():
        for p in eff.params:
            out[p.name] = eff.id
    return out


@dataclass
class FreeParameter:
    """A free parameter in SI units. ``scale`` ``"log"`` searches x = ln θ, ``"linear"``
    x = θ; ``rh`` is the RH level [%] of a per-RH value (None: shared)."""

    name: str
    initial: float
    lower: float
    upper: float
    scale: str
    unit: str
    rh: float | None = None

    @property
    def label(self) -> str:
        return self.name if self.rh is None else f"{self.name}@RH{self.rh:g}"

    def to_x(self, theta):
        return np.log(theta) if self.scale == "log" else np.asarray(theta, dtype=float)

    def from_x(self, x):
        """SI value of search coordinate ``x``, held within [lower, upper]: exp(ln b) can land an
        ulp beyond the bound b, and a fit ending on its bound is a result, not an error."""
        v = np.exp(x) if self.scale == "log" else np.asarray(x, dtype=float)
        return np.clip(v, self.lower, self.upper)

    @property
    def x_bounds(self) -> tuple[float, float]:
        return float(self.to_x(self.lower)), float(self.to_x(self.upper))


def parse_names(text: str | Sequence[str] | None, what: str = arg("free")) -> list[str]:
    """``"kf,beta_f"`` or a list → names (duplicates refused)."""
    if text is None:
        return []
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if str(n).strip()]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"{what}: parameter(s) {', '.join(dup)} given twice")
    return names


def _value_with_unit(text: str, name: str, spec_unit: str, where: str) -> float:
    parts = text.strip().split(None, 1)
    try:
        v = float(parts[0])
    except (ValueError, IndexError):
        raise InputError(f"{where}: {name}={text!r}: expected a number, optionally followed by a unit "
                         f"(SI unit {spec_unit!r})") from None
    if len(parts) == 2:
        try:
            v = to_si(v, parts[1], spec_unit)
        except Exception as exc:
            raise InputError(f"{where}: {name}={text!r}: {exc}") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: {name}={text!r} is not finite")
    return float(v)


def parse_assignments(text: str | Mapping | None, *, ranges: bool = False, what: str = arg("start")) -> dict:
    """``"kf=0.004,Y=0.2 GPa"`` → {name: SI value}; with ``ranges`` ``"kf=1e-4:1e-1"`` →
    {name: (lo, hi)} (a unit after the range applies to both ends).  SI when no unit."""
    if text is None:
        return {}
    specs = all_param_specs()
    items = text.items() if isinstance(text, Mapping) else \
        [tuple(s.split("=", 1)) if "=" in s else (s, None) for s in text.split(",") if s.strip()]
    out = {}
    for name, val in items:
        name = str(name).strip()
        if val is None:
            raise InputError(f"{what}: item {name!r} must look like name=value")
        if name not in specs:
            raise InputError(f"{what}: unknown parameter {name!r}{_suggest(name, specs)}")
        unit = specs[name].unit
        if ranges:
            if isinstance(val, (tuple, list)):
                lo, hi = (float(v) for v in val)
            else:
                body, _, u = str(val).strip().partition(" ")
                if ":" not in body:
                    raise InputError(f"{what}: {name}={val!r}: expected lo:hi, e.g. {name}=1e-4:1e-1")
                a, b = body.split(":", 1)
                lo = _value_with_unit(f"{a} {u}".strip(), name, unit, what)
                hi = _value_with_unit(f"{b} {u}".strip(), name, unit, what)
            if not lo < hi:
                raise InputError(f"{what}: {name}: lower bound {lo:g} must be below upper bound {hi:g}")
            out[name] = (lo, hi)
        else:
            out[name] = float(val) if isinstance(val, (int, float)) else _value_with_unit(str(val), name, unit, what)
    return out


def _suggest(key: str, known) -> str:
    close = difflib.get_close_matches(key, list(known), n=3)
    return f" (did you mean {', '.join(close)}?)" if close else ""


def _default_scale(spec) -> str:
    """Linear search for fractions in [0, 1] and for parameters that may be negative, else log."""
    return "linear" if spec.lo < 0 or (spec.unit == "1" and spec.lo >= 0 and spec.hi <= 1) else "log"


def _make_param(name, initial, spec, bounds, rh=None) -> FreeParameter:
    scale = _default_scale(spec)
    where = f"parameter {name}" + (f" at RH {rh:g} %" if rh is not None else "")
    if bounds is not None:
        lo, hi = bounds
        if lo < spec.lo or hi > spec.hi:
            raise InputError(f"bounds of {name}: [{lo:g}, {hi:g}] {spec.unit} leave the admissible range "
                             f"[{spec.lo:g}, {spec.hi:g}] {spec.unit}")
    elif scale == "log":
        if initial <= 0:
            raise InputError(f"{where}: start value {initial:g} {spec.unit} is not positive; it is searched "
                             f"in log space: give a positive start value ({arg('start')}: {name}=...)")
        lo = max(spec.lo, initial * 10 ** -DEFAULT_DECADES)
        hi = min(spec.hi, initial * 10 ** DEFAULT_DECADES)
    else:
        lo, hi = spec.lo, spec.hi
    if scale == "log" and lo <= 0:
        if bounds is not None:
            raise InputError(f"bounds of {name}: the lower bound must be positive (log-space search)")
    if not (lo <= initial <= hi):
        raise InputError(f"{where}: start value {initial:g} {spec.unit} is outside its bounds "
                         f"[{lo:g}, {hi:g}] {spec.unit}")
    return FreeParameter(name, float(initial), float(lo), float(hi), scale, spec.unit, rh)


# ============================================================================ targets


