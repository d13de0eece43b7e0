"""Blocked cross-validation when the validation data are few (every network, by its base class).

One validation tail of a few hundred samples ranks models by chance: a tuned trial that
validates 5 % better on it can test 10 % worse, and a network's correction can be dropped
or kept on noise.  So when the validation is the last ``val_fraction`` of the training
records and its data are **few** — fewer than :data:`MIN_WINDOWS` independent windows, a
window being the measured output's correlation time
(:func:`nnmodel.batches.correlation_time`) — a fit is scored on :data:`FOLDS` folds instead
of one (``cv_folds: auto``; a whole number forces that many, also with validation records of
their own, which otherwise decide alone; 1 turns it off):

* fold 0 is the split the model trains on (the validation records, or the last
  ``val_fraction`` of each training record);
* every further fold holds out an earlier contiguous block of every training record, as
  long as that tail, and trains on what precedes it (*rolling origin*: a model never trains
  on samples after the ones it is scored on, and the block is scored as the continuation of
  its record, its input filters warmed by the record's own past, as fold 0's tail is);
* a fold whose training part would be shorter than its validation block is not made.

Each fold trains the model anew (same seed, same structure) and scores its free-run NRMSE
on the fold's block; the score of the model is the mean over the folds and its **spread**
the standard deviation of the fold scores.  A residual model (a linear start, the hybrid's
physics) keeps its trained correction only when the correction's gain over its reference,
fold by fold, is larger on average than its spread across the folds — that decision replaces
the single-tail one (:func:`nnmodel.models.base.keep_if_better`).  The further folds train on
less data (60 % and 40 % of each record when ``val_fraction`` is 0.2, against fold 0's
80 %), so cross-validation costs about 1 + 0.75 + 0.5 = 2.25 fits where one was made (a
structure search pays it per candidate), and is used only where the data are few, which is
where a fit is cheap.
"""
from __future__ import annotations

import copy
import math
import warnings

import numpy as np

__all__ = ["FOLDS", "MIN_WINDOWS", "independent_windows", "plan", "cross_validate", "paired_win", "describe"]

#: folds when the validation data are few (``cv_folds: auto``)
FOLDS = 3
#: fewer independent windows (samples / correlation time of the output) of validation data
#: than this: cross-validate
MIN_WINDOWS = 20
#: the shortest block a fold may train or validate on (samples)
MIN_PIECE = 32


def independent_windows(records) -> float:
    """Independent windows in ``records``: samples divided by the correlation time of the
    measured output (per record, summed)."""
    from ..batches import correlation_time
    return float(sum(len(r) / max(1.0, correlation_time(r.y)) for r in records if len(r) > 2))


def _standard_validation(model, train, val):
    """The validation data of the split a model trains on (records or tails)."""
    from ..data import split_records
    if val:
        return list(val)
    return split_records(train, model.val_fraction, MIN_PIECE)[1]


def plan(model, train, val) -> list[tuple[list, list | None, float]] | None:
    """The extra folds of a fit, ``[(train records, validation records or None, val_fraction)]``
    (fold 0, the model's own split, not included), or None when one split suffices: the
    validation data hold :data:`MIN_WINDOWS` independent windows or more (``cv_folds:
    auto``) or are validation records of their own (which stand for the conditions the model
    is for, and decide alone unless ``cv_folds`` is a number), ``cv_folds`` is 1, or no record
    is long enough for another fold."""
    folds = model.cv_folds
    if folds == 1:
        return None
    vdata = _standard_validation(model, train, val)
    windows = independent_windows(vdata) if vdata else 0.0
    if folds == "auto":
        if val or not vdata or windows >= MIN_WINDOWS:   # validation records of their own decide alone
            return None
        folds = FOLDS
    f = model.val_fraction if model.val_fraction > 0 else 0.2
    out = []
    used = 0 if val else 1     # tails already held out before the next fold's block
    while len(out) < folds - 1:
        keep = 1.0 - used * f            # the records are cut to this fraction ...
        if keep - f < f:                 # ... and must train on at least as much as they validate
            break
        parts = [r[:int(round(len(r) * keep))] for r in train]
        if not all(len(p) * f / keep >= MIN_PIECE for p in parts):
            break
        out.append((parts, None, f / keep))
        used += 1
    return out or None


def _fold_model(model, val_fraction: float):
    """A fresh copy of ``model``'s settings for one fold: the structure it chose, no nested
    search or cross-validation, no progress bar."""
    params = {**model.get_params(), "structures": None, "cv_folds": 1, "val_fraction": val_fraction,
              "progress_bar": False}
    return type(model)(**params)


