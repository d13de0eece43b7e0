"""Why a network falls short, in plain words (the page of ``eap train-compare``).

A network *falls short* when its free-run test error is above the linear yardstick's or the
physics model's, when its correction was dropped (it then *is* its linear start and ties
the linear row), or when its one-step residual is biased (its mean is a large part of its
RMS: the model is systematically off, which more training does not cure).  For each
shortfall the cause is looked for in the data and in how the network was kept:

* its **correction was dropped** — not better than its start on validation at all (then its
  structure misses what the linear model misses), or better by less than the uncertainty of
  few validation data (then more validation data decide it);
* the output **saturates or is clipped** (a static compression the linear model cannot
  follow: a cubic term of its own output explains part of its residual, or the samples pile
  at the output's extremes);
* an **integrating plant** (the linear model's slowest pole does not decay within a record;
  such data usually come from a closed loop around the plant);
* a **closed loop** (:func:`feedback`: past outputs predict the input beyond the input's own
  past — a controller produced the input from the measured output);
* **too few independent windows** of training data (samples divided by the output's
  correlation time) for the network's map;
* an output offset that differs between records, too few RH levels, validation data unlike
  the test, records shorter than the slow dynamics the recipe covers.

Each finding says what to do, and each piece of advice is tested by following it on a case
that raises it (``tests/test_shortfalls_followed.py``): the result moves the way it says.
No network kind is named here: advice reads the model's own hyper-parameters.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.stats import f as f_distribution

from physics.pages.columns import quantity

from .models.crossval import independent_windows

__all__ = ["data_facts", "facts", "explain", "sentences", "saturation", "integrating", "feedback", "feedback_statistic",
           "BIAS_RATIO", "MIN_RH_LEVELS", "MIN_TRAIN_WINDOWS"]

#: a one-step residual whose mean exceeds this fraction of its RMS is biased
BIAS_RATIO = 0.5
#: a humidity-aware network needs at least this many training RH levels to interpolate
MIN_RH_LEVELS = 3
#: test and training output means further apart than this many output standard deviations
OFFSET_SHIFT = 0.5
#: fewer independent windows of training data than this: a nonlinear map is poorly determined
MIN_TRAIN_WINDOWS = 50
#: a cubic term of the linear model's output that explains this share of its residual
#: variance, and compresses, is a saturation
SATURATION_SHARE = 0.1
#: this share of the samples within 1 % of the output's range from its maximum (or minimum),
#: on flat stretches reached at least :data:`CLIP_VISITS` separate times, is a clipped output
CLIP_SHARE = 0.02
CLIP_VISITS = 3
#: a slowest linear mode whose time constant exceeds this fraction of a training record, with a
#: static gain above :data:`INTEGRATOR_GAIN`, is an integrator within the record
INTEGRATOR_FRACTION = 0.5
#: static gain of the linear model (output standard deviations per input standard deviation)
#: above which a slow mode integrates (a spurious near-cancelled slow pole has a modest gain)
INTEGRATOR_GAIN = 10.0
#: the feedback test (:func:`feedback`): lags of the input's own past and of the linear model's
#: free run (the restricted regression) and of the measured output (added), in samples
FEEDBACK_INPUT_LAGS = 20
FEEDBACK_OUTPUT_LAGS = 10
#: past outputs that explain at least this share of the input's unpredictable variance and
#: :data:`FEEDBACK_INPUT_SHARE` of its variance (both beyond chance), with an F-test p-value
#: below :data:`FEEDBACK_P`, are a closed loop
FEEDBACK_SHARE = 0.01
FEEDBACK_INPUT_SHARE = 1e-3
FEEDBACK_P = 1e-3
#: errors within this relative difference are the same (float32 rounding of a network that is
#: its linear start)
SAME = 1e-3
#: what the advice asks for when a correction was dropped within its uncertainty
MORE_VALIDATION_FRACTION = 0.4


# ---------------------------------------------------------------------- evidence in the data
def _free_runs(linear, records) -> list[np.ndarray]:
    """The linear model's free run over each record, started on its measured outputs."""
    return [linear.simulate(r.u, r.rh if linear.uses_rh else None, y_init=r.y[:linear.n_init]) for r in records]


