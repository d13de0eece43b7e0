"""The verdict: two answers, each calibrated, in one object that every output renders.

**Which effect is missing.**  The candidates of a step (:mod:`.diagnosis`: the catalog and
user effects the model lacks, each fitted on top of the step's base) are weighed by their
evidence E = ΔBIC + :data:`QUALITY_BIC` × (quality flags), ΔBIC computed on the pooled error the
report prints (one noise model for all records, N_eff from the residual's correlation:
:func:`.candidates.compare_fits`); the Schwarz weight exp(−E/2), normalised over the step's
base (E = 0) and every evaluated candidate, is an approximate posterior probability (equal
priors; Schwarz 1978, Kass & Raftery 1995) penalised by what makes a fit suspect.  A
candidate's **quality flags** (:func:`quality`): one of its parameters ends on a bound of its
range; its relative standard error exceeds 50 %; it is correlated with another parameter
beyond |ρ| = 0.99 (only a combination is determined); its expected residual signature is
absent.  A candidate can be picked when it passes the criteria of :data:`CRITERIA` (very
strong ΔBIC, Bonferroni p-value, at least a third of the failure explained — of the excess
error power over the noise floor — and a base above the noise: a flexible effect that trims a
little off an error it does not explain is no answer; on a later step of the chain, no quality
flag at all — the error left there is mostly the base's own mismatch, which a flexible effect
trims — unless the candidate removes at least :data:`AFTER_PICK_SHARE` of the excess, nearly
all the failure left, which no trim does); the pick is the one with the lowest E.  Two candidates that pass are
**ambiguous** when they are close on fit (their pairwise |ΔBIC| < 6, or the better leaves more
than two thirds of the other's excess error power over the noise floor while their predictions
differ by less than the RMS error the better one leaves — two models that differ by more than
their misfit explain different parts of the records and are not twins), whatever their
quality flags: near twins are not told apart by a flag; the verdict then names the record that
would separate them (:func:`separating_record`) and the chain does not stop there: it carries on
with the twin of stronger evidence, labelled "low", and tries the other on top of it (a hidden
pair's second effect is found, and the model written is the better one).

**How sure.**  Over tens of thousands of correlated samples every ΔBIC is in the thousands and
every weight 1.000, so the weight is not the confidence.  The label (:mod:`.confidence`) asks
what generalises: the error the pick removes and the error it leaves, both in noise floors (an
effect that barely changes the model cannot be "high"; one that leaves a large structured
residual may be a proxy and says so), the share of the closest rival's excess it removes (a near
twin keeps it "low"), the share of records on which it lowers the error, its quality flags and
its weight.  The thresholds are chosen on some truth families and reported on a held-out one
(``bench/diagnose_calibration.py``).

The selection runs both ways (:func:`.diagnosis.select`): after a pick the remaining
candidates are tried again on top of it (up to ``max_effects``); when none passes but the best
fails only "explains a third of the excess" (:func:`lead_of`), the others are tried on top of it,
and the two are taken when they remove nearly all the failure together (:func:`ahead`: two effects
that pull the response in opposite ways each explain little alone); when none passes, an effect
of the user's model that the data do not support is removed and tried again as a candidate
with its own parameters free; taken back, it is the user's own effect refitted, listed apart and
never named as the missing one (:attr:`Pick.own`).

**Is the final model adequate.**  Its RMS error against the noise floor — the measurement's
own, one number everywhere (:mod:`.records`) — adequate within :data:`ADEQUATE_RATIO` ×
(:mod:`.adequacy`), with the records' own slow wander that does not repeat from record to
record allowed beside it when the floor was estimated, and a plain statement of what remains —
structured (the residual forms that describe it, :func:`.forms.describe`) or unstructured (a
small mismatch of the base model itself).  When the base is already within the threshold
there is **nothing to explain** — unless it is within only because a slow wander the records
cannot attribute is counted (:data:`UNATTRIBUTED`).  A null answer carries no confidence, and
"explained" is never claimed without a noise floor.  The nuisance terms of every record
(offset, linear drift) are reported with their plausibility (:func:`nuisance_summary`).

:class:`Verdict` holds both answers; :meth:`Verdict.lines` is the one text the terminal,
the page and ``diagnosis.json`` show.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from ..device import all_param_specs
from ..analysis.metrics import remove_nuisance
from ..analysis import stats
from . import confidence as conf
from .adequacy import ADEQUATE_RATIO, Adequacy
from .confidence import excess_share
from .candidates import on_bound
from .specs import effect_params, excitation

#: Evidence against a candidate per quality flag, in BIC units ("very strong", Kass & Raftery).
QUALITY_BIC = 10.0
#: Relative standard error and |correlation| beyond which a parameter is flagged.
REL_SE_FLAG, CORR_FLAG = 0.5, 0.99
#: Pick criteria: very strong ΔBIC, a Bonferroni p-value, a share of the failure explained (the
#: excess error power over the noise floor, rmse² − noise², that the candidate removes) and a
#: base above the noise.
DELTA_BIC_MIN, ALPHA, MIN_SHARE = 10.0, 0.01, 1.0 / 3.0
#: On a later step of the chain a candidate with quality flags passes only when it removes at
#: least this share of the excess error power the step's base leaves above the noise floor.
AFTER_PICK_SHARE = 0.9
CRITERIA = ("very_strong_bic", "p_below_alpha_over_m", "explains_a_third_of_the_excess", "base_above_noise",
            "no_quality_flag_after_a_pick")
#: Each criterion of :data:`CRITERIA` a candidate fails, as the reason of "none named" says it.
FAILED = {"very_strong_bic": f"its evidence is not very strong (ΔBIC above −{DELTA_BIC_MIN:g})",
          "p_below_alpha_over_m": "its p-value is not below α/m",
          "explains_a_third_of_the_excess": "it removes less than a third of the error above the noise floor",
          "base_above_noise": "the base is already within the noise floor",
          "no_quality_flag_after_a_pick": f"it has quality flags after a pick and removes less than "
                                          f"{100 * AFTER_PICK_SHARE:.0f} % of the error above the noise floor"}
#: Two candidates closer than this in pairwise ΔBIC are close on fit.
DISTINCT_BIC = 6.0
#: Status of a base within the noise floor only because the floor counts a slow wander that the
#: records cannot attribute (one record, or records that hint at sharing it without confirming:
#: the sensor's own drift, or a drift of the setup?).
UNATTRIBUTED = "within the noise only if its slow wander is the sensor's"
STATUSES = ("explained", "partly explained", "found (adequacy not assessed)",
            "not explained by the catalog", "nothing to explain", UNATTRIBUTED)


# ============================================================================ quality


def _own_estimates(c):
    """(index, parameter, label, value, whether on a bound, relative standard error or None)
    of each parameter of a fitted candidate's own effect (and of the roles it takes over)."""
    f = c.fit
    own = set(effect_params(c.effect)) | set(_role_params(c.effect))
    problem = f.result.problem
    for i, prm in enumerate(problem.params):
        if prm.name in own:
            lab = problem.labels[i]
            v = f.values.get(lab, float(f.result.fit.theta[i]))
            yield i, prm, lab, v, on_bound(prm, v), f.rel_std_errors.get(lab)


