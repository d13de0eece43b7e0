"""Training settings shared by every network, in one object.

Each model's constructor takes only what describes the model (lags, layers, filters ...);
the settings of *how* it is trained — budget, optimiser, early stopping, threads, progress —
are one :class:`TrainingConfig` (``model.training``).  Recipes, ``--set`` and bundle cards
keep them as flat hyper-parameters (``max_epochs: 200``): a model accepts them as keyword
arguments and reads and writes them as attributes, which go to ``model.training``.  A model
class states only where its defaults differ (:attr:`NeuralModel.TRAINING_DEFAULTS`).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields

from physics.errors import InputError


@dataclass
class TrainingConfig:
    """How a network is trained.

    ``max_epochs``: the budget (epochs; 0 = no gradient training); ``max_time`` [s]: a
    wall-clock guard only (the card says if it fired); ``patience``: epochs without a better
    validation free-run error before stopping; ``val_fraction``: tail of each training
    record held out when no validation records are given; ``num_threads``: torch threads
    (None: torch's default); ``checkpoint_dir``: where Lightning may write checkpoints."""

    seed: int = 0
    lr: float = 1e-3
    weight_decay: float = 0.0
    batch_size: int = 256
    max_epochs: int = 100
    max_time: float | None = None
    patience: int = 10
    val_fraction: float = 0.2
    grad_clip: float | None = None
    accelerator: str = "cpu"
    progress_bar: bool = True
    num_threads: int | None = 1
    checkpoint_dir: str | None = None

    def fit_settings(self) -> dict:
        """Keyword arguments of :func:`nnmodel.training.fit_core` (without the window
        settings, which depend on the model)."""
        out = asdict(self)
        for k in ("val_fraction", "num_threads"):
            out.pop(k)
        return out


#: Names of the training settings (flat hyper-parameters of every model).
TRAINING_FIELDS = tuple(f.name for f in fields(TrainingConfig))


def training_config(kind: str, defaults: dict, given: dict) -> TrainingConfig:
    """The config of a model of ``kind``: TrainingConfig's defaults, then the class's
    ``defaults``, then the ``given`` keyword arguments (unknown names are refused)."""
    unknown = sorted(set(given) - set(TRAINING_FIELDS))
    if unknown:
        raise InputError(f"unknown hyper-parameter(s) {unknown} for model {kind!r}")
    return TrainingConfig(**{**defaults, **given})