def saturation(records, linear) -> dict | None:
    """Evidence that the output saturates or is clipped, or None: ``{"kind": "clipped"|
    "saturates", ...}``.  Clipped: more than :data:`CLIP_SHARE` of the samples sit within 1 %
    of the output's range from its maximum or minimum on flat stretches, reached at least
    :data:`CLIP_VISITS` separate times (a limit, not one long plateau).  Saturates: regressing
    the measured output on the linear model's free run ŷ and ŷ³ (centred, on the training
    records), the cubic term compresses (its sign opposes the linear one) and explains at least
    :data:`SATURATION_SHARE` of the linear residual's variance — a Wiener-type static output
    nonlinearity."""
    y = np.concatenate([r.y for r in records])
    lo, hi = float(np.min(y)), float(np.max(y))
    span = hi - lo
    if not span > 0:
        return None
    flat = np.concatenate([np.r_[np.abs(np.diff(r.y)) <= 0.01 * span, False] for r in records])
    for side, edge in (("maximum", hi), ("minimum", lo)):
        at = (np.abs(y - edge) <= 0.01 * span) & flat
        visits = int(np.count_nonzero(np.diff(np.r_[0, at.astype(np.int8)]) == 1))
        if np.mean(at) >= CLIP_SHARE and visits >= CLIP_VISITS:
            return {"kind": "clipped", "side": side, "level": edge, "share": float(np.mean(at)), "visits": visits}
    if linear is None:
        return None
    yh = np.concatenate(_free_runs(linear, records))
    z = (yh - np.mean(y)) / (np.std(y) or 1.0)
    t = (y - np.mean(y)) / (np.std(y) or 1.0)
    ok = np.isfinite(z)
    z, t = z[ok], t[ok]
    if z.size < 10:
        return None
    c1 = float(np.dot(z, t) / max(np.dot(z, z), 1e-300))
    base = float(np.mean((t - c1 * z) ** 2))
    X = np.stack([z, z ** 3], 1)
    (a, b), *_ = np.linalg.lstsq(X, t, rcond=None)
    share = 1.0 - float(np.mean((t - X @ np.array([a, b])) ** 2)) / max(base, 1e-300)
    if a * b < 0 and share >= SATURATION_SHARE:
        return {"kind": "saturates", "share": share, "range": [lo, hi]}
    return None


def integrating(linear, records) -> dict | None:
    """Evidence of an integrator (or a mode slower than the records): the time constant of the
    linear model's slowest pole exceeds :data:`INTEGRATOR_FRACTION` of the median training
    record (or the pole does not decay: |pole| ≥ 1) and its static gain B(1)/A(1), in output
    per input standard deviations, exceeds :data:`INTEGRATOR_GAIN` (or is infinite).
    ``{"pole", "time_constant_samples", "record_samples", "static_gain"}`` or None.  Such
    plants are usually measured in a closed loop (a controller holds the integral in range)."""
    if linear is None or linear.na == 0:
        return None
    a = np.asarray(linear.a, float)
    p = float(np.max(np.abs(np.roots(np.r_[1.0, -a]))))
    n = float(np.median([len(r) for r in records]))
    tau = np.inf if p >= 1.0 else -1.0 / np.log(p)
    den = 1.0 - float(np.sum(a))
    gain = abs(float(np.sum(linear.b)) / den) if den != 0 else np.inf
    if tau < INTEGRATOR_FRACTION * n or gain < INTEGRATOR_GAIN:
        return None
    return {"pole": p, "time_constant_samples": float(tau), "record_samples": n, "static_gain": gain}


def _lagged(x: np.ndarray, start: int, k: int) -> np.ndarray:
    """Rows ``x[t-k], …, x[t-1]`` for t = ``start`` … len(x) − 1."""
    return sliding_window_view(x[:-1], k)[start - k:]


