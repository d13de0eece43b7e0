"""The typed protocol of each stage of the model chain (:data:`physics.effects.CHAIN`).

A stage is filled by its "no effect" default or by the one switched-on effect that replaces
it (subclasses the default and overrides these hooks).  The solvers call the hooks through
:meth:`physics.model.ActuatorModel.hook`.  Arguments: ``s`` complex frequencies [rad/s]
(array), ``p`` the parameters in SI at the current RH (dict), ``d`` the double layer's
derived quantities (:class:`~physics.effects.double_layer.DoubleLayerProps`), ``edges``
segment edges along the free length [m].  :data:`STAGE_PROTOCOLS` maps each stage name to
its protocol; :func:`physics.effects.check_effect` checks a stage replacement against it.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class DoubleLayerStage(Protocol):
    """``double_layer`` (always on): the linearised PNP branch."""

    def props(self, p: dict, T=None):
        """Derived double-layer quantities at temperature ``T`` [K] (None: T_ext)."""

    def realize(self, d, w_hi: float, law=None):
        """The branch as a :class:`physics.solvers.lti.StateSpace`: input U [V]; outputs current density
        [A/m²], interface excess [mol/m³], charge [C/m²]; accurate up to ``w_hi`` [rad/s]; ``law``: the
        charge law's :meth:`ChargeLawStage.realized_charge` when not None."""


