"""Parsing of unit strings into SI scale factors and dimensions.

A unit string is a product of unit symbols with optional integer or decimal powers,
``/`` dividing by the next factor or parenthesised group, e.g. ``"N m/mol"``,
``"W/(m^2 K)"``, ``"m^2/s"``, ``"g/cm^3"``, ``"1/s"``, ``"1"``.  ``"J/kg K"`` is
rejected as ambiguous: write ``"J/(kg K)"``.  Temperatures are absolute and given in
``K`` or ``degC`` (the only affine unit, allowed alone only).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

# Dimension exponents over the SI base quantities (m, kg, s, A, K, mol).
_BASE = ("m", "kg", "s", "A", "K", "mol")


@dataclass(frozen=True)
class Quantity:
    """A unit as an SI scale factor and a dimension vector."""

    factor: float
    dim: tuple[float, ...]

    def __mul__(self, other: "Quantity") -> "Quantity":
        return Quantity(self.factor * other.factor, tuple(a + b for a, b in zip(self.dim, other.dim)))

    def __truediv__(self, other: "Quantity") -> "Quantity":
        return Quantity(self.factor / other.factor, tuple(a - b for a, b in zip(self.dim, other.dim)))

    def __pow__(self, p: float) -> "Quantity":
        return Quantity(self.factor ** p, tuple(a * p for a in self.dim))

    def same_dimension(self, other: "Quantity") -> bool:
        return np.allclose(self.dim, other.dim)

    def describe(self) -> str:
        parts = [f"{b}^{e:g}" if e != 1 else b for b, e in zip(_BASE, self.dim) if e != 0]
        return " ".join(parts) or "dimensionless"


def _q(factor: float, **dims: float) -> Quantity:
    return Quantity(factor, tuple(float(dims.get(b, 0.0)) for b in _BASE))


_ONE = _q(1.0)
_M, _KG, _S, _A, _K, _MOL = (_q(1.0, **{b: 1}) for b in _BASE)
_N = _KG * _M / _S ** 2
_J = _N * _M
_W = _J / _S
_V = _W / _A
_OHM = _V / _A
_C = _A * _S

_UNITS: dict[str, Quantity] = {
    "1": _ONE, "rad": _ONE, "pct": _q(0.01), "%": _q(0.01),
    "m": _M, "cm": _q(1e-2, m=1), "mm": _q(1e-3, m=1), "um": _q(1e-6, m=1), "µm": _q(1e-6, m=1),
    "nm": _q(1e-9, m=1), "km": _q(1e3, m=1),
    "kg": _KG, "g": _q(1e-3, kg=1),
    "s": _S, "ms": _q(1e-3, s=1), "us": _q(1e-6, s=1), "min": _q(60.0, s=1), "h": _q(3600.0, s=1),
    "Hz": _ONE / _S, "kHz": _q(1e3, s=-1),
    "A": _A, "mA": _q(1e-3, A=1), "uA": _q(1e-6, A=1),
    "K": _K,
    "mol": _MOL, "mmol": _q(1e-3, mol=1),
    "L": _q(1e-3, m=3),
    "N": _N, "J": _J, "kJ": _q(1e3) * _J, "W": _W, "mW": _q(1e-3) * _W,
    "Pa": _N / _M ** 2, "kPa": _q(1e3) * _N / _M ** 2, "MPa": _q(1e6) * _N / _M ** 2,
    "GPa": _q(1e9) * _N / _M ** 2,
    "V": _V, "mV": _q(1e-3) * _V,
    "ohm": _OHM, "Ohm": _OHM, "Ω": _OHM, "kohm": _q(1e3) * _OHM,
    "S": _ONE / _OHM, "mS": _q(1e-3) / _OHM,
    "F": _C / _V, "mF": _q(1e-3) * _C / _V, "uF": _q(1e-6) * _C / _V,
    "C": _C,
}

_TOKEN = re.compile(r"\s*(\(|\)|/|\*|\^\s*-?\d+(?:\.\d+)?|[A-Za-zµΩ%][A-Za-z0-9µΩ%]*|1)")


class UnitError(ValueError):
    """A unit string that cannot be parsed."""


def parse_unit(text: str) -> Quantity:
    """Parse a unit string into a :class:`Quantity` (SI factor and dimension)."""
    if not isinstance(text, str) or not text.strip():
        raise UnitError(f"empty unit {text!r}")
    s = text.strip()
    if s in ("degC", "°C", "C_abs"):
        raise UnitError("degC is affine; use parse_temperature for absolute temperatures")
    tokens, pos = [], 0
    while pos < len(s):
        m = _TOKEN.match(s, pos)
        if not m:
            raise UnitError(f"cannot parse unit {text!r} at {s[pos:]!r}")
        tokens.append(m.group(1).replace(" ", ""))
        pos = m.end()
    q, rest = _parse_product(tokens, text)
    if rest:
        raise UnitError(f"cannot parse unit {text!r}: unexpected {''.join(rest)!r}")
    return q


def _parse_product(tokens: list[str], text: str) -> tuple[Quantity, list[str]]:
    q = _ONE
    divide_next = False
    after_division = False
    while tokens and tokens[0] != ")":
        tok = tokens[0]
        if tok == "/":
            if divide_next:
                raise UnitError(f"cannot parse unit {text!r}: '//'")
            divide_next, tokens = True, tokens[1:]
            continue
        if tok == "*":
            tokens = tokens[1:]
            continue
        if after_division and not divide_next:
            raise UnitError(f"ambiguous unit {text!r}: after '/' group the denominator in parentheses, "
                            f"e.g. 'J/(kg K)'")
        factor, tokens = _parse_factor(tokens, text)
        if divide_next:
            q, divide_next, after_division = q / factor, False, True
        else:
            q = q * factor
    if divide_next:
        raise UnitError(f"cannot parse unit {text!r}: '/' at the end")
    return q, tokens


def _parse_factor(tokens: list[str], text: str) -> tuple[Quantity, list[str]]:
    tok, tokens = tokens[0], tokens[1:]
    if tok == "(":
        q, tokens = _parse_product(tokens, text)
        if not tokens or tokens[0] != ")":
            raise UnitError(f"cannot parse unit {text!r}: missing ')'")
        tokens = tokens[1:]
    elif tok in _UNITS:
        q = _UNITS[tok]
    else:
        raise UnitError(f"unknown unit symbol {tok!r} in {text!r}")
    if tokens and tokens[0].startswith("^"):
        q = q ** float(tokens[0][1:])
        tokens = tokens[1:]
    return q, tokens


def to_si(value, unit: str, expected: str | None = None):
    """Convert ``value`` given in ``unit`` to SI; check the dimension against the
    unit string ``expected`` if given.  Absolute temperatures accept ``K`` or ``degC``.
    Raises :class:`UnitError` with a message naming both units on a mismatch."""
    if expected == "K" and unit.strip() in ("degC", "°C"):
        return np.asarray(value, dtype=float) + 273.15 if np.ndim(value) else float(value) + 273.15
    q = parse_unit(unit)
    if expected is not None:
        e = parse_unit(expected)
        if not q.same_dimension(e):
            raise UnitError(f"unit {unit!r} ({q.describe()}) is not compatible with {expected!r} "
                            f"({e.describe()})")
        q = Quantity(q.factor / e.factor, q.dim)  # express in the expected unit's scale
    if np.ndim(value):
        return np.asarray(value, dtype=float) * q.factor
    return float(value) * q.factor
