"""Physical effects (stable ids), the model chain's "no effect" defaults, and user effects.

``CHAIN`` lists, in chain order, the default variant of every stage of the model (the
contract is in :mod:`physics.effects.base`, each stage's typed protocol in
:mod:`physics.effects.stages`); an effect replaces the stage whose default it subclasses, or
adds factors (:class:`LoadEffect`: ``load_factor``; :class:`OutputEffect`: ``output_response``).
:func:`check_effect` runs the contract on any effect (:mod:`physics.contract`).  ``EFFECTS`` maps each id
to its class: the built-ins of ``BUILT_IN_EFFECTS``, then those added by users with
:func:`register`, from a file with :func:`load_effects_file` (``--effects-path FILE.py``) or
from installed packages with :func:`load_plugins` (entry-point group ``eap.effects``).
"""
from __future__ import annotations

import importlib.util
import inspect
import sys
from pathlib import Path

from ..errors import InputError, arg
from .base import DIAGNOSIS_KEYS, REFERENCE, REVEAL_RULES, Effect, LoadEffect, OutputEffect
from .declaration import declaration_problems
from .usercode import contain_class, import_limited
from .catalog import BUILT_IN, BUILT_IN_EFFECTS, CHAIN, CORE, FACTOR_HOOKS, adds_factors, stage_of
from .double_layer import DoubleLayer
from .electrode_resistance import ElectrodeResistance, EquipotentialElectrodes
from .fractional_coupling import ConstantCoupling, FractionalCoupling
from .humidity import Humidity, HumidityInvariant
from .layered_beam import HomogeneousSection, LayeredBeam
from .nonlinear_charge import LinearCharge, NonlinearCharge
from .solvent_diffusion import SolventDiffusion, SolventDrag
from .thermal import Isothermal, Thermal
from .viscoelastic import ElasticModulus, Viscoelastic

EFFECTS: dict[str, type[Effect]] = {cls.id: cls for cls in BUILT_IN_EFFECTS}


def __getattr__(name):
    if name == "LINEAR_EFFECTS":     # computed on access, so that it includes registered user effects
        return tuple(k for k, v in EFFECTS.items() if v.linear)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


ENTRY_POINT_GROUP = "eap.effects"
_PATH = arg("effects_path", "path")    # how a caller names an effect file


#: The contract's runner, installed by :mod:`physics.contract` when ``physics`` is imported: its
#: checks run the model and the solvers, layers above this package, which must not import them.
_CONTRACT: list = []


def check_effect(cls, device="ipmc_pt_eg", *, fast: bool = False, rh: float = 60.0):
    """Run the effect contract on effect class ``cls`` (or a registered id) with ``device`` at
    ``rh`` [%]: a :class:`physics.contract.ContractReport`, one line per check; ``fast``: the
    quick checks only (for checks at load time).  See :mod:`physics.contract`."""
    return _CONTRACT[-1](cls, device, fast=fast, rh=rh)


def register(cls: type[Effect]) -> type[Effect]:
    """Register a user effect class (its declaration checked: :func:`declaration_problems`);
    returns it.  It either replaces a stage (subclasses one of :data:`CHAIN`) or adds factors
    (:class:`OutputEffect`, :class:`LoadEffect`, or any effect with ``load_factor``)."""
    where = f"effect class {getattr(cls, '__name__', cls)!r}"
    problems = declaration_problems(cls, user=True)
    if problems:
        raise InputError(f"{where}: {problems[0]}")
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


def effect_classes_in_file(path) -> list[type[Effect]]:
    """Import the Python file ``path`` and return the user effect classes it defines.

    The file is code that runs with the caller's rights: its import and every call of its
    classes' methods run contained (:mod:`physics.effects.usercode`: exit calls caught, a time
    limit per call)."""
    p = Path(path)
    if p.suffix != ".py" or not p.is_file():
        raise InputError(f"{_PATH} {p}: expected an existing Python file (.py) defining an effect")
    name = f"eap_user_effects_{p.stem}"
    spec = importlib.util.spec_from_file_location(name, p)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        import_limited(spec.loader.exec_module, module, f"{_PATH} {p}: importing it")
    except InputError:
        raise
    except Exception as exc:  # a user's file: report what went wrong in it, one line
        raise InputError(f"{_PATH} {p}: importing it failed: {type(exc).__name__}: {exc}") from None
    for c in vars(module).values():
        if inspect.isclass(c) and c.__module__ == name:
            contain_class(c, p)
    classes = [c for c in vars(module).values() if inspect.isclass(c) and issubclass(c, Effect)
               and c.__module__ == name and isinstance(getattr(c, "id", None), str)]
    for c in classes:
        c.source_file = str(p.resolve())   # so that worker processes can load it too
    if not classes:
        raise InputError(f"{_PATH} {p}: defines no subclass of physics.effects.OutputEffect, LoadEffect "
                         "(or Effect) with an id")
    return classes


def load_effects_file(path) -> list[str]:
    """Register every user effect defined in ``path`` after the fast checks of its contract
    (:func:`check_effect`: declaration, builds, protocol, finite, stable, passive), refused
    with the file and the failing check; returns their ids."""
    import warnings

    import numpy as np

    classes = effect_classes_in_file(path)
    for c in classes:
        with np.errstate(all="ignore"), warnings.catch_warnings():   # the verdict says what failed
            warnings.simplefilter("ignore", RuntimeWarning)
            report = check_effect(c, fast=True)
        report.raise_on_failure(f"{_PATH} {path}")
    return [register(c).id for c in classes]


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
    from ..plugins import load_entry_points
    return [cls.id for cls in load_entry_points(ENTRY_POINT_GROUP, register)]


__all__ = ["Effect", "OutputEffect", "LoadEffect", "EFFECTS", "CHAIN", "CORE", "BUILT_IN", "BUILT_IN_EFFECTS", "LINEAR_EFFECTS",
           "REFERENCE", "register", "unregister", "stage_of", "adds_factors", "load_effects_file", "load_plugins",
           "effect_classes_in_file", "user_effect_files", "ensure_registered", "check_effect", "declaration_problems"]
