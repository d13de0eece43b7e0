"""Physical effects (stable ids) and their explicit "off" variants.

``EFFECTS`` maps each id to its class; ``SLOTS`` lists, in chain order, the slot each
effect fills and the variant used when the effect is off.
"""
from .base import Effect
from .double_layer import DoubleLayer
from .electrode_resistance import ElectrodeResistance, EquipotentialElectrodes
from .fractional_coupling import ConstantCoupling, FractionalCoupling
from .humidity import Humidity, HumidityInvariant
from .layered_beam import HomogeneousSection, LayeredBeam
from .nonlinear_charge import LinearCharge, NonlinearCharge
from .solvent_diffusion import SolventDiffusion, SolventDrag
from .thermal import Isothermal, Thermal
from .viscoelastic import ElasticModulus, Viscoelastic

# slot -> (effect class when on, variant when off); DoubleLayer cannot be switched off.
SLOTS: dict[str, tuple[type[Effect], type[Effect] | None]] = {
    "double_layer": (DoubleLayer, None),
    "charge_law": (NonlinearCharge, LinearCharge),
    "line": (ElectrodeResistance, EquipotentialElectrodes),
    "solvent": (SolventDiffusion, SolventDrag),
    "coupling": (FractionalCoupling, ConstantCoupling),
    "modulus": (Viscoelastic, ElasticModulus),
    "section": (LayeredBeam, HomogeneousSection),
    "humidity": (Humidity, HumidityInvariant),
    "temperature": (Thermal, Isothermal),
}

EFFECTS: dict[str, type[Effect]] = {on.id: on for on, _ in SLOTS.values()}
LINEAR_EFFECTS = tuple(k for k, v in EFFECTS.items() if v.linear)

__all__ = ["Effect", "EFFECTS", "SLOTS", "LINEAR_EFFECTS"]