def feedback_statistic(records, linear) -> dict | None:
    """The test statistic of :func:`feedback` — ``{"share", "F", "p", "input_lags",
    "output_lags", "samples"}`` — whether or not it finds a loop; None without a linear
    model or records long enough for the regressions."""
    if linear is None:
        return None
    na, k = FEEDBACK_INPUT_LAGS, FEEDBACK_OUTPUT_LAGS
    start, n_r, n_f = max(na, k), 1 + na + k, 1 + na + 2 * k
    u_all, y_all = np.concatenate([r.u for r in records]), np.concatenate([r.y for r in records])
    su, my, sy = float(np.std(u_all)) or 1.0, float(np.mean(y_all)), float(np.std(y_all)) or 1.0
    tss = rss_r = rss_f = 0.0
    n = used = 0
    res = []
    for r, yh in zip(records, _free_runs(linear, records)):
        if len(r) - start < 2 * n_f:
            continue
        u = r.u / su
        A = np.hstack([np.ones((len(r) - start, 1)), _lagged(u, start, na), _lagged((yh - my) / sy, start, k)])
        B = np.hstack([A, _lagged((r.y - my) / sy, start, k)])
        t = u[start:]
        e_r = t - A @ np.linalg.lstsq(A, t, rcond=None)[0]
        e_f = t - B @ np.linalg.lstsq(B, t, rcond=None)[0]
        if not (np.all(np.isfinite(e_r)) and np.all(np.isfinite(e_f))):
            continue
        tss += float(np.sum((t - np.mean(t)) ** 2))
        rss_r, rss_f, n, used = rss_r + float(e_r @ e_r), rss_f + float(e_f @ e_f), n + t.size, used + 1
        res.append(e_f)
    df_r, df_f = n - used * n_r, n - used * n_f
    if not used or not rss_r > 0 or df_f <= 0:
        return None
    rho = abs(sum(float(e[1:] @ e[:-1]) for e in res) / max(rss_f, 1e-300))
    df_eff = n * (1 - rho) / (1 + rho) - used * n_f
    if df_eff <= 0:
        return None
    share = 1.0 - (rss_f / df_f) / (rss_r / df_r)
    q = used * k
    F = ((rss_r - rss_f) / q) / max(rss_f / df_eff, 1e-300)
    return {"share": float(share), "input_share": float((rss_r / df_r - rss_f / df_f) / (tss / (n - used))), "F": float(F), "p": float(f_distribution.sf(F, q, df_eff)), "input_lags": na,
            "output_lags": k, "samples": int(n)}


def feedback(records, linear) -> dict | None:
    """Evidence that the input was produced by a loop reacting to the measured output (a
    controller), or None: a Granger-causality test (C. W. J. Granger, Econometrica 37 (1969)
    424–438; L. Ljung, *System Identification*, 2nd ed., 1999, §13.4, testing for feedback).

    In each record the input u(t) is regressed on its own past u(t−1 … t−na) and on the
    ``linear`` model's free run ŷ(t−1 … t−k) — the part of the output the input explains —
    then also on the measured output y(t−1 … t−k) (na = :data:`FEEDBACK_INPUT_LAGS`, k =
    :data:`FEEDBACK_OUTPUT_LAGS`; each record has coefficients of its own, so a pulse and a
    sweep are not forced into one predictor).  In open loop what remains of the output (noise,
    disturbances) is independent of the input and predicts nothing; in a closed loop u = C(r − y)
    it was fed back into the input.  Pooled over the records: ``share``, the drop of the
    residual variance adjusted for the added regressors (≈ 0 by chance); ``F`` and its ``p``
    value, the denominator's degrees of freedom reduced for the residual's lag-one correlation
    ρ (n (1 − |ρ|)/(1 + |ρ|), Bartlett's effective sample size).  A closed loop: ``share`` ≥
    :data:`FEEDBACK_SHARE` and ``p`` < :data:`FEEDBACK_P`.  Returns ``{"share", "F", "p",
    "input_lags", "output_lags", "samples"}`` or None (no loop, or no linear model)."""
    stat = feedback_statistic(records, linear)
    found = stat is not None and stat["share"] >= FEEDBACK_SHARE and stat["input_share"] >= FEEDBACK_INPUT_SHARE \
        and stat["p"] < FEEDBACK_P
    return stat if found else None


def data_facts(ds, linear=None) -> dict:
    """What the causes are judged from, for a dataset (:func:`facts`); RH levels grouped
    within the hygrometer's tolerance (:func:`physics.compare.cluster_rh`)."""
    from physics.compare import cluster_rh
    levels = (ds.meta.get("rh_levels") or {}).get("train") if ds.has_rh else None
    if levels:
        levels = sorted(set(cluster_rh([float(v) for v in levels])))
    return facts(ds.records("train"), [ds.record(e) for e in ds.entries("test")], levels,
                 ds.meta.get("output") or {"name": "deflection", "unit": "m"}, len(ds.entries("validation")), linear)


def facts(train, test, rh_levels, output: dict, validation_records: int = 0, linear=None) -> dict:
    """What the causes are judged from: training samples and record lengths, RH levels, the
    mean and spread of the output in the training and ``test`` records, independent windows,
    and (with the ``linear`` yardstick) the evidence of :func:`saturation`,
    :func:`integrating` and :func:`feedback`."""
    y_tr = np.concatenate([r.y for r in train])
    y_te = np.concatenate([r.y for r in test]) if test else y_tr
    return {"train_samples": int(y_tr.size), "record_s": float(np.median([r.duration for r in train])),
            "rh_levels": None if rh_levels is None else [float(v) for v in rh_levels],
            "train_mean": float(np.mean(y_tr)), "test_mean": float(np.mean(y_te)),
            "output_std": float(np.std(y_tr)) or 1.0, "unit": str(output.get("unit", "m")),
            "validation_records": int(validation_records), "quantity": str(output.get("name", "deflection")),
            "train_windows": independent_windows(train),
            "saturation": saturation(train, linear), "integrating": integrating(linear, train),
            "feedback": feedback(train, linear)}


