"""Predictors: one contract for physics models and trained networks, y = predictor(voltage, rh, fs)."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..errors import InputError
from ..model import ActuatorModel


class Predictor:
    """Interface shared by physics and neural models (see the module doc).

    Subclasses implement :meth:`__call__`; those with a closed-form small-signal response
    also implement :meth:`frequency_response`.  ``name`` labels plots and reports,
    :meth:`describe` returns JSON-ready information (device, effects, card...)."""

    name: str = "model"
    #: measured samples at a record's start the model is handed to start from (its start-up
    #: window, ``offset="start"`` of :func:`~physics.compare.compare`); 0: it starts from rest
    start_samples: int = 0
    #: True for a model of the measured (sensor) output itself, e.g. a network trained on
    #: measurements: no sensor low-pass is added to it (``sensor_bandwidth="auto"``)
    measured_output: bool = False

    def run_record(self, ts, rh) -> np.ndarray:
        """The output for a measured record ``ts`` (``rh``: the RH a model is given, see
        :func:`~physics.compare.model_rh`); a model that starts from the measured outputs of
        its start-up window reads them here."""
        return self(ts.voltage, rh, ts.fs)

    def __call__(self, voltage: np.ndarray, rh, fs: float) -> np.ndarray:
        """Tip deflection [m] for ``voltage`` [V] sampled at ``fs`` [Hz] from t = 0, at
        ``rh`` [%] (constant or per sample)."""
        raise NotImplementedError

    def frequency_response(self, freq: np.ndarray, rh: float) -> np.ndarray | None:
        """Closed-form deflection per volt [m/V] at ``freq`` [Hz], or ``None``."""
        return None

    @property
    def has_closed_form(self) -> bool:
        return type(self).frequency_response is not Predictor.frequency_response

    def describe(self) -> dict:
        return {"name": self.name, "kind": type(self).__name__}


class PhysicsPredictor(Predictor):
    """A physics model (device + effects): :func:`physics.solvers.timedomain.simulate` in time
    (``hold``: input interpolation, ``cubic`` for smooth records, ``linear`` for steps),
    :func:`physics.solvers.frequency.frequency_response` in frequency."""

    def __init__(self, model: ActuatorModel, hold: str = "cubic"):
        if not isinstance(model, ActuatorModel):
            raise InputError(f"PhysicsPredictor needs an ActuatorModel, got {type(model).__name__}")
        if hold not in ("cubic", "linear"):
            raise InputError(f"hold must be 'cubic' or 'linear', got {hold!r}")
        self.model = model
        self.hold = hold
        self.name = f"{model.device.name} [{', '.join(model.effect_ids)}]"

    @classmethod
    def from_device(cls, device, effects=None, *, n_modes: int = 4, hold: str = "cubic") -> "PhysicsPredictor":
        return cls(ActuatorModel(device, effects, n_modes=n_modes), hold=hold)

    def __call__(self, voltage, rh, fs):
        from ..solvers.timedomain import simulate
        v = np.asarray(voltage, dtype=float)
        t = np.arange(v.size) / float(fs)
        return simulate(self.model, None, t, v, rh=rh, hold=self.hold).deflection

    def frequency_response(self, freq, rh):
        from ..solvers.frequency import frequency_response
        return frequency_response(self.model, None, np.asarray(freq, dtype=float), rh=rh).deflection

    def describe(self) -> dict:
        d = self.model.device
        return {"name": self.name, "kind": "physics", "device": d.name, "device_file": d.path,
                "effects": list(self.model.effect_ids), "n_modes": self.model.n_modes, "hold": self.hold}


class CallablePredictor(Predictor):
    """Any function ``fn(voltage [V], rh [%], fs [Hz]) -> deflection [m]`` (e.g. a neural
    model bundle's ``predict``); ``info`` is reported as is."""

    def __init__(self, fn: Callable[[np.ndarray, Any, float], np.ndarray], name: str = "model",
                 info: dict | None = None, *, record_fn: Callable | None = None, start_samples: int = 0,
                 measured_output: bool = False):
        if not callable(fn):
            raise InputError(f"CallablePredictor needs a callable, got {type(fn).__name__}")
        self.fn, self.name, self.info = fn, str(name), dict(info or {})
        self.record_fn, self.start_samples, self.measured_output = record_fn, int(start_samples), measured_output

    def __call__(self, voltage, rh, fs):
        return self.fn(voltage, rh, fs)

    def run_record(self, ts, rh):
        return self.fn(ts.voltage, rh, ts.fs) if self.record_fn is None else self.record_fn(ts, rh)

    def describe(self) -> dict:
        return {"name": self.name, "kind": "callable", **self.info}


def _check_output(y, n: int, who: str) -> np.ndarray:
    arr = np.asarray(y, dtype=float).reshape(-1) if y is not None else None
    if arr is None or arr.size != n:
        raise InputError(f"model {who} returned {None if arr is None else arr.size} samples for an "
                         f"input of {n}; a predictor must return one deflection [m] per voltage sample")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"model {who} returned NaN or infinite deflections")
    return arr