def _undetermined(rel) -> bool:
    return rel is not None and (not math.isfinite(rel) or rel > REL_SE_FLAG)


def pinned(c) -> list[str]:
    """The own parameters of a fitted candidate that ended on a bound of their range *and*
    are not determined: the data chose a limit of the effect, not a value of it."""
    return [lab for _, _, lab, _, bound, rel in _own_estimates(c) if bound and _undetermined(rel)]


def undetermined(c) -> list[str]:
    """The own parameters of a fitted candidate that ended inside their range and are not
    determined: the records do not say how much of the effect there is.  So too, all of them, when
    each is correlated beyond :data:`CORR_FLAG` with a parameter of the rest of the model
    (:func:`_traded`): the rest can trade for every direction the effect adds, and only a
    combination with it is determined.  On a two-record strip with one Maxwell arm, ``layered_beam``
    picked second took 2.01 → 1.03 µm with its electrode modulus correlated −0.9995 with the first
    pick's modulus scale and −0.998 with the coupling, and was "medium"."""
    est = list(_own_estimates(c))
    every = bool(est) and len(_traded(c, est)) == len(est)
    return [lab for _, _, lab, _, bound, rel in est if not bound and (every or _undetermined(rel))]


def traded_only(c) -> list[str]:
    """Of :func:`undetermined`, the parameters counted only because every own parameter trades with
    the rest of the model (their relative standard error, which already carries that trade, is
    within :data:`REL_SE_FLAG`)."""
    est = list(_own_estimates(c))
    if not est or len(_traded(c, est)) != len(est):
        return []
    return [lab for _, _, lab, _, bound, rel in est if not bound and not _undetermined(rel)]


def _traded(c, est: list) -> set[int]:
    """Indices of the own parameters ``est`` (:func:`_own_estimates` of ``c``) correlated beyond
    :data:`CORR_FLAG` with a parameter that is not the candidate's own."""
    corr, mine = c.fit.correlation, {e[0] for e in est}
    if corr is None:
        return set()
    return {i for i in mine for j in range(corr.shape[0])
            if j not in mine and math.isfinite(corr[i, j]) and abs(corr[i, j]) > CORR_FLAG}


def held(c) -> list[str]:
    """The own parameters of a fitted candidate that ended on a bound of their range (determined
    or not): its error is what its range allowed, not necessarily what the effect can reach."""
    return [lab for _, _, lab, _, bound, _ in _own_estimates(c) if bound]


def _flags(c):
    """(kind, sentence) of each quality flag of a fitted candidate (module doc); kind "own pair": a
    correlation between two of its own parameters, "rest": of one of them with a parameter of the
    rest of the model, else "flag"."""
    f = c.fit
    labels = f.result.problem.labels
    mine = []
    for i, prm, lab, v, bound, rel in _own_estimates(c):
        mine.append(i)
        if bound:
            yield "flag", f"{lab} = {v:.4g} {prm.unit} is on a bound of its range [{prm.lower:.3g}, {prm.upper:.3g}]"
        if _undetermined(rel):
            yield "flag", (f"{lab} is not determined (relative standard error "
                           f"{'∞' if not math.isfinite(rel) else f'{100 * rel:.3g} %'})")
    corr = f.correlation
    if corr is not None:
        for i in mine:
            for j in range(len(labels)):
                if j == i or (j in mine and j < i):
                    continue
                r = corr[i, j]
                if math.isfinite(r) and abs(r) > CORR_FLAG:
                    yield ("own pair" if j in mine else "rest"), (
                        f"{labels[i]} and {labels[j]} are correlated (ρ = {r:+.4f}): only a combination is determined")
    sig = c.signature or {}
    if sig.get("score") == 0:
        yield "flag", f"its residual signature ({', '.join(sig.get('expected', []))}) is absent"


def quality(c, *, own_pairs: bool = True) -> list[str]:
    """The quality flags of a fitted candidate (module doc), as sentences; ``own_pairs=False``
    leaves out a correlation between two of its own parameters (:func:`doubts`)."""
    return [text for kind, text in _flags(c) if own_pairs or kind != "own pair"]


def with_rest(c) -> list[str]:
    """Of :func:`doubts`, the correlations of the candidate's own parameters with a parameter of the
    rest of the model: a local statement that the rest could trade for part of it, which
    :mod:`.confidence` does not count once removing the effect costs the model many noise floors."""
    return [text for kind, text in _flags(c) if kind == "rest"]


def doubts(c) -> list[str]:
    """The quality flags that question whether a candidate's effect is there, which the
    confidence label counts (:mod:`.confidence`): all but a correlation between two of its own
    parameters (a stiffness scale it takes over and its frequency slope), which says which of
    its values the records determine, not whether it is needed — a correlation with a parameter
    of the rest of the model says the rest could stand in for it, and counts unless the pick's
    removal costs :data:`.confidence.CHANGE_HIGH` noise floors or more (:func:`with_rest`)."""
    return quality(c, own_pairs=False)


