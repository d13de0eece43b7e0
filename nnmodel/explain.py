"""The sentences beside the numbers of a network comparison that a reader would stop at.

:func:`notes` reads a train-compare summary (``compare.json``) and returns, for each odd
number on the page, one note ``{"text": ..., "links": {words: address}}``: records where
every model fails by design (measurement-like records carry physics absent from training),
networks worse than the physics row, a hybrid below its parents (and what budget would
change it), where a network falls short of the linear or physics row and why
(:mod:`nnmodel.shortfalls`, the findings the summary holds), and why the training and
validation losses differ by orders of magnitude.  Every number in a note is read from the summary; nothing is assumed
about a dataset, a model list or a row's name beyond the roles in the summary.
"""
from __future__ import annotations

import math
from typing import Any

from physics.pages.columns import number

#: A network's held-out error this much above a reference row counts as "worse" (ratio).
WORSE = 1.1
#: Errors within this relative difference are the same (a hybrid whose correction was dropped
#: scores its physics part to rounding).
SAME = 1e-3


def _nrmse(row: dict, group: str) -> float | None:
    g = (row.get("free_run") or {}).get(group) or {}
    v = g.get("nrmse")
    return None if v is None or not math.isfinite(v) else 100.0 * v


def _is_physics(row: dict) -> bool:
    return row.get("n_parameters") is None and str(row.get("kind", "")).startswith("physics")


def _is_linear(name: str, row: dict) -> bool:
    return str(row.get("kind", "")).startswith("linear") or name in ("linear", "arx")


def _networks(models: dict) -> dict:
    return {k: v for k, v in models.items() if not _is_physics(v) and not _is_linear(k, v)}


def _group(models: dict) -> str:
    return "heldout_rh" if any("heldout_rh" in (r.get("free_run") or {}) for r in models.values()) else "test"


def _pct(x: float) -> str:
    return f"{number(x)} %"


def _span(values, fmt) -> str:
    """``a–b`` of some values (one value when they agree to the shown digits)."""
    lo, hi = fmt(min(values)), fmt(max(values))
    return lo if lo == hi else f"{lo}–{hi}"


def note(text: str, links: dict | None = None) -> dict:
    return {"text": text, "links": dict(links or {})}


def measurement_like(summary: dict, diagnosis: str | None = None) -> list[dict]:
    """Why every model, the physics included, fails on the measurement-like records."""
    models = summary.get("models") or {}
    scores = {k: _nrmse(r, "measurement_like") for k, r in models.items()}
    scores = {k: v for k, v in scores.items() if v is not None}
    if not scores:
        return []
    grp = (summary.get("test_groups") or {}).get("measurement_like") or {}
    effects = ", ".join(grp.get("extra_effects") or []) or "effects"
    n, rhs = grp.get("records", "the"), grp.get("rh_pct") or []
    where = f" at RH {', '.join(number(r) for r in rhs)} %" if rhs else ""
    corr = [((r.get("free_run") or {}).get("measurement_like") or {}).get("correlation") for r in models.values()]
    corr = [c for c in corr if c is not None and math.isfinite(c)]
    phys = [v for k, v in scores.items() if _is_physics(models[k])]
    records = f"{n} measurement-like record" + ("" if n == 1 else "s")
    text = (f"The {records}{where} {'was' if n == 1 else 'were'} simulated with {effects} — physics that is not "
            f"in the training data nor in the physics row's model. Every model scores "
            f"{_span(scores.values(), _pct)} NRMSE there"
            + (f", the physics simulator itself {_pct(phys[0])}" if phys else "") + ". ")
    if corr:
        text += (f"Correlation with the measurement is still {_span(corr, number)}: the shape of the response is "
                 "followed, its size is not. ")
    if max(scores.values()) >= 80:
        text += "An NRMSE of 100 % is the error of predicting the record's mean. "
    text += "These records are there to show what an unmodelled effect looks like, not to rank the networks."
    links = {}
    if diagnosis and diagnosis.startswith("#"):
        text += " The diagnosis below finds such a missing effect."
        links = {"The diagnosis below": diagnosis}
    elif diagnosis:
        text += f" To find the missing effect: {diagnosis}"
    return [note(text, links)]


