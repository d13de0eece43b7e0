"""Structure search on validation data, a settings part every model composes.

``structures`` is a list of hyper-parameter overrides (e.g. ``[{}, {na: 10, nb: 10}]``:
without and with output feedback).  Each is fitted — in full, or as a model's cheap
stand-in (:attr:`NeuralModel.SELECTION_PROXY`, e.g. the FF network's linear least-squares
start) — and scored by its free-run NRMSE on the validation data; the best is trained and
every score goes into the bundle card (``structure_search``).  The choice uses validation
data only, so one recipe serves plants that need output feedback (a resonance) and plants
where it drifts.
"""
from __future__ import annotations

import copy
import math
import warnings
from dataclasses import dataclass

import numpy as np

from physics.errors import InputError

from ..data import split_index
from .params import Part

__all__ = ["StructureSearch", "select_structure", "selection_score", "validation_errors", "validation_nrmse",
           "nrmse_of"]


def _check(v):
    if v is None or (isinstance(v, list) and all(isinstance(c, dict) for c in v)):
        return None
    return "null or a list of hyper-parameter mappings, e.g. [{}, {na: 10, nb: 10}]"


def _check_folds(v):
    if v == "auto" or (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 10):
        return None
    return "'auto' (cross-validate when the validation data are few) or a number of folds 1-10 (1: one split)"


@dataclass
class StructureSearch(Part):
    """``structures``: hyper-parameter overrides tried in turn (None or one entry: no search);
    ``cv_folds``: how many folds a fit is scored on (:mod:`.crossval`; ``auto``: 3 when the
    validation data are few, else 1)."""

    ATTR = "search"
    CHECKS = {"structures": _check, "cv_folds": _check_folds}

    structures: list | None = None
    cv_folds: int | str = "auto"

    @property
    def active(self) -> bool:
        return len(self.structures or []) > 1


def select_structure(model, train, val) -> None:
    """Fit ``model`` in the structure of its ``structures`` with the lowest free-run NRMSE
    on the validation data (:func:`validation_nrmse`); sets ``model.structure_search_``."""
    known = set(model.param_names()) - {"structures"}
    for over in model.structures:
        if set(over) - known:
            raise InputError(f"model {model.kind!r}: structures entry {over} names unknown hyper-parameter(s) "
                             f"{sorted(set(over) - known)}; known: {', '.join(sorted(known))}")
    proxy = type(model).SELECTION_PROXY or {}
    tried, best = [], None
    for over in model.structures:
        cand = copy.deepcopy(model)
        cand.set_params(**{**over, **proxy, "structures": None})
        with warnings.catch_warnings():
            if best is not None:        # the data-fit warnings were already given once
                warnings.simplefilter("ignore", UserWarning)
            cand.fit(train, val)
        score = selection_score(cand, train, val)
        cv = cand.__dict__.get("cross_validation_")
        tried.append({"structure": dict(over), "validation_free_run_nrmse": score,
                      "scored_as": "linear least-squares start" if proxy else "fitted model",
                      "fit_time_s": cand.fit_time_, **({"cv_folds": cv["folds"], "cv_spread": cv["spread"]}
                                                       if cv else {})})
        if best is None or score < best[0]:
            best = (score, over, cand)
    chosen = best[2]
    if proxy:
        chosen = copy.deepcopy(model)
        chosen.set_params(**{**best[1], "structures": None})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            chosen.fit(train, val)
    structures = model.structures
    model.__dict__.update(chosen.__dict__)
    model.structures = structures
    model.structure_search_ = tried


def selection_score(model, train, val) -> float:
    """What a fitted model is selected by: the mean free-run NRMSE over its cross-validation
    folds when it was cross-validated (:mod:`.crossval`), else its validation NRMSE."""
    cv = model.__dict__.get("cross_validation_")
    return float(cv["mean"]) if cv else validation_nrmse(model, train, val)


def validation_errors(model, train, val) -> tuple[list[np.ndarray], float] | None:
    """(squared free-run errors of a fitted ``model`` per validation part, Σ(y − ȳ)² over the
    parts): the ``val`` records, or (without them) the last ``val_fraction`` of each training
    record simulated from its start; None when the simulation diverges."""
    if val:
        parts = [(r, 0) for r in val]
    else:
        parts = [(r, split_index(len(r), model.val_fraction, model.n_init_ + 2) or 0) for r in train]
    errors, v2 = [], 0.0
    for r, k in parts:
        with np.errstate(all="ignore"):
            yh = model.simulate(r.u, r.rh if model.uses_rh else None, y_init=r.y[:model.n_init_])
        s = max(k, model.n_init_)
        y, e = r.y[s:], yh[s:] - r.y[s:]
        if not np.all(np.isfinite(e)):
            return None
        errors.append(e ** 2)
        v2 += float(np.sum((y - y.mean()) ** 2))
    return errors, v2


def validation_nrmse(model, train, val) -> float:
    """Pooled free-run NRMSE of a fitted ``model`` on its validation data
    (:func:`validation_errors`); inf when the simulation diverges."""
    return nrmse_of(validation_errors(model, train, val))


def nrmse_of(got) -> float:
    """The pooled NRMSE of :func:`validation_errors`' result; inf for None (diverged) or a
    validation without variance."""
    if got is None or not got[1] > 0:
        return math.inf
    return math.sqrt(sum(float(e.sum()) for e in got[0]) / got[1])