def _role_params(effect: str) -> list[str]:
    from .specs import spec_of
    return [r[0] for r in spec_of(effect).get("roles", {}).values()]


# ============================================================================ one step


@dataclass
class Decision:
    """What one step of the forward selection concluded."""

    pick: object | None                   # the CandidateResult picked, or None
    weights: dict                         # {"base": w, effect: w, ...}
    evidence: dict                        # {effect: E = ΔBIC + quality penalty}
    ambiguous: list[str] = field(default_factory=list)
    separating: str = ""
    reason: str = ""
    alpha: float = ALPHA
    confidence: conf.Confidence | None = None     # of the pick (:mod:`.confidence`)
    relabelled: dict = field(default_factory=dict)  # the pick labelled again on a later model: where, RMS without/with [m], ΔBIC

    @property
    def weight(self) -> float | None:
        return None if self.pick is None else self.weights.get(self.pick.effect)


def decide(base, ranked: Sequence, noise: float, taus_ref, records,
           compare_fits, prediction_distance, after_pick: bool = False, structure: bool = False,
           wander: float = 0.0) -> Decision:
    """One step: flags, evidence, weights, the pick — for near twins the one of stronger evidence,
    "low", with ``ambiguous`` naming both (module doc).  ``ranked``
    are the step's evaluated CandidateResults with their comparison to ``base`` (``after_pick``:
    a later step of the chain, on top of a pick; ``structure``: the base's residual holds
    significant deterministic structure whatever its size — a drift the records share — so
    a base within the noise floor still has something to explain; ``wander`` [m]: the records'
    own slow wander that does not repeat from record to record, allowed beside the floor)."""
    m = max(len(ranked), 1)
    alpha = ALPHA / m
    within = math.isfinite(noise) and base.rmse <= ADEQUATE_RATIO * math.hypot(noise, wander) and not structure
    for c in ranked:
        c.quality = quality(c)
        cmp = c.comparison
        c.passes = {"very_strong_bic": bool(cmp.delta_bic <= -DELTA_BIC_MIN),
                    "p_below_alpha_over_m": bool(math.isfinite(cmp.p_value) and cmp.p_value <= alpha),
                    "explains_a_third_of_the_excess": bool(excess_share(base.rmse, c.fit.rmse, noise) >= MIN_SHARE),
                    "base_above_noise": not within,
                    "no_quality_flag_after_a_pick": not (after_pick and c.quality and excess_share(
                        base.rmse, c.fit.rmse, noise) < AFTER_PICK_SHARE)}
    ev = {c.effect: c.comparison.delta_bic + QUALITY_BIC * len(c.quality) for c in ranked}
    w = stats.bic_weights([0.0] + list(ev.values()))
    weights = {"base": float(w[0]), **{e: float(x) for e, x in zip(ev, w[1:])}}
    eligible = sorted([c for c in ranked if all(c.passes.values())], key=lambda c: ev[c.effect])
    if not eligible:
        return Decision(None, weights, ev, reason=_no_pick_reason(base, ranked, noise, within, wander), alpha=alpha)
    top = eligible[0]
    if len(eligible) > 1:
        ru = eligible[1]
        pair = compare_fits(ru.fit, top.fit, nested=False, taus=taus_ref)
        dist = prediction_distance(top.fit, ru.fit)
        # close on fit: the data do not separate them (ΔBIC), or the better one removes less than
        # MIN_SHARE of what the other leaves above the noise floor (a difference that matters) while
        # their predictions differ by less than the error the better one leaves (near twins say nearly
        # the same thing; two models that differ by more than their misfit explain different parts of
        # the records, and the chain tries the other on top of the better)
        close_fit = pair.delta_bic > -DISTINCT_BIC or (
            excess_share(ru.fit.rmse, top.fit.rmse, noise) < MIN_SHARE and dist <= top.fit.rmse)
        if close_fit:       # near twins: quality flags do not separate what the fit cannot
            top.indistinguishable_from.append(ru.effect)
            ru.indistinguishable_from.append(top.effect)
            sep = separating_record(top, ru, records, noise)
            reason = (f"{top.effect} and {ru.effect} both explain the failure and these data cannot tell them apart: "
                      f"ΔBIC between them {pair.delta_bic:.3g}, predictions differ by {1e6 * dist:.3g} µm RMS, "
                      f"{top.effect} removes {100 * excess_share(ru.fit.rmse, top.fit.rmse, noise):.3g} % of the "
                      f"error {ru.effect} leaves above the noise floor, "
                      f"{len(top.quality)} and {len(ru.quality)} quality flag(s); the chain carries on with "
                      f"{top.effect}, the stronger evidence, and tries {ru.effect} again on top of it")
            # the chain does not stop at a pair it cannot separate: it carries on with the twin of
            # stronger evidence (a hidden pair's second effect is found on top of it, and the model
            # written is the better one), labelled "low" — the data do not say which twin it is
            c = _confidence(top, base, ranked, weights, noise)
            c.label = "low"
            c.why.insert(0, f"{conf.TWIN_WHY} {ru.effect}, fits as well: these data cannot tell them apart")
            return Decision(top, weights, ev, [top.effect, ru.effect], sep, reason, alpha, c)
    cmp = top.comparison
    reason = (f"ΔBIC {cmp.delta_bic:.4g} ({stats.evidence_label(cmp.delta_bic)}), p = {cmp.p_value:.2g} "
              f"(< {alpha:.2g}), RMS error {1e6 * base.rmse:.4g} → {1e6 * top.fit.rmse:.4g} µm")
    if top.quality:
        reason += "; quality flags: " + "; ".join(top.quality)
    rivals = [c for c in eligible[1:] if len(c.quality) > len(top.quality)
              and c.comparison.delta_bic < cmp.delta_bic]
    if rivals:
        reason += (f"; {', '.join(c.effect for c in rivals)} lowered the error as much or more but "
                   f"{'is' if len(rivals) == 1 else 'are'} less credible (" +
                   "; ".join(f"{c.effect}: " + "; ".join(c.quality) for c in rivals) + ")")
    c = _confidence(top, base, ranked, weights, noise)
    if c.label != "high":
        reason += "; confidence " + c.label + ": " + "; ".join(c.why)
    return Decision(top, weights, ev, reason=reason, alpha=alpha, confidence=c)


