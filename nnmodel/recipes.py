"""Training recipes: ``configs/train/NAME.yaml``, one per network (the model's hyper-parameters).

A recipe is ``{model, description, hyper_parameters, tune}`` (``tune``: the search space of
``eap train-compare --tune``, :mod:`nnmodel.tuning`); :func:`load_recipe` layers the
model's defaults, the file, then the caller's overrides (``--set MODEL.KEY=VALUE``), and
refuses unknown keys and invalid values before any training; :func:`make_model` builds the
model.  This module sits above both the model registry and the training loop (it imports
the models, the training loop imports neither).
"""
from __future__ import annotations

import os
from pathlib import Path

from physics.errors import InputError
from physics.io.yamlio import load_yaml

__all__ = ["recipe_dir", "load_recipe", "make_model"]

_RECIPE_KEYS = {"model", "description", "hyper_parameters", "tune"}


def recipe_dir() -> Path:
    """Folder of the training recipes: ``$EAP_TRAIN_RECIPES``, else ``train/`` of the package's
    configuration folder (:func:`physics.device.config_dir`: the wheel's copy or the checkout's
    ``configs/``)."""
    env = os.environ.get("EAP_TRAIN_RECIPES")
    if env:
        return Path(env)
    from physics.device import config_dir
    return config_dir() / "train"


def _beside_module(name: str) -> Path | None:
    """``NAME.yaml`` next to the module of a registered network of that kind (a network
    installed under ``eap.networks`` ships its recipe with its code), if there is one."""
    import sys

    from .models import MODELS
    module = sys.modules.get(getattr(MODELS.get(name), "__module__", ""))
    path = Path(getattr(module, "__file__", None) or ".").parent / f"{name}.yaml"
    return path if getattr(module, "__file__", None) and path.is_file() else None


def load_recipe(name: str, overrides: dict | None = None, directory: str | os.PathLike | None = None) -> dict:
    """Read the recipe ``NAME.yaml`` and apply ``overrides`` (hyper-parameter -> value).

    The recipe is read from ``directory`` (default :func:`recipe_dir`); a network installed
    under the entry-point group ``eap.networks`` (registered here) may ship it beside its
    module instead.

    Returns ``{"model": kind, "description": str, "hyper_parameters": {...}, "tune": {...}}`` where the
    hyper-parameters are the model's defaults updated by the file and then the overrides.
    Unknown keys (in the file or in the overrides) raise :class:`InputError`.
    """
    from .models import MODELS, load_plugins

    load_plugins()
    folder = Path(directory) if directory else recipe_dir()
    path = folder / f"{name}.yaml"
    if not path.is_file():
        path = _beside_module(name) or path
    if not path.is_file():
        avail = sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []
        raise InputError(f"no training recipe {name!r} ({path} not found); available: "
                         f"{', '.join(avail) or 'none'}")
    doc = load_yaml(path, "training recipe") or {}    # one-line errors naming the file, bounded
    if not isinstance(doc, dict):
        raise InputError(f"{path}: a recipe must be a mapping with keys {sorted(_RECIPE_KEYS)}")
    bad = sorted(set(doc) - _RECIPE_KEYS)
    if bad:
        raise InputError(f"{path}: unknown key(s) {bad}; a recipe has {sorted(_RECIPE_KEYS)}")
    kind = doc.get("model", name)
    if kind not in MODELS:
        raise InputError(f"{path}: unknown model {kind!r}; known models: {', '.join(sorted(MODELS))}")
    cls = MODELS[kind]
    hp = doc.get("hyper_parameters") or {}
    if not isinstance(hp, dict):
        raise InputError(f"{path}: hyper_parameters must be a mapping")
    known = set(cls.param_names())
    for where, d in ((str(path), hp), ("overrides", overrides or {})):
        bad = sorted(set(d) - known)
        if bad:
            raise InputError(f"{where}: unknown hyper-parameter(s) {bad} for model {kind!r}; "
                             f"known: {', '.join(sorted(known))}")
    params = cls.default_params()
    params.update(hp)
    params.update(overrides or {})
    cls(**params)  # validates values (raises InputError)
    tune = doc.get("tune") or {}
    if not isinstance(tune, dict):
        raise InputError(f"{path}: tune must be a mapping of hyper-parameter -> {{low, high}} or {{choices}}")
    return {"model": kind, "description": str(doc.get("description", "")), "hyper_parameters": params,
            "tune": tune}


def make_model(name: str, overrides: dict | None = None, directory=None):
    """A model built from its recipe (see :func:`load_recipe`)."""
    from .models import MODELS

    rec = load_recipe(name, overrides, directory)
    return MODELS[rec["model"]](**rec["hyper_parameters"])
