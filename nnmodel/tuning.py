"""Tuning on validation data (``eap train-compare ... --tune N``), reproducible and parallel.

Each model's search space is the ``tune:`` section of its recipe (``configs/train/NAME.yaml``):
hyper-parameter -> ``{low, high}`` (whole numbers when both bounds are; ``log: true`` for a
log scale) or ``{choices: [...]}``; the pseudo-parameter ``structure`` picks one entry of
the recipe's ``structures`` or ``search`` (the recipe's own search over them).  The first
trial is the recipe itself (its values, clipped into the ranges), so tuning never ends
worse than the defaults on validation.  When the validation data are few every trial is
cross-validated (:mod:`nnmodel.models.crossval`: its score is the mean over the folds) and
a trial replaces the recipe only when its fold-by-fold gain over the recipe is larger on
average than its spread; of such trials the lowest-scoring is kept (:func:`choose`).  N trials are drawn by Optuna's TPE sampler (Bergstra et al.,
NeurIPS 2011) seeded with the model's seed, asked and told in fixed batches of
:data:`BATCH` — the trials of a batch are tasks on the execution layer
(:mod:`physics.execution.parallel`, ``--workers``/``--scheduler``) and are told back in trial order —
so the trials, and therefore the result, do not depend on the worker count or on which
trial finishes first.  A trial trains the model with the recipe plus its parameters on the
training records and scores its free-run NRMSE on the validation data (the validation
records, or the last ``val_fraction`` of each training record); the test records are never
seen.  The best trial's settings are then trained again (same seed: the same model) and
saved by ``train-compare``; every trial is listed in the card and on the page.
"""
from __future__ import annotations

import math
import time
import warnings

from physics.errors import InputError

__all__ = ["BATCH", "search_space", "tune", "choose"]

#: trials asked (and run side by side) before the sampler is told their scores
BATCH = 4
#: the pseudo-parameter that picks an entry of the recipe's ``structures`` (or SEARCH)
STRUCTURE = "structure"
#: the ``structure`` choice that keeps the recipe's own search over its structures
SEARCH = "search"


def search_space(name: str, spec: dict, params: dict) -> dict:
    """Optuna distributions of a recipe's ``tune`` section (``params``: the recipe's
    hyper-parameters, to check names and the ``structure`` choice against)."""
    from optuna.distributions import CategoricalDistribution, FloatDistribution, IntDistribution

    out = {}
    for key, d in (spec or {}).items():
        where = f"recipe {name!r}, tune.{key}"
        if key == STRUCTURE:
            n = len(params.get("structures") or [])
            if n < 2:
                raise InputError(f"{where}: the recipe has no structures to choose from")
            out[key] = CategoricalDistribution([SEARCH] + list(range(n)))
            continue
        if key not in params:
            raise InputError(f"{where}: not a hyper-parameter of {name!r}")
        if not isinstance(d, dict):
            raise InputError(f"{where}: expected {{low, high}} or {{choices: [...]}}, got {d!r}")
        if "choices" in d:
            if not isinstance(d["choices"], list) or not d["choices"]:
                raise InputError(f"{where}: choices must be a non-empty list")
            out[key] = CategoricalDistribution(d["choices"])
            continue
        lo, hi, log = d.get("low"), d.get("high"), bool(d.get("log", False))
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (lo, hi)) or not lo < hi \
                or (log and lo <= 0):
            raise InputError(f"{where}: needs numbers low < high (positive with log: true), got {d!r}")
        out[key] = IntDistribution(lo, hi, log=log) if isinstance(lo, int) and isinstance(hi, int) \
            else FloatDistribution(float(lo), float(hi), log=log)
    if not out:
        raise InputError(f"recipe {name!r} has no tune section: nothing to search")
    return out


def overrides_of(params: dict, recipe_params: dict) -> dict:
    """Hyper-parameter overrides of a trial (``structure`` expanded to its entry)."""
    out = {k: v for k, v in params.items() if k != STRUCTURE}
    if params.get(STRUCTURE, SEARCH) != SEARCH:
        out = {**recipe_params["structures"][params[STRUCTURE]], **out, "structures": None}
    return out


def recipe_trial(space: dict, params: dict) -> dict:
    """The recipe's own values as a trial of ``space`` (numbers clipped into their range,
    the structure search as the recipe has it)."""
    from optuna.distributions import CategoricalDistribution
    out = {}
    for key, dist in space.items():
        if key == STRUCTURE:
            out[key] = SEARCH
        elif isinstance(dist, CategoricalDistribution):
            if params[key] in dist.choices:
                out[key] = params[key]
        else:
            v = min(max(params[key], dist.low), dist.high)
            out[key] = int(round(v)) if isinstance(dist.low, int) and not isinstance(dist.low, bool) else float(v)
    return out