def lead_of(d: Decision, ranked) -> "object | None":
    """Of a step without a pick, the candidate of lowest evidence among those that fail only
    "explains a third of the excess" (every other criterion passed), else None: the one the chain
    looks ahead with (:func:`.diagnosis.select`)."""
    if d.pick is not None:
        return None
    near = [c for c in ranked if c.passes and all(v for k, v in c.passes.items()
                                                  if k != "explains_a_third_of_the_excess")]
    return min(near, key=lambda c: d.evidence[c.effect], default=None)


def ahead(d: Decision, lead, second, base, ranked, noise: float) -> Decision:
    """The decision of a step without a pick once its lead (:func:`lead_of`), with ``second`` picked
    on top of it, removes at least :data:`AFTER_PICK_SHARE` of the excess error the step's ``base``
    leaves above the noise floor: the lead is the step's pick, never "high" (it was picked for what
    the two do together; :attr:`.confidence.Confidence.ahead_of`)."""
    c = _confidence(lead, base, ranked, d.weights, noise)
    c.ahead_of = second.effect
    conf.label(c)
    alone, both = (excess_share(base.rmse, f.rmse, noise) for f in (lead.fit, second.fit))
    reason = (f"no candidate passes alone: the best, {lead.effect} (ΔBIC {lead.comparison.delta_bic:.4g}), removes "
              f"{100 * alone:.2g} % of the excess error over the noise floor (RMS {1e6 * base.rmse:.4g} → "
              f"{1e6 * lead.fit.rmse:.4g} µm); with {second.effect} picked on top of it the two remove "
              f"{100 * both:.3g} % (→ {1e6 * second.fit.rmse:.4g} µm): two effects that each hide what the other "
              f"does; confidence {c.label}: " + "; ".join(c.why))
    return replace(d, pick=lead, reason=reason, confidence=c)


def _confidence(top, base, ranked, weights: dict, noise: float) -> conf.Confidence:
    """The labelled confidence of the pick ``top`` among the step's evaluated ``ranked``."""
    return conf.label(conf.features(top, base, ranked, weights[top.effect], noise, len(doubts(top)),
                                    len(pinned(top)), _held(ranked), len(undetermined(top)),
                                    len(with_rest(top)), len(traded_only(top))))


def _held(ranked) -> set[str]:
    """The effects of the evaluated candidates held on a bound (:func:`held`)."""
    return {c.effect for c in ranked if held(c)}


def _no_pick_reason(base, ranked, noise, within, wander: float = 0.0) -> str:
    if within and wander > 0 and base.rmse > ADEQUATE_RATIO * noise:
        return (f"the base model fits to within {ADEQUATE_RATIO}× the noise floor once the records' own slow wander "
                f"is counted ({1e6 * base.rmse:.3g} µm vs a floor of {1e6 * noise:.3g} µm and a wander of "
                f"{1e6 * wander:.3g} µm that does not repeat from record to record: a sensor's drift, not physics)")
    if within:
        return (f"the base model already fits to within {ADEQUATE_RATIO}× the noise floor "
                f"({1e6 * base.rmse:.3g} µm vs {1e6 * noise:.3g} µm)")
    if not ranked:
        return "no candidate could be evaluated on these data (see the candidates not evaluated)"
    top = min(ranked, key=lambda c: c.comparison.delta_bic)
    failed = [FAILED[k] for k, v in top.passes.items() if not v]
    return (f"no candidate passes every criterion; the best, {top.effect}, fails: {'; '.join(failed)} "
            f"(ΔBIC {top.comparison.delta_bic:.3g}, p = {top.comparison.p_value:.2g}, RMS {1e6 * base.rmse:.3g} → "
            f"{1e6 * top.fit.rmse:.3g} µm)")


# ============================================================================ separating record


def separating_record(a, b, records, noise: float) -> str:
    """The record (among a few standard designs) on which the fitted models of candidates
    ``a`` and ``b`` differ most, relative to the noise floor: a long pulse, a slow sweep, a
    sweep beyond the measured band, another RH, another amplitude."""
    from .. import signals
    from ..solvers.timedomain import simulate
    amp = float(np.median([r.amplitude for r in records]))
    rh = float(np.median([r.rh for r in records]))
    f_hi = max(r.band[1] for r in records)
    designs = [("a square pulse held 60 s", signals.square(amp, t_on=60.0, t_off=60.0, cycles=1, fs=50.0), rh),
               ("a swept sine 0.01–1 Hz (200 s)", signals.sweep(amp, 0.01, 1.0, 200.0, 20.0), rh),
               (f"a swept sine up to {2 * f_hi:.3g} Hz", signals.sweep(amp, 0.5 * f_hi, 2 * f_hi, 20.0, 10 * f_hi), rh)]
    if a.fit.model.needs_rh or b.fit.model.needs_rh:
        other = rh - 20.0 if rh > 50 else rh + 20.0
        designs.append((f"the same sweep at RH {other:g} %", signals.sweep(amp, 0.1, f_hi, 60.0, 5 * f_hi), other))
    if not (a.fit.model.is_linear and b.fit.model.is_linear):
        designs.append(("the sweep at 4× the amplitude", signals.sweep(4 * amp, 0.1, f_hi, 60.0, 5 * f_hi), rh))
    best = None
    for text, sig, rh_d in designs:
        try:
            ya = simulate(a.fit.model, None, sig.t, sig.v, rh=rh_d).deflection
            yb = simulate(b.fit.model, None, sig.t, sig.v, rh=rh_d).deflection
        except Exception:       # a design a model cannot run says nothing
            continue
        d = float(np.sqrt(np.mean(remove_nuisance(ya - yb, sig.t) ** 2)))
        if best is None or d > best[1]:
            best = (text, d)
    if best is None:
        return f"to separate them: {a.effect} needs {excitation(a.effect) or '?'}; {b.effect} needs " \
               f"{excitation(b.effect) or '?'}"
    ratio = f" ({best[1] / noise:.3g}× the noise floor)" if math.isfinite(noise) and noise > 0 else ""
    return (f"{best[0]} would separate them: their fitted models' predictions differ there by "
            f"{1e6 * best[1]:.3g} µm RMS{ratio}")


