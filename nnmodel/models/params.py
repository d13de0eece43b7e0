"""Hyper-parameters: value checks, and the settings parts a model composes.

A model's hyper-parameters are its constructor's own arguments (what the network *is*:
lags, layers, centres ...) plus the fields of the settings *parts* it composes, one
dataclass each (:data:`nnmodel.models.base.PARTS`): how it is trained
(:class:`~.config.TrainingConfig`), which input features it sees
(:class:`~.features.InputFeatures`: memory filters, RH knots), which structures it tries
(:class:`~.structure.StructureSearch`).  Recipes, ``--set`` and bundle cards keep every
hyper-parameter as one flat key (``max_epochs: 200``, ``memory_filters: 16``); the model
routes it to its part, and reads and writes it as an attribute through :class:`PartField`.
"""
from __future__ import annotations

import math
from dataclasses import asdict, fields
from typing import Callable, ClassVar

import numpy as np

from physics.errors import InputError

__all__ = ["pos_int", "pos_float", "flag", "size", "Part", "PartField", "check_values", "MAX_PARAMETERS"]

#: Size caps, checked before anything is allocated (a bundle card is input like any file):
#: lags, widths, depth, centres, states ... and the learned parameters of a whole network.
MAX_LAGS = 1000
MAX_WIDTH = 4096
MAX_LAYERS = 64
MAX_CENTRES = 20000
MAX_FILTERS = 256
MAX_STATES = 1000
MAX_PARAMETERS = 50_000_000

Check = Callable[[object], "str | None"]


def pos_int(v, zero: bool = False) -> str | None:
    """None for a positive (``zero``: non-negative) whole number, else what was expected."""
    ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and (v >= 0 if zero else v >= 1)
    return None if ok else ("a non-negative integer" if zero else "a positive integer")


def size(most: int, zero: bool = False) -> Check:
    """Check of a size parameter: a positive (``zero``: non-negative) whole number up to ``most``."""
    def check(v):
        return pos_int(v, zero) or (None if v <= most else f"at most {most:,} (a size cap; larger networks "
                                                                  "are refused before anything is allocated)")
    return check


def pos_float(v, zero: bool = False) -> str | None:
    """None for a finite positive (``zero``: non-negative) number, else what was expected."""
    ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and math.isfinite(v) \
        and (v >= 0 if zero else v > 0)
    return None if ok else ("a non-negative number" if zero else "a positive number")


def flag(v) -> str | None:
    return None if isinstance(v, bool) else "true or false"


def check_values(kind: str, values: dict, checks: dict[str, Check]) -> None:
    """Raise an :class:`InputError` naming the first value that fails its check."""
    for name, value in values.items():
        chk = checks.get(name)
        msg = chk(value) if chk is not None else None
        if msg:
            raise InputError(f"model {kind!r}: hyper-parameter {name}={value!r} is invalid; expected {msg}")


class Part:
    """Base of the settings parts (dataclasses).  ``ATTR`` is the model attribute holding
    the part (``model.training``); ``CHECKS`` maps a field to its value check."""

    ATTR: ClassVar[str] = ""
    CHECKS: ClassVar[dict[str, Check]] = {}

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in fields(cls))

    @classmethod
    def build(cls, kind: str, defaults: dict, given: dict) -> "Part":
        """The part of a model of ``kind``: the dataclass defaults, then the model class's
        ``defaults`` for these fields, then the ``given`` values."""
        mine = set(cls.names())
        return cls(**{k: v for k, v in {**defaults, **given}.items() if k in mine})

    def values(self) -> dict:
        return asdict(self)

    def validate(self, kind: str) -> None:
        check_values(kind, self.values(), self.CHECKS)


class PartField:
    """Descriptor: ``model.max_epochs`` reads and writes ``model.training.max_epochs`` (one
    descriptor per part field, installed on the model base class)."""

    def __init__(self, part: str, name: str):
        self.part, self.name = part, name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        return getattr(obj.__dict__[self.part], self.name)

    def __set__(self, obj, value):
        setattr(obj.__dict__[self.part], self.name, value)
