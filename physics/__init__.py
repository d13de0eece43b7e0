"""Physics of ionic electroactive-polymer actuators (IPMC, IP2C): device parameters,
switchable physical effects, frequency- and time-domain solvers, signals, measurements.

Quick start::

    import numpy as np, physics
    fr = physics.frequency_response("ipmc_pt_eg", ["electrode_resistance"], np.logspace(-1, 1.7, 200), rh=100)
    t = np.arange(0, 10, 1e-3)
    res = physics.simulate("ipmc_pt_eg", "default", t, 2 * np.sin(2 * np.pi * t), rh=60)
"""
from ._version import __version__

#: Public name -> module that defines it; imported on first use (PEP 562), so that
#: ``import physics`` (or ``physics.errors``) does not pull in SciPy, the solvers and the effects.
_LAZY = {
    "ActuatorModel": "physics.model",
    "ContractReport": "physics.contract", "check_effect": "physics.contract",
    "Device": "physics.device", "available_devices": "physics.device", "load_device": "physics.device",
    "EFFECTS": "physics.effects",
    "InputError": "physics.errors", "ModelError": "physics.errors",
    "FrequencyResponse": "physics.solvers.frequency", "frequency_response": "physics.solvers.frequency",
    "SimulationResult": "physics.solvers.timedomain", "simulate": "physics.solvers.timedomain",
}

__all__ = ["__version__", *sorted(_LAZY)]


def __getattr__(name: str):
    """Import a public name's module on first access (PEP 562)."""
    import importlib
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if not name.startswith("_"):          # a subpackage or module, e.g. physics.device
        try:
            return importlib.import_module(f"physics.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"physics.{name}":
                raise
    raise AttributeError(f"module 'physics' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