# ============================================================================ the verdict


@dataclass
class Pick:
    """One effect of the chain: picked at step ``step`` on top of the effects before it.  Its
    RMS errors [m] and ΔBIC are the step's — or, when it was labelled again on a later model
    (``on`` names it: after a refit of the model's own effects or a swap), that model's without
    it → with it, so that every line of the chain reads on the model the verdict describes."""

    step: int
    effect: str
    weight: float
    rmse_before: float
    rmse_after: float
    delta_bic: float
    p_value: float
    parameters: dict
    quality: list
    reason: str
    confidence: conf.Confidence | None = None
    twin: str = ""                   # a near twin the data could not tell from it (the chain carried on)
    separating: str = ""             # the record that would separate them
    on: str = ""                     # labelled again on a later model (its numbers are then without → with it there)
    left_out: str = ""               # why the model written leaves it out (the draft rounds put drafts in its place)
    stood_in: str = ""               # the kept drafts it stood in for: left out for forms its physics does not make
    own: bool = False                # an effect of the user's model, removed as given and taken back refitted

    @property
    def label(self) -> str:
        return self.confidence.label if self.confidence is not None else "low"

    @property
    def in_place_of(self) -> str | None:
        """The kept draft this pick names the physics of, fitted in its place
        (:func:`.draft._name_counterparts`); None for a pick of the chain."""
        return self.confidence.in_place_of if self.confidence is not None else None

    def to_dict(self) -> dict:
        return {"step": self.step, "effect": self.effect, "confidence": self.weight, "confidence_label": self.label,
                "confidence_features": self.confidence.to_dict() if self.confidence else None,
                "rmse_before_m": self.rmse_before, "rmse_after_m": self.rmse_after, "delta_bic": self.delta_bic,
                "p_value": self.p_value, "parameters": self.parameters, "quality_flags": self.quality,
                "reason": self.reason, "near_twin": self.twin or None, "separating_record": self.separating or None,
                "relabelled_on": self.on or None, "left_out_of_written": self.left_out or None,
                "stood_in_for": self.stood_in or None, "own_effect_taken_back": self.own}


