"""Neural and grey-box models of the actuator (one module per network).

``MODELS`` maps the registry name used in recipes and on the command line to the class:
the built-ins of :data:`BUILT_IN_MODELS`, then any added with :func:`register` or by an
installed package under the entry-point group ``eap.networks`` (:func:`load_plugins`).  Every
class follows the contract of :class:`nnmodel.models.base.NeuralModel`, which
:func:`nnmodel.check_model` checks.
"""
from __future__ import annotations

from physics.errors import InputError

from .base import PARTS, NeuralModel, NotFittedError
from .ff import FFModel
from .hybrid import HybridModel
from .narx import NARXModel
from .rbf import RBFModel
from .rnn import GRUModel, LSTMModel
from .ss import SSModel

#: The networks shipped with the package.
BUILT_IN_MODELS: tuple[type[NeuralModel], ...] = (FFModel, RBFModel, NARXModel, LSTMModel, GRUModel, SSModel, HybridModel)
MODELS: dict[str, type[NeuralModel]] = {cls.kind: cls for cls in BUILT_IN_MODELS}
#: Entry-point group under which installed packages declare networks (``kind = module:Class``).
ENTRY_POINT_GROUP = "eap.networks"


def register(cls: type[NeuralModel]) -> type[NeuralModel]:
    """Add a network class to :data:`MODELS` under its ``kind`` (its recipe is
    ``KIND.yaml`` in the recipe folder); the class is checked for the static part of the
    contract (run :func:`nnmodel.check_model` for the whole of it).  Returns the class."""
    if not (isinstance(cls, type) and issubclass(cls, NeuralModel)):
        raise InputError(f"{cls!r} is not a NeuralModel subclass")
    if not isinstance(cls.kind, str) or not cls.kind.isidentifier() or cls.kind == NeuralModel.kind:
        raise InputError(f"{cls.__name__}: kind must be a name such as 'tcn', got {cls.kind!r}")
    if MODELS.get(cls.kind, cls) is not cls:
        raise InputError(f"{cls.__name__}: kind {cls.kind!r} is already registered by {MODELS[cls.kind].__name__}")
    shared = set(cls._model_params()) & {n for part in PARTS for n in part.names()}
    if shared:
        raise InputError(f"{cls.__name__}: constructor parameters {sorted(shared)} are settings of the shared "
                         "parts (training, features, structure search); take them through **settings")
    MODELS[cls.kind] = cls
    return cls


def default_kinds() -> tuple[str, ...]:
    """The kinds trained when no models are named: every registered network that declares
    ``IN_DEFAULT_SET`` (built-ins first, then plug-ins in the order they were registered)."""
    return tuple(kind for kind, cls in MODELS.items() if cls.IN_DEFAULT_SET)


def load_plugins() -> list[str]:
    """Register the networks of installed packages (entry-point group ``eap.networks``, each
    entry ``NAME = module:Class``); returns their kinds.  A network's recipe ``KIND.yaml``
    is read from the recipe folder, else from beside its module
    (:func:`nnmodel.recipes.load_recipe`)."""
    from physics.execution.plugins import load_entry_points
    return [cls.kind for cls in load_entry_points(ENTRY_POINT_GROUP, register)]


__all__ = ["MODELS", "BUILT_IN_MODELS", "ENTRY_POINT_GROUP", "register", "load_plugins", "default_kinds", "NeuralModel", "NotFittedError", "FFModel", "RBFModel",
           "NARXModel", "LSTMModel", "GRUModel", "SSModel", "HybridModel"]
