"""The effect interface.

An effect is a switchable piece of physics with a stable ``id``.  Each effect fills a
*slot* of the model chain (see :mod:`physics.model`); every slot has an explicit
"off" variant, so a model is always a plain list of effect objects that can be read
back (``model.effects``).  Effects declare the parameters they need; the device loader
validates them and the model refuses to build when an enabled effect lacks one.
"""
from __future__ import annotations

from typing import ClassVar

from ..errors import InputError
from ..parameters import ParamSpec, TableSpec


class Effect:
    """Base class of all effect variants (the "on" variants carry an ``id``)."""

    id: ClassVar[str | None] = None
    slot: ClassVar[str]
    enabled: ClassVar[bool] = True
    summary: ClassVar[str] = ""
    explanation: ClassVar[str] = ""
    params: ClassVar[tuple[ParamSpec, ...]] = ()     # parameters owned by this effect (own section)
    tables: ClassVar[tuple[TableSpec, ...]] = ()
    requires: ClassVar[tuple[str, ...]] = ()         # further parameter names needed (any section)
    linear: ClassVar[bool] = True                   # False: large-signal behaviour in the time domain only

    def __init__(self, device):
        self.device = device
        missing = [n for n in self.needed() if not device.has(n)]
        if missing:
            where = f"section {self.id!r}" if self.id else "the device file"
            raise InputError(f"{type(self).__name__} needs {', '.join(missing)} in {where} of device "
                             f"{device.name!r} ({device.path or 'in memory'})")

    @classmethod
    def needed(cls) -> list[str]:
        return [p.name for p in cls.params if not p.optional] + [t.name for t in cls.tables if not t.optional] \
            + list(cls.requires)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    @property
    def label(self) -> str:
        return self.id if self.id else f"{type(self).__name__} (off)"