@dataclass
class Verdict:
    """Both answers (module doc); :meth:`lines` is the one text of every output."""

    status: str
    picks: list[Pick]
    weights: dict
    adequacy: Adequacy | None
    base_rmse: float
    noise_floor: float
    noise_source: str
    reason: str = ""
    remaining: list[dict] = field(default_factory=list)      # described forms of what remains
    remaining_kind: str = ""                                 # none | described | base mismatch | unknown
    stopped: str = ""                                        # why the chain stopped
    alpha_bonferroni: float = ALPHA
    nuisance: dict = field(default_factory=dict)
    removed: list = field(default_factory=list)             # effects of the model the data do not support
    withdrawn: list = field(default_factory=list)           # picks the data no longer favour once refitted
    refitted: dict = field(default_factory=dict)            # own effects' parameters refitted: {name: values}
    refined: dict = field(default_factory=dict)             # the picks' refine parameters fitted at the end: likewise
    #: what the draft rounds found where no residual form of the final model described the rest ("" none)
    drafted_remaining: str = ""
    #: what the draft rounds did with the drafts of the described forms, once they ran
    #: ({"kept": {form id: effect id}, "fitted": [form ids], "rmse_m": the RMS error [m] of the
    #: model they reached, None when they kept none}; None: they did not run)
    drafts: dict | None = None
    #: an interference line in every record's residual (:mod:`.interference`), said where no form
    #: describes the rest ("" none)
    interference: str = ""

    # --- the first answer, as before the chain existed ---------------------------------
    @property
    def named(self) -> list[Pick]:
        """The picks the verdict names as missing: all but those left out as stand-ins for kept
        drafts (:attr:`Pick.stood_in`, set by :func:`.draft._left_out_of_written`) and the model's
        own effects taken back refitted (:attr:`Pick.own`: the user's model had them)."""
        return [p for p in self.picks if not p.stood_in and not p.own]

    @property
    def taken_back(self) -> list[Pick]:
        """The model's own effects taken back refitted (:attr:`Pick.own`), stand-ins aside."""
        return [p for p in self.picks if p.own and not p.stood_in]

    @property
    def ambiguous(self) -> list[str]:
        """The first pick and its near twin when the data could not tell them apart, else []."""
        p = next(iter(self.named), None)
        return [p.effect, p.twin] if p is not None and p.twin else []

    @property
    def separating(self) -> str:
        """The record that would separate the first pick from its near twin ("" without one)."""
        return self.named[0].separating if self.named else ""

    @property
    def missing_effect(self) -> str | None:
        return self.named[0].effect if self.named else None

    @property
    def confidence(self) -> float | None:
        """Weight of the first pick; None for a null answer (no confidence is claimed)."""
        return self.named[0].weight if self.named else None

    @property
    def label(self) -> str | None:
        return self.named[0].label if self.named else None

    @property
    def chain(self) -> list[str]:
        return [p.effect for p in self.named]

    @property
    def on_chain(self) -> list[Pick]:
        """The picks of the chain's final model (not those named for a draft in its place)."""
        return [p for p in self.picks if not p.in_place_of]

    @property
    def final_rmse(self) -> float:
        return self.adequacy.rmse if self.adequacy is not None else (
            self.on_chain[-1].rmse_after if self.on_chain else self.base_rmse)

    def lines(self) -> list[str]:
        """The verdict as sentences: status, which effect, adequacy, what remains, nuisance."""
        out = [f"Verdict: {self.status}."]
        for r in self.removed:
            out.append(f"Removed from the model: {r['effect']} — RMS error {1e6 * r['rmse_before_m']:.4g} → "
                       f"{1e6 * r['rmse_after_m']:.4g} µm ({r['reason']}); tried again as a candidate with its own "
                       "parameters free.")
        if self.refitted:
            out.append("Its own effects refitted (the device's values are a start, not this strip's): "
                       + ", ".join(_fmt_refit(n, v) for n, v in self.refitted.items()) + ".")
        for r in self.withdrawn:
            out.append(f"Swapped out: {r['effect']}, the first pick — {r['reason']}: picked before the later effects "
                       "were in the model, it stood in for its runner-up." if r.get("swapped_for") else
                       f"Withdrawn: {r['effect']}, picked before the model's own effects were refitted — on the "
                       f"refitted model it is {r['reason']}: it stood in for the device's values, not for missing "
                       "physics.")
        if self.picks:
            first = next(iter(self.named), None)
            stood = [p for p in self.picks if p.stood_in]
            own = [p.effect for p in self.taken_back]
            if own and first is None and not stood:
                one = len(own) == 1
                out.append(f"Which effect: none the model lacks — {' and '.join(own)} {'is' if one else 'are'} in "
                           f"your model already: the data did not support {'it' if one else 'them'} with the "
                           f"device's values, and taken back with {'its' if one else 'their'} own parameters free "
                           f"{'it lowers' if one else 'they lower'} the error (below): the device's values were not this strip's.")
            if stood and (first is None or first.in_place_of):
                one, picks = " and " not in stood[0].stood_in, len(stood) > 1
                out.append(("Which effect: none from the catalog — " if first is None else "Which effect: ")
                           + f"the model written fits the records better with {stood[0].stood_in} "
                           f"({'a form' if one else 'forms'} outside the catalog) and without the chain's "
                           f"{'picks' if picks else 'pick'} below, which may have stood in for {'it' if one else 'them'}"
                           + ("." if first is None else "; a catalog effect whose physics makes a kept draft is named "
                                                        "for it below."))
            for p in self.picks:
                head = (f"Named for the draft {p.in_place_of}: " if p.in_place_of else
                        f"Left out, a stand-in for {p.stood_in}: " if p.stood_in else
                        "Your model's own effect, taken back refitted: " if p.own else
                        "Which effect: " if p is first else "Then, on top of it: ")
                params = ", ".join(_fmt_param(n, v) for n, v in p.parameters.items())
                if p.twin:
                    out.append(f"{head}ambiguous between {p.effect} and {p.twin} — these data cannot tell them apart"
                               + (f"; {p.separating}" if p.separating else "") + ".")
                    head = "  The chain carries on with the one of stronger evidence: "
                on = f"on {p.on}, without it → with it: " if p.on else ""
                out.append(f"{head}{p.effect} (confidence {p.label}, weight {_w(p.weight)}) — {on}RMS error "
                           f"{1e6 * p.rmse_before:.4g} → {1e6 * p.rmse_after:.4g} µm, ΔBIC {_signed(p.delta_bic)}"
                           + (f"; {params}" if params else "") + ".")
                swapped = next((r["effect"] for r in self.withdrawn if r.get("swapped_for") == p.effect), None)
                if p.confidence is not None and p.confidence.ahead_of and swapped:
                    out.append(f"  Alone it explained less than {swapped}, whose place it took: {p.effect} was picked "
                               f"for what it does with {p.confidence.ahead_of}, fitted on top of it (a swap).")
                elif p.confidence is not None and p.confidence.ahead_of:
                    out.append(f"  Alone it explains less than a third of the failure: {p.effect} was picked for "
                               f"what it does with {p.confidence.ahead_of}, tried on top of it (a look-ahead).")
                if p.confidence is not None and p.confidence.chain_left > conf.LEFT_LOW:
                    out.append(f"  A possible proxy: the chain ends leaving {p.confidence.chain_left:.3g}× the noise "
                               f"floor, so {p.effect} explains a part of the failure, and that part may be physics "
                               "the catalog lacks that its form happens to follow (hence \"low\").")
                why = conf.told_apart(p.confidence) if p.confidence is not None and p.label != "high" else []
                if why:
                    out.append("  Not \"high\": " + "; ".join(why) + ".")
                if p.quality:
                    out.append(f"  Caution on {p.effect}: " + "; ".join(p.quality) + ".")
                if p.left_out:
                    out.append(f"  Left out of the model written: {p.left_out}.")
            if self.stopped:
                out.append(f"The chain stops: {self.stopped}.")
            if self.refined:
                out.append("The picks' shape refined once picked (held at the device's values while the candidates "
                           "competed, so that it could not let a pick stand in for another effect): "
                           + ", ".join(_fmt_refit(n, v) for n, v in self.refined.items()) + ".")
        elif self.status == "nothing to explain":
            out.append(f"Which effect: none is needed — {self.reason}.")
        elif self.refitted and self.adequacy is not None and self.adequacy.adequate:
            out.append(f"Which effect: none is missing — {self.reason}.")
        else:
            out.append(f"Which effect: none named — {self.reason}.")
        out.append("Is the model adequate: " + self._adequacy_text())
        if self.remaining_kind and self.status not in ("nothing to explain", UNATTRIBUTED):
            out.append("What remains: " + self._remaining_text())
        if self.nuisance:
            out.append(f"Nuisance terms (estimated per record, not physics): {self.nuisance['text']}.")
            for f in self.nuisance.get("flags", []):
                out.append(f"  Flagged: {f}.")
        return out

    def _adequacy_text(self) -> str:
        ad = self.adequacy
        model = "the base" + "".join(f" − {r['effect']}" for r in self.removed) + \
            (" with its own effects refitted" if self.refitted else "") + \
            "".join(f" + {p.effect}" for p in self.on_chain) + \
            (" (the picks' shape refined)" if self.refined else "")
        if ad is None or ad.adequate is None:
            return f"not assessed — the noise floor is unknown ({self.noise_source})."
        verdict = "yes" if ad.adequate else "no"
        but = f"; but {ad.structure}" if ad.structure else ""
        wander = (f"; with the records' own slow wander of {1e6 * ad.wander:.3g} µm counted beside it (it does not "
                  f"repeat from record to record: a drift, not physics), {'within' if ad.adequate else 'above'} "
                  f"{ADEQUATE_RATIO}× {1e6 * math.hypot(ad.noise_floor, ad.wander):.3g} µm") if ad.wander > 0 else ""
        return (f"{verdict} — {model} leaves {1e6 * ad.rmse:.4g} µm RMS = {ad.ratio:.2f}× the noise floor of "
                f"{1e6 * self.noise_floor:.3g} µm ({self.noise_source}; adequate within {ADEQUATE_RATIO}×){wander}"
                f"{but}.")

    def _remaining_text(self) -> str:
        if self.remaining_kind == "described":
            return "; and ".join(d["text"] for d in self.remaining) + " — " + self._how_to_model() + "."
        if self.remaining_kind == "base mismatch" and self.interference:
            return self.interference + "."
        if self.remaining_kind == "base mismatch" and self.drafted_remaining:
            return ("no residual form fitted to the final model's residual describes it, but the drafts fitted "
                    f"with the model do: {self.drafted_remaining} (the best model below).")
        if self.remaining_kind == "base mismatch":
            return ("no residual form describes it: an unstructured mismatch of the model's own base forms "
                    "(its physics differs a little from the device's), not a missing effect of the catalog.")
        if self.remaining_kind == "none":
            return "nothing beyond the noise."
        return "unknown (no noise floor to compare with)."

    def _how_to_model(self) -> str:
        """What to do with the described forms: ``--draft-effects`` writes the draftable ones as
        effects; the others (an amplitude or RH dependence) are described, not drafted.
        Once the draft rounds ran (:attr:`drafts`), it says what they did with each draft instead
        of offering them: a page read "--draft-effects drafts effect files for the saturation of
        the input" beside "nothing written (no draft lowers the error)"."""
        from .forms import form_of
        write = "write an effect for {} like examples/effects/creep.py and pass it back with --effects-path"
        drafted = [d for d in self.remaining if d.get("draftable")]
        named = [form_of(d["kind"]).title for d in self.remaining if not d.get("draftable")]
        parts = []
        if self.drafts is not None:
            kept = [d for d in drafted if d["kind"] in self.drafts["kept"]]
            fitted = [d for d in drafted if d not in kept and d["kind"] in self.drafts["fitted"]]
            if kept:
                parts.append(f"the draft rounds kept {', '.join(self.drafts['kept'][d['kind']] for d in kept)} for the "
                             f"{' and the '.join(form_of(d['kind']).title for d in kept)}, written with the report "
                             "(pass it back with --effects-path)")
            # a kept draft of a form this text does not describe (not significant on the final model's
            # residual beside the others, or drafted behind a large-signal pick) is named too: a page
            # listed the sensor's low-pass alone beside a model written with a saturation of the drive
            unlisted = [k for k in self.drafts["kept"] if k not in {d["kind"] for d in kept}]
            if unlisted:
                parts.append(f"{'they' if kept else 'the draft rounds'} also kept "
                             f"{', '.join(self.drafts['kept'][k] for k in unlisted)} for the "
                             f"{' and the '.join(form_of(k).title for k in unlisted)}, which the final model's "
                             "residual did not show on its own")
            rmse = self.drafts.get("rmse_m")
            if self.drafts["kept"] and rmse is not None and rmse <= ADEQUATE_RATIO * self.noise_floor:
                return "; ".join(parts + [f"with the kept drafts the model is within the noise ({1e6 * rmse:.4g} µm, "
                                          "the best model below): nothing else to write"])
            if fitted:
                one = len(fitted) == 1
                parts.append(f"the draft rounds fitted the draft{'' if one else 's'} of the "
                             f"{' and the '.join(form_of(d['kind']).title for d in fitted)} with the model and did not "
                             f"keep {'it' if one else 'them'} (the draft lines say why): "
                             + write.format("it" if one else "them"))
            named += [form_of(d["kind"]).title for d in drafted if d not in kept and d not in fitted]
        elif drafted and not named:
            return ("to model it, `eap diagnose … --draft-effects DIR` drafts effect files for it (or write one like "
                    "examples/effects/creep.py); pass one back with --effects-path")
        elif drafted:
            parts.append(f"`eap diagnose … --draft-effects DIR` drafts effect files for the "
                         f"{' and the '.join(form_of(d['kind']).title for d in drafted)} (pass one back with "
                         "--effects-path)")
        if named:
            one = len(named) == 1
            parts.append(f"the {' and the '.join(named)} {'is' if one else 'are'} described, not drafted: "
                         + write.format("it" if one else "them"))
        return "; ".join(parts)

    def to_dict(self) -> dict:
        return {"status": self.status, "chain": [p.to_dict() for p in self.named],
                "stood_in": [p.to_dict() for p in self.picks if p.stood_in],
                "own_taken_back": [p.to_dict() for p in self.taken_back],
                "missing_effect": self.missing_effect, "confidence": self.confidence,
                "confidence_label": self.label, "weights": self.weights, "reason": self.reason,
                "ambiguous": self.ambiguous, "separating_record": self.separating,
                "adequacy": self.adequacy.to_dict() if self.adequacy else None,
                "remaining_kind": self.remaining_kind, "remaining": self.remaining,
                "drafted_remaining": self.drafted_remaining or None, "interference": self.interference or None,
                "drafts": self.drafts, "chain_stopped": self.stopped,
                "nuisance": self.nuisance, "alpha_bonferroni": self.alpha_bonferroni, "text": self.lines(),
                "removed": self.removed, "withdrawn": self.withdrawn, "refitted": self.refitted, "refined": self.refined,
                "final_rmse_m": self.final_rmse,
                "criteria": {"delta_bic_max": -DELTA_BIC_MIN, "alpha": ALPHA, "min_excess_share": MIN_SHARE,
                             "after_pick_flagged_share": AFTER_PICK_SHARE,
                             "adequate_ratio": ADEQUATE_RATIO, "distinct_delta_bic": DISTINCT_BIC,
                             "quality_penalty_bic": QUALITY_BIC, "rel_se_flag": REL_SE_FLAG, "corr_flag": CORR_FLAG,
                             "confidence": conf.thresholds()}}


