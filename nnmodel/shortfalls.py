"""Why a network falls short, in plain words (the page of ``eap train-compare``).

A network *falls short* when its free-run test error is above the linear yardstick's or the
physics model's, or when its one-step residual is biased (its mean is a large part of its
RMS: the model is systematically off, which more training does not cure).  For each
shortfall the likely cause is looked for in the data — too few RH levels, too few training
samples for the network's size, records shorter than the slow dynamics the recipe covers,
an output offset that differs between records — and the finding says what to do.
"""
from __future__ import annotations

import numpy as np

__all__ = ["data_facts", "explain", "sentences", "BIAS_RATIO", "MIN_SAMPLES_PER_PARAMETER", "MIN_RH_LEVELS"]

#: a one-step residual whose mean exceeds this fraction of its RMS is biased
BIAS_RATIO = 0.5
#: fewer training samples per learned parameter than this: the network can fit noise
MIN_SAMPLES_PER_PARAMETER = 10
#: a humidity-aware network needs at least this many training RH levels to interpolate
MIN_RH_LEVELS = 3
#: test and training output means further apart than this many output standard deviations
OFFSET_SHIFT = 0.5


def data_facts(ds) -> dict:
    """What the causes are judged from: training samples and record lengths, RH levels,
    and the mean and spread of the output in the training and test records."""
    train = ds.records("train")
    test = [ds.record(e) for e in ds.entries("test")]
    levels = (ds.meta.get("rh_levels") or {}).get("train") if ds.has_rh else None
    y_tr = np.concatenate([r.y for r in train])
    y_te = np.concatenate([r.y for r in test]) if test else y_tr
    out = ds.meta.get("output") or {"name": "deflection", "unit": "m"}
    return {"train_samples": int(y_tr.size), "record_s": float(np.median([r.duration for r in train])),
            "rh_levels": None if levels is None else [float(v) for v in levels],
            "train_mean": float(np.mean(y_tr)), "test_mean": float(np.mean(y_te)),
            "output_std": float(np.std(y_tr)) or 1.0, "unit": str(out.get("unit", "m")),
            "validation_records": len(ds.entries("validation")),
            "quantity": str(out.get("name", "deflection"))}


def _value(v: float, unit: str) -> str:
    if unit == "m":
        a = abs(v)
        return f"{v * 1e3:.3g} mm" if a >= 1e-4 else f"{v * 1e6:.3g} µm"
    return f"{v:.3g} {unit}"


def _smaller(name: str, model) -> str:
    """How to ask for a smaller network of this kind on the command line."""
    params = model.get_params() if hasattr(model, "get_params") else {}
    sizes = [f"--set {name}.{k}={max(2, int(params[k]) // 4)}" for k in ("hidden", "n_centres") if k in params]
    return ", ".join(sizes + ([f"fewer lags (--set {name}.nb=...)"] if "nb" in params else [])) or "fewer parameters"