def reference_rows(summary: dict) -> list[dict]:
    """Networks worse than the physics row."""
    models = summary.get("models") or {}
    g = _group(models)
    label = "held-out RH" if g == "heldout_rh" else "test records"
    nets = {k: _nrmse(v, g) for k, v in _networks(models).items()}
    nets = {k: v for k, v in nets.items() if v is not None}
    out = []
    phys = summary.get("physics") or {}
    if "physics" in models and _nrmse(models["physics"], g) is not None and nets:
        p = _nrmse(models["physics"], g)
        worse = sorted((k for k, v in nets.items() if v > WORSE * p), key=nets.get)
        if worse:
            if phys.get("is_generator"):
                why = ("the physics row is the simulator that generated these records, so its error is the sensor "
                       "noise alone: a floor no model can go below, and a network's distance to it is what the "
                       "network has not learned")
            else:
                why = f"the physics row is the device {phys.get('device')} named with --physics"
            out.append(note(f"{', '.join(worse)} ({', '.join(_pct(nets[k]) for k in worse)} on {label}) "
                            f"{'is' if len(worse) == 1 else 'are'} above the physics row ({_pct(p)}): {why}."))
    return out


def hybrid(summary: dict) -> list[dict]:
    """A hybrid below one of its parents: its own physics part, or the best pure network."""
    models = summary.get("models") or {}
    g = _group(models)
    out = []
    for name, row in models.items():
        grey = (row.get("reference_start") or {}).get("reference") == "physics" \
            or (row.get("own") or {}).get("reference") == "physics"
        if not grey:
            continue
        h = _nrmse(row, g)
        if h is None:
            continue
        if row.get("falls_back_to"):
            own = (row.get("own") or {}).get("validation", {}).get("nrmse")
            out.append(note(f"The {name} row validated worse" + (f" ({_pct(100 * own)} NRMSE)" if own else "")
                            + f" than its parent {row['falls_back_to']} ({_pct(100 * row['validation']['nrmse'])}), "
                            f"so it falls back to {row['falls_back_to']}: its row and bundle are that network's."))
            continue
        part = "physics_base" if "physics_base" in models else ("physics" if "physics" in models else None)
        parents = {}
        if part is not None and _nrmse(models[part], g) is not None:
            parents["its physics part alone"] = _nrmse(models[part], g)
        pure = {k: _nrmse(v, g) for k, v in _networks(models).items() if k != name}
        pure = {k: v for k, v in pure.items() if v is not None}
        if pure:
            best = min(pure, key=pure.get)
            parents[f"the best pure network ({best})"] = pure[best]
        below = {k: v for k, v in parents.items() if h > v * (1 + SAME)}
        if not below:
            if part is not None and abs(h - parents.get("its physics part alone", math.inf)) <= SAME * h:
                out.append(note(f"The hybrid ({_pct(h)}) equals its physics part alone: its correction did not "
                                "validate better than the physics, so it was dropped (the card's "
                                "'reference_start' says so)."))
            continue
        text = (f"The hybrid ({_pct(h)}) is behind " + " and ".join(f"{k} ({_pct(v)})" for k, v in below.items())
                + ". Its output is the physics plus a correction fitted to what the physics misses"
                + (" — and here the physics is the simulator that generated the data, so the best correction is "
                   "none" if part == "physics" and (summary.get("physics") or {}).get("is_generator") else "") + f". {_budget_sentence(name, row)}")
        out.append(note(text))
    return out


def _budget_sentence(name: str, row: dict) -> str:
    """What the training history says a larger epoch budget would do."""
    hist = row.get("history") or []
    start = next((h["val_loss"] for h in hist if h.get("epoch") == -1 and h.get("val_loss") is not None), None)
    vals = [h["val_loss"] for h in hist if h.get("epoch", -1) >= 0 and h.get("val_loss") is not None]
    tr = row.get("training") or {}
    ran, budget = tr.get("epochs"), tr.get("max_epochs")
    if start is not None and vals and min(vals) >= start:
        return (f"None of its {len(vals)} epoch{'' if len(vals) == 1 else 's'} lowered the validation error "
                f"(RMS of the normalised output) below its least-squares start ({number(start)}), so the start "
                "was kept: a larger epoch budget would not change its place; more training records or another "
                "structure would.")
    if ran is not None and budget and ran < budget:
        return (f"Training stopped early after {ran} of {budget} epochs, the validation error no longer falling: "
                "a larger epoch budget would not change its place.")
    if ran is not None and budget and ran >= budget:
        if len(vals) > 1 and vals[-1] <= min(vals[:-1]):
            return (f"Training ended on its budget of {budget} epochs with its best validation error at the last "
                    f"epoch: only a longer run (--set {name}.max_epochs={2 * budget}; early stopping ends it when "
                    "the validation error stops falling) can tell whether more epochs change its place.")
        return (f"Training ended on its budget of {budget} epochs, the validation error no longer falling: a "
                "larger epoch budget is unlikely to change its place.")
    return ""