def _signed(x: float) -> str:
    return f"{x:.4g}".replace("-", "−")


def _w(w: float) -> str:
    return f"{w:.3f}" if w >= 1e-3 else f"{w:.2g}"


#: Units as a reader writes them.
_READABLE = (("^2", "²"), ("^3", "³"), ("ohm", "Ω"), ("degC", "°C"), ("um", "µm"))


def readable_unit(unit: str) -> str:
    """``m^2/s`` → ``m²/s``, ``ohm`` → ``Ω`` (a dimensionless ``1`` → empty)."""
    if unit == "1":
        return ""
    for a, b in _READABLE:
        unit = unit.replace(a, b)
    return unit


def _unit_of(name: str) -> str:
    spec = all_param_specs().get(name.split("@")[0])
    return readable_unit(spec.unit) if spec else ""


def _fmt_refit(name: str, v: dict) -> str:
    """``Rs 120 → 360 Ω``: a refitted parameter from the device's value (when it has one)."""
    unit = _unit_of(name)
    dev = "(no device value)" if v.get("device") is None else f"{v['device']:.4g}"
    return f"{name} {dev} → {v['refined']:.4g}{(' ' + unit) if unit else ''}"


def _fmt_param(name: str, v: dict) -> str:
    unit = _unit_of(name)
    se = v.get("std_error")
    se_txt = f" ± {se:.2g}" if se is not None and math.isfinite(se) else ""
    return f"{name} = {v['value']:.4g}{se_txt}{(' ' + unit) if unit else ''}"