# ---------------------------------------------------------------------- causes
def _value(v: float, unit: str) -> str:
    return quantity(v, unit)


def _dropped(model) -> dict | None:
    """How the correction was dropped (the card's ``reference_start``), or None when kept."""
    rs = getattr(model, "reference_start_", None) or {}
    end, start = rs.get("end") or {}, rs.get("start") or {}
    if not end or end.get("kept") == "network":
        return None
    if start.get("kept") not in (None, "network") and end.get("validation_nrmse_network") is not None \
            and end["validation_nrmse_network"] >= end["validation_nrmse_reference"]:
        end = start      # dropped before training and never better after: the start's comparison says why
    return {"reference": rs.get("reference", end.get("kept")), **end}


def _param(model, key):
    params = model.get_params() if hasattr(model, "get_params") else {}
    return params.get(key)


def _more_data(facts: dict) -> str:
    """How much training data give :data:`MIN_TRAIN_WINDOWS` independent windows."""
    per = facts["train_samples"] / max(facts.get("train_windows") or 1.0, 1e-9)
    return f"about {int(np.ceil(MIN_TRAIN_WINDOWS * per)):,} training samples give {MIN_TRAIN_WINDOWS} windows"


def _dropped_cause(name: str, drop: dict, facts: dict) -> tuple[str, str]:
    ref = drop["reference"]
    net, base = drop.get("validation_nrmse_network"), drop.get("validation_nrmse_reference")
    if net is not None and base is not None and net < base:
        how = drop.get("reason") or "its validation gain is within its uncertainty"
        return (f"its correction was dropped: on validation it lowered the error below its {ref} start "
                f"({100 * base:.3g} % → {100 * net:.3g} %), but {how}; so it is its {ref} start",
                f"record more: longer or more records ({_more_data(facts)}), and validation records of their own "
                "(`eap dataset --validation FILE ...`): a correction fitted on more data, judged on more, is kept "
                f"where it is real and the row falls below the {ref} row")
    return (f"its correction was dropped: on validation it was no better than its {ref} start ("
            + (f"{100 * base:.3g} % → {100 * net:.3g} %" if net is not None and base is not None else "no gain")
            + f"), so it is its {ref} start",
            f"another structure or budget: search its settings with `eap train-compare ... --models {name} --tune 20` "
            "(the chosen trial never validates worse than the recipe)")


def _loop_causes(name: str, model, facts: dict) -> list[tuple[str, str]]:
    """The integrator and closed-loop findings (cause, what to do), said once together: an
    integrator's data usually come from a loop, and the k-step-ahead advice is given once."""
    out = []
    integ, loop = facts.get("integrating"), facts.get("feedback")
    k_step = "judge it also by k-step-ahead prediction (`eap predict --steps-ahead K`)"
    k_step_said = False
    if integ:
        tau = integ["time_constant_samples"]
        what = (f"the linear model's slowest pole ({integ['pole']:.4f}) "
                + ("does not decay" if not np.isfinite(tau) else f"decays over {tau:,.0f} samples")
                + f", against training records of {integ['record_samples']:,.0f} samples: within a record the plant "
                "integrates its input, or creeps on longer than a record lasts"
                + (" (its data come from a closed loop, below)" if loop else
                   " (an integrator's data usually come from a closed loop, whose controller kept the integral in "
                   "range)"))
        if model is not None and model.__dict__.get("reference_start_") is None and _param(model, "na") == 0:
            action = (f"give it a state that can integrate: its linear start (`--set {name}.linear_start=true`) or "
                      f"output feedback (`--set {name}.na=10`); a free run from the input alone cannot hold the "
                      "integral")
        else:
            action = ("a free run of an integrator accumulates every small error that the loop corrected in the "
                      f"measurement: {k_step}")
            k_step_said = True
        out.append((f"an integrating plant: {what}", action))
    if loop:
        out.append((f"a closed loop: the input was produced by a controller reacting to the measured output — the "
                    f"past {loop['output_lags']} outputs predict {100 * loop['share']:.0f} % of the input's "
                    f"unpredictable variation beyond its own past (Granger test, F = {loop['F']:.3g}, "
                    + (f"p = {loop['p']:.0e}" if loop["p"] > 0 else "p < 1e-300") + "); the output's noise was fed back into the input, so a model trained on the "
                    "measured input as if it were free is biased towards the inverse of the controller (Ljung, "
                    "System Identification, §13.4; Forssell and Ljung, Automatica 1999)",
                    "if the plant is stable without its controller, record it in open loop, driven by a signal of "
                    "the same range and bandwidth that is not computed from the output: a model trained on those "
                    "records learns the plant, and its error on drives that do not react to the output falls; to "
                    "predict the loop as it runs, make its reference (set-point) the input (`eap dataset ... "
                    "--columns voltage=REFERENCE,...` with the reference's column, the other columns as before): "
                    "reference → output is an open-loop system, identified consistently"
                    + ("" if k_step_said else f"; with neither, {k_step}")))
    return out


