"""Physics of ionic electroactive-polymer actuators (IPMC, IP2C): device parameters,
switchable physical effects, frequency- and time-domain solvers, signals, measurements.

Quick start::

    import numpy as np, physics
    fr = physics.frequency_response("ipmc_pt_eg", ["electrode_resistance"], np.logspace(-1, 1.7, 200), rh=100)
    t = np.arange(0, 10, 1e-3)
    res = physics.simulate("ipmc_pt_eg", "default", t, 2 * np.sin(2 * np.pi * t), rh=60)
"""
from ._version import __version__
from .contract import ContractReport, check_effect     # also installs physics.effects.check_effect
from .device import Device, available_devices, load_device
from .effects import EFFECTS
from .errors import InputError, ModelError
from .frequency import FrequencyResponse, frequency_response
from .model import ActuatorModel
from .timedomain import SimulationResult, simulate

__all__ = ["__version__", "ActuatorModel", "ContractReport", "Device", "EFFECTS", "FrequencyResponse", "InputError", "ModelError",
           "SimulationResult", "available_devices", "check_effect", "frequency_response", "load_device", "simulate"]