def remaining_of(ad: Adequacy | None) -> tuple[str, list[dict]]:
    """(kind, described forms) of what the final model leaves (module doc)."""
    if ad is None or ad.adequate is None:
        return "unknown", []
    if ad.adequate:
        return "none", []
    found = ad.remaining()
    return ("described", found) if found else ("base mismatch", [])


def nuisance_summary(fit, records) -> dict:
    """Offsets [µm] and drifts [µm/min] of the final model's residual, per record, with their
    plausibility: a least-squares term beyond what a sensor's zero does (:func:`.records.bounded_nuisance`)
    is flagged and not used — the bound is, and the rest stays in the error as the model's."""
    rows, flags, names = [], [], record_names(records)
    for r, nz, name in zip(records, fit.nuisance, names):
        row = {"record": r.source, "offset_um": 1e6 * nz.offset, "drift_um_per_min": 60e6 * nz.drift,
               "least_squares_offset_um": 1e6 * nz.offset_ls, "least_squares_drift_um_per_min": 60e6 * nz.drift_ls,
               "offset_bounded": nz.offset_clipped, "drift_bounded": nz.drift_clipped}
        rows.append(row)
        if nz.drift_clipped:
            flags.append(f"{name}: a least-squares drift of {60e6 * nz.drift_ls:+.3g} µm/min would rise "
                         f"{1e6 * abs(nz.drift_ls) * r.ts.duration:.3g} µm over the record, more than a sensor's zero "
                         f"drifts ({1e6 * r.drift_bound:.3g} µm: {_drift_basis(r)}); bounded to "
                         f"{60e6 * nz.drift:+.3g} µm/min, the rest is the model's error")
        if nz.offset_clipped:
            flags.append(f"{name}: the offset that fits best, {1e6 * nz.offset_free:+.4g} µm, stands "
                         f"{1e6 * abs(nz.offset_free - nz.level):.3g} µm from the level the record starts at "
                         f"({1e6 * nz.level:+.4g} µm, the device at rest), more than a sensor's zero allows "
                         f"({1e6 * r.offset_bound:.3g} µm); not used: the offset is held at {1e6 * nz.offset:+.4g} µm")
    if not rows:
        return {}
    text = "; ".join(f"{name}: offset {x['offset_um']:+.4g} µm, drift {x['drift_um_per_min']:+.3g} µm/min"
                     for x, name in zip(rows, names))
    return {"records": rows, "text": text, "flags": flags}


def record_names(records) -> list[str]:
    """How the verdict's text names each record: its file name, or every record's whole source
    where two share a file name (``diagnosis.json`` keeps the sources)."""
    names = [Path(r.source).name or r.source for r in records]
    return names if len(set(names)) == len(names) else [r.source for r in records]


def _drift_basis(r) -> str:
    from .records import DRIFT_NOISE, DRIFT_SHARE, STATED_DRIFT_FACTOR
    s = r.ts.meta.get("sensor") if isinstance(r.ts.meta.get("sensor"), dict) else {}
    if isinstance(s.get("deflection_drift"), (int, float)):
        return f"{STATED_DRIFT_FACTOR:g}× the drift the sensor states"
    return (f"{100 * DRIFT_SHARE:g} % of the records' largest peak-to-peak deflection, at least {DRIFT_NOISE:g}× "
            "the record's white noise")


__all__ = ["Verdict", "Pick", "Decision", "decide", "quality", "doubts", "separating_record", "remaining_of",
           "nuisance_summary", "STATUSES", "UNATTRIBUTED", "CRITERIA", "QUALITY_BIC"]
