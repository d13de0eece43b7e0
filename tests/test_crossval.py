"""Selection that survives small data (nnmodel/models/crossval.py, nnmodel/tuning.py): when the
validation data hold few independent windows a fit is scored on rolling-origin folds, the
spread is reported, a correction is kept and a tuned trial replaces the recipe only when it
wins by more than that spread; the card states the protocol."""
import json
import math
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

from nnmodel.bundle import load, save
from nnmodel.data import Experiment
from nnmodel.models.crossval import FOLDS, MIN_WINDOWS, independent_windows, paired_win, plan
from nnmodel.recipes import make_model
from nnmodel.tuning import choose


def _plant(n, seed, tau=5.0):
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n), rng.integers(1, 8, n))[:n]
    a = np.exp(-1 / tau)
    y = np.tanh(2 * lfilter([1 - a], [1, -a], u))
    return Experiment(u, y + 0.01 * rng.normal(size=n), None, 1.0)


def test_cross_validation_only_where_the_validation_data_are_few():
    model = make_model("rbf", {"structures": None})
    small, large = [_plant(400, 1)], [_plant(20_000, 1)]
    assert independent_windows([r[320:] for r in small]) < MIN_WINDOWS <= independent_windows([large[0][16000:]])
    folds = plan(model, small, None)
    assert len(folds) == FOLDS - 1
    # rolling origin: each further fold trains on what precedes its block, the block as long as fold 0's tail
    (tr1, va1, vf1), (tr2, va2, vf2) = folds
    assert va1 is None and len(tr1[0]) == 320 and round(len(tr1[0]) * vf1) == 80
    assert len(tr2[0]) == 240 and round(len(tr2[0]) * vf2) == 80
    assert plan(model, large, None) is None
    assert plan(make_model("rbf", {"structures": None, "cv_folds": 1}), small, None) is None
    assert len(plan(make_model("rbf", {"structures": None, "cv_folds": 3}), large, None)) == 2
    # validation records of their own stand for the conditions the model is for: they decide
    # alone, unless folds are asked for; then fold 0 is that split and the further folds tails
    assert plan(model, small, [_plant(200, 5)]) is None
    (tr, va, vf), _ = plan(make_model("rbf", {"structures": None, "cv_folds": 3}), small, [_plant(200, 5)])
    assert len(tr[0]) == 400 and vf == pytest.approx(0.2)


def test_the_protocol_and_the_spread_are_on_the_card(tmp_path):
    m = make_model("rbf", {"structures": None, "n_centres": 20, "progress_bar": False})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit([_plant(400, 2)], None)
    cv = m.cross_validation_
    assert cv["folds"] == 3 and len(cv["score_folds"]) == 3 and cv["protocol"].startswith("blocked cross-validation")
    assert cv["mean"] == pytest.approx(np.mean(cv["score_folds"])) and math.isfinite(cv["spread"])
    assert m.reference_start_["end"]["decided_by"] == "cross-validation"
    card = json.loads((save(m, tmp_path / "b") / "card.json").read_text())
    assert card["cross_validation"]["protocol"] == cv["protocol"] and card["hyper_parameters"]["cv_folds"] == "auto"
    back = load(tmp_path / "b").model    # what train-compare's findings read from the saved bundle
    assert back.cross_validation_["spread"] == pytest.approx(cv["spread"])
    assert back.reference_start_["end"]["kept"] == m.reference_start_["end"]["kept"]


def test_a_win_must_exceed_its_spread_over_the_folds():
    assert paired_win([0.30, 0.32, 0.31], [0.20, 0.22, 0.21]) == (True, pytest.approx(0.10), pytest.approx(0.0))
    wins, gain, spread = paired_win([0.30, 0.32, 0.31], [0.20, 0.35, 0.25])
    assert not wins and gain > 0 and spread > gain            # better on average, not beyond its spread
    assert not paired_win([0.3, None, 0.3], [0.1, 0.1, None])[0]   # one common fold: never a win


def _trial(k, folds):
    return {"trial": k, "params": {}, "validation_nrmse": float(np.mean(folds)), "validation_nrmse_folds": folds,
            "spread": float(np.std(folds, ddof=1))}


def test_a_tuned_trial_replaces_the_recipe_only_when_it_wins_by_more_than_the_spread():
    recipe = _trial(0, [0.30, 0.32, 0.31])
    lucky = _trial(1, [0.05, 0.40, 0.30])           # the lowest mean, from one lucky fold
    best, rule = choose([recipe, lucky])
    assert best is recipe and rule.startswith("the recipe is kept: no trial wins") and "(the best, trial 1," in rule
    steady = _trial(2, [0.25, 0.27, 0.26])
    best, rule = choose([recipe, lucky, steady])
    assert best is steady and rule.startswith("trial 2 wins over the recipe")   # not the lucky one
    one = [{**r, "validation_nrmse_folds": None} for r in (recipe, lucky)]   # one split: the lowest score
    assert choose(one)[0]["trial"] == 1