@runtime_checkable
class CompiledChargeLaw(Protocol):
    """The charge law with its constants bound, for the time stepper's inner loop (returned by
    :meth:`ChargeLawStage.compiled`).  ``Q`` is the electrode charge per area [C/m²], an array
    (one entry per branch, or (samples, branches))."""

    def evaluate(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(equilibrium voltage U_eq(Q) [V], slope dU_eq/dQ [V m²/C]), shaped like ``Q``."""

    def excess(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interface cation excess at the upper and lower faces [mol/m³], shaped like ``Q``."""


@runtime_checkable
class ChargeLawStage(Protocol):
    """``charge_law``: how the double layers store charge (linear, or large-signal)."""

    def small_signal(self, s, d, p) -> tuple[np.ndarray, np.ndarray]:
        """(Q/U [C/(m² V)], load-equivalent interface excess per volt [mol/(m³ V)]) at ``s``."""

    def compiled(self, d, p) -> CompiledChargeLaw:
        """The large-signal law for the time stepper."""

    def realized_charge(self, d, p):
        """None when the linear time branch is the double layer's own; else (s -> (Q/U, load/U),
        lowest frequency [rad/s]) for the double layer to realise instead."""


@runtime_checkable
class LineStage(Protocol):
    """``line``: the voltage along the electrodes."""

    def distribution(self, s, Yp, p, z) -> np.ndarray:
        """U(z)/Vin at nodes ``z`` [m] for polymer admittances ``Yp`` [S/m²]: (len(s), len(z))."""

    def series_conductances(self, p, edges) -> np.ndarray | None:
        """Ladder link conductances [S] from the clamp to the segment centres (None: every
        segment at Vin).  The time solver and the reference solver both use them."""


@runtime_checkable
class SolventStage(Protocol):
    """``solvent``: the solvent the cations drag."""

    def solvent_factor(self, s, p) -> np.ndarray:
        """B(s): first moment of the solvent excess relative to no back-diffusion."""

    def solvent_diffusivity(self, p) -> float:
        """The solvent's back-diffusion coefficient Ds [m²/s] (0: none), for the reference
        solver, which transports the solvent itself."""


@runtime_checkable
class CouplingStage(Protocol):
    """``coupling``: the load constant."""

    def kf(self, s, p) -> np.ndarray:
        """kf(s) [N m/mol] at ``s`` (humidity already applied to ``p``)."""

    def gain_equivalent(self, p, w: float) -> float:
        """The constant gain [N m/mol] equivalent to this stage's at ω = ``w`` [rad/s] (the
        diagnosis translates fitted values into starts when an effect takes the role over)."""

    def gain_start(self, value: float, p, w: float) -> dict:
        """This stage's parameters {name: SI} that give the constant gain ``value`` at ``w``."""


@runtime_checkable
class ModulusStage(Protocol):
    """``modulus``: the polymer's modulus."""

    def polymer_modulus(self, p, layered: bool):
        """E*(s) as a :class:`~physics.effects.viscoelastic.Prony` series [Pa]; ``layered``: the
        bare membrane's (the section adds the electrode layers)."""

    def modulus_equivalent(self, p, f: float, layered: bool) -> float:
        """The elastic polymer modulus [Pa] equivalent to this stage's at ``f`` [Hz] (role
        translation of starts, as :meth:`CouplingStage.gain_equivalent`)."""

    def modulus_start(self, value: float, p, f: float, layered: bool) -> dict:
        """This stage's parameters {name: SI} that give the polymer modulus ``value`` at ``f``."""


@runtime_checkable
class SectionStage(Protocol):
    """``section``: the beam's cross-section."""

    layered: bool

    def section(self, p, polymer, y_factor: float = 1.0):
        """(EI*(s) Prony series [N m²], mass per length ρA [kg/m]) with the humidity factor."""

    def layer_modulus(self, p) -> float:
        """Stiffness the section adds to the polymer's, as a modulus of the polymer section [Pa]."""


@runtime_checkable
class HumidityStage(Protocol):
    """``humidity``: what relative humidity changes."""

    def params_at(self, base: dict, rh: float) -> dict:
        """Parameters at ``rh`` [%] (the stiffness factor is applied by the section)."""

    def stiffness_factor(self, rh):
        """Factor on the polymer modulus at ``rh`` (array like ``rh``)."""

    def coupling_factor(self, rh):
        """Factor on the load constant at ``rh`` (array like ``rh``)."""

    def electrochemistry_varies(self) -> bool:
        """True when RH changes parameters upstream of the mechanics (the time solver then
        re-solves the electrochemistry as RH varies)."""


@runtime_checkable
class TemperatureStage(Protocol):
    """``temperature``: the heat balance along the strip."""

    def network(self, p, edges):
        """The lumped heat network (:class:`~physics.effects.thermal.ThermalNetwork`), or None
        (isothermal at T_ext)."""


#: Protocol of each stage, by stage name (the ``stage`` of its default in ``CHAIN``).
STAGE_PROTOCOLS: dict[str, type] = {
    "double_layer": DoubleLayerStage, "charge_law": ChargeLawStage, "line": LineStage, "solvent": SolventStage,
    "coupling": CouplingStage, "modulus": ModulusStage, "section": SectionStage, "humidity": HumidityStage,
    "temperature": TemperatureStage,
}


@runtime_checkable
class LoadFactor(Protocol):
    """An added effect on the bending load (:class:`~physics.effects.LoadEffect`)."""

    def load_factor(self, s, p) -> np.ndarray:
        """Factor on the load at ``s`` (after kf and the solvent factor); the time solver
        realises it with real poles over the band."""


@runtime_checkable
class InputFactor(Protocol):
    """An added effect on the drive voltage (:class:`~physics.effects.InputEffect`)."""

    def filter_input(self, v: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The drive voltage ``v`` [V] at ``fs`` [Hz] as the strip sees it."""

    def input_response(self, s, p) -> np.ndarray:
        """The map's small-signal factor at ``s`` (what the frequency solver uses)."""


@runtime_checkable
class OutputFactor(Protocol):
    """An added effect on the tip deflection (:class:`~physics.effects.OutputEffect`)."""

    def output_response(self, s, p) -> np.ndarray:
        """Factor on the deflection at ``s`` (the small-signal form when the map is nonlinear)."""

    def filter_output(self, y: np.ndarray, fs: float, p: dict) -> np.ndarray:
        """The simulated deflection ``y`` [m] at ``fs`` [Hz] through the effect."""