def _causes(name: str, model, facts: dict, biased: bool, drop: dict | None) -> list[tuple[str, str]]:
    """(cause, what to do) pairs the data and the model's card support."""
    out = []
    if drop is not None:
        out.append(_dropped_cause(name, drop, facts))
    sat = facts.get("saturation")
    if sat:
        where = (f"at its {sat['side']} ({_value(sat['level'], facts['unit'])}: "
                 f"{100 * sat['share']:.1f} % of the training samples sit there)" if sat["kind"] == "clipped" else
                 f": a cubic term of the linear model's output explains {100 * sat['share']:.0f} % of its residual "
                 "and compresses it")
        if sat["kind"] == "clipped":
            action = ("record within the output's range (a lower drive, or a sensor range that holds the output): "
                      "the clipped samples show the limit, not the plant, and a linear model then follows the records")
        else:
            action = (f"the linear row cannot follow a saturation, a network's correction can, given data enough to "
                      f"fit and keep it: record more ({_more_data(facts)})")
        out.append((f"the output {'is clipped ' if sat['kind'] == 'clipped' else 'saturates'}{where}", action))
    out += _loop_causes(name, model, facts)
    shift = abs(facts["test_mean"] - facts["train_mean"]) / facts["output_std"]
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
    if model is not None and drop is None:
        windows = facts.get("train_windows")
        if windows is not None and windows < MIN_TRAIN_WINDOWS:
            per = facts["train_samples"] / max(windows, 1e-9)
            out.append((f"too few independent windows: the training data hold {windows:.0f} (the output's "
                        f"correlation time is {per:.0f} samples), too few to pin down a map of "
                        f"{model.n_parameters:,} parameters",
                        f"record longer, or more records ({_more_data(facts)}): the error falls as the windows grow"))
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
    drop = _dropped(model) if model is not None else None
    if lin is not None and test > (1 + SAME) * lin["free_run"]["test"]["nrmse"]:
        gaps.append(f"its free-run test error ({100 * test:.2f} %) is above the linear model's "
                    f"({100 * lin['free_run']['test']['nrmse']:.2f} %)")
    elif drop is not None:
        gaps.append(f"it is its {drop['reference']} start (free-run test error {100 * test:.2f} %): its correction "
                    "was dropped")
    phys = results.get("physics")
    if phys is not None and test > (1 + SAME) * phys["free_run"]["test"]["nrmse"]:
        gaps.append(f"its free-run test error ({100 * test:.2f} %) is above the physics model's "
                    f"({100 * phys['free_run']['test']['nrmse']:.2f} %)")
    one = (row.get("one_step") or {}).get("test") or {}
    biased = bool(one) and abs(one.get("mean_error", 0.0)) > BIAS_RATIO * one.get("rmse_m", np.inf)
    if biased:
        gaps.append(f"its one-step residual is biased: it sits {_value(one['mean_error'], facts['unit'])} off zero "
                    f"({100 * abs(one['mean_error']) / one['rmse_m']:.0f} % of its RMS)")
    if not gaps:
        return []
    causes = _causes(name, model, facts, biased, drop) or [(
        "no cause found in the data: the recipe's structure or budget does not suit this plant",
        f"search its settings on the validation data with `eap train-compare ... --models {name} --tune 20`")]
    return [{"finding": f"{name}: {'; '.join(gaps)}", "causes": [{"cause": c, "action": a} for c, a in causes]}]


def sentences(finding: dict) -> list[str]:
    """A finding as plain sentences: what falls short, then each likely cause and what to do."""
    return [f"{finding['finding']}."] + [f"Likely cause: {c['cause']}. What to do: {c['action']}."
                                         for c in finding["causes"]]
