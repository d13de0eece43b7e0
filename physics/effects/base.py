"""The effect interface.

An effect is a switchable piece of physics with a stable ``id``.  Each effect fills a
*slot* of the model chain (see :mod:`physics.model`); every slot has an explicit
"off" variant, so a model is always a plain list of effect objects that can be read
back (``model.effects``).  Effects declare the parameters they need; the device loader
validates them and the model refuses to build when an enabled effect lacks one.
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

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
    #: Plain-data diagnosis spec of an effect added by a user (see :class:`OutputEffect`).
    diagnosis: ClassVar[dict | None] = None

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

    def value(self, p: dict, name: str) -> float:
        """Parameter ``name`` from the parameters ``p`` (SI), else its declared default."""
        if name in p:
            return float(p[name])
        spec = next((s for s in self.params if s.name == name), None)
        if spec is None or spec.default is None:
            raise InputError(f"effect {self.id!r}: no value for {name!r} (add it to section {self.id!r} of the "
                             "device file or declare a default)")
        return float(spec.default)


class OutputEffect(Effect):
    """An effect acting on the tip deflection after the rest of the chain: the contract
    for effects added by users (``--effects-path FILE.py``, entry points ``eap.effects``).

    Subclass it in one file with an ``id``, a ``summary``, the ``params`` (each with a
    ``default``) and :meth:`output_tf`, the transfer function (numerator, denominator
    polynomials in s, highest power first) multiplying the deflection.  Both solvers call
    it: the frequency solver multiplies the response by it, the time solver filters the
    simulated deflection with its Tustin discretisation (accurate for frequencies well
    below the sampling rate).  ``diagnosis`` (a plain dict) makes it a diagnosis candidate:

    ``free``: its parameters to fit; ``bounds``: {name: (lo, hi)}; ``starts``: a list of
    {name: value} start points; ``nested``: True when some parameter value switches it off;
    ``excitation``: the excitation that reveals it (text).
    See ``examples/effects/creep.py``.
    """

    slot = "output"
    summary = "user-defined output effect"

    @classmethod
    def needed(cls) -> list[str]:
        return [p.name for p in cls.params if not p.optional and p.default is None] + list(cls.requires)

    def output_tf(self, p: dict) -> tuple[list[float], list[float]]:
        """(numerator, denominator) in s of the factor on the deflection; parameters ``p`` in SI."""
        raise NotImplementedError

    def output_response(self, s: np.ndarray, p: dict) -> np.ndarray:
        """The factor at complex frequencies ``s`` [rad/s]."""
        num, den = self.output_tf(p)
        return np.polyval(num, s) / np.polyval(den, s)

    def filter_output(self, y: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The deflection ``y`` [m] sampled at ``fs`` [Hz] through the factor, started in the
        steady state of the first sample (as the rest of the chain)."""
        from scipy.signal import bilinear, lfilter, lfilter_zi
        num, den = self.output_tf(p)
        b, a = bilinear(num, den, fs)
        if len(a) == 1:
            return b[0] / a[0] * np.asarray(y, float)
        return lfilter(b, a, y, zi=lfilter_zi(b, a) * y[0])[0]
