"""Physical effects (stable ids), the model chain's "no effect" defaults, and user effects.

``CHAIN`` lists, in chain order, the default variant of every stage of the model (the
contract is in :mod:`physics.effects.base`, each stage's typed protocol in
:mod:`physics.effects.stages`); an effect replaces the stage whose default it subclasses, or
adds factors (:class:`LoadEffect`: ``load_factor``; :class:`OutputEffect`: ``output_response``;
:class:`InputEffect`: ``filter_input``).
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
from .base import DIAGNOSIS_KEYS, REFERENCE, REVEAL_RULES, Effect, InputEffect, LoadEffect, OutputEffect
from .declaration import declaration_problems
from ..execution.usercode import contain_class, import_limited
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

#: Every effect class by its id, the built-ins first, then those registered by users
#: (with :func:`register`, a file given with ``--effects-path``, or an installed package's
#: entry point ``eap.effects``).
EFFECTS: dict[str, type[Effect]] = {cls.id: cls for cls in BUILT_IN_EFFECTS}


def __getattr__(name):
    if name == "LINEAR_EFFECTS":     # computed on access, so that it includes registered user effects
        return tuple(k for k, v in EFFECTS.items() if v.linear)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


ENTRY_POINT_GROUP = "eap.effects"
_PATH = arg("effects_path", "path")    # how a caller names an effect file


#: The contract's runner, installed by :mod:`physics.contract` when it is imported (on first use): its
#: checks run the model and the solvers, layers above this package, which must not import them.
_CONTRACT: list = []


def check_effect(cls, device="ipmc_pt_eg", *, fast: bool = False, rh: float = 60.0):
    """Run the effect contract on an effect.

    The checks: the declaration, the model builds, the stage protocol or factor hooks, finite
    responses, stability of a rational factor, passivity (the input admittance has a
    non-negative real part; no negative material loss), a complete diagnosis spec, frequency
    and time solvers within 1 % / 1° over 0.1–20 Hz, the spec's "off" values give exactly the
    model without the effect, and identification recovers its free parameters within 2 % on
    its own frequency response.

    Parameters
    ----------
    cls : type or str
        An effect class, or the id of a registered effect.
    device : str or Device
        The device the effect is added to (default: the thesis IPMC).
    fast : bool
        Only the quick checks (declaration to passivity), as loading a file runs them.
    rh : float
        Relative humidity of the checks [%].

    Returns
    -------
    ContractReport
        One line per check when printed; ``ok`` is True when none failed.

    Examples
    --------
    >>> from physics.effects import check_effect
    >>> report = check_effect("electrode_resistance", fast=True)
    >>> report.ok, [c.status for c in report.checks][:2]
    (True, ['pass', 'pass'])
    """
    if not _CONTRACT:                # the runner lives a floor above (it runs the model): imported by name,
        import importlib             # on first use, so that this package never imports the solvers
        importlib.import_module("physics.contract")
    return _CONTRACT[-1](cls, device, fast=fast, rh=rh)


def register(cls: type[Effect]) -> type[Effect]:
    """Register an effect class under its id, so that ``--effects`` and the diagnosis know it.

    The class either replaces a stage of the model (it subclasses that stage's default in
    ``physics.effects.CHAIN``) or adds a factor (:class:`OutputEffect`, :class:`LoadEffect`,
    :class:`InputEffect`).
    Its declaration is checked; the full contract is :func:`check_effect`.

    Parameters
    ----------
    cls : type
        The effect class.

    Returns
    -------
    type
        ``cls`` (so it can decorate the class).

    Raises
    ------
    InputError
        A declaration that breaks the contract, or an id another class already holds.

    Examples
    --------
    >>> import numpy as np, physics
    >>> from physics.effects import OutputEffect, register, unregister
    >>> @register
    ... class Halve(OutputEffect):
    ...     id = "halve"
    ...     summary = "half the deflection (an example)"
    ...     def output_tf(self, p):
    ...         return [0.5], [1.0]
    >>> fr = physics.frequency_response("ipmc_pt_eg", "none,+halve", [1.0])
    >>> ref = physics.frequency_response("ipmc_pt_eg", "none", [1.0])
    >>> round(float(fr.magnitude[0] / ref.magnitude[0]), 6)
    0.5
    >>> unregister("halve")
    """
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
    classes' methods run contained (:mod:`physics.execution.usercode`: exit calls caught, a time
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
        raise InputError(f"{_PATH} {p}: defines no subclass of physics.effects.OutputEffect, LoadEffect, "
                         "InputEffect (or Effect) with an id")
    return classes


def load_effects_file(path) -> list[str]:
    """Register every effect defined in a Python file, after the quick checks of its contract.

    What ``--effects-path FILE.py`` does.  The file is imported: it is code and runs with your
    permissions.

    Parameters
    ----------
    path : str or path
        The Python file.

    Returns
    -------
    list of str
        The ids of the effects it registered.

    Raises
    ------
    InputError
        The file cannot be read or imported, defines no effect, or an effect fails a check
        (named with the file).

    Examples
    --------
    >>> from physics.effects import EFFECTS, load_effects_file, unregister
    >>> load_effects_file("examples/effects/creep.py")
    ['creep']
    >>> EFFECTS["creep"].summary
    'polymer creep: tip load × (1 + r/(1 + sτ)), a slow extra deflection'
    >>> unregister("creep")
    """
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
    from ..execution.plugins import load_entry_points
    return [cls.id for cls in load_entry_points(ENTRY_POINT_GROUP, register)]


__all__ = ["Effect", "OutputEffect", "LoadEffect", "InputEffect", "EFFECTS", "CHAIN", "CORE", "BUILT_IN",
           "BUILT_IN_EFFECTS", "LINEAR_EFFECTS",
           "REFERENCE", "register", "unregister", "stage_of", "adds_factors", "load_effects_file", "load_plugins",
           "effect_classes_in_file", "user_effect_files", "ensure_registered", "check_effect", "declaration_problems"]
