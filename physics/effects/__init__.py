"""Physical effects (stable ids), their explicit "off" variants, and effects added by users.

``EFFECTS`` maps each id to its class; ``SLOTS`` lists, in chain order, the slot each
built-in effect fills and the variant used when the effect is off.  Effects added by
users (:class:`OutputEffect` subclasses) act on the tip deflection after the chain; they
are registered with :func:`register`, from a file with :func:`load_effects_file`
(``--effects-path FILE.py``) or from installed packages with :func:`load_plugins`
(entry-point group ``eap.effects``).
"""
from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path

from ..errors import InputError
from .base import Effect, OutputEffect
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
#: Ids of the effects shipped with the package (the rest were registered by users).
BUILT_IN = tuple(EFFECTS)
LINEAR_EFFECTS = tuple(k for k, v in EFFECTS.items() if v.linear)
ENTRY_POINT_GROUP = "eap.effects"


def register(cls: type[OutputEffect]) -> type[OutputEffect]:
    """Register a user effect class (checked against the contract); returns it."""
    where = f"effect class {getattr(cls, '__name__', cls)!r}"
    if not (inspect.isclass(cls) and issubclass(cls, OutputEffect)):
        raise InputError(f"{where}: a user effect must subclass physics.effects.OutputEffect")
    if not isinstance(cls.id, str) or not cls.id.isidentifier():
        raise InputError(f"{where}: needs an id that is a Python identifier, got {cls.id!r}")
    if cls.id in BUILT_IN:
        raise InputError(f"{where}: id {cls.id!r} is a built-in effect; choose another id")
    if cls.output_tf is OutputEffect.output_tf and cls.filter_output is OutputEffect.filter_output:
        raise InputError(f"{where}: define output_tf(self, p) (or filter_output and output_response)")
    for spec in cls.params:
        if spec.default is None:
            raise InputError(f"{where}: parameter {spec.name!r} needs a default (ParamSpec(..., default=...))")
    known = {s.name for s in cls.params}
    spec = cls.diagnosis
    if spec is not None:
        if not isinstance(spec, dict) or not spec.get("free"):
            raise InputError(f"{where}: diagnosis must be a dict with at least 'free' (parameters to fit)")
        bad = [n for n in list(spec["free"]) + list(spec.get("bounds", {})) if n not in known]
        if bad:
            raise InputError(f"{where}: diagnosis names parameters {bad} that the effect does not declare")
    old = EFFECTS.get(cls.id)
    if old is not None and old is not cls and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
        raise InputError(f"{where}: id {cls.id!r} is already registered by {old.__module__}.{old.__qualname__}")
    EFFECTS[cls.id] = cls
    return cls


def unregister(effect_id: str) -> None:
    """Remove a user effect (built-ins cannot be removed)."""
    if effect_id in BUILT_IN:
        raise InputError(f"{effect_id!r} is a built-in effect")
    EFFECTS.pop(effect_id, None)


def effect_classes_in_file(path) -> list[type[OutputEffect]]:
    """Import the Python file ``path`` and return the user effect classes it defines."""
    p = Path(path)
    if p.suffix != ".py" or not p.is_file():
        raise InputError(f"--effects-path {p}: expected an existing Python file (.py) defining an effect")
    name = f"eap_user_effects_{p.stem}"
    spec = importlib.util.spec_from_file_location(name, p)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except InputError:
        raise
    except Exception as exc:  # a user's file: report what went wrong in it, one line
        raise InputError(f"--effects-path {p}: importing it failed: {type(exc).__name__}: {exc}") from None
    classes = [c for c in vars(module).values() if inspect.isclass(c) and issubclass(c, OutputEffect)
               and c is not OutputEffect and c.__module__ == name]
    for c in classes:
        c.source_file = str(p.resolve())   # so that worker processes can load it too
    if not classes:
        raise InputError(f"--effects-path {p}: defines no subclass of physics.effects.OutputEffect")
    return classes


def load_effects_file(path) -> list[str]:
    """Register every user effect defined in ``path``; returns their ids."""
    return [register(c).id for c in effect_classes_in_file(path)]


def user_effect_files() -> list[str]:
    """Files of the registered user effects (to register them again in worker processes)."""
    return sorted({getattr(c, "source_file") for e, c in EFFECTS.items()
                   if e not in BUILT_IN and getattr(c, "source_file", None)})


def ensure_registered(files) -> None:
    """Register the effects of ``files`` and of installed plugins unless already present."""
    load_plugins()
    for f in files:
        if not any(getattr(c, "source_file", None) == f for c in EFFECTS.values()):
            load_effects_file(f)


def load_plugins() -> list[str]:
    """Register the effects of installed packages (entry-point group ``eap.effects``)."""
    from importlib.metadata import entry_points
    ids = []
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
        except Exception as exc:
            raise InputError(f"entry point {ep.name!r} ({ep.value}) of group {ENTRY_POINT_GROUP}: {exc}") from None
        ids.append(register(cls).id)
    return ids


__all__ = ["Effect", "OutputEffect", "EFFECTS", "SLOTS", "BUILT_IN", "LINEAR_EFFECTS", "register", "unregister",
           "load_effects_file", "load_plugins", "effect_classes_in_file", "user_effect_files", "ensure_registered"]
