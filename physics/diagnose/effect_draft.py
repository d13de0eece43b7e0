"""The text of a drafted effect file: its parameters and the effect source.

An :class:`EffectDraft` is what a residual form (:mod:`.forms`) writes as an effect: rendered
here as one Python file following the effect contract (:class:`physics.effects.OutputEffect`,
or :class:`physics.effects.InputEffect` for a map of the drive voltage; the how-to "Write an
effect"): the fitted values as parameter defaults, the ``diagnosis`` spec filled in (free
parameters, bounds and starts around the fitted values, the off values, the excitation and
reveal rule, the residual signature) and a docstring saying what was seen, with numbers and
units.  It imports nothing of the diagnosis, so the forms and :mod:`.draft` (which
selects and writes the drafts) both build on it.
"""
from __future__ import annotations

import math
import pprint
import textwrap
from dataclasses import dataclass, field

import numpy as np


#: How a drafted parameter's search range follows its value v: ``log`` v/30…30·v, ``zero``
#: v/1000…20·v (its off value 0 lies just below), ``signed`` −10|v|…10|v|, ``fixed`` its
#: admissible range; a (lo, hi) pair: that search range whatever v (starts spread over it).
RANGES = ("log", "zero", "signed", "fixed")


@dataclass
class Param:
    """A drafted effect parameter: admissible range [lo, hi], value ``default`` (SI) and how
    its search range follows it (:data:`RANGES`)."""

    name: str
    unit: str
    lo: float
    hi: float
    description: str
    default: float
    range: str | tuple = "log"

    @property
    def bounds(self) -> tuple[float, float]:
        v = self.default
        if isinstance(self.range, tuple):
            return max(min(self.range[0], v), self.lo), min(max(self.range[1], v), self.hi)
        lo, hi = {"log": (v / 30.0, v * 30.0), "zero": (v / 1000.0, 20.0 * v), "signed": (-10 * abs(v), 10 * abs(v)),
                  "fixed": (self.lo, self.hi)}[self.range]
        return max(lo, self.lo), min(hi, self.hi)


@dataclass
class EffectDraft:
    """What a form writes as an effect (see the module doc)."""

    form: str
    effect_id: str
    class_name: str
    summary: str
    model: str
    params: list[Param]
    scan: str                        # the parameter started at its value, /3 and ×3 (unknown scale)
    off: dict
    excitation: str
    reveal: dict
    signature: list[tuple[str, float]]
    body: str
    imports: tuple[str, ...] = ()
    seen: str = ""
    evidence: dict = field(default_factory=dict)
    base: str = "OutputEffect"       # the effect class it subclasses (physics.effects)
    starts: list = field(default_factory=list)    # further start points {param: value} (SI)

    def refit(self, values: dict) -> None:
        """Take ``values`` (fitted jointly with the model) as the defaults; bounds and starts follow."""
        for p in self.params:
            if p.name in values:
                p.default = float(min(max(float(values[p.name]), p.lo), p.hi))

    @property
    def file_name(self) -> str:
        return f"{self.effect_id}.py"

    def diagnosis(self) -> dict:
        return {"free": tuple(p.name for p in self.params),
                "bounds": {p.name: tuple(_num(b) for b in p.bounds) for p in self.params},
                "starts": [{self.scan: _num(v)} for v in self.scan_values()]
                + [{k: _num(v) for k, v in st.items()} for st in self.starts],
                "nested": True, "off": {k: _num(v) for k, v in self.off.items()},
                "excitation": self.excitation, "reveal": {k: _num(v) for k, v in self.reveal.items()},
                "signature": [tuple(s) for s in self.signature]}

    def scan_values(self) -> list[float]:
        p = next(q for q in self.params if q.name == self.scan)
        lo, hi = p.bounds
        if isinstance(p.range, tuple) and lo > 0:
            return [p.default] + [float(x) for x in np.geomspace(lo, hi, 6)[:-1]]
        return [min(max(p.default * k, lo), hi) for k in (1.0, 1 / 3.0, 3.0)]

    def source(self) -> str:
        """The effect file's text."""
        doc = "\n\n".join(textwrap.fill(par, 96, break_on_hyphens=False, break_long_words=False) for par in (
            f"{self.summary[0].upper()}{self.summary[1:]} — drafted by `eap diagnose --draft-effects` from what "
            "remained after the best model.",
            f"What was seen: {self.seen}",
            f"Model: {self.model}",
            "Check it with the contract tests (``physics.effects.check_effect``; the how-to \"Write an effect\") "
            "and pass it back with "
            f"``--effects-path {self.file_name}``; edit the defaults, bounds and docstring as you learn more."))
        params = "\n".join(f"        ParamSpec({p.name!r}, {p.unit!r}, {_num(p.lo)!r}, {_num(p.hi)!r}, {p.description!r},"
                           f"\n                  optional=True, default={_num(p.default)!r}),"
                           for p in self.params)
        spec = pprint.pformat(self.diagnosis(), width=100, sort_dicts=False)
        spec = textwrap.indent(spec, " " * 16).strip()
        imports = "".join(f"{line}\n" for line in self.imports)
        return (f'"""{doc}\n"""\n'
                f"{imports}from physics.effects import {self.base}\n"
                "from physics.parameters import ParamSpec\n\n\n"
                f"class {self.class_name}({self.base}):\n"
                f"    id = {self.effect_id!r}\n"
                f"    summary = {self.summary!r}\n"
                f"    explanation = __doc__\n"
                f"    params = (\n{params}\n    )\n"
                f"    diagnosis = {spec}\n\n"
                f"{self.body}")


def _num(x: float) -> float:
    """A value rounded to 4 significant digits for a readable file."""
    x = float(x)
    return float(f"{x:.4g}") if math.isfinite(x) and x != 0 else x


__all__ = ["EffectDraft", "Param", "RANGES"]