def _trial(task: dict) -> dict:
    """One trial (a task of :func:`physics.execution.parallel.map_tasks`): train with the overrides,
    return the free-run validation NRMSE (inf when training fails or diverges)."""
    from physics.effects import ensure_registered

    from .dataset import load_dataset
    from .models.structure import selection_score
    from .recipes import make_model

    ensure_registered(task["effect_files"])
    ds = load_dataset(task["dataset"])
    train, val = ds.records("train"), ds.records("validation") or None
    model = make_model(task["name"], task["overrides"])
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model.fit(train, val)
        score = selection_score(model, train, val)
        error = None
    except InputError as exc:
        score, error = math.inf, str(exc)
    cv = model.__dict__.get("cross_validation_") if error is None else None
    return {"score": score if math.isfinite(score) else None, "error": error,
            "fit_time_s": time.perf_counter() - t0, "n_parameters": model.n_parameters if error is None else None,
            "folds": cv["score_folds"] if cv else None, "spread": cv["spread"] if cv else None}


def tune(name: str, recipe: dict, base: dict, n_trials: int, dataset: str, settings, effect_files,
         echo=None) -> dict:
    """Run ``n_trials`` trials for model ``name`` (``recipe`` from :func:`load_recipe` with
    the ``tune`` section, ``base``: the caller's overrides, kept in every trial); returns
    ``{"best": {...}, "trials": [...], ...}`` with the overrides of the best trial."""
    import optuna

    from physics.execution.parallel import map_tasks

    if isinstance(n_trials, bool) or not isinstance(n_trials, int) or n_trials < 1:
        raise InputError(f"--tune {n_trials!r}: must be a positive whole number of trials")
    params = recipe["hyper_parameters"]
    space = {k: v for k, v in search_space(name, recipe.get("tune"), params).items() if k not in base}
    seed = int(params.get("seed", 0))
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(direction="minimize", sampler=optuna.samplers.TPESampler(seed=seed))
    study.enqueue_trial(recipe_trial(space, params))
    rows = []
    while len(rows) < n_trials:
        asked = [study.ask(space) for _ in range(min(BATCH, n_trials - len(rows)))]
        tasks = [{"name": name, "dataset": dataset, "effect_files": effect_files,
                  "overrides": {**overrides_of(t.params, params), **base, "progress_bar": False}} for t in asked]
        for t, task, res in zip(asked, tasks, map_tasks(_trial, tasks, settings, desc=f"{name} trials",
                                                         progress=False)):
            if res["score"] is None:
                study.tell(t, state=optuna.trial.TrialState.FAIL)
            else:
                study.tell(t, res["score"])
            rows.append({"trial": t.number, "params": dict(t.params), "validation_nrmse": res["score"],
                         "fit_time_s": res["fit_time_s"], "n_parameters": res["n_parameters"], "error": res["error"],
                         "validation_nrmse_folds": res["folds"], "spread": res["spread"]})
        if echo is not None:
            done = [r["validation_nrmse"] for r in rows if r["validation_nrmse"] is not None]
            echo(f"  {name}: {len(rows)}/{n_trials} trials, best validation NRMSE "
                 + (f"{100 * min(done):.3g} %" if done else "-"))
    ok = [r for r in rows if r["validation_nrmse"] is not None]
    if not ok:
        raise InputError(f"--tune: every trial of {name!r} failed (first: {rows[0]['error']})")
    best, rule = choose(rows)
    cv = rows[0]["validation_nrmse_folds"] is not None
    return {"n_trials": n_trials, "sampler": f"TPE (optuna {optuna.__version__}), seed {seed}", "batch": BATCH,
            "space": {k: repr(v) for k, v in space.items()},
            "score": ("mean free-run NRMSE over the cross-validation folds (crossval)" if cv
                      else "free-run NRMSE on the validation data"), "rule": rule,
            "trials": rows, "best": {"trial": best["trial"], "params": best["params"],
                                     "validation_nrmse": best["validation_nrmse"], "spread": best["spread"],
                                     "overrides": overrides_of(best["params"], params)}}


def choose(rows: list[dict]) -> tuple[dict, str]:
    """The trial to keep, and the rule that chose it: the lowest score; when the trials were
    cross-validated, the lowest score among the trials that win over the recipe (trial 0) by
    more than the spread of their fold-by-fold gain
    (:func:`nnmodel.models.crossval.paired_win`), else the recipe."""
    from .models.crossval import paired_win
    ok = [r for r in rows if r["validation_nrmse"] is not None]
    best = min(ok, key=lambda r: (r["validation_nrmse"], r["trial"]))
    recipe = rows[0]
    if recipe["validation_nrmse_folds"] is None or recipe["validation_nrmse"] is None or best is recipe:
        return best, "lowest validation score"
    wins = {r["trial"]: paired_win(recipe["validation_nrmse_folds"], r["validation_nrmse_folds"] or [])
            for r in ok if r is not recipe}
    winners = [r for r in ok if r is not recipe and wins[r["trial"]][0]]
    if winners:
        pick = min(winners, key=lambda r: (r["validation_nrmse"], r["trial"]))
        _, gain, spread = wins[pick["trial"]]
        return pick, (f"trial {pick['trial']} wins over the recipe by {100 * gain:.3g} % NRMSE on average over the "
                      f"folds, more than the spread of that gain ({100 * spread:.3g} %)")
    _, gain, spread = wins[best["trial"]]
    return recipe, (f"the recipe is kept: no trial wins over it by more than the spread of its fold-by-fold gain "
                    f"(the best, trial {best['trial']}, by {100 * gain:.3g} % against {100 * spread:.3g} %)")