def losses(summary: dict) -> list[dict]:
    """Why the training loss and the validation loss differ by orders of magnitude."""
    rows = []
    for name, row in (summary.get("models") or {}).items():
        hist = [h for h in row.get("history") or [] if h.get("epoch", -1) >= 0]
        tl = [h["train_loss"] for h in hist if h.get("train_loss") is not None]
        vl = [h["val_loss"] for h in hist if h.get("val_loss") is not None]
        if tl and vl:
            rows.append((name, tl[-1], vl[-1]))
    if not rows:
        return []
    name, t, v = max(rows, key=lambda r: r[2] / max(r[1], 1e-300))
    return [note(f"Training and validation losses are on different scales: train_loss is the mean square error "
                 f"of the normalised output on short training windows, val_loss the root-mean-square free-run "
                 f"error of the normalised output over whole validation records. For {name} the last epoch gives "
                 f"train_loss {number(t)} and val_loss {number(v)}" + (f" ({number(v / t)}×)" if t > 0 else "")
                 + ": compare √train_loss = "
                 f"{number(math.sqrt(t))} with val_loss; the rest of the gap is between short windows started "
                 "from measured outputs and a free run over whole records.")]


def dropped(summary: dict) -> list[dict]:
    """Networks whose correction was dropped because its validation gain was within its
    uncertainty (:func:`nnmodel.models.base.keep_if_better`, or cross-validation): they run
    their start.  "Equals its start" is said only where the row's test score is the start's
    row's (the linear row) to rounding; otherwise both scores are given."""
    out = []
    models = summary.get("models") or {}
    lin = next((r for k, r in models.items() if _is_linear(k, r)), None)
    lin_score = None if lin is None else _nrmse(lin, "test")
    for name, row in _networks(models).items():
        end = (row.get("reference_start") or {}).get("end") or {}
        ref = (row.get("reference_start") or {}).get("reference", end.get("kept"))
        if end.get("kept") in (None, "network") or "reason" not in end or ref == "physics":  # hybrid(): its own note
            continue
        if not end.get("validation_nrmse_network", math.inf) < end.get("validation_nrmse_reference", -math.inf):
            continue        # it lowered nothing: the shortfall findings say so ("no better at all")
        score = _nrmse(row, "test")
        if ref == "linear" and score is not None and lin_score is not None \
                and abs(score - lin_score) <= SAME * max(lin_score, 1e-300):
            head = f"{name} equals its linear start (the linear row, {_pct(score)} test NRMSE)"
        else:
            head = (f"{name} runs its {ref} start" + (f" ({_pct(score)} test NRMSE" + (
                f" against the linear row's {_pct(lin_score)})" if lin_score is not None else ")")
                if score is not None else ""))
        out.append(note(f"{head}: its correction lowered the validation error "
                        f"({_pct(100 * end['validation_nrmse_reference'])} → "
                        f"{_pct(100 * end['validation_nrmse_network'])} NRMSE) but was dropped: {end['reason']}. "
                        "More data, and validation records of their own (`eap dataset --validation FILE ...`), "
                        "decide it."))
    return out


def shortfalls(summary: dict) -> list[dict]:
    """Each network's shortfall findings (``models.NAME.shortfalls``) as one note: what
    falls short, then each likely cause and what to do."""
    from .shortfalls import sentences
    return [note(" ".join(sentences(f))) for r in (summary.get("models") or {}).values()
            for f in r.get("shortfalls") or []]


def notes(summary: dict, *, diagnosis: str | None = None, with_shortfalls: bool = True) -> list[dict]:
    """Every note for a comparison's page (see the module doc).  ``diagnosis``: a page
    anchor (``#…``) or a command that diagnoses the measurement-like records;
    ``with_shortfalls``: False where the page lists the shortfalls in a section of their own."""
    return (measurement_like(summary, diagnosis) + reference_rows(summary) + hybrid(summary) + dropped(summary)
            + (shortfalls(summary) if with_shortfalls else []) + losses(summary))


def group_facts(entries: list[dict], group_of) -> dict[str, Any]:
    """Per test group: records, nominal RH levels and the effects added to the generator
    (read from the dataset's entries; ``group_of(entry)`` names the group)."""
    out: dict[str, dict] = {}
    for e in entries:
        g = out.setdefault(group_of(e), {"records": 0, "rh_pct": [], "extra_effects": [], "paths": []})
        g["records"] += 1
        if isinstance(e.get("rh_pct"), (int, float)) and round(e["rh_pct"]) not in g["rh_pct"]:
            g["rh_pct"].append(round(e["rh_pct"]))
        g["extra_effects"] += [x for x in e.get("extra_effects") or [] if x not in g["extra_effects"]]
        g["paths"].append(e["path"])
    return out


__all__ = ["notes", "note", "group_facts", "measurement_like", "reference_rows", "hybrid", "shortfalls", "losses"]
