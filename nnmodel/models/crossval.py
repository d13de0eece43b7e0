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
* a fold whose training part would be shorter than its validation block is not made;
* a further fold whose block leaves the output range its training part saw (more than
  :data:`MAX_OUTSIDE` of the block's samples above its largest or below its smallest
  measured output) is not scored: it would measure extrapolation into a regime — a
  saturation, an overflow — that the model trained on all records has seen (the card
  lists it under ``folds_skipped``).

Each fold trains the model anew (same seed, same structure; the fold keeps its trained
correction, :meth:`~nnmodel.models.base.NeuralModel.fit_fold`) and scores its free-run NRMSE
on the fold's block; the score of the model is the mean over the folds and its **spread**
the standard deviation of the fold scores.  A residual model (a linear start, the hybrid's
physics) keeps its trained correction only when, over the scored folds, its squared-error
gain over its reference is larger than its standard error (the folds' batch-means errors,
:func:`nnmodel.batches.paired_gain`, pooled) and no fold is worse than the reference by more
than its own standard error (:func:`pooled_win`) — that decision replaces the single-tail
one (:func:`nnmodel.models.base.keep_if_better`).  Blocks differ in how much of the plant's
nonlinearity they hold, so a real gain differs from fold to fold; the spread across folds
is reported, and decides where trials are compared (:func:`paired_win`, ``--tune``).  The
further folds train on less data (60 % and 40 % of each record when ``val_fraction`` is
0.2, against fold 0's 80 %), so cross-validation costs about 1 + 0.75 + 0.5 = 2.25 fits
where one was made (a structure search pays it per candidate), and is used only where the
data are few, which is where a fit is cheap.
"""
from __future__ import annotations

import copy
import math
import warnings

import numpy as np

__all__ = ["FOLDS", "MIN_WINDOWS", "MAX_OUTSIDE", "independent_windows", "plan", "cross_validate", "paired_win",
           "pooled_win", "describe"]

#: folds when the validation data are few (``cv_folds: auto``)
FOLDS = 3
#: fewer independent windows (samples / correlation time of the output) of validation data
#: than this: cross-validate
MIN_WINDOWS = 20
#: the shortest block a fold may train or validate on (samples)
MIN_PIECE = 32
#: a further fold is not scored when more than this share of its block's measured outputs lie
#: outside the range of its training part's (extrapolation, not generalisation)
MAX_OUTSIDE = 0.1


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


def extrapolation(train, val_fraction: float) -> float:
    """Share of a fold's block (the last ``val_fraction`` of each of ``train``) whose measured
    outputs lie outside the range of the outputs before it."""
    from ..data import split_records
    fit, block = split_records(train, val_fraction, MIN_PIECE)
    if not block:
        return 0.0
    lo, hi = min(float(np.min(r.y)) for r in fit), max(float(np.max(r.y)) for r in fit)
    outside = sum(int(np.sum((r.y < lo) | (r.y > hi))) for r in block)
    return outside / sum(len(r) for r in block)


def scores(model, train, val) -> tuple[float, float | None, float, float]:
    """(free-run validation NRMSE of the fitted ``model``, the same with its correction zeroed
    — its reference alone — or None without one, the correction's gain in squared NRMSE and
    its standard error by batch means; the last two nan without a reference)."""
    from ..batches import GAIN_BLOCKS, paired_gain
    from .structure import nrmse_of, validation_errors
    e_net = validation_errors(model, train, val)
    if model.__dict__.get("reference_start_") is None:
        return nrmse_of(e_net), None, math.nan, math.nan
    ref = copy.deepcopy(model)
    ref.net_.core.zero_correction()
    e_ref = validation_errors(ref, train, val)
    if e_net is None or e_ref is None or not e_ref[1] > 0:
        gain, se = (-math.inf if e_net is None else math.nan), math.nan
    else:
        gain, se, _ = paired_gain(e_ref[0], e_net[0], GAIN_BLOCKS)
        n = sum(min(a.size, b.size) for a, b in zip(e_ref[0], e_net[0]))
        gain, se = gain * n / e_ref[1], se * n / e_ref[1]
    return nrmse_of(e_net), nrmse_of(e_ref), gain, se


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


def pooled_win(gains: list, ses: list) -> tuple[bool, float, float, str]:
    """(wins, mean gain, its standard error, why not): a correction's gain over its reference
    per fold (squared NRMSE) with its standard error by batch means (inf: unknown); it wins
    when the mean over the folds exceeds :data:`~nnmodel.batches.GAIN_SE` standard errors of
    that mean (the folds' errors pooled as independent) and no fold is worse than the
    reference by more than its own standard error (unknown: by anything).  Folds missing
    (nan) are left out; fewer than two never win."""
    from ..batches import GAIN_SE
    pairs = [(g, s) for g, s in zip(gains, ses) if not math.isnan(g)]
    if len(pairs) < 2:
        return False, math.nan, math.nan, "fewer than two folds were scored"
    g = np.array([p[0] for p in pairs], float)
    s = np.array([p[1] for p in pairs], float)
    mean = float(g.mean()) if np.all(np.isfinite(g)) else -math.inf
    known = np.isfinite(s)
    se = float(np.sqrt(np.sum(s[known] ** 2))) / len(pairs)
    worse = int(np.sum(g < -GAIN_SE * np.where(known, s, 0.0)))
    if worse:
        return False, mean, se, f"it is worse than its reference on {worse} of {len(pairs)} folds, beyond the " \
                                "fold's own uncertainty"
    if not mean > GAIN_SE * se:
        return False, mean, se, "its gain over the folds is within its uncertainty"
    return True, mean, se, ""


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
        share = extrapolation(tr, vf) if va is None else 0.0
        if share > MAX_OUTSIDE:
            skipped.append(f"fold {k}: {100 * share:.0f} % of its block lies outside the output range its training "
                           "part saw (extrapolation; not scored)")
            folds.append((None, None, math.nan, math.nan))
            continue
        fm = _fold_model(model, vf)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fm.fit_fold(tr, va)
        except InputError as exc:
            skipped.append(f"fold {k}: {exc}")
            folds.append((None, None, math.nan, math.nan))
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
            _, gain, spread = paired_win(ref, net)
            keep, sq, sq_se, why_not = pooled_win([f[2] for f in folds], [f[3] for f in folds])
            out.update(reference_nrmse_folds=ref, correction_gain=gain, correction_gain_spread=spread,
                       correction_gain_sq=sq, correction_gain_sq_se=sq_se)
            why = (f"cross-validation over {used} folds: {why_not} (NRMSE gain over the "
                   f"{model.reference_start_['reference']} start {_pct(gain)} on average, spread across the folds "
                   f"{_pct(spread)})")
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
            "on what precedes it, and not scored when its block leaves the output range that part saw; score = mean "
            "free-run validation NRMSE over the scored folds, spread = their standard deviation")