def test_heterogeneous_real_gains_win_and_a_fold_clearly_worse_vetoes():
    from nnmodel.models.crossval import pooled_win
    # a correction that helps a lot where the block holds the nonlinearity and a little where
    # it does not: every fold gains beyond its uncertainty, though the gains differ widely
    wins, mean, se, _ = pooled_win([0.07, 0.004], [0.02, 0.001])
    assert wins and mean == pytest.approx(0.037) and not paired_win([0.41, 0.066], [0.16, 0.055])[0]
    wins, _, _, why = pooled_win([0.07, -0.01, 0.004], [0.02, 0.002, 0.001])   # one fold clearly worse
    assert not wins and "worse than its reference on 1 of 3 folds" in why
    assert pooled_win([0.07, -0.001, 0.004], [0.02, 0.002, 0.001])[0]         # worse within its noise: no veto
    assert not pooled_win([0.01, 0.01], [0.02, 0.02])[0]                       # within its uncertainty
    assert not pooled_win([0.07, math.nan], [0.02, math.nan])[0]               # one fold scored: never a win


def _rising(n, seed):
    """A plant whose last third is driven into a range the first two thirds never reach."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n), rng.integers(1, 8, n))[:n]
    u[2 * n // 3:] += 2.0
    a = np.exp(-1 / 5.0)
    y = np.tanh(lfilter([1 - a], [1, -a], u))
    return Experiment(u, y + 0.01 * rng.normal(size=n), None, 1.0)


def test_a_fold_that_would_measure_extrapolation_is_not_scored():
    m = make_model("rbf", {"structures": None, "n_centres": 20, "progress_bar": False})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit([_rising(600, 3)], None)
    cv = m.cross_validation_
    # fold 1 trains on the first 60 % and validates on 60–80 %, where the output leaves the
    # range it saw; fold 0 (the model's own split, trained up to 80 %) is always scored
    assert cv["score_folds"][0] is not None and cv["score_folds"][1] is None
    assert cv["folds_skipped"][0].startswith("fold 1: ") and "outside the output range its training part" in \
        cv["folds_skipped"][0]


def _linear_plant(n, seed):
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n), rng.integers(1, 8, n))[:n]
    a = np.exp(-1 / 5.0)
    return Experiment(u, lfilter([1 - a], [1, -a], u) + 0.05 * rng.normal(size=n), None, 1.0)


def test_a_fold_keeps_an_untrained_correction_its_start_would_drop():
    """A correction that is not trained after its start (the RBF recipe: least squares, no
    epochs): one split drops it at its start for good; a fold keeps it for the folds to judge
    together (a fold that zeroes it scores as an exact tie with the reference, which once let a
    correction that was better on one tail only be kept and then diverge on the test)."""
    from nnmodel.models.crossval import _is_reference
    rec = [_linear_plant(400, 0)]
    settings = {"structures": None, "progress_bar": False, "cv_folds": 1}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = make_model("rbf", settings).fit(rec, None)
        fold = make_model("rbf", settings).fit_fold(rec, None)
    assert alone.max_epochs == 0
    assert alone.reference_start_["start"]["kept"] == "linear" and _is_reference(alone)
    assert fold.reference_start_["start"]["kept"] == "network" and not _is_reference(fold)


def test_a_fold_measures_the_correction_it_trained():
    """A fold keeps its trained correction for the folds to judge together, where one split
    alone (``fit``) judges it on its own tail and here drops a gain within its uncertainty."""
    from nnmodel.models.crossval import _is_reference
    rec = [_linear_plant(400, 0)]
    settings = {"structures": None, "hidden": 8, "max_epochs": 20, "progress_bar": False, "cv_folds": 1}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        alone = make_model("ff", settings).fit(rec, None)
        fold = make_model("ff", settings).fit_fold(rec, None)
    end = alone.reference_start_["end"]
    assert end["kept"] == "linear" and end["validation_nrmse_network"] < end["validation_nrmse_reference"]
    assert _is_reference(alone)                    # its correction zeroed
    assert fold.reference_start_["end"]["kept"] == "network" and "cross_validation_" not in fold.__dict__
    assert not _is_reference(fold)                 # the same training, its correction kept
    assert fold.reference_start_["end"]["validation_nrmse_network"] == end["validation_nrmse_network"]
