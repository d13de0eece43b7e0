"""What :func:`physics.effects.register` checks of an effect class before it joins the catalog
(the first check of the contract, :mod:`physics.contract`)."""
from __future__ import annotations

import inspect

from .base import DIAGNOSIS_KEYS, REFERENCE, REVEAL_RULES, Effect, InputEffect, LoadEffect, OutputEffect
from .catalog import BUILT_IN, CHAIN, adds_factors, stage_of


def declaration_problems(cls, *, user: bool = True) -> list[str]:
    """What is wrong with the declaration of effect class ``cls`` (empty: nothing).  ``user``:
    checked as a user effect (its id is not a built-in one, every parameter has a default)."""
    if not (inspect.isclass(cls) and issubclass(cls, Effect)):
        return ["a user effect must subclass physics.effects.OutputEffect, LoadEffect, InputEffect (or Effect)"]
    out = []
    if not isinstance(cls.id, str) or not cls.id.isidentifier():
        out.append(f"needs an id that is a Python identifier, got {cls.id!r}")
    elif user and cls.id in BUILT_IN:
        out.append(f"id {cls.id!r} is a built-in effect; choose another id")
    if issubclass(cls, OutputEffect):
        if cls.output_tf is OutputEffect.output_tf and cls.filter_output is OutputEffect.filter_output:
            out.append("define output_tf(self, p) (or filter_output and output_response)")
    elif issubclass(cls, LoadEffect):
        if cls.load_tf is LoadEffect.load_tf and cls.load_factor is LoadEffect.load_factor:
            out.append("define load_tf(self, p) (or load_factor(self, s, p))")
    elif issubclass(cls, InputEffect):
        if cls.filter_input is InputEffect.filter_input:
            out.append("define filter_input(self, v, fs, p)")
    elif stage_of(cls) is None and not adds_factors(cls):
        out.append(f"an effect must replace a stage (subclass one of {', '.join(c.__name__ for c in CHAIN)}) or "
                   "define load_factor(self, s, p); the simplest is a subclass of OutputEffect or LoadEffect")
    if user:
        out += [f"parameter {s.name!r} needs a default (ParamSpec(..., default=...))"
                for s in cls.params if s.default is None]
    ref = cls.__dict__.get("reference", cls.reference)
    if ref not in REFERENCE:
        out.append(f"reference must be one of {', '.join(REFERENCE)}, got {ref!r}")
    known = {s.name for s in cls.params}
    spec = cls.diagnosis
    if spec is not None:
        if not isinstance(spec, dict) or "free" not in spec or (user and not spec["free"]):
            return out + ["diagnosis must be a dict with at least 'free' (parameters to fit)"]
        unknown = sorted(set(spec) - set(DIAGNOSIS_KEYS))
        if unknown:
            out.append(f"unknown diagnosis key(s) {unknown}; known: {', '.join(DIAGNOSIS_KEYS)}")
        names = [*spec["free"], *spec.get("shape", ()), *spec.get("refine", ()), *spec.get("bounds", {})]
        bad = [n for n in names if n not in known | set(cls.requires)]
        if user and bad:
            out.append(f"diagnosis names parameters {bad} that the effect does not declare")
        shows = spec.get("shows_as", ())
        if not isinstance(shows, (tuple, list)) or not all(isinstance(f, str) for f in shows):
            out.append(f"diagnosis 'shows_as' must be a tuple of residual-form ids, got {shows!r}")
        bad_rules = sorted(set(spec.get("reveal", {})) - set(REVEAL_RULES))
        if bad_rules:
            out.append(f"unknown reveal rule(s) {bad_rules}; known: {', '.join(REVEAL_RULES)}")
    return out
