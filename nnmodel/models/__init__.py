"""Neural and grey-box models of the actuator (one module per model family).

``MODELS`` maps the registry name used in recipes and on the command line to the class;
every class follows the contract of :class:`nnmodel.models.base.NeuralModel`.
"""
from __future__ import annotations

from .base import NeuralModel, NotFittedError
from .ff import FFModel
from .hybrid import HybridModel
from .narx import NARXModel
from .rbf import RBFModel
from .rnn import GRUModel, LSTMModel

MODELS: dict[str, type[NeuralModel]] = {
    "ff": FFModel,
    "rbf": RBFModel,
    "narx": NARXModel,
    "lstm": LSTMModel,
    "gru": GRUModel,
    "hybrid": HybridModel,
}

__all__ = ["MODELS", "NeuralModel", "NotFittedError", "FFModel", "RBFModel", "NARXModel",
           "LSTMModel", "GRUModel", "HybridModel"]
