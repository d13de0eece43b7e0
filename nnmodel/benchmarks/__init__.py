"""Benchmark suites for the neural models.

A suite is a function ``run(models, out, *, quick=False, overrides=None, progress=True,
settings=None, **options) -> dict`` in a module of this package (``settings``: where its
models train, :mod:`physics.execution.parallel`); :data:`SUITES` maps the name used by
``eap benchmark --suite NAME`` to a :class:`Suite` entry.  Entries name the function by
import path, so listing the suites (for the command line's choices) imports no torch.
Add a suite by writing its module and one ``register(Suite(...))`` line below.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Callable

__all__ = ["Suite", "SUITES", "register", "get_suite"]


@dataclass(frozen=True)
class Suite:
    name: str
    target: str  # "package.module:function"
    help: str
    default_models: tuple[str, ...] = field(default=("ff", "rbf", "narx", "lstm", "gru"))

    def load(self) -> Callable:
        mod, func = self.target.split(":")
        return getattr(importlib.import_module(mod), func)


SUITES: dict[str, Suite] = {}


def register(suite: Suite) -> Suite:
    SUITES[suite.name] = suite
    return suite


def get_suite(name: str) -> Suite:
    from physics.errors import InputError

    if name not in SUITES:
        raise InputError(f"unknown benchmark suite {name!r}; available: {', '.join(sorted(SUITES))}")
    return SUITES[name]


register(Suite("eap", "nnmodel.benchmarks.eap:run",
               "FF, RBF, NARX, LSTM and the grey-box hybrid on the default humidity dataset "
               "(generated unless --data DATASET), free-run NRMSE on held-out RH",
               default_models=("ff", "rbf", "narx", "lstm", "hybrid")))
register(Suite("greybox", "nnmodel.benchmarks.greybox:run",
               "grey-box hybrid vs its physics alone vs pure networks on data with an effect the "
               "physics lacks (configs/datasets/greybox.yaml), and a data-efficiency curve",
               default_models=("hybrid", "narx", "ff")))
register(Suite("silverbox", "nnmodel.benchmarks.silverbox:run",
               "real measured Silverbox data (Wigren & Schoukens 2013), standard split, "
               "free-run RMSE in mV beside published results",
               default_models=("ff", "rbf", "narx", "lstm", "gru", "ss")))
