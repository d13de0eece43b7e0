"""The catalog of built-in effects and the model chain: each stage's "no effect" default
(``CHAIN``), the effects shipped with the package, and how a class relates to the chain."""
from __future__ import annotations

from .base import Effect
from .double_layer import DoubleLayer
from .electrode_resistance import ElectrodeResistance, EquipotentialElectrodes
from .fractional_charge import FractionalCharge
from .fractional_coupling import ConstantCoupling, FractionalCoupling
from .humidity import Humidity, HumidityInvariant
from .layered_beam import HomogeneousSection, LayeredBeam
from .nonlinear_charge import LinearCharge, NonlinearCharge
from .solvent_diffusion import SolventDiffusion, SolventDrag
from .thermal import Isothermal, Thermal
from .viscoelastic import ElasticModulus, Viscoelastic

#: The stages of the model chain, in order, each as its "no effect" variant (the double layer
#: is the model's core and always on).
CHAIN: tuple[type[Effect], ...] = (DoubleLayer, LinearCharge, EquipotentialElectrodes, SolventDrag, ConstantCoupling,
                                   ElasticModulus, HomogeneousSection, HumidityInvariant, Isothermal)
#: The effects shipped with the package.
BUILT_IN_EFFECTS: tuple[type[Effect], ...] = (DoubleLayer, NonlinearCharge, ElectrodeResistance, SolventDiffusion,
                                              FractionalCoupling, FractionalCharge, Viscoelastic, LayeredBeam,
                                              Humidity, Thermal)

#: The model's core: stage defaults with an id, always on (they cannot be removed).
CORE = tuple(cls.id for cls in CHAIN if cls.id)
#: Ids of the effects shipped with the package (the rest were registered by users).
BUILT_IN = tuple(cls.id for cls in BUILT_IN_EFFECTS)
#: Factor hooks an added effect may implement (see :mod:`physics.effects.base`).
FACTOR_HOOKS = ("load_factor", "output_response", "filter_output", "filter_input")


def stage_of(cls: type[Effect]) -> type[Effect] | None:
    """The default variant of the stage that ``cls`` fills (None: an added effect)."""
    return next((d for d in CHAIN if issubclass(cls, d)), None)


def adds_factors(cls: type[Effect]) -> bool:
    """True when ``cls`` implements a factor hook."""
    return any(callable(getattr(cls, h, None)) for h in FACTOR_HOOKS)