def scores(model, train, val) -> tuple[float, float | None]:
    """(free-run validation NRMSE of the fitted ``model``, the same with its correction zeroed
    — its reference alone — or None without one)."""
    from .structure import validation_nrmse
    net = validation_nrmse(model, train, val)
    if model.__dict__.get("reference_start_") is None:
        return net, None
    ref = copy.deepcopy(model)
    ref.net_.core.zero_correction()
    return net, validation_nrmse(ref, train, val)


def paired_win(base: list, new: list) -> tuple[bool, float, float]:
    """(wins, mean gain, spread): ``new`` wins over ``base`` when its fold-by-fold gain
    ``base - new`` is positive on average and larger than its standard deviation over the
    folds (the spread); folds missing on either side (None) are left out, and fewer than two
    common folds never win."""
    pairs = [(b, n) for b, n in zip(base, new) if b is not None and n is not None]
    d = np.array([b - n for b, n in pairs], float)
    if d.size == 0 or not np.all(np.isfinite(d)):
        return False, math.nan, math.nan
    mean = float(d.mean())
    spread = float(d.std(ddof=1)) if d.size > 1 else math.inf
    return bool(mean > 0 and mean > spread), mean, spread


def cross_validate(model, train, val, extra) -> dict:
    """Score the fitted ``model`` (fold 0) and fresh fits on the ``extra`` folds of
    :func:`plan` (a fold that cannot be trained, e.g. shorter than one training window, is
    None); decide its correction over its reference by :func:`paired_win` (zeroing it when it
    does not win; with no fold but the first, by the single-split rule); returns the record
    stored as ``model.cross_validation_``."""
    from physics.errors import InputError

    from ..batches import gain_is_real
    folds, skipped = [scores(model, train, val)], []
    for k, (tr, va, vf) in enumerate(extra, start=1):
        fm = _fold_model(model, vf)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fm.fit(tr, va)
        except InputError as exc:
            skipped.append(f"fold {k}: {exc}")
            folds.append((None, None))
            continue
        folds.append(scores(fm, tr, va))
    net = [f[0] for f in folds]
    used = sum(v is not None for v in net)
    out = {"folds": len(folds), "folds_scored": used, "protocol": describe(len(folds), bool(val)),
           "validation_nrmse_folds": net}
    if skipped:
        out["folds_skipped"] = skipped
    if folds[0][1] is not None:
        ref = [f[1] for f in folds]
        end = model.reference_start_["end"]
        if used >= 2:
            keep, gain, spread = paired_win(ref, net)
            out.update(reference_nrmse_folds=ref, correction_gain=gain, correction_gain_spread=spread)
            why = (f"cross-validation over {used} folds: its NRMSE gain over the {model.reference_start_['reference']} "
                   f"start, {_pct(gain)} on average, is not larger than its spread across the folds ({_pct(spread)})")
            end["decided_by"] = "cross-validation"
        else:                          # no further fold could be trained: the single-split rule
            se = end["validation_gain_se"]
            keep = gain_is_real(end["validation_nrmse_network"], end["validation_nrmse_reference"],
                                end["validation_gain"], math.inf if se is None else se)
            why = "its validation gain is within its uncertainty (no further fold could be trained)"
            end["decided_by"] = "one split (no further fold could be trained)"
        if keep and _is_reference(model):
            keep, why = False, "its correction is zero (dropped at its start and not trained since)"
        out["correction_kept"] = keep
        if keep:
            end.pop("reason", None)
            end["kept"] = "network"
        else:
            model.net_.core.zero_correction()
            end["kept"] = model.reference_start_["reference"]
            end["reason"] = why
            net = ref
    scored = [v for v in net if v is not None]
    out["score_folds"] = net
    finite = all(math.isfinite(v) for v in scored)
    out["mean"] = float(np.mean(scored)) if finite else math.inf
    out["spread"] = float(np.std(scored, ddof=1)) if finite and len(scored) > 1 else math.inf
    return out


def _is_reference(model) -> bool:
    """True when a residual core's correction is zero: the core equals its zeroed copy."""
    import torch
    ref = copy.deepcopy(model.net_.core)
    ref.zero_correction()
    mine = model.net_.core.state_dict()
    return all(torch.equal(mine[k], v) for k, v in ref.state_dict().items())


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %" if math.isfinite(x) else "undefined"


def describe(folds: int, own_validation: bool) -> str:
    """The protocol in one sentence (card and page)."""
    first = "its validation records" if own_validation else "the last val_fraction of every training record"
    return (f"blocked cross-validation, rolling origin, {folds} folds: fold 0 validates on {first}, each further "
            "fold on an earlier block of every training record, as long as that tail (the latest first), trained "
            "on what precedes it; score = mean free-run validation NRMSE over the folds, spread = their standard "
            "deviation")