def _causes(name: str, model, facts: dict, biased: bool) -> list[tuple[str, str]]:
    """(cause, what to do) pairs the data support."""
    out = []
    shift = abs(facts["test_mean"] - facts["train_mean"]) / facts["output_std"]
    if biased or shift > OFFSET_SHIFT:
        if shift > OFFSET_SHIFT:
            out.append((f"offset not removed: the test records' mean {facts['quantity']} differs from the training "
                        f"records' by {_value(facts['test_mean'] - facts['train_mean'], facts['unit'])} "
                        f"({shift:.1f} standard deviations), a zero the network cannot know",
                        "remove each record's offset before `eap dataset` (subtract its rest value, e.g. the mean "
                        "before the drive starts), or record with one sensor zero"))
    levels = facts["rh_levels"]
    if model is not None and model.uses_rh and levels is not None and len(levels) < MIN_RH_LEVELS:
        out.append((f"too few RH levels: trained at {len(levels)} ({', '.join(f'{v:g}' for v in levels)} %), "
                    "too few to learn how humidity changes the response between them",
                    f"record at {MIN_RH_LEVELS} or more RH levels spanning the range you predict at"))
    start = getattr(model, "reference_start_", None) or {}
    end = start.get("end") or {}
    if end.get("kept") == "network" and end.get("validation_gain_se") is not None:
        own = facts.get("validation_records", 0)
        out.append((f"its validation data could not foresee it: there it beat its {start['reference']} start "
                    f"({100 * end['validation_nrmse_reference']:.2f} % → {100 * end['validation_nrmse_network']:.2f} % "
                    f"NRMSE, a gain of {end['validation_gain'] / end['validation_gain_se']:.1f} standard errors) on "
                    + (f"{own} validation record(s) unlike the test records" if own else
                       "the tails of the training records, which resemble the training data more than the test"),
                    "give validation records of their own that vary like the test conditions "
                    "(`eap dataset --validation FILE ...`)"))
    if model is not None:
        per = facts["train_samples"] / max(1, model.n_parameters)
        if per < MIN_SAMPLES_PER_PARAMETER:
            out.append((f"too short records: {facts['train_samples']:,} training samples for "
                        f"{model.n_parameters:,} parameters ({per:.1f} per parameter), so it can fit noise",
                        f"record longer (about {MIN_SAMPLES_PER_PARAMETER * model.n_parameters:,} samples) or train a "
                        f"smaller network ({_smaller(name, model)})"))
        rng = model.memory_range_
        if rng is not None and rng[1] < 0.99 * float(model.memory_max_s):
            out.append((f"records may be too short for slow dynamics: at {facts['record_s']:.3g} s they cover "
                        f"responses up to {rng[1]:.3g} s, the recipe up to {float(model.memory_max_s):g} s",
                        "if the plant responds that slowly, record at least twice as long as its slowest response"))
    return out


def explain(name: str, row: dict, results: dict, model, facts: dict, linear: str = "linear") -> list[dict]:
    """Findings for the network ``name`` (its result ``row``; ``model`` the trained model):
    ``[{"finding", "causes": [{"cause", "action"}, ...]}]`` in plain words; empty when it
    falls short nowhere."""
    test = row["free_run"]["test"]["nrmse"]
    gaps = []
    lin = results.get(linear)
    if lin is not None and test > lin["free_run"]["test"]["nrmse"]:
        gaps.append(f"its free-run test error ({100 * test:.2f} %) is above the linear model's "
                    f"({100 * lin['free_run']['test']['nrmse']:.2f} %)")
    phys = results.get("physics")
    if phys is not None and test > phys["free_run"]["test"]["nrmse"]:
        gaps.append(f"its free-run test error ({100 * test:.2f} %) is above the physics model's "
                    f"({100 * phys['free_run']['test']['nrmse']:.2f} %)")
    one = (row.get("one_step") or {}).get("test") or {}
    biased = bool(one) and abs(one.get("mean_error", 0.0)) > BIAS_RATIO * one.get("rmse_m", np.inf)
    if biased:
        gaps.append(f"its one-step residual is biased: it sits {_value(one['mean_error'], facts['unit'])} off zero "
                    f"({100 * abs(one['mean_error']) / one['rmse_m']:.0f} % of its RMS)")
    if not gaps:
        return []
    causes = _causes(name, model, facts, biased) or [(
        "no cause found in the data: the recipe's structure or budget does not suit this plant",
        f"search its settings on the validation data with `eap train-compare ... --models {name} --tune 20`")]
    return [{"finding": f"{name}: {'; '.join(gaps)}", "causes": [{"cause": c, "action": a} for c, a in causes]}]


def sentences(finding: dict) -> list[str]:
    """A finding as plain sentences: what falls short, then each likely cause and what to do."""
    return [f"{finding['finding']}."] + [f"Likely cause: {c['cause']}. What to do: {c['action']}."
                                         for c in finding["causes"]]
