"""How a network is trained, in one settings part (:class:`TrainingConfig`, ``model.training``).

Each model's constructor takes only what describes the model (lags, layers, centres ...);
the settings of *how* it is trained — budget, optimiser, training windows, early
stopping, threads, progress — are one :class:`TrainingConfig`.  Recipes, ``--set`` and
bundle cards keep them as flat hyper-parameters (``max_epochs: 200``); a model class states
only where its defaults differ (:attr:`NeuralModel.DEFAULTS`).
"""
from __future__ import annotations

from dataclasses import dataclass

from .params import Part, flag, pos_float, pos_int, size

__all__ = ["TrainingConfig", "TRAINING_FIELDS"]


@dataclass
class TrainingConfig(Part):
    """How a network is trained.

    ``max_epochs``: the budget (epochs; 0 = no gradient training); ``max_time`` [s]: a
    wall-clock guard only (the card says if it fired); ``horizon``: simulated samples per
    training window after the measured history (1 = one-step / series-parallel training,
    longer = closed loop, truncated back-propagation through time), ``stride``: samples
    between window starts; ``patience``: epochs without a better validation free-run error
    before stopping; ``val_fraction``: tail of each training record held out when no
    validation records are given; ``num_threads``: torch threads (None: torch's default);
    ``checkpoint_dir``: where Lightning may write checkpoints."""

    ATTR = "training"
    CHECKS = {
        "seed": lambda v: pos_int(v, zero=True),
        "lr": pos_float,
        "weight_decay": lambda v: pos_float(v, zero=True),
        "batch_size": size(1_000_000),
        "max_epochs": lambda v: pos_int(v, zero=True),
        "max_time": lambda v: None if v is None else pos_float(v),
        "horizon": size(1_000_000),
        "stride": size(1_000_000),
        "patience": pos_int,
        "val_fraction": lambda v: None if (pos_float(v, zero=True) is None and v < 1) else "a number in [0, 1)",
        "grad_clip": lambda v: None if v is None else pos_float(v),
        "progress_bar": flag,
        "num_threads": lambda v: None if v is None else pos_int(v),
        "accelerator": lambda v: None if isinstance(v, str) else "a Lightning accelerator name such as 'cpu'",
        "checkpoint_dir": lambda v: None if v is None or isinstance(v, str) else "a folder path or null",
    }

    seed: int = 0
    lr: float = 1e-3
    weight_decay: float = 0.0
    batch_size: int = 256
    max_epochs: int = 100
    max_time: float | None = None
    horizon: int = 1
    stride: int = 1
    patience: int = 10
    val_fraction: float = 0.2
    grad_clip: float | None = None
    accelerator: str = "cpu"
    progress_bar: bool = True
    num_threads: int | None = 1
    checkpoint_dir: str | None = None


#: Names of the training settings (flat hyper-parameters of every model).
TRAINING_FIELDS = TrainingConfig.names()
