"""The diagnosis: where the model fails, which effects are missing, and whether the data can tell.

:func:`diagnose` runs its phases in order, each a function here:

1. :func:`read_records` — classification, amplitude and RH levels, decimation, noise floor
   (:mod:`.records`); frequency-response targets for the fits.  What the records determine is
   freed (:func:`_resolve_free`): with records at two or more RH levels, the parameters the
   model's humidity law declares per RH (as ``identify --per-rh``); a parameter the device
   holds per RH (an absolute map, as ``identify`` writes it) is fitted per RH.
2. :func:`fit_base` — the user's model (device + effects) with its free parameters fitted on
   the FRF targets (:func:`physics.identify.fit_lsq`), then simulated on every record with
   the per-record nuisance terms (offset, linear drift, bounded: :func:`.records.bounded_nuisance`)
   removed (:func:`.candidates.score`); the records' slow wander beside the floor
   (:func:`add_wander`).
3. Where it fails (:mod:`.residuals`): correlations with 99 % bands, residual FRF with its
   noise floor, errors by band, amplitude, RH and after steps, findings.
4. :func:`try_candidates` — each effect the model lacks (catalog and user effects) that
   the data can reveal (:func:`.signatures.revealable`) is switched on, refitted with the
   base's free parameters and scored against the base (:func:`compare_step`: ΔBIC, ΔAIC
   and a p-value with one effective sample size for every comparison, :mod:`physics.analysis.stats`;
   the residual signature, :mod:`.signatures`).  Effects the data cannot reveal are listed
   with the excitation that would.
5. :func:`select` — stepwise selection both ways: the step's decision (:func:`.verdict.decide`:
   evidence, quality flags, weights, the pick or the ambiguity, the pick's confidence label);
   after a pick the remaining candidates are tried again on top of it while one passes, up to
   ``max_effects``; when none passes alone, the others are tried on top of the best once
   (:func:`_look_ahead`: a pair each of whose effects hides the other); when none passes, an
   effect of the user's model that the data do not support is removed (:func:`try_removal`) and
   tried again as a candidate with its own parameters free (taken back, it is the user's own effect
   refitted, not the missing one: :attr:`.verdict.Pick.own`); when no removal is favoured either
   (or the chain is full), the model's own effects are refitted once (:func:`refine_own`), the
   picks the refitted model does not need are withdrawn and the candidates tried again on top of
   it (unless ``--free`` names the free parameters: the user's list, nothing besides).
6. Adequacy of the final model and what remains (:mod:`.adequacy`, :mod:`.verdict`).
7. :func:`assess_support` — in the final model each of its own effects is switched off and
   refitted; an effect whose removal does not cost ΔBIC ≥ 6 is "not supported by these data".

The verdict (:class:`.verdict.Verdict`) is the one object every output renders.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from ..analysis import stats
from ..device import Device, all_param_specs, load_device
from ..effects import EFFECTS, ensure_registered, user_effect_files
from ..errors import InputError, ModelError, arg
from ..solvers.frequency import frequency_response
from ..identify import build_targets, parse_assignments, parse_names
from ..identify.free_parameters import held_per_rh, switchable
from ..identify.options import FitOptions
from ..model import ActuatorModel, resolve_effects
from ..execution.parallel import map_tasks, warm_up
from ..execution.threads import single_threaded
from .candidates import (Comparison, ModelFit, ModelSpec, ROLE_GAIN, ROLE_STIFF, candidate_spec, compare_fits,
                         default_candidates, default_free, derived_starts, effect_rows, effect_values, fit_model, is_nested,
                         no_worse_than_base, param_used, prediction_distance, refine_on_time, removal_spec, score,
                         start_in_range, start_on_time, held_on_time, TIME_REFINE_SIMS)
from . import confidence as conf
from .adequacy import Adequacy, assess
from .forms import MIN_GAIN, SIGNIFICANT_BIC
from .interference import find_line
from .records import NUISANCE_TERMS, PreparedRecord, frf_measurements, prepare_records, stated_drift
from .wander import shared_wander, slow_wander
from .residuals import ResidualAnalysis, analyse
from .signatures import features, revealable, signatures
from .specs import (declared_default, effect_params, excitation, keeps_spec_range, param_bounds, refine_params,
                    role_family, shape_params, spec_of, start_points)
from .verdict import (ADEQUATE_RATIO, AFTER_PICK_SHARE, UNATTRIBUTED, Decision, Pick, Verdict, _signed, ahead,
                      decide, doubts, lead_of, nuisance_summary, pinned, quality, remaining_of, traded_only,
                      undetermined, with_rest)

#: Removing an effect of the model must cost at least this ΔBIC for the data to support it.
SUPPORT_BIC = 6.0
#: Default length of the forward-selection chain.
MAX_EFFECTS = 2
#: Simulations of the records the time refinement of the own-effects refit may spend (it frees
#: many parameters: ~12 iterations at 16).
REFIT_TIME_SIMS = 4 * TIME_REFINE_SIMS


@dataclass(frozen=True)
class SelectionOptions:
    """The stepwise selection of :func:`diagnose` (:func:`select`): at most ``max_effects``
    picks forward; ``backward``: when no candidate passes, an effect of the user's model that
    the data do not support is removed and tried again as a candidate; ``refine_base``: the
    base is refined on the time records (:func:`.candidates.refine_on_time`) from its start when
    that fits them better than its FRF optimum — a draft round's base is the model the round
    before kept, refined on them, and refitted on the FRF alone it would lose that;
    ``refine_rival``: when a step's pick is large-signal (whose fit cannot be refined on the time
    records), the best linear candidate is refined on them before the step decides again, as a
    linear pick would have been — the draft rounds, where a drafted map of the drive competes with
    a large-signal catalog effect (a held-out strip's soft saturation of the drive: 16.2 µm from its
    FRF fit, 12.4 µm refined, against the catalog double layer's 15.4 µm), and a step without a pick
    beside a base refined on the time records refines its best linear candidate on them from the
    base's values, then those that stayed at the base's error (:func:`_leads_to_refine`); ``refit_own``: the
    model's own effects refitted after the picks (:func:`refine_own`; None: unless ``free`` is given)."""

    max_effects: int = MAX_EFFECTS
    backward: bool = True
    refine_base: bool = False
    refine_rival: bool = False
    refit_own: bool | None = None


@dataclass(frozen=True)
class AnalysisOptions:
    """How :func:`diagnose` analyses the records (:func:`read_records`): ``noise_floor`` [m]
    overrides the records' own; ``fs_max`` [Hz] caps the analysis sampling rate (default ≥ 5×
    the highest frequency that matters)."""

    noise_floor: float | None = None
    fs_max: float | None = None


@dataclass
class CandidateResult:
    """One effect tried (or not) as a missing one, at step ``step`` of the selection."""

    effect: str
    status: str                                  # evaluated | not_revealable | failed
    reason: str = ""
    fit: ModelFit | None = None
    comparison: Comparison | None = None
    signature: dict | None = None
    indistinguishable_from: list[str] = field(default_factory=list)
    explanation: str = ""
    passes: dict = field(default_factory=dict)
    quality: list[str] = field(default_factory=list)
    step: int = 1

    @property
    def evaluated(self) -> bool:
        return self.status == "evaluated"

    def evidence(self, base: ModelFit) -> str:
        """Kass–Raftery grade of ΔBIC — unless the error falls by less than 10 %: with
        records far above their noise floor a tiny, irrelevant improvement can be
        statistically detectable, and is then called what it is."""
        d = self.comparison.delta_bic
        gain = 1.0 - self.fit.rmse / base.rmse if base.rmse > 0 else 0.0
        if d <= -2 and gain < 0.10:
            return f"detectable but negligible ({100 * gain:.2g} % lower error)"
        return stats.evidence_label(d)

    def row(self, base: ModelFit, weight: float | None = None) -> dict:
        f, c = self.fit, self.comparison
        out = {"effect": self.effect, "status": self.status, "step": self.step}
        if self.evaluated:
            out.update({"rmse_after": f.rmse, "fit_pct_after": f.fit_pct, "delta_bic": c.delta_bic,
                        "delta_aic": c.delta_aic, "p_value": c.p_value, "test": c.test, "weight": weight,
                        "evidence": self.evidence(base), "explanation": self.explanation,
                        "rmse_ratio": f.rmse / base.rmse if base.rmse > 0 else None,
                        "n_eff": c.n_eff, "tau_samples": c.tau, "extra_parameters": c.dk,
                        "parameters": {k: {"value": v, "std_error": f.std_errors.get(k),
                                           "rel_std_error": f.rel_std_errors.get(k)} for k, v in f.values.items()},
                        "effect_parameters": effect_values(f, self.effect), "quality_flags": self.quality,
                        "signature": self.signature, "indistinguishable_from": self.indistinguishable_from,
                        "identifiability_warnings": f.warnings, "notes": f.spec.notes,
                        "passes": self.passes, "fit_s": f.fit_s, "score_s": f.score_s})
        else:
            out.update({"explanation": self.reason, "excitation_needed": excitation(self.effect)})
        return out


@dataclass
class SupportResult:
    effect: str
    status: str                                  # assessed | not_assessable | failed
    supported: bool | None = None
    delta_bic_if_removed: float | None = None
    p_value: float | None = None
    rmse_without: float | None = None
    explanation: str = ""

    def row(self) -> dict:
        return {"effect": self.effect, "status": self.status, "supported": self.supported,
                "delta_bic_if_removed": self.delta_bic_if_removed, "p_value": self.p_value,
                "rmse_without": self.rmse_without, "explanation": self.explanation}


@dataclass
class Step:
    """One step of the stepwise selection: its base, its candidates and its decision — or,
    a backward step, the effect removed (``removal``: of the user's model, or a pick withdrawn)
    and the model without it (``removed_fit``) — or a refit step, the model with its own
    effects' parameters refitted (``refit``, the values in ``refitted``: :func:`refine_own`)."""

    index: int
    base: ModelFit
    candidates: list[CandidateResult]
    decision: Decision
    removal: "SupportResult | None" = None
    removed_fit: ModelFit | None = None
    refit: ModelFit | None = None
    refitted: dict = field(default_factory=dict)
    withdrawn: bool = False           # the removal is of a pick (after the refit), not of the user's model
    picks_refined: bool = False       # a refit of the picks' refine parameters (:func:`refine_picks`)
    swapped_for: str = ""             # a pick withdrawn for the runner-up of its step (:func:`_swap_first`)

    @property
    def kind(self) -> str:
        """``add`` (a forward step), ``remove``, ``withdraw`` (a pick) or ``refit``."""
        if self.refit is not None:
            return "refit"
        return "add" if self.removal is None else "withdraw" if self.withdrawn else "remove"

    @property
    def ranking(self) -> list[CandidateResult]:
        return sorted([c for c in self.candidates if c.evaluated], key=lambda c: self.decision.evidence[c.effect])

    @property
    def result(self) -> ModelFit:
        """The model after this step."""
        if self.refit is not None:
            return self.refit
        if self.removed_fit is not None:
            return self.removed_fit
        return self.decision.pick.fit if self.decision.pick is not None else self.base


@dataclass
class PreparedRecords:
    """The records of a diagnosis and what the fits are made on (:func:`read_records`)."""

    records: list[PreparedRecord]
    targets: list
    target_records: list[PreparedRecord]
    band: tuple[float, float]
    noise: float
    noise_d: float
    noise_source: str
    df_cache: dict = field(default_factory=dict)
    white: float = math.nan           # the records' white noise floor [m] (before any wander)
    white_d: float = math.nan
    wander: float = 0.0               # the records' own slow wander allowed beside it [m] (:func:`add_wander`)
    wander_total: float = 0.0         # the whole slow wander [m], the records' shared part included
    wander_split: object = None       # what the records share of it (:class:`.wander.WanderSplit`)
    wander_beyond: float = 0.0        # floor from sensor metadata: the wander beyond their stated drift [m]
    wanders: dict = field(default_factory=dict)   # (id(fit), rmse) -> (fit, wander, split): :func:`wander_of`

    @property
    def estimated(self) -> bool:
        """True when the noise floors were estimated from the records (no sensor metadata)."""
        return all(r.noise_source.startswith("estimated") for r in self.records)


@dataclass
class DiagnosisRun:
    """How this diagnosis runs: the shared options and its own settings, the resonance of the
    base (for the reveal rules), where timings go, the progress callback."""

    options: FitOptions
    n_starts: int
    force: bool = False
    max_effects: int = 2
    backward: bool = True
    refit_own: bool = True            # the own effects refitted in the chain (:func:`select`); not with --free
    refine_rival: bool = False        # SelectionOptions.refine_rival
    resonance: float | None = None
    timings: dict = field(default_factory=dict)
    progress: Callable[[str], None] | None = None
    supports: dict = field(default_factory=dict)   # (effect, id(fit)) -> (fit, support, fit without it)

    def log(self, msg: str) -> None:
        if self.progress is not None:
            self.progress(msg)


@dataclass
class DiagnosisResult:
    """Everything :func:`diagnose` found (see the module doc); JSON via :meth:`to_dict`."""

    device: Device
    records: list[PreparedRecord]
    base: ModelFit
    steps: list[Step]
    support: list[SupportResult]
    verdict: Verdict
    analysis_base: ResidualAnalysis
    analysis_after: ResidualAnalysis | None
    features: dict
    noise_floor: float
    resonance_hz: float | None
    settings: dict
    timings: dict
    warnings: list[str] = field(default_factory=list)

    @property
    def candidates(self) -> list[CandidateResult]:
        """The candidates of the first step (evaluated, ranked, then the others)."""
        s = self.steps[0]
        return s.ranking + [c for c in s.candidates if not c.evaluated]

    @property
    def ranking(self) -> list[CandidateResult]:
        return self.steps[0].ranking

    @property
    def adequacy(self) -> Adequacy | None:
        return self.verdict.adequacy

    @property
    def winner(self) -> CandidateResult | None:
        """The first pick still in the final model (None for a null verdict)."""
        return next(iter(self.picks), None)

    @property
    def picks(self) -> list[CandidateResult]:
        """The picks of the chain still in the final model (not withdrawn)."""
        return [s.decision.pick for s in self.steps
                if s.decision.pick is not None and s.decision.pick.effect in self.final.effects]

    @property
    def removals(self) -> list["SupportResult"]:
        return [s.removal for s in self.steps if s.removal is not None]

    @property
    def final(self) -> ModelFit:
        """The final model: the base with every pick of the chain and without every removal."""
        return self.steps[-1].result if self.steps else self.base

    @property
    def draft_base(self) -> ModelFit:
        """Where drafted effects start from: the model after the last backward or refit step (the
        base without the effects the data do not support, with its own effects refitted), else
        the base."""
        back = [s for s in self.steps if s.kind != "add"]
        return back[-1].result if back else self.base

    @property
    def best(self) -> CandidateResult | None:
        """The top-ranked candidate of the first step (whatever the verdict)."""
        r = self.ranking
        return r[0] if r else None

    def to_dict(self) -> dict:
        from ..io.fileio import jsonable
        b = self.base
        return jsonable({
            "device": self.device.name, "device_file": self.device.path,
            "base": {"effects": [e for e in b.effects], "free": b.spec.free, "per_rh": b.spec.per_rh,
                     "rmse": b.rmse, "fit_pct": b.fit_pct, "bic": b.bic, "aic": b.aic,
                     "rmse_by_record": dict(zip([r.source for r in self.records], b.rmse_records)),
                     "parameters": {k: {"value": v, "std_error": b.std_errors.get(k),
                                        "rel_std_error": b.rel_std_errors.get(k)} for k, v in b.values.items()},
                     "identifiability_warnings": b.warnings, "tau_samples": b.taus,
                     "n_samples_analysed": b.n},
            "noise_floor_m": self.noise_floor, "resonance_Hz": self.resonance_hz,
            "verdict": self.verdict.to_dict(),
            "steps": [{"step": s.index, "kind": s.kind, "refitted": s.refitted or None,
                       "picks_refined": s.picks_refined,
                       "base_effects": list(s.base.effects), "base_rmse": s.base.rmse,
                       "ranking": [c.row(s.base, s.decision.weights.get(c.effect)) for c in s.ranking],
                       "weight_of_base": s.decision.weights.get("base"),
                       "picked": s.decision.pick.effect if s.decision.pick else None,
                       "removed": s.removal.row() if s.removal else None,
                       "swapped_for": s.swapped_for or None, "rmse_after": s.result.rmse}
                      for s in self.steps],
            "ranking": [c.row(b, self.steps[0].decision.weights.get(c.effect)) for c in self.ranking],
            "not_evaluated": [c.row(b) for c in self.steps[0].candidates if not c.evaluated],
            "support": [s.row() for s in self.support],
            "adequacy": self.adequacy.to_dict() if self.adequacy else None,
            "where_it_fails": self.analysis_base.to_dict(),
            "after_winner": self.analysis_after.to_dict() if self.analysis_after else None,
            "signature_features": self.features,
            "records": [r.describe() for r in self.records],
            "excitation_needed": {e: excitation(e) for e in EFFECTS if excitation(e)},
            "statistics": {
                "n_eff": "n / tau_int per record, tau_int from the autocorrelation (Sokal's window) of the residual "
                         "closest to noise (the best-fitting model's); one n_eff for every comparison of a step",
                "bic": "N_eff ln(MSE) + k ln(N_eff) (Schwarz 1978), MSE the pooled mean square error over all records "
                       "(the squared RMS error reported), N_eff = sum_r n_r/tau_r; k = free parameters + "
                       f"{NUISANCE_TERMS} nuisance terms per record (offset, linear drift)",
                "p_value": "nested: Wilks likelihood ratio on the effective scale vs chi2(dk) (conservative at the "
                           "'off' boundary); otherwise Vuong's test; compare with alpha/m (Bonferroni)",
                "weight": "Schwarz weight exp(-E/2), E = dBIC + 10 per quality flag, among the step's base and its "
                          "candidates (approximate posterior probability, equal priors)"},
            "settings": self.settings, "timings_s": self.timings, "warnings": self.warnings})


# ============================================================================ the phases


def read_records(measurements, options: FitOptions, *, noise_floor: float | None = None,
                 fs_max: float | None = None) -> PreparedRecords:
    """Phase 1: the records (:func:`.records.prepare_records`) and the FRF targets of the fits."""
    records = prepare_records(measurements, rh=options.rh, sensor_bandwidth=options.sensor_bandwidth,
                              fs_max=fs_max, noise_floor=noise_floor, rh_tolerance=options.rh_tolerance)
    ms, trecs = frf_measurements(records)
    if not ms:
        raise InputError("the diagnosis fits the model on frequency responses: give at least one broadband record "
                         "(swept sine, multisine, noise) or tone record besides steps/pulses")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        targets = build_targets(ms, frf_options=options.frf, rh_tolerance=options.rh_tolerance,
                                sensor_bandwidth=options.sensor_bandwidth, weighting=options.weighting,
                                min_coherence=options.min_coherence)
    band = (min(float(t.freq.min()) for t in targets), max(float(t.freq.max()) for t in targets))
    n_all = [r.ts.n for r in records]
    nf = [r.noise_floor for r in records]
    noise = math.sqrt(sum(n * x * x for n, x in zip(n_all, nf)) / sum(n_all)) if all(map(math.isfinite, nf)) \
        else math.nan
    noise_d = _pooled_noise_d(records)
    return PreparedRecords(records, targets, trecs, band, noise, noise_d, _noise_source(records), white=noise, white_d=noise_d)


def add_wander(data: PreparedRecords, base) -> None:
    """The records' slow wander beside the noise floor — never *in* it.  The floor is the
    measurement's own (the sensor metadata, or the white level of the deflection spectrum where
    the response has fallen away: :mod:`.records`), one number in every output.  A sensor's zero
    also wanders slowly; below the broadband records' excited band, where the input has no power,
    the base's residual shows it (:func:`.wander.slow_wander`, its lowest lines only: a drift rate
    fitted to a residual would take the model's slow error too).  Its part that does not repeat
    from record to record (:func:`.wander.shared_wander`: a drift shared by the records is the
    setup's, deterministic, left to be described and drafted) is kept in ``data.wander``: when the
    floor was estimated (the sensor states no drift) a model within the adequacy ratio of the
    floor *with* that wander (at most its own residual's: :func:`allowed_wander`) is adequate,
    and the verdict says so with both numbers.  With sensor metadata the wander beyond the
    stated drift is kept in ``data.wander_beyond`` for the verdict (:func:`build_verdict`).  A
    floor the user gave is taken as the whole noise."""
    if not math.isfinite(data.white) or any(r.noise_source == "given" for r in data.records):
        return
    w, split = wander_of(data, base)
    if split is None:
        return
    counted = w * math.sqrt(1.0 - split.fraction) if split.testable else w
    data.wander_total, data.wander_split = w, split
    if not data.estimated:
        allowed = math.sqrt(sum(r.ts.n * stated_drift(r.ts) ** 2 for r in data.records) /
                            sum(r.ts.n for r in data.records))
        data.wander_beyond = math.sqrt(max(counted ** 2 - allowed ** 2, 0.0))
        return
    data.wander = counted


def wander_of(data: PreparedRecords, fit) -> tuple[float, object]:
    """(slow wander [m] in the residual of ``fit`` below the excited band, what the records share
    of it) (:func:`.wander.slow_wander` without the fitted drift rates,
    :func:`.wander.shared_wander`); (NaN, None) when no record can show it.  Computed once per fit
    and score (the fit is kept with it, so its id stays its own; a fit refined in place scores
    anew)."""
    key = (id(fit), fit.rmse)
    if key not in data.wanders:
        w = slow_wander(data.records, fit.resid_d, fit.nuisance, trend=False)
        split = shared_wander(data.records, fit.resid_d, fit.nuisance, w) if math.isfinite(w) else None
        data.wanders[key] = (fit, w, split)
    return data.wanders[key][1:]


def wander_for(data: PreparedRecords, fit) -> float:
    """:func:`allowed_wander` beside ``fit``, unless ``fit`` is within the floor only thanks to
    it and what it leaves follows the input (:func:`.adequacy.assess`: an input-driven residual
    form describes it) — then 0: a creep or a back-relaxation below the excited band is the
    model's error, not the records' wander."""
    w = allowed_wander(data, fit)
    if w <= 0 or not math.isfinite(data.noise) or fit.rmse <= ADEQUATE_RATIO * data.noise:
        return w
    return assess("", fit, data.records, data.noise, describe=False, wander=w).wander


def allowed_wander(data: PreparedRecords, fit=None) -> float:
    """The records' slow wander [m] a model may leave beside the noise floor and still be
    adequate: the part that does not repeat from record to record, when the floor was estimated
    and the records could tell (testable, not inconclusive); else 0 (:func:`add_wander`).

    Beside ``fit``, at most what ``fit``'s own residual holds below the excited band
    (:func:`wander_of`, its lowest lines; computed once per fit): the base's holds the sensor's wander *and*
    the base's own slow error — a slow effect it lacks leaves a transient from each record's
    start, which reaches those lines — while the sensor's wander is in every model's residual.
    The least of the two bounds the sensor's part; a model never has a wander its own residual
    does not show counted beside it."""
    split = data.wander_split
    if not data.estimated or split is None or not split.testable or split.inconclusive:
        return 0.0
    if fit is None:
        return data.wander
    own, _ = wander_of(data, fit)
    return min(data.wander, own) if math.isfinite(own) else data.wander


def features_of(ra: ResidualAnalysis, data: PreparedRecords, fit, run: DiagnosisRun) -> dict:
    """The residual features of ``fit`` (:func:`.signatures.features`); a drift the records
    share (:func:`.wander.shared_wander`, significant) is a ``slow_trend`` whether or not it
    outlasts the linear trends the nuisance terms take."""
    feats = features(ra, data.records, run.resonance)
    _, split = wander_of(data, fit) if math.isfinite(data.white) else (math.nan, None)
    if split is not None and split.testable and split.fraction > 0:
        feats["slow_trend"] = {**feats.get("slow_trend", {}), "present": True, "shared_p": split.p_value}
    return feats


def shared_structure(data: PreparedRecords, fit) -> str:
    """A sentence when the records share a significant part of the slow residual of ``fit``
    (a drift of the setup from each record's start: deterministic structure, however small
    against the noise floor) that matters — removing it would lower the RMS error of ``fit``
    by at least :data:`.forms.MIN_GAIN`, what a residual form must to be described — else ""."""
    if not math.isfinite(data.white) or len(data.records) < 2:
        return ""
    w, split = wander_of(data, fit)
    if split is None or not (split.testable and split.fraction > 0) \
            or split.rms < math.sqrt(1.0 - (1.0 - MIN_GAIN) ** 2) * fit.rmse:
        return ""
    return (f"the records share a drift of {1e6 * split.rms:.3g} µm RMS (A ≈ {1e6 * split.amplitude:+.3g} µm, "
            f"τ ≈ {split.tau:.3g} s from each record's start; shared-drift test p = {split.p_value:.2g}): structure, "
            "not noise, however small against the floor")


def _noise_source(records) -> str:
    """One phrase for where the noise floors of the records came from."""
    kinds = []
    for r in records:
        src = r.noise_source
        k = ("estimated from the records' deflection spectra (the white level where the response has fallen away, "
             "or in a record's quietest segments or the difference of its periods where that reads clearly lower; "
             "drift not included)") if src.startswith("estimated") else src
        if k not in kinds:
            kinds.append(k)
    return "; ".join(kinds)


def fit_base(data: PreparedRecords, dev: Device, base_ids, options: FitOptions, free_l, per_rh_l, n_starts: int) -> ModelFit:
    """Phase 2: the user's model with its free parameters fitted and scored."""
    spec = ModelSpec("base", base_ids, list(free_l), list(per_rh_l), parse_assignments(options.start),
                       parse_assignments(options.bounds, ranges=True, what=arg("bounds")))
    for name in free_l:         # an effect's own parameter keeps its range (a drafted refit starts from a pick's)
        if name not in spec.bounds and keeps_spec_range(name) and (b := param_bounds(name, dev)) is not None:
            spec.bounds[name] = b
            v = dev.params.get(name)
            if v is not None and name not in spec.start and not b[0] <= v <= b[1]:
                # a value fitted in a wider range (the model without an unsupported effect, refitted, hands
                # the draft rounds a ve_slope of 0.69 for a search range up to 0.6): started on its edge
                spec.start[name] = float(min(max(v, b[0]), b[1]))
                spec.notes.append(f"{name}: the device's value {v:.4g} lies outside its search range [{b[0]:.4g}, "
                                  f"{b[1]:.4g}]; started at {spec.start[name]:.4g}")
    for name in spec.start:
        if name not in free_l + per_rh_l:
            raise InputError(f"{arg('start')}: {name} is not a free parameter")
    for name in free_l:
        if name not in dev.params and name not in spec.start:
            default = declared_default(name)
            if default is None:
                raise InputError(f"device {dev.name!r} has no value for free parameter {name}; give a start value with "
                                 f"{arg('start')}")
            spec.start[name] = default
    base = fit_model(spec, dev, data.targets, data.target_records, n_starts=n_starts, seed=options.seed,
                       n_modes=options.n_modes, df_cache=data.df_cache, keep=options.keep_starts)
    if not base.ok:
        raise ModelError(f"the base model could not be fitted: {base.error}")
    score(base, data.records)
    if not base.ok:
        raise ModelError(f"the base model could not be simulated: {base.error}")
    return base


def refine_own(data: PreparedRecords, fit: ModelFit, options: FitOptions, n_starts: int,
               resonance_hz: float | None) -> tuple[ModelFit | None, dict]:
    """``fit`` with the parameters of its own effects that the records can reveal
    (:func:`.signatures.revealable`) and that it holds at the device's values fitted beside its
    free ones, from those values (else the effect's derived start): the device's values of an
    effect are a start, not this strip's.  A step of the chain after the candidates (:func:`select`;
    refitted before them, a refitted effect could stand in for a missing one); kept when it
    lowers the BIC with its parameters counted (:func:`.candidates.compare_fits`).
    Returns (the refitted model or None, {name: {"device": value or None, "refined": value}})."""
    taken = set(fit.spec.free) | set(fit.spec.per_rh)
    own = {e: [n for n in effect_params(e) + shape_params(e) if n not in taken] for e in switchable(fit.effects)
           if (spec := spec_of(e)) and not spec.get("describing_function")
           and revealable(e, data.records, resonance_hz)[0]}
    return _freed(data, fit, own, options, n_starts, "final, own effects refitted")


def refine_picks(data: PreparedRecords, fit: ModelFit, picked: Sequence[str], options: FitOptions,
                 n_starts: int) -> tuple[ModelFit | None, dict]:
    """``fit`` (the chain's final model) with the ``refine`` parameters (:func:`.specs.refine_params`)
    of the effects the chain ``picked`` fitted beside its free ones: the last step of :func:`select`,
    after every pick, removal and refit is decided, so that a parameter which shapes a pick's law
    cannot let it stand in for another effect while the chain chooses.  Fitted with the candidates,
    the layer at each face into which ``solvent_diffusion`` releases its solvent took two strips
    whose solvent is released so from 1.78× and 1.68× the true model's error to 1.31× and 1.44×, but
    on a held-out strip the model without its relaxing modulus then fitted better, the chain removed
    it and the pick fell from "high" to "medium".  Kept as a draft is kept: ΔBIC ≤
    −:data:`.forms.SIGNIFICANT_BIC` with the parameters counted and an RMS error lower by
    :data:`.forms.MIN_GAIN` (over thousands of correlated samples a lower BIC alone gave a layer to a
    test strip whose solvent is released at the face, for 0.3 % less error).  The user's own effects
    are not refined (their device values are the user's).  Returns (the refined model or None,
    {name: {"device": value, "refined": value}})."""
    taken = set(fit.spec.free) | set(fit.spec.per_rh)
    own = {e: [n for n in refine_params(e) if n not in taken] for e in picked if e in fit.effects}
    return _freed(data, fit, own, options, n_starts, "final, picks refined", need_bic=SIGNIFICANT_BIC,
                  need_gain=MIN_GAIN)


def _freed(data: PreparedRecords, fit: ModelFit, own: dict, options: FitOptions, n_starts: int,
           label: str, need_bic: float = 0.0, need_gain: float = 0.0) -> tuple[ModelFit | None, dict]:
    """``fit`` refitted with the parameters ``own`` ({effect: names}) freed beside its free ones, from
    where it is (a freed parameter from its device value, else the effect's derived start, inside its
    spec's range) and, one effect at a time, from its spec's start points (the device's value of a
    strip's parameter may sit in another valley than this strip's: a rough electrode's line fitted
    with a constant-phase charge); kept when it lowers the BIC with them counted (by more than
    ``need_bic``) and the RMS error by at least the share ``need_gain``."""
    names = [n for ns in own.values() for n in ns]
    if not names:
        return None, {}
    dev = fit.device                    # the fitted model's device: its own effects still at the device's values
    start = {**fit.spec.start, **{n: float(fit.values[n]) for n in fit.spec.free if n in fit.values}}   # where it is
    bounds, specs = dict(fit.spec.bounds), all_param_specs()
    for e, ns in own.items():
        derived = derived_starts(e, dev)
        for n in ns:
            # an effect's own parameter keeps its spec's range (a user effect's without one: its declared range)
            bounds[n] = param_bounds(n, dev) or (specs[n].lo, specs[n].hi)
            start[n] = start_in_range(n, dev, derived, bounds[n])
    extra = [st for e, ns in own.items() for pt in start_points(e, dev)
             if (st := {n: float(np.clip(v, *bounds[n])) for n, v in pt.items() if n in ns})]
    spec = ModelSpec(label, fit.effects, list(fit.spec.free) + names, list(fit.spec.per_rh), start, bounds, extra)
    out = fit_model(spec, dev, data.targets, data.target_records, n_starts=n_starts, seed=options.seed,
                    n_modes=options.n_modes, df_cache=data.df_cache, keep=options.keep_starts)
    if out.ok:
        score(out, data.records)
        # the FRF optimum need not be the time records': refined on them, from the start (the model as it
        # was) when that fits them better (refine_on_time compares the two)
        refine_on_time(out, data.records, sims=REFIT_TIME_SIMS, start=out.result.problem.theta0)
    if not out.ok or not compare_fits(fit, out, True).delta_bic < -need_bic \
            or out.rmse > (1.0 - need_gain) * fit.rmse:
        return None, {}
    return out, {n: {"device": dev.params.get(n, declared_default(n)), "refined": float(out.values[n])}
                 for n in names}


def try_candidates(step: int, base: ModelFit, cand_ids, data: PreparedRecords, run: DiagnosisRun) -> list[CandidateResult]:
    """Phase 4: each candidate switched on in ``base``, fitted and scored (independent tasks,
    in this process or on workers: :func:`physics.execution.parallel.map_tasks`)."""
    n_levels = len({t.level for t in data.targets})
    results: list[CandidateResult] = []
    tasks, slots = [], []
    settings = run.options.settings
    for eff in cand_ids:
        ok, why = revealable(eff, data.records, run.resonance)
        if not ok and not run.force:
            results.append(CandidateResult(eff, "not_revealable", reason=f"the data cannot reveal {eff}: {why}",
                                           step=step))
            continue
        try:
            spec = candidate_spec(eff, base.effects, base.spec.free, base.spec.per_rh, base.device, data.band,
                                    n_levels)
        except (InputError, KeyError) as exc:
            results.append(CandidateResult(eff, "failed", reason=f"{eff} cannot be added to this device: {exc}",
                                           step=step))
            continue
        if not ok:
            spec.notes.append(f"forced: the data cannot reveal {eff} ({why})")
        slots.append(len(results))
        results.append(CandidateResult(eff, "pending", reason=why if ok else f"forced ({why})", step=step))
        tasks.append({"spec": spec, "device": base.device, "targets": data.targets, "trecs": data.target_records,
                      "records": data.records, "n_starts": run.n_starts, "keep": run.options.keep_starts,
                      "seed": run.options.seed,
                      "n_modes": run.options.n_modes, "effect_files": user_effect_files(),
                      "df_cache": data.df_cache if settings is None or settings.serial else None})
    fitted = map_tasks(_fit_candidate, tasks, settings, desc="candidates", progress=False, cost=_candidate_cost)
    for k, (mf, wall) in zip(slots, fitted):
        c = results[k]
        if not mf.ok:
            results[k] = CandidateResult(c.effect, "failed", reason=f"{c.effect}: fit or simulation failed: {mf.error}",
                                         fit=mf, step=step)
            continue
        c.status, c.fit = "evaluated", no_worse_than_base(mf, base)
        run.timings[f"step {step}: candidate {c.effect}" if step > 1 else f"candidate {c.effect}"] = wall
        run.log(f"  {'+' * step}{c.effect:22s} RMS {1e6 * c.fit.rmse:9.4g} µm  ({wall:.1f} s)")
    return results


def compare_step(base: ModelFit, results: list[CandidateResult], data: PreparedRecords, feats: dict) -> list:
    """Every evaluated candidate against ``base`` with one noise model: the autocorrelation
    of the residual closest to noise (the best-fitting model's), so that n_eff does not change
    from candidate to candidate.  Fills comparisons and signatures; returns τ per record."""
    fits = [base] + [c.fit for c in results if c.evaluated]
    ref = min(fits, key=lambda f: f.rmse)
    taus_ref = list(ref.taus)
    n_eff_ref = sum(n / t for n, t in zip(base.n, taus_ref))
    k_base = base.k + NUISANCE_TERMS * len(data.records)
    base.bic = stats.bic([base.rmse ** 2], [1], [n_eff_ref], k_base)
    base.aic = stats.aic([base.rmse ** 2], [1], [n_eff_ref], k_base)
    sigs = signatures(feats, [c.effect for c in results])
    for c in results:
        if c.evaluated:
            c.comparison = compare_fits(base, c.fit, _nested(c), taus_ref)
            c.fit.bic = base.bic + c.comparison.delta_bic
            c.fit.aic = base.aic + c.comparison.delta_aic
            d = prediction_distance(c.fit, base)
            if c.comparison.delta_bic > -10 and math.isfinite(data.noise_d) and d < data.noise_d:
                c.indistinguishable_from.append("base")
        c.signature = sigs.get(c.effect)
    return taus_ref


def _nested(c: CandidateResult) -> bool:
    """Whether the candidate's model nests the base (an effect fitted through per-RH parameters
    only when they were freed, ≥ 2 RH levels)."""
    return is_nested(c.effect) and (not spec_of(c.effect).get("per_rh") or bool(c.fit.spec.per_rh))


def select(data: PreparedRecords, base: ModelFit, cand_ids, feats: dict, run: DiagnosisRun) -> list[Step]:
    """Phase 5: stepwise selection, both ways.  Forward: the candidates on top of the current
    model, the step's decision (:func:`.verdict.decide`); after a pick the remaining candidates
    are tried again on top of it, up to ``max_effects`` picks; a step where none passes alone looks
    ahead once (:func:`_look_ahead`).  When no candidate passes and the
    model is not within the noise, backward (``run.backward``): each effect of the user's model
    is switched off and the model refitted (:func:`try_removal`); the one whose removal the data
    favour most (the model without it has the lower BIC) is removed, and it becomes a candidate
    again with its own parameters free, then forward again.  When no removal is favoured (or the
    chain is full), once and unless ``--free`` names the free parameters (``run.refit_own``): the
    model's own effects refitted (:func:`refine_own`: the device's values of an effect are a
    start, not the strip's), kept when it lowers the BIC; on top of it, the picks the data no
    longer favour (or without which it is within the noise floor) are withdrawn (removal, as
    above, not tried again), those that stay are labelled again on it (:func:`_withdraw`) and
    the candidates are tried again.  The refit comes after the candidates so that a refitted
    effect never stands in for a missing one the candidates find.  Each effect is removed at most once.  Returns the
    steps (the first always)."""
    steps: list[Step] = []
    step_base, left, step_feats = base, list(cand_ids), feats
    removed: set = set()
    own = [e for e in switchable(base.effects)]
    picked: list[str] = []
    refitted = False
    while True:
        k = len(steps) + 1
        if len(picked) < run.max_effects and left:
            pick = _forward(k, step_base, left, step_feats, data, run, bool(picked), steps)
            if pick is None and len(picked) + 2 <= run.max_effects:
                pair = _look_ahead(steps[-1], left, data, run, steps)
                if pair is not None:
                    picked.append(pair[0].effect)
                    pick = pair[1]
            if pick is not None:
                picked.append(pick.effect)
                left = [e for e in left if e != pick.effect and e not in pick.fit.effects]
                step_base = pick.fit
                if _adequate(data, pick.fit):
                    break
                if len(picked) < run.max_effects and left:
                    if run.refit_own:       # the next candidates compete with the picks at their best shape
                        refined = _refine_shape(steps, step_base, picked, data, run, "before the next candidates")
                        if refined is not None:
                            step_base = refined
                            if _adequate(data, step_base):
                                break
                    step_feats = _features_after(data, step_base, f"+{pick.effect}", run)
                    run.log(f"step {k + 1}: the remaining candidates on top of {pick.effect}")
                    continue
            k = len(steps) + 1
        within = math.isfinite(data.noise) and step_base.rmse <= ADEQUATE_RATIO * math.hypot(
            data.noise, wander_for(data, step_base))
        if within:
            break
        removable = [e for e in own if e in step_base.effects and e not in removed]
        if run.backward and removable and (len(picked) < run.max_effects or refitted):
            t0 = time.perf_counter()
            got, _ = try_removal(step_base, removable, data, run)
            run.timings[f"step {k}: removal"] = time.perf_counter() - t0
            if got is not None:
                step_base = _removal_step(k, step_base, got, steps, removed, run)
                if spec_of(got[0].effect) and got[0].effect not in left:
                    left.append(got[0].effect)
                step_feats = _features_after(data, step_base, f"-{got[0].effect}", run)
                continue
        if not run.refit_own or refitted:
            break
        refitted = True
        fit, values = _timed(run, f"step {k}: own effects", refine_own, data, step_base, run.options, run.n_starts,
                             run.resonance)
        if fit is None:
            break
        reason = (f"its own effects refitted ({', '.join(values)}): RMS error {1e6 * step_base.rmse:.4g} → "
                  f"{1e6 * fit.rmse:.4g} µm")
        steps.append(Step(k, step_base, [], Decision(None, {}, {}, reason=reason), refit=fit, refitted=values))
        run.log(f"step {k}: {reason}")
        step_base = _withdraw(fit, picked, steps, removed, data, run)
        if _adequate(data, step_base):
            break
        step_feats = _features_after(data, step_base, "refitted", run)
    if not steps:       # no candidate (the draft rounds' refit of the own effects alone), nothing refitted
        steps.append(Step(1, base, [], Decision(None, {}, {}, reason="no candidate was tried")))
    _swap_first(steps, removed, data, run)
    if run.refit_own:
        _refine_last(steps, data, run)
    return steps


#: Where the picks are labelled again after the refinement of their shape (:func:`_refine_last`).
REFINED = "the model with the picks' shape refined"


def _refine_last(steps: list[Step], data: PreparedRecords, run: DiagnosisRun) -> None:
    """The picks' ``refine`` parameters fitted on the chain's final model (:func:`_refine_shape`)
    when the chain did not refine them before a next step."""
    picked = [s.decision.pick.effect for s in steps if s.decision.pick is not None]
    _refine_shape(steps, steps[-1].result, picked, data, run, "on the final model")


def _refine_shape(steps: list[Step], current: ModelFit, picked: list, data: PreparedRecords, run: DiagnosisRun,
                  where: str) -> "ModelFit | None":
    """The ``refine`` parameters of the ``picked`` effects, not yet free, fitted on ``current``
    (:func:`refine_picks`): a refit step appended when the data favour them, and the picks labelled
    again on the refined model, as on a model whose own effects were refitted (:func:`_relabel`:
    each switched off there, the error it removes and the error the model leaves).  Returns the
    refined model, or None.  The chain runs it after a pick when it goes on (the next candidates
    then compete with the pick at its best shape, not with what its shape at the device's values
    leaves: on a two-record strip with a solvent released in a face layer, ``fractional_coupling``
    with an exponent of 0.005 took 2.33 → 1.07 µm that the layer takes to 1.08 µm) and at the end."""
    if not any(n not in current.spec.free for e in picked for n in refine_params(e)):
        return None                         # nothing to refine: no fit, no timing row
    k = len(steps) + 1
    fit, values = _timed(run, f"step {k}: picks refined", refine_picks, data, current, picked, run.options,
                         run.n_starts)
    if fit is None:
        return None
    reason = (f"the picks' shape refined {where} ({', '.join(values)}): RMS error "
              f"{1e6 * current.rmse:.4g} → {1e6 * fit.rmse:.4g} µm")
    steps.append(Step(k, current, [], Decision(None, {}, {}, reason=reason), refit=fit, refitted=values,
                      picks_refined=True))
    run.log(f"step {k}: {reason}")
    every = _timed(run, f"step {k}: picks labelled again", lambda: {
        e: _support_of(e, fit, data, run) for e in picked if e in fit.effects})
    _relabel(steps, every, fit, data, run, REFINED)
    return fit


def _swap_first(steps: list[Step], removed: set, data: PreparedRecords, run: DiagnosisRun) -> None:
    """The swap move after the stepwise selection: when the chain holds two picks or more, the
    runner-up of the first pick's step (the candidate next in its ranking, not in the model, that
    passed ΔBIC ≤ −:data:`.forms.SIGNIFICANT_BIC` there) is tried in its place, on top of the
    later picks (the first pick switched off, the model refitted, the runner-up a forward step on
    it).  When the chain holds one pick and ends outside the noise, the runner-up is tried in its
    place, judged as on the step it lost (no pick beneath it, so no bar on a quality flag: on
    pnp_sweep seed 61's rough electrode + solvent strip fractional_coupling, its signature absent,
    passed step 1 and was refused in the swap, viscoelastic left at 29× the true model's error), and the
    other candidates of that step in a forward step on top of it (when the runner-up
    alone fails only for the share of the excess it explains, the look-ahead on it, :func:`_look_ahead`:
    on a rough electrode + solvent strip fractional_coupling alone took 121 → 100 µm, 32 % of the
    excess, behind viscoelastic's 88.7 µm).  It takes the place
    when the model so made has a BIC lower than the chain's (in a chain that may hold one pick only,
    than the lone pick's with what the step's others do on top of it: :func:`_ahead_of_lone`) by
    :data:`.forms.SIGNIFICANT_BIC`: a withdrawal step and its forward steps are appended.  A
    greedy chain cannot undo its first pick, which was chosen before the later effects were in
    the model: on the test strip it was found on (rough electrodes and solvent diffusion), viscoelastic
    (101 µm) beat fractional_coupling (114 µm) on the base, and with solvent_diffusion on top
    the chain stopped at 35.2 µm against the true model's 1.5 µm; on a two-record strip with the
    same pair, viscoelastic was the one pick (66 µm, 66 noise floors) and solvent_diffusion did not
    pass on top of it, while on top of fractional_coupling it does."""
    final = steps[-1].result
    adds = [s for s in steps if s.decision.pick is not None and s.decision.pick.effect in final.effects]
    lone = len(adds) == 1 and not _adequate(data, final)
    if len(adds) < 2 and not lone:
        return
    first = adds[0]
    p1 = first.decision.pick.effect
    rival = next((c for c in first.ranking if c.effect != p1 and c.effect not in final.effects
                  and c.effect not in removed and c.comparison is not None
                  and c.comparison.delta_bic <= -SIGNIFICANT_BIC), None)
    if rival is None:
        return
    sup, without = _support_of(p1, final, data, run)
    if without is None:
        return
    run.log(f"swap: {rival.effect} (the runner-up of step {first.index}) in the place of {p1}")
    k = len(steps) + 1
    trial: list[Step] = []
    pick = _forward(k + 1, without, [rival.effect], _features_after(data, without, f"-{p1}", run), data, run,
                    not lone, trial)
    others = [c.effect for c in first.ranking if c.effect != p1 and c.effect not in final.effects
              and c.effect not in removed]          # the step's other candidates, the runner-up among them
    rest = [e for e in others if e != rival.effect] if lone else []
    if pick is None:        # a lone pick's runner-up that fails only for the share it explains: the look-ahead
        pair = _look_ahead(trial[0], [rival.effect, *rest], data, run, trial) if rest else None
        if pair is None:
            run.log(f"  not taken: {rival.effect} is not picked on the model without {p1}")
            return
        pick, rest = pair[1], []
    rest = [e for e in rest if e not in pick.fit.effects]
    if rest:                # a lone pick's runner-up: what the step's other candidates do on top of it
        second = _forward(k + 2, pick.fit, rest, _features_after(data, pick.fit, f"+{rival.effect}", run), data,
                          run, True, trial)
        c = trial[0].decision.confidence
        if second is not None and c is not None:    # taken for what the two do: not "high" on its step
            c.ahead_of = second.effect
            conf.label(c)
        pick = second or pick
    bar = _ahead_of_lone(p1, final, others, data, run, k + 3) \
        if lone and run.max_effects == 1 and pick.effect != rival.effect else None
    against = final if bar is None else bar.fit
    cmp = compare_fits(against, pick.fit, False, list(min((against, pick.fit), key=lambda f: f.rmse).taus))
    if cmp.delta_bic > -SIGNIFICANT_BIC:
        run.log(f"  not taken: RMS error {1e6 * pick.fit.rmse:.4g} µm against the chain's {1e6 * final.rmse:.4g} µm"
                + ("" if bar is None else f", {1e6 * against.rmse:.4g} µm with {bar.effect} on top of {p1}")
                + f" (ΔBIC {cmp.delta_bic:+.4g})")
        return
    on_top = "" if pick.effect == rival.effect else f" with {pick.effect} on top of it"
    than = "" if bar is None else f" than {p1} with {bar.effect} on top of it"
    why = (f"the runner-up of step {first.index}, {rival.effect}, in its place{on_top} fits better{than}: RMS error "
           f"{1e6 * against.rmse:.4g} → {1e6 * pick.fit.rmse:.4g} µm, ΔBIC {_signed(cmp.delta_bic)}")
    removed.add(p1)
    steps.append(Step(k, final, [], Decision(None, {}, {}, reason=why), replace(sup, explanation=why), without,
                      withdrawn=True, swapped_for=rival.effect))
    run.log(f"step {k}: {p1} swapped out ({why})")
    steps += trial
    later = [s.decision.pick.effect for s in adds[1:]]
    _relabel(steps[:-1], {e: _support_of(e, pick.fit, data, run) for e in later}, pick.fit, data, run,
             "the model after the swap")


def _ahead_of_lone(p1: str, final: ModelFit, others: list, data: PreparedRecords, run: DiagnosisRun,
                   k: int) -> "CandidateResult | None":
    """What the swap measures a lone pick's runner-up with a second effect on top against when the
    chain could hold one pick only (``max_effects`` 1, each draft round's): the pick ``p1`` (the model
    ``final``) with the step's ``others`` in a forward step on top of it (its pick, or None).  Two effects against one:
    on pnp_fd seed 70's low-pass sensor beside a saturating charge the runner-up delay with a
    saturation on top (19.7 µm) took the place of the drafted low-pass alone (34.5 µm), and the
    rounds wrote 13× the noise floor."""
    return _forward(k, final, others, _features_after(data, final, f"+{p1}", run), data, run, True, []) if others else None


def _adequate(data: PreparedRecords, fit: ModelFit) -> bool:
    """Whether ``fit`` is within the noise (:func:`.adequacy.assess`, the records' wander allowed)."""
    return bool(assess("", fit, data.records, data.noise, describe=False, wander=allowed_wander(data, fit)).adequate)


def _removal_step(k: int, current: ModelFit, got, steps: list, removed: set, run: DiagnosisRun) -> ModelFit:
    """Append the backward step removing ``got`` = (support, fit without it); returns that fit."""
    sup, fit = got
    removed.add(sup.effect)
    s = Step(k, current, [], Decision(None, {}, {}, reason=sup.explanation), sup, fit,
             withdrawn=sup.effect not in steps[0].base.effects)
    steps.append(s)
    run.log(f"step {k}: {sup.effect} {'withdrawn' if s.withdrawn else 'removed'} ({sup.explanation})")
    return fit


def _withdraw(current: ModelFit, picked: list, steps: list, removed: set, data: PreparedRecords,
              run: DiagnosisRun) -> ModelFit:
    """After the own effects were refitted: each pick switched off again; the one the refitted
    model needs least is withdrawn while the data favour its removal, or, when none is, one
    without which the model is within the noise floor (:func:`_not_needed`): it stood in for
    the device's values, not for missing physics.  The picks that stay are labelled again on the
    refitted model (:func:`.confidence.reconfirmed`): the error each removes there and the
    error the model leaves (a near twin's pick stays "low").  Returns the model after the
    withdrawals."""
    every: dict = {}          # the last test's supports, all on ``current`` when no withdrawal followed
    while picked:
        got, every = try_removal(current, [e for e in picked if e not in removed], data, run)
        if got is None:
            got = _not_needed(every, data)
        if got is None:
            break
        current = _removal_step(len(steps) + 1, current, got, steps, removed, run)
        picked.remove(got[0].effect)
        every = {}
    _relabel(steps, every, current, data, run, "the model with its own effects refitted")
    return current


def _within_floor(data: PreparedRecords, fit: ModelFit) -> bool:
    """Whether ``fit`` is within the noise floor as a forward step reads it (:func:`.verdict.decide`:
    within ADEQUATE_RATIO of the floor with the records' wander beside it, and no drift the records
    share): a base on which no candidate is picked."""
    return (math.isfinite(data.noise)
            and fit.rmse <= ADEQUATE_RATIO * math.hypot(data.noise, wander_for(data, fit))
            and not shared_structure(data, fit))


def _not_needed(every: dict, data: PreparedRecords) -> "tuple[SupportResult, ModelFit] | None":
    """Of ``every`` ({pick: (support, fit without it)} on the refitted model), the pick without
    which the model is within the noise floor (:func:`_within_floor`; the lowest such error when
    several are), its support's explanation saying so; else None.  A forward step on that model
    would not pick it: the lower error it buys there is within the noise, however many samples
    make its ΔBIC significant (the residual numerics of the solver, a noise realisation)."""
    best = None
    for sup, mf in every.values():
        if sup.status == "assessed" and mf is not None and _within_floor(data, mf) \
                and (best is None or mf.rmse < best[1].rmse):
            best = (sup, mf)
    if best is None:
        return None
    sup, mf = best
    why = (f"not needed: without it the RMS error is {1e6 * mf.rmse:.4g} µm, within the noise floor of "
           f"{1e6 * data.noise:.4g} µm (adequate within {ADEQUATE_RATIO:g}×), where no candidate is picked")
    return replace(sup, explanation=why), mf


def _relabel(steps: list[Step], every: dict, current: ModelFit, data: PreparedRecords, run: DiagnosisRun,
             where: str) -> None:
    """The picks of ``steps`` in ``every`` ({effect: (support, fit without it)} on ``current``)
    labelled again on ``current`` (:func:`.confidence.reconfirmed`): the error each removes
    there, the error the model leaves and its own parameters' quality flags there; a near
    twin's pick stays "low".  ``where`` names ``current`` in the pick's reason, which, like the
    verdict's caution line (:func:`build_verdict`), names the quality flags there: a label lowered
    for "2 quality flag(s)" says which."""
    for s in steps:
        d = s.decision
        if d.pick is None or d.pick.effect not in every or d.confidence is None or d.ambiguous:
            continue
        sup, _ = every[d.pick.effect]
        if sup.status == "assessed" and sup.rmse_without is not None:
            on_it = replace(d.pick, fit=current)    # the pick's own parameters as fitted there
            flags = doubts(on_it)
            d.confidence = c = conf.reconfirmed(d.confidence, current.rmse, sup.rmse_without, data.noise,
                                                len(flags), len(pinned(on_it)), current.effects,
                                                len(undetermined(on_it)), len(with_rest(on_it)),
                                                len(traded_only(on_it)))
            if sup.delta_bic_if_removed is not None:       # the verdict's line of the pick reads on ``current``
                d.relabelled = {"on": where, "rmse_without": sup.rmse_without, "rmse_with": current.rmse,
                                "delta_bic": -sup.delta_bic_if_removed, "quality": quality(on_it)}
            d.reason += (f"; on {where} it lowers the RMS error {1e6 * sup.rmse_without:.4g} → "
                         f"{1e6 * current.rmse:.4g} µm: confidence {c.label}" + (": " + "; ".join(c.why) if c.why else "")
                         + (f" (quality flags there: {'; '.join(flags)})" if flags else ""))
            run.log(f"  {d.pick.effect} on {where}: confidence {c.label}")


def _forward(k: int, step_base: ModelFit, left, step_feats: dict, data: PreparedRecords, run: DiagnosisRun,
             after_pick: bool, steps: list) -> "CandidateResult | None":
    """One forward step of :func:`select`: ``left`` tried on top of ``step_base``, compared and
    decided; the step appended to ``steps``; returns its pick (or None)."""
    t0 = time.perf_counter()
    results = try_candidates(k, step_base, left, data, run)
    taus = compare_step(step_base, results, data, step_feats)
    ranked = [c for c in results if c.evaluated]

    def decided():
        return decide(step_base, ranked, data.noise, taus, data.records, compare_fits,
                      prediction_distance, after_pick=after_pick,
                      structure=bool(shared_structure(data, step_base)), wander=wander_for(data, step_base))
    decision = decided()
    rival = _linear_rival(decision.pick, ranked) if run.refine_rival else None
    if rival is not None and refine_on_time(rival.fit, data.records):
        rival.comparison = compare_fits(step_base, rival.fit, _nested(rival), taus)
        run.log(f"  {rival.effect} (beside the large-signal {decision.pick.effect}) refined on the time records: "
                f"RMS {1e6 * rival.fit.rmse:.4g} µm")
        decision = decided()
    # each refined in place on the time records from the base's values; those whose refinement ran
    leads = [c for c in (_leads_to_refine(decision.pick, ranked, step_base) if run.refine_rival else [])
             if refine_on_time(c.fit, data.records, start=_values_of(step_base, c.fit))]
    for lead in leads:
        lead.comparison = compare_fits(step_base, lead.fit, _nested(lead), taus)
        run.log(f"  {lead.effect} (no pick beside a base refined on the time records) refined on them from the "
                f"base's values: RMS {1e6 * lead.fit.rmse:.4g} µm")
    if leads:
        decision = decided()
    if decision.pick is not None and refine_on_time(decision.pick.fit, data.records):
        # the pick refitted on the time records (its FRF optimum is not theirs): the pick stands,
        # and its evidence, reason and confidence are those of the error the verdict reports
        decision.pick.comparison = compare_fits(step_base, decision.pick.fit, _nested(decision.pick), taus)
        run.log(f"  {decision.pick.effect} refined on the time records: RMS {1e6 * decision.pick.fit.rmse:.4g} µm")
        again = decided()
        if again.pick is not None and again.pick.effect == decision.pick.effect:
            decision = again
    for c in ranked:
        c.explanation = _explain(c, step_base)
    steps.append(Step(k, step_base, results, decision))
    run.timings[f"step {k}"] = time.perf_counter() - t0
    return decision.pick


def _look_ahead(step: Step, left, data: PreparedRecords, run: DiagnosisRun, steps: list) \
        -> "tuple[CandidateResult, CandidateResult] | None":
    """A forward ``step`` without a pick whose lead fails only "explains a third of the excess"
    (:func:`.verdict.lead_of`): the other candidates of ``left`` tried on top of the lead (a forward
    step after a pick).  Taken when one is picked there and the two remove at least
    :data:`.verdict.AFTER_PICK_SHARE` of the excess error ``step``'s base leaves above the noise floor
    — nearly all the failure, which no trim of a misfit does: the step's decision becomes the lead
    (:func:`.verdict.ahead`, never "high") and the step on top of it is appended to ``steps``;
    returns (lead, second pick), else None.  Two effects that pull the response in opposite ways
    each explain little alone: on a held-out strip with rough electrodes and solvent back-relaxation
    the solvent alone took 132 → 114 µm, and fractional_coupling fitted without it ended off; the
    two together reach the noise floor."""
    lead = lead_of(step.decision, step.ranking)
    rest = [] if lead is None else [e for e in left if e != lead.effect and e not in lead.fit.effects]
    if not rest:
        return None
    k = step.index + 1
    run.log(f"step {k}: no candidate passes alone; the others on top of {lead.effect} (look-ahead)")
    trial: list[Step] = []
    second = _forward(k, lead.fit, rest, _features_after(data, lead.fit, f"+{lead.effect}", run), data, run, True,
                      trial)
    if second is None or conf.excess_share(step.base.rmse, second.fit.rmse, data.noise) < AFTER_PICK_SHARE:
        run.timings[f"step {k}: look-ahead on {lead.effect}, not taken"] = run.timings.pop(f"step {k}")
        why = "no pick on top of it" if second is None else f"the two leave RMS {1e6 * second.fit.rmse:.4g} µm"
        run.log(f"  not taken: {why}")
        return None
    step.decision = ahead(step.decision, lead, second, step.base, step.ranking, data.noise)
    run.log(f"  taken: {lead.effect} and {second.effect}, RMS {1e6 * step.base.rmse:.4g} → "
            f"{1e6 * second.fit.rmse:.4g} µm")
    steps += trial
    return lead, second


def _linear_rival(pick, ranked) -> "CandidateResult | None":
    """The linear candidate of ``ranked`` with the lowest ΔBIC when ``pick`` is large-signal, else None
    (:attr:`SelectionOptions.refine_rival`)."""
    if pick is None or pick.fit.model.is_linear:
        return None
    return _best_linear(ranked, pick)


#: A candidate whose RMS error is within this share of its base's did not move from the base
#: (:func:`_leads_to_refine`): 25.94 µm printed for both on a held-out strip.
STAYED = 1e-3


def _linear(ranked, but=None) -> list:
    """The linear candidates of ``ranked`` (other than ``but``) compared with their base."""
    return [c for c in ranked if c is not but and c.fit.model.is_linear and c.comparison is not None]


def _best_linear(ranked, but=None) -> "CandidateResult | None":
    """The linear candidate of ``ranked`` (other than ``but``) with the lowest ΔBIC, or None."""
    return min(_linear(ranked, but), key=lambda c: c.comparison.delta_bic, default=None)


def _leads_to_refine(pick, ranked, base: ModelFit) -> list:
    """Where a step has no pick and its base was refined on the time records, the linear
    candidate with the lowest ΔBIC (:attr:`SelectionOptions.refine_rival`, the draft rounds), then
    the other linear ones that ended at the base's error, in ΔBIC order: refined on them too, from
    the base's values (:func:`_forward`; then the step decides among all), so that they and the base are
    compared on equal terms.  A candidate is fitted on the FRF, the base's own effects were refitted on the
    time records: a held-out strip's drafted saturation of the drive came back with the FRF optimum
    of its solvent diffusion, which the step record (not in the FRF) does not follow — 33.6 µm
    against the base's 35.7 µm, where the base's values with the drive's true law give 3.4 µm.  A
    candidate that ended at the base's error did not move from it there; when every one did, the
    lowest ΔBIC is only the fewest parameters (circuit_lab s38: five drafts at the base's 25.94 µm,
    and the dead zone, of one parameter, was the only one refined; refined in turn until one was
    picked, the clip was, 19.03 µm, before the soft law was tried)."""
    if pick is not None or not getattr(base, "time_refined", False):
        return []
    lead = _best_linear(ranked)
    if lead is None:
        return []
    stayed = [c for c in _linear(ranked, lead) if abs(c.fit.rmse - base.rmse) <= STAYED * base.rmse]
    return [lead] + sorted(stayed, key=lambda c: c.comparison.delta_bic)


def _values_of(base: ModelFit, fit: ModelFit) -> np.ndarray:
    """The problem coordinates of ``fit`` with each parameter the base also fitted at the base's
    value (a start for :func:`.candidates.refine_on_time`)."""
    problem = fit.result.problem
    return np.array([float(base.values.get(lbl, th)) for lbl, th in zip(problem.labels, fit.result.fit.theta)])


def _features_after(data: PreparedRecords, fit: ModelFit, label: str, run: DiagnosisRun) -> dict:
    ra = analyse(label, data.records, fit.resid_d, fit.pred_d, resonance_hz=_resonance(fit, data.band, data.records),
                 per_rh=bool(fit.spec.per_rh))
    return features_of(ra, data, fit, run)


def try_removal(current: ModelFit, effects, data: PreparedRecords, run: DiagnosisRun) \
        -> "tuple[tuple[SupportResult, ModelFit] | None, dict]":
    """The backward step: each of ``effects`` switched off in ``current`` and the model refitted
    (:func:`_support_of`); (its support, the fit without it) for the effect whose removal the
    data favour most — the model without it has the lower BIC — or None; and every effect's
    ``(support, fit without it)``."""
    best, every = None, {}
    for eff in effects:
        sup, mf = every[eff] = _support_of(eff, current, data, run)
        if sup.status != "assessed" or sup.delta_bic_if_removed is None or sup.delta_bic_if_removed >= 0:
            continue
        if best is None or sup.delta_bic_if_removed < best[0].delta_bic_if_removed:
            best = (sup, mf)
    return best, every


def build_verdict(data: PreparedRecords, base: ModelFit, steps: list[Step], max_effects: int) -> Verdict:
    """Phase 6: the chain of picks, the adequacy of the final model and what remains."""
    picks, removed, withdrawn, refitted, refined = [], [], [], {}, {}
    final = steps[-1].result
    for s in steps:
        p = s.decision.pick
        (refined if s.picks_refined else refitted).update(s.refitted)
        if s.removal is not None:
            (withdrawn if s.withdrawn else removed).append(
                {"step": s.index, "effect": s.removal.effect, "rmse_before_m": s.base.rmse,
                 "rmse_after_m": s.removed_fit.rmse, "delta_bic": s.removal.delta_bic_if_removed,
                 "reason": s.removal.explanation, "swapped_for": s.swapped_for})
        if p is None or p.effect not in final.effects:        # a pick withdrawn later is not in the chain
            continue
        again = s.decision.relabelled       # labelled again on a later model: its numbers there
        at = final if again or any(t.refit is not None and t.index > s.index for t in steps) else p.fit   # its values now
        before, after, dbic = ((again["rmse_without"], again["rmse_with"], again["delta_bic"]) if again
                               else (s.base.rmse, p.fit.rmse, p.comparison.delta_bic))
        picks.append(Pick(s.index, p.effect, s.decision.weight, before, after, dbic, p.comparison.p_value,
                          effect_rows(at, p.effect),
                          list(again.get("quality", p.quality)), s.decision.reason,
                          s.decision.confidence and conf.at_chain_end(s.decision.confidence, final.rmse, data.noise),
                          next((e for e in s.decision.ambiguous if e != p.effect), ""), s.decision.separating,
                          again.get("on", "")))
    # an effect the support test removed and a later step took back with its own parameters free was
    # in the user's model all along: refitted, not missing (circuit_lab seed 62's AC-coupled sensor:
    # the device's modulus table removed, a free-shaped one taken back and named as the missing effect)
    gone = {r["effect"] for r in removed}
    for q in picks:
        q.own = q.effect in gone
    named = [q for q in picks if not q.own]
    label = "base" + "".join(f" − {r['effect']}" for r in removed) + (" (own effects refitted)" if refitted else "") \
        + "".join(f" + {p.effect}" for p in picks) + (" (the picks' shape refined)" if refined else "")
    ad = assess(label, final, data.records, data.noise, structure=shared_structure(data, final),
                wander=allowed_wander(data, final))
    first = steps[0].decision
    tol = math.hypot(data.noise, wander_for(data, base))
    structured = bool(shared_structure(data, base) if final is not base else ad.structure)
    within = math.isfinite(data.noise) and base.rmse <= ADEQUATE_RATIO * tol and not structured
    split = data.wander_split
    unattributed = (not within and not structured and data.estimated and split is not None
                    and (not split.testable or split.inconclusive)
                    and base.rmse <= ADEQUATE_RATIO * math.hypot(data.noise, data.wander)
                    and bool(assess("", base, data.records, data.noise, describe=False, wander=data.wander).adequate))
    if unattributed:        # within the noise only by counting a wander the records cannot attribute
        status = UNATTRIBUTED
    elif within:
        status = "nothing to explain"
    elif named or ((removed or refitted) and ad.adequate):
        status = {True: "explained", False: "partly explained", None: "found (adequacy not assessed)"}[ad.adequate]
    else:
        status = "not explained by the catalog"
    kind, forms = remaining_of(ad)
    stopped = ""
    last = next(s for s in reversed(steps) if not s.picks_refined)     # where the chain stopped
    if (picks or removed or refitted) and last.kind == "add" and last.decision.pick is None and last is not steps[0]:
        stopped = f"no further candidate passes on top of [{', '.join(last.base.effects)}] ({last.decision.reason})"
    elif picks and len(picks) == max_effects and ad.adequate is False:
        stopped = f"the chain reached max_effects = {max_effects}"
    reason = first.reason if not named else named[0].reason
    if (refitted or picks) and not named and ad.adequate:
        how = ([f"its own effects refitted ({', '.join(refitted)})"] if refitted else []) + \
            ([f"{', '.join(q.effect for q in picks)} taken back with its own parameters free"] if picks else [])
        reason = (f"with {' and '.join(how)} the model leaves {1e6 * final.rmse:.4g} µm "
                  f"(the base {1e6 * base.rmse:.4g} µm): the device's values of its effects were not this strip's")
    noise, source = data.noise, data.noise_source
    if unattributed:
        reason = (f"the base leaves {1e6 * base.rmse:.4g} µm = {base.rmse / data.noise:.2f}× the noise floor of "
                  f"{1e6 * data.noise:.3g} µm; it would be within {ADEQUATE_RATIO}× with the records' slow wander of "
                  f"{1e6 * data.wander:.3g} µm counted as the sensor's, but {split.why or split.text()}; if "
                  "the sensor does not drift, state its noise floor (eap diagnose --noise-floor-um, noise_floor= in "
                  "Python) and what remains is described and drafted, or record the test again (more records sharpen "
                  "the test)")
    elif status == "not explained by the catalog" and kind == "base mismatch" and data.wander_beyond > 0 \
            and base.rmse <= ADEQUATE_RATIO * math.hypot(data.noise, data.wander_beyond):
        # nothing the catalog or a form explains, and the base is within the noise once the records' own
        # wander beyond the sensor's stated drift is counted: a drift of the setup that does not repeat
        status = UNATTRIBUTED
        w = 1e6 * data.wander_beyond
        how = (f"it does not repeat from record to record (shared-drift test p = {split.p_value:.2g})"
               if split.testable else split.why)
        reason = (f"the base leaves {1e6 * base.rmse:.4g} µm = {base.rmse / data.noise:.2f}× the noise floor the sensor "
                  f"metadata state ({1e6 * data.noise:.3g} µm), but the records wander slowly by {w:.3g} µm RMS beyond "
                  f"their linear trends and the sensor's stated drift, independently of the input (below the excited "
                  f"band) — {how}; with that wander the base is within {ADEQUATE_RATIO}× "
                  f"{1e6 * math.hypot(data.noise, data.wander_beyond):.3g} µm. A drift that differs from record to "
                  "record is not physics and no effect can model it: if the setup should not drift (temperature, the "
                  "clamp settling), find what does and record the test again")
        ad = assess(label, final, data.records, noise, describe=False, wander=data.wander_beyond)
        kind, forms = remaining_of(ad)
    line = find_line(data.records, final.resid_d, final.pred_d) if kind == "base mismatch" else None
    return Verdict(status, picks, first.weights, ad, base.rmse, noise, source, reason, forms, kind, stopped,
                   first.alpha, nuisance_summary(final, data.records), removed, withdrawn, refitted, refined,
                   interference=line.text(final.rmse, noise, ADEQUATE_RATIO) if line is not None else "")


def assess_support(final: ModelFit, picked: Sequence[str], data: PreparedRecords, run: DiagnosisRun) -> list[SupportResult]:
    """Phase 7: switch each effect of the final model off (but the double layer and the picks)
    and refit: does the data support it?"""
    out = []
    for eff in [e for e in switchable(final.effects) if e not in picked]:
        sup, mf = _support_of(eff, final, data, run)
        out.append(sup)
        if mf is not None:
            run.log(f"  -{eff:22s} RMS {1e6 * mf.rmse:9.4g} µm  {'supported' if sup.supported else 'not supported'}")
    return out


def _support_of(eff: str, final: ModelFit, data: PreparedRecords, run: DiagnosisRun) -> "tuple[SupportResult, ModelFit | None]":
    """``eff`` switched off in ``final`` and the model refitted: (its support, the fit without it).
    Computed once per model: the backward step after a refit and the support check (phase 7)
    ask the same of a final model the chain did not change."""
    key = (eff, id(final))
    if key in run.supports and run.supports[key][0] is final:
        return run.supports[key][1:]
    out = _support_fit(eff, final, data, run)
    run.supports[key] = (final, *out)
    return out


def _support_fit(eff: str, final: ModelFit, data: PreparedRecords, run: DiagnosisRun) -> "tuple[SupportResult, ModelFit | None]":
    """:func:`_support_of`, computed."""
    ok, why = revealable(eff, data.records, run.resonance)
    if not ok:
        return SupportResult(eff, "not_assessable",
                             explanation=f"cannot be assessed: the data cannot reveal {eff} ({why})"), None
    try:
        spec = removal_spec(eff, final.effects, final.spec.free, final.spec.per_rh, final.device, data.band)
    except (InputError, KeyError) as exc:
        return SupportResult(eff, "failed", explanation=str(exc)), None
    if not spec.free and not spec.per_rh:
        return SupportResult(eff, "failed", explanation="no free parameter left without it"), None
    mf = fit_model(spec, final.device, data.targets, data.target_records, n_starts=run.n_starts,
                     keep=run.options.keep_starts, seed=run.options.seed, n_modes=run.options.n_modes,
                     df_cache=data.df_cache)
    if mf.ok:
        score(mf, data.records)
    if not mf.ok:
        return SupportResult(eff, "failed", explanation=f"the model without {eff} failed: {mf.error}"), None
    cmp = compare_fits(mf, final, is_nested(eff))
    supported = cmp.delta_bic <= -SUPPORT_BIC
    if supported:
        txt = (f"supported: removing {eff} raises the RMS error from {1e6 * final.rmse:.4g} to "
               f"{1e6 * mf.rmse:.4g} µm (ΔBIC {-cmp.delta_bic:+.4g} against removal)")
    elif cmp.delta_bic <= -2:
        txt = (f"weakly supported: without {eff} the RMS error is {1e6 * mf.rmse:.4g} µm instead of "
               f"{1e6 * final.rmse:.4g} µm (ΔBIC {-cmp.delta_bic:+.4g}); the data barely need it")
    elif mf.rmse < final.rmse:
        txt = (f"not supported by these data: without {eff} the model fits better ({1e6 * mf.rmse:.4g} vs "
               f"{1e6 * final.rmse:.4g} µm RMS, ΔBIC {-cmp.delta_bic:+.4g} for removing it)")
    else:
        txt = (f"not supported by these data: without {eff} the model fits as well ({1e6 * mf.rmse:.4g} vs "
               f"{1e6 * final.rmse:.4g} µm RMS, ΔBIC {-cmp.delta_bic:+.4g} for removing it)")
    return SupportResult(eff, "assessed", supported, -cmp.delta_bic, cmp.p_value, mf.rmse, txt), mf


# ============================================================================ the driver


def _declared_per_rh(base_ids) -> list[str]:
    """Parameters an effect of the model declares fittable once per RH level (its spec's ``per_rh``)."""
    out = []
    for e in base_ids:
        out += [n for n in spec_of(e).get("per_rh", ()) if n not in out]
    return out


def _check_names(dev: Device, base_ids, free, per_rh, candidates) -> tuple[list, list | None, list]:
    """The free and per-RH parameter names and the candidates, checked.  ``identify``'s
    vocabulary: a per-RH name is any parameter the model uses or one an effect of the model
    declares per RH (a Table V humidity map of ``Y`` scales whichever modulus is active).
    Per RH ``None``: "auto" (:func:`_resolve_free`)."""
    free_l = parse_names(free) if free not in (None, "") else default_free(base_ids)
    auto = per_rh in (None, "", (), [], "auto")
    per_rh_l = [] if auto or per_rh == "none" else parse_names(per_rh, arg("per_rh"))
    specs = all_param_specs()
    declared = _declared_per_rh(base_ids)
    for name, what in [(n, "free") for n in free_l] + [(n, "per_rh") for n in per_rh_l]:
        if name not in specs:
            raise InputError(f"{arg(what)}: unknown parameter {name!r}")
        if not param_used(name, base_ids) and not (what == "per_rh" and name in declared):
            raise InputError(f"{arg(what)}: {name} has no effect in a model with effects [{', '.join(base_ids)}]; "
                             f"free parameters of this model by default: {', '.join(default_free(base_ids))}"
                             + (f"; per RH level: {', '.join(declared)}" if declared else ""))
    both = sorted(set(free_l) & set(per_rh_l))
    if both and free not in (None, ""):
        raise InputError(f"{', '.join(both)}: a parameter is either shared ({arg('free')}) or per RH "
                         f"({arg('per_rh')}), not both")
    free_l = [n for n in free_l if n not in per_rh_l]
    if candidates in (None, "", "default"):
        cand_ids = [e for e in default_candidates() if e not in base_ids]
    else:
        cand_ids = parse_names(candidates, arg("candidates"))
        bad = [e for e in cand_ids if not spec_of(e)]
        if bad:
            raise InputError(f"{arg('candidates')}: unknown or fixed effect(s) {', '.join(bad)} (no diagnosis spec); "
                             f"catalog: {', '.join(e for e in EFFECTS if spec_of(e))}")
        already = [e for e in cand_ids if e in base_ids]
        if already:
            raise InputError(f"{arg('candidates')}: {', '.join(already)} already in the model ({arg('effects')})")
    return free_l, None if auto else per_rh_l, cand_ids


def _resolve_free(dev: Device, base_ids, free_l: list, per_rh_l: list | None, records,
                  free_given: bool) -> tuple[Device, list, list, list[str]]:
    """(device, free, per-RH, notes): what the records can determine.

    * A parameter the device holds per RH (an absolute humidity map, as ``eap identify
      --per-rh`` writes) has no shared value to fit: with records at two or more RH levels it
      is fitted per RH level, else its map's value at the records' RH becomes its value.
    * Per RH "auto": with records at two or more RH levels and an effect of the model that
      declares per-RH parameters (a humidity law), those are fitted once per level (Table V
      style) — the device's humidity law is a start, not the strip's — and the parameters whose
      role they take (the coupling gain, the stiffness) leave the shared ones."""
    from .records import rh_levels
    levels = rh_levels(records)
    multi = len(levels) >= 2 and ActuatorModel(dev, base_ids).needs_rh
    dev, free_l, per, notes = held_per_rh(dev, free_l, per_rh_l or [], levels if multi else levels[:1],
                                          records[0].rh_measured)
    if per_rh_l is None and multi and not free_given:
        declared = [n for n in _declared_per_rh(base_ids) if n not in per]
        if declared:
            per += declared
            for role in (ROLE_GAIN, ROLE_STIFF):
                if any(n in role_family(role) for n in per):
                    free_l = [n for n in free_l if n not in role_family(role)]
            free_l = [n for n in free_l if n not in per]          # shared or per RH, never both
            notes.append(f"records at {len(levels)} RH levels ({', '.join(f'{x:g}' for x in levels)} %): "
                         f"{', '.join(declared)} fitted once per RH level (the device's humidity law is a start, "
                         "not this strip's; --per-rh none keeps it)")
    return dev, free_l, per, notes


@single_threaded
def diagnose(measurements: Sequence, device, effects=None, free: Sequence[str] | str | None = None, *,
             options: FitOptions | None = None, candidates: Sequence[str] | str | None = None, force: bool = False,
             check_support: bool = True, selection: SelectionOptions | None = None,
             analysis: AnalysisOptions | None = None, progress: Callable[[str], None] | None = None,
             **shared) -> DiagnosisResult:
    """Diagnose ``device`` with ``effects`` against ``measurements`` (paths or
    :class:`~physics.io.timeseries.TimeSeries`); see the module doc.

    ``free``: the base's free parameters (default: gain, stiffness, ``beta_f``);
    ``options``: measurement and fit options shared with ``identify``
    (:class:`~physics.identify.options.FitOptions`; its fields may also be given as keywords,
    e.g. ``rh_tolerance=1.0``, ``n_starts=4``, ``settings=...``); ``candidates``: effects to try
    (default: every effect with a diagnosis spec that the model lacks, except those tried only
    on request); ``force``: also try effects the data cannot reveal; ``check_support``: test
    each effect of the final model (:func:`assess_support`); ``selection``: the longest chain
    of picks and the backward step (:class:`SelectionOptions`); ``analysis``: the noise floor
    and the analysis sampling rate (:class:`AnalysisOptions`); ``progress``: a callback for
    one-line progress messages."""
    t_all = time.perf_counter()
    opts = FitOptions.merged(options, **({"free": free} if free not in (None, "") else {}), **shared)
    selection = selection if selection is not None else SelectionOptions()
    analysis = analysis if analysis is not None else AnalysisOptions()
    max_effects, noise_floor, fs_max = selection.max_effects, analysis.noise_floor, analysis.fs_max
    run = DiagnosisRun(opts, 4 if opts.n_starts is None else int(opts.n_starts), force, int(max_effects),
                       bool(selection.backward),
                       opts.free in (None, "", ()) if selection.refit_own is None else bool(selection.refit_own),
                       bool(selection.refine_rival),
                       progress=progress)
    if run.n_starts < 1:
        raise InputError(f"{arg('n_starts')} must be at least 1")
    if run.max_effects < 1:
        raise InputError(f"{arg('max_effects')}={max_effects!r} must be at least 1")
    warm_up(opts.settings)   # the workers start beside the base fit and the residual analysis
    dev = load_device(device)
    base_ids = resolve_effects(effects, dev)
    free_l, per_rh_l, cand_ids = _check_names(dev, base_ids, opts.free, opts.per_rh, candidates)
    data = _timed(run, "records", read_records, measurements, opts, noise_floor=noise_floor, fs_max=fs_max)
    dev, free_l, per_rh_l, notes = _resolve_free(dev, base_ids, free_l, per_rh_l, data.records,
                                                 opts.free not in (None, "", ()))
    for n in notes:
        run.log(n)
    run.log(f"{len(data.records)} record(s), {sum(t.freq.size for t in data.targets)} FRF lines over "
            f"{data.band[0]:.3g}–{data.band[1]:.3g} Hz; noise floor {1e6 * data.noise:.3g} µm")
    base = _timed(run, "base", fit_base, data, dev, base_ids, opts, free_l, per_rh_l, run.n_starts)
    run.log(f"base [{', '.join(base_ids)}] fitted: RMS error {1e6 * base.rmse:.4g} µm, fit {base.fit_pct:.2f} %")
    if selection.refine_base and _timed(run, "base_on_time", refine_on_time, base, data.records,
                                        sims=REFIT_TIME_SIMS, start=base.result.problem.theta0):
        run.log(f"  base refined on the time records: RMS error {1e6 * base.rmse:.4g} µm")
    add_wander(data, base)
    run.resonance = _resonance(base, data.band, data.records)
    ra_base = _timed(run, "residual_analysis", analyse, "base", data.records, base.resid_d, base.pred_d,
                     resonance_hz=run.resonance, per_rh=bool(base.spec.per_rh))
    feats = features_of(ra_base, data, base, run)
    steps = select(data, base, cand_ids, feats, run)
    final = steps[-1].result
    picks = [s.decision.pick for s in steps if s.decision.pick is not None and s.decision.pick.effect in final.effects]
    verdict = build_verdict(data, base, steps, run.max_effects)
    support = _timed(run, "support", assess_support, final, [p.effect for p in picks], data, run) \
        if check_support else []
    own_refined = next((s.refitted for s in steps if s.refit is not None and not s.picks_refined), {})
    shown = picks[-1] if picks else (steps[0].ranking[0] if steps[0].ranking else None)
    ra_after = None if shown is None else analyse(
        "+" + " +".join(p.effect for p in picks) if picks else f"+{shown.effect}", data.records, shown.fit.resid_d,
        shown.fit.pred_d, resonance_hz=_resonance(shown.fit, data.band, data.records), per_rh=bool(shown.fit.spec.per_rh))
    run.timings["total"] = time.perf_counter() - t_all
    settings = {"effects": list(base_ids), "free": base.spec.free, "per_rh": base.spec.per_rh,
                "candidates": cand_ids, "force": force, "max_effects": run.max_effects, "backward": run.backward,
                "n_starts": run.n_starts, "notes": notes, "own_refined": own_refined,
                "options": opts.describe(), "noise_floor_given_m": noise_floor, "fs_max_Hz": fs_max,
                "noise": {"white_m": data.white, "wander_allowed_m": allowed_wander(data),
                          "wander_unshared_m": data.wander, "wander_total_m": data.wander_total,
                          "wander_shared": None if data.wander_split is None or not data.estimated
                          else data.wander_split.text(),
                          "wander_beyond_stated_drift_m": data.wander_beyond,
                          "floor_m": data.noise,
                          "source": data.noise_source}}
    return DiagnosisResult(dev, data.records, base, steps, support, verdict, ra_base, ra_after, feats, data.noise,
                           run.resonance, settings, run.timings, list(base.warnings))


def _timed(run: DiagnosisRun, label: str, fn, *args, **kw):
    """``fn(*args, **kw)``, its wall time recorded in ``run.timings[label]``."""
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    run.timings[label] = time.perf_counter() - t0
    return out


def _candidate_cost(task: dict) -> float:
    """Relative cost of a candidate fit, to start the dearest first: a nonlinear model runs
    the implicit time stepper (~5–10× a linear one); each free parameter adds evaluations."""
    spec = task["spec"]
    linear = ActuatorModel(task["device"], list(spec.effects), n_modes=task["n_modes"]).is_linear
    return (1.0 if linear else 8.0) * (len(spec.free) + len(spec.per_rh) + 1)


def _fit_candidate(task: dict):
    """Fit and score one candidate (a task of :func:`physics.execution.parallel.map_tasks`)."""
    ensure_registered(task["effect_files"])
    t0 = time.perf_counter()
    mf = fit_model(task["spec"], task["device"], task["targets"], task["trecs"], n_starts=task["n_starts"],
                     keep=task["keep"], seed=task["seed"], n_modes=task["n_modes"],
                     df_cache=task["df_cache"] if task["df_cache"] is not None else {})
    if mf.ok:
        score(mf, task["records"])
        start_on_time(mf, task["records"]) or held_on_time(mf, task["records"])
    return mf, time.perf_counter() - t0


def _resonance(mf: ModelFit, band, records) -> float | None:
    try:
        f = np.geomspace(max(band[0], 0.05), band[1] * 1.5, 400)
        fr = frequency_response(mf.model, None, f, rh=records[0].rh_measured)
        r = fr.resonance()
        return float(r[0]) if r else None
    except (InputError, ModelError):
        return None


def _pooled_noise_d(records) -> float:
    n = [r.y_d.size for r in records]
    v = [r.noise_floor_d for r in records]
    if not all(map(math.isfinite, v)):
        return math.nan
    return math.sqrt(sum(a * b * b for a, b in zip(n, v)) / sum(n))


def _fmt_params(values: dict, errors: dict) -> str:
    specs = all_param_specs()
    parts = []
    for k, v in values.items():
        unit = specs.get(k.split("@")[0]).unit if specs.get(k.split("@")[0]) else ""
        se = errors.get(k)
        se_txt = f" ± {se:.2g}" if se is not None and math.isfinite(se) else ""
        parts.append(f"{k} = {v:.4g}{se_txt} {unit}".strip())
    return ", ".join(parts)


def _explain(c: CandidateResult, base: ModelFit) -> str:
    f, cmp = c.fit, c.comparison
    vals = effect_values(f, c.effect)
    txt = (f"Adding {c.effect}" + (f" ({_fmt_params(vals, f.std_errors)})" if vals else "") +
           f" changes the RMS error from {1e6 * base.rmse:.4g} to {1e6 * f.rmse:.4g} µm (fit {base.fit_pct:.2f} → "
           f"{f.fit_pct:.2f} %); ΔBIC = {cmp.delta_bic:.4g} with n_eff = {cmp.n_eff:.4g} (τ = {cmp.tau:.3g} samples): "
           f"evidence: {c.evidence(base)}; p = {cmp.p_value:.2g} ({cmp.test}).")
    sig = c.signature or {}
    if sig.get("score") is not None:
        if sig["observed"]:
            txt += f" Signature observed: {', '.join(sig['observed'])}."
        else:
            txt += f" Its signature ({', '.join(sig['expected'])}) is not observed."
    if "base" in c.indistinguishable_from:
        d = prediction_distance(f, base)
        txt += (f" Its fitted model predicts the same deflection as the base with re-tuned "
                f"{', '.join(base.spec.free)} (RMS difference {1e6 * d:.3g} µm, below the noise): the data cannot "
                "tell it apart from the base.")
    others = [x for x in c.indistinguishable_from if x != "base"]
    if others:
        txt += f" Cannot be told apart from {', '.join(others)} with these data."
    if c.quality:
        txt += " Quality flags (evidence against it): " + "; ".join(c.quality) + "."
    for n in f.spec.notes:
        txt += f" Note: {n}."
    return txt


__all__ = ["diagnose", "DiagnosisResult", "CandidateResult", "SupportResult", "Step", "PreparedRecords", "read_records",
           "fit_base", "try_candidates", "compare_step", "select", "build_verdict", "assess_support", "DiagnosisRun", "MAX_EFFECTS"]
