"""The diagnosis: where the model fails, which effect is missing, and whether the data can tell.

:func:`diagnose` runs, in order:

1. **Records** (:mod:`.records`): classification, amplitude and RH levels, decimation,
   noise floor; H1 / stepped-sine frequency-response targets.
2. **Base fit**: the user's model (device + effects) with its free parameters fitted on
   the FRF targets (:func:`physics.identify.fit_lsq`), then simulated on every record
   (:func:`.candidates.score`).
3. **Where it fails** (:mod:`.residuals`): correlations with 99 % bands, residual FRF
   with its noise floor, errors by band, amplitude, RH and after steps, findings.
4. **Candidates** (:mod:`.candidates`): each catalog effect the model lacks and the data
   can reveal (:func:`.signatures.revealable`) is switched on, refitted with the base's
   free parameters and scored against the base: ΔBIC, ΔAIC and a p-value with one
   effective sample size for every comparison, n/τ_int of the residual closest to noise
   (the best-fitting model's; :mod:`.stats`); its residual signature (:mod:`.signatures`)
   is checked.  Effects the data cannot reveal are listed with the
   reason and the excitation that would reveal them.
5. **Support** of the model's own effects: in the final model (the base, plus the missing
   effect when one is found) each is switched off and refitted; an effect whose removal
   does not cost at least ΔBIC = 6 is "not supported by these data".
6. **Verdict**: the best candidate is the missing effect when (a) ΔBIC ≤ −10 (very strong,
   Kass & Raftery), (b) its p-value is below 0.01/m for m candidates evaluated
   (Bonferroni), (c) it lowers the RMS error by at least 10 % and the base's error
   exceeds 1.2× the noise floor (when the noise floor is known) — an improvement inside
   the noise is not a finding — and (d) it is distinguishable from the runner-up
   (pairwise ΔBIC ≤ −6 and predictions differing by more than the noise); if two
   candidates cannot be told apart the verdict is null and both are named.  Confidence:
   the Schwarz weight exp(−ΔBIC/2) of the winner among the base and the candidates that
   pass (c) (approximate posterior probability, equal priors); for a null verdict the
   base's weight.  A winner whose residual signature is absent keeps the verdict but its
   confidence label is lowered one step.
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..compare import FRFOptions
from ..device import Device, all_param_specs, load_device
from ..errors import InputError, ModelError
from ..frequency import frequency_response
from ..identify import build_targets, parse_assignments, parse_names
from ..effects import EFFECTS, ensure_registered, user_effect_files
from ..model import ActuatorModel, resolve_effects
from ..parallel import ParallelSettings, map_tasks, warm_up
from ..threads import single_threaded
from . import candidates as C
from . import stats
from .records import Record, frf_measurements, prepare_records
from . import forms
from .adequacy import ADEQUATE_RATIO, Adequacy, assess
from .residuals import ResidualAnalysis, analyse
from .signatures import features, revealable, signatures
from .specs import declared_default, excitation, spec_of

DELTA_BIC_MIN = 10.0
ALPHA = 0.01
MIN_IMPROVEMENT = 0.10
NOISE_MARGIN = 1.2
DISTINCT_BIC = 6.0
SUPPORT_BIC = 6.0


@dataclass
class CandidateResult:
    """One catalog effect tried (or not) as the missing one."""

    effect: str
    status: str                                  # evaluated | not_revealable | failed
    reason: str = ""
    fit: C.ModelFit | None = None
    comparison: C.Comparison | None = None
    signature: dict | None = None
    indistinguishable_from: list[str] = field(default_factory=list)
    explanation: str = ""
    passes: dict = field(default_factory=dict)

    @property
    def evaluated(self) -> bool:
        return self.status == "evaluated"

    def evidence(self, base: C.ModelFit) -> str:
        """Kass–Raftery grade of ΔBIC — unless the error falls by less than 10 %: with
        records far above their noise floor a tiny, irrelevant improvement can be
        statistically detectable, and is then called what it is."""
        d = self.comparison.delta_bic
        gain = 1.0 - self.fit.rmse / base.rmse if base.rmse > 0 else 0.0
        if d <= -2 and gain < MIN_IMPROVEMENT:
            return f"detectable but negligible ({100 * gain:.2g} % lower error)"
        return stats.evidence_label(d)

    def row(self, base: C.ModelFit) -> dict:
        f, c = self.fit, self.comparison
        out = {"effect": self.effect, "status": self.status}
        if self.evaluated:
            out.update({"rmse_after": f.rmse, "fit_pct_after": f.fit_pct, "delta_bic": c.delta_bic,
                        "delta_aic": c.delta_aic, "p_value": c.p_value, "test": c.test,
                        "evidence": self.evidence(base), "explanation": self.explanation,
                        "rmse_ratio": f.rmse / base.rmse if base.rmse > 0 else None,
                        "n_eff": c.n_eff, "tau_samples": c.tau, "extra_parameters": c.dk,
                        "parameters": {k: {"value": v, "std_error": f.std_errors.get(k),
                                           "rel_std_error": f.rel_std_errors.get(k)} for k, v in f.values.items()},
                        "effect_parameters": C.effect_values(f, self.effect),
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


#: Verdict statuses (:func:`_apply_adequacy`).
STATUSES = ("explained", "partly explained", "ambiguous", "not explained by the catalog", "nothing to explain")


@dataclass
class Verdict:
    missing_effect: str | None
    confidence: float
    label: str
    reason: str
    ambiguous: list[str] = field(default_factory=list)
    alpha_bonferroni: float = ALPHA
    status: str = ""
    remaining: str = ""

    def to_dict(self) -> dict:
        return {"status": self.status, "missing_effect": self.missing_effect, "confidence": self.confidence,
                "confidence_label": self.label, "reason": self.reason, "remaining": self.remaining,
                "ambiguous": self.ambiguous, "alpha_bonferroni": self.alpha_bonferroni,
                "criteria": {"delta_bic_max": -DELTA_BIC_MIN, "alpha": ALPHA,
                             "min_rmse_reduction": MIN_IMPROVEMENT, "noise_margin": NOISE_MARGIN,
                             "distinct_delta_bic": DISTINCT_BIC}}


@dataclass
class DiagnosisResult:
    """Everything :func:`diagnose` found (see the module doc); JSON via :meth:`to_dict`."""

    device: Device
    records: list[Record]
    base: C.ModelFit
    candidates: list[CandidateResult]
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
    adequacy: Adequacy | None = None

    @property
    def ranking(self) -> list[CandidateResult]:
        return [c for c in self.candidates if c.evaluated]

    @property
    def winner(self) -> CandidateResult | None:
        if self.verdict.missing_effect is None:
            return None
        return next(c for c in self.candidates if c.effect == self.verdict.missing_effect)

    @property
    def best(self) -> CandidateResult | None:
        """The top-ranked candidate (whatever the verdict)."""
        r = self.ranking
        return r[0] if r else None

    def to_dict(self) -> dict:
        from ..report import jsonable
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
            "noise_floor_m": self.noise_floor, "tau_reference_samples": self.settings.get("tau_reference"), "resonance_Hz": self.resonance_hz,
            "ranking": [c.row(b) for c in self.ranking],
            "not_evaluated": [c.row(b) for c in self.candidates if not c.evaluated],
            "support": [s.row() for s in self.support],
            "verdict": self.verdict.to_dict(),
            "adequacy": self.adequacy.to_dict() if self.adequacy else None,
            "where_it_fails": self.analysis_base.to_dict(),
            "after_winner": self.analysis_after.to_dict() if self.analysis_after else None,
            "signature_features": self.features,
            "records": [r.describe() for r in self.records],
            "excitation_needed": {e: excitation(e) for e in EFFECTS if excitation(e)},
            "statistics": {
                "n_eff": "n / tau_int per record, tau_int from the autocorrelation (Sokal's window) of the residual "
                         "closest to noise (the best-fitting model's); one n_eff for every comparison",
                "bic": "sum_r n_eff,r ln(RSS_r/n_r) + k ln(sum n_eff) (Schwarz 1978); k = free parameters + one "
                       "offset per record",
                "p_value": "nested: Wilks likelihood ratio on the effective scale vs chi2(dk) (conservative at the "
                           "'off' boundary); otherwise Vuong's test; compare with alpha/m (Bonferroni)",
                "confidence": "Schwarz weight exp(-dBIC/2) of the verdict among the base and the candidates that "
                              "lower the error by at least 10 % (approximate posterior probability, equal priors)"},
            "settings": self.settings, "timings_s": self.timings, "warnings": self.warnings})


# ============================================================================ driver


def _log(cb, msg):
    if cb is not None:
        cb(msg)


@single_threaded
def diagnose(measurements: Sequence, device, effects=None, free: Sequence[str] | str | None = None, *,
             per_rh: Sequence[str] | str = (), candidates: Sequence[str] | str | None = None, force: bool = False,
             check_support: bool = True, rh: float | None = None, start=None, bounds=None,
             frf_options: FRFOptions | None = None, sensor_bandwidth="auto", rh_tolerance: float = 2.5,
             noise_floor: float | None = None, fs_max: float | None = None, n_starts: int = 4, seed: int = 0,
             n_modes: int = 4, progress: Callable[[str], None] | None = None,
             settings: ParallelSettings | None = None) -> DiagnosisResult:
    """Diagnose ``device`` with ``effects`` against ``measurements`` (paths or
    :class:`~physics.timeseries.TimeSeries`); see the module doc.

    ``free``: the base's free parameters (default: gain, stiffness, ``beta_f``);
    ``per_rh``: base parameters fitted per RH level; ``candidates``: effects to try
    (default: every catalog effect the model lacks except ``thermal``); ``force``: also try
    effects the data cannot reveal; ``noise_floor`` [m]: overrides the records' own;
    ``fs_max`` [Hz]: cap on the analysis sampling rate (default ≥ 5× the highest excited
    frequency); ``progress``: a callback for one-line progress messages; ``settings``: where
    the candidate fits run (:mod:`physics.parallel`; the same verdict for any worker count)."""
    t_all = time.perf_counter()
    warm_up(settings)   # the workers start beside the base fit and the residual analysis
    timings: dict = {}
    dev = load_device(device)
    base_ids = resolve_effects(effects, dev)
    free_l = parse_names(free) if free not in (None, "") else C.default_free(base_ids)
    per_rh_l = parse_names(per_rh, "--per-rh")
    specs = all_param_specs()
    for name in free_l + per_rh_l:
        if name not in specs:
            raise InputError(f"--free: unknown parameter {name!r}")
        if not C.param_used(name, base_ids):
            raise InputError(f"--free: {name} has no effect in a model with effects [{', '.join(base_ids)}]; "
                             f"free parameters of this model by default: {', '.join(C.default_free(base_ids))}")
    if candidates in (None, "", "default"):
        cand_ids = [e for e in C.default_candidates() if e not in base_ids]
    else:
        cand_ids = parse_names(candidates, "--candidates")
        bad = [e for e in cand_ids if not spec_of(e)]
        if bad:
            raise InputError(f"--candidates: unknown or fixed effect(s) {', '.join(bad)} (no diagnosis spec); "
                             f"catalog: {', '.join(e for e in EFFECTS if spec_of(e))}")
        already = [e for e in cand_ids if e in base_ids]
        if already:
            raise InputError(f"--candidates: {', '.join(already)} already in the model (--effects)")
    if n_starts < 1:
        raise InputError("n_starts must be at least 1")

    # 1. records and targets
    t0 = time.perf_counter()
    records = prepare_records(measurements, rh=rh, sensor_bandwidth=sensor_bandwidth, fs_max=fs_max,
                              noise_floor=noise_floor, rh_tolerance=rh_tolerance)
    ms, trecs = frf_measurements(records)
    if not ms:
        raise InputError("the diagnosis fits the model on frequency responses: give at least one broadband record "
                         "(swept sine, multisine, noise) or tone record besides steps/pulses")
    opts = frf_options or FRFOptions()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        targets = build_targets(ms, frf_options=opts, sensor_bandwidth=sensor_bandwidth, rh_tolerance=rh_tolerance)
    band = (min(float(t.freq.min()) for t in targets), max(float(t.freq.max()) for t in targets))
    timings["records"] = time.perf_counter() - t0
    n_all = [r.ts.n for r in records]
    nf = [r.noise_floor for r in records]
    noise = math.sqrt(sum(n * x * x for n, x in zip(n_all, nf)) / sum(n_all)) if all(map(math.isfinite, nf)) else math.nan
    _log(progress, f"{len(records)} record(s), {sum(t.freq.size for t in targets)} FRF lines over "
                   f"{band[0]:.3g}–{band[1]:.3g} Hz; noise floor {1e6 * noise:.3g} µm")

    # 2. base
    t0 = time.perf_counter()
    df_cache: dict = {}
    base_spec = C.ModelSpec("base", base_ids, list(free_l), list(per_rh_l), parse_assignments(start),
                            parse_assignments(bounds, ranges=True, what="--bounds"))
    for name, v in base_spec.start.items():
        if name not in free_l + per_rh_l:
            raise InputError(f"--start: {name} is not a free parameter")
    for name in free_l:
        if name not in dev.params and name not in base_spec.start:
            default = declared_default(name)
            if default is None:
                raise InputError(f"device {dev.name!r} has no value for free parameter {name}; give one with --start")
            base_spec.start[name] = default
    base = C.fit_model(base_spec, dev, targets, trecs, n_starts=n_starts, seed=seed, n_modes=n_modes,
                       df_cache=df_cache)
    if not base.ok:
        raise ModelError(f"the base model could not be fitted: {base.error}")
    C.score(base, records)
    if not base.ok:
        raise ModelError(f"the base model could not be simulated: {base.error}")
    timings["base"] = time.perf_counter() - t0
    _log(progress, f"base [{', '.join(base_ids)}] fitted: RMS error {1e6 * base.rmse:.4g} µm, fit {base.fit_pct:.2f} %")
    dev_fit = base.device
    resonance = _resonance(base, band, records)

    # 3. where it fails
    t0 = time.perf_counter()
    ra_base = analyse("base", records, base.resid_d, base.pred_d, resonance_hz=resonance)
    feats = features(ra_base, records, resonance)
    timings["residual_analysis"] = time.perf_counter() - t0

    # 4. candidates (fitted as independent tasks: in this process, or on workers)
    n_levels = len({t.rh for t in targets})
    results: list[CandidateResult] = []
    tasks, slots = [], []
    for eff in cand_ids:
        ok, why = revealable(eff, records, resonance)
        if not ok and not force:
            results.append(CandidateResult(eff, "not_revealable", reason=f"the data cannot reveal {eff}: {why}"))
            continue
        try:
            spec = C.candidate_spec(eff, base_ids, base.spec.free, base.spec.per_rh, dev_fit, band, n_levels)
        except (InputError, KeyError) as exc:
            results.append(CandidateResult(eff, "failed", reason=f"{eff} cannot be added to this device: {exc}"))
            continue
        if not ok:
            spec.notes.append(f"forced: the data cannot reveal {eff} ({why})")
        slots.append(len(results))
        results.append(CandidateResult(eff, "pending", reason=why if ok else f"forced ({why})"))
        tasks.append({"spec": spec, "device": dev_fit, "targets": targets, "trecs": trecs, "records": records,
                      "n_starts": n_starts, "seed": seed, "n_modes": n_modes, "effect_files": user_effect_files(),
                      "df_cache": df_cache if settings is None or settings.serial else None})
    fitted = map_tasks(_fit_candidate, tasks, settings, desc="candidates", progress=False, cost=_candidate_cost)
    for k, (mf, wall) in zip(slots, fitted):
        c = results[k]
        if not mf.ok:
            results[k] = CandidateResult(c.effect, "failed", reason=f"{c.effect}: fit or simulation failed: {mf.error}",
                                         fit=mf)
            continue
        c.status, c.fit = "evaluated", mf
        timings[f"candidate {c.effect}"] = wall
        _log(progress, f"  +{c.effect:22s} RMS {1e6 * mf.rmse:9.4g} µm  ({wall:.1f} s)")
    # one noise model for every comparison: the autocorrelation of the residual closest to
    # noise (the best-fitting model's), so that n_eff does not change from candidate to candidate
    fits = [base] + [c.fit for c in results if c.evaluated]
    ref = min(fits, key=lambda f: sum(f.rss))
    taus_ref = list(ref.taus)
    n_eff_ref = [n / t for n, t in zip(base.n, taus_ref)]
    base.bic = stats.bic(base.rss, base.n, n_eff_ref, base.k + len(records))
    base.aic = stats.aic(base.rss, base.n, n_eff_ref, base.k + len(records))
    for c in results:
        if c.evaluated:
            # an effect fitted through per-RH parameters nests only when they were freed (≥ 2 RH levels)
            nested = C.is_nested(c.effect) and (not spec_of(c.effect).get("per_rh") or bool(c.fit.spec.per_rh))
            c.comparison = C.compare_fits(base, c.fit, nested, taus_ref)
            c.fit.bic = base.bic + c.comparison.delta_bic
            c.fit.aic = base.aic + c.comparison.delta_aic
    sigs = signatures(feats, [c.effect for c in results])
    for c in results:
        c.signature = sigs.get(c.effect)
    ranked = sorted([c for c in results if c.evaluated], key=lambda c: c.comparison.delta_bic)
    others = [c for c in results if not c.evaluated]

    # distinguishability
    noise_d = _pooled_noise_d(records)
    for c in ranked:
        d = C.prediction_distance(c.fit, base)
        if c.comparison.delta_bic > -DELTA_BIC_MIN and math.isfinite(noise_d) and d < noise_d:
            c.indistinguishable_from.append("base")
    verdict = _verdict(base, ranked, noise, noise_d, taus_ref)
    win = next((c for c in ranked if c.effect == verdict.missing_effect), None)
    adequacy = assess(f"base + {win.effect}" if win else "base", win.fit if win else base, records, noise)
    _apply_adequacy(verdict, adequacy, base, noise)
    for c in ranked:
        c.explanation = _explain(c, base, noise)
    support: list[SupportResult] = []
    if check_support:
        # against the final model: the base, or the base with the missing effect when one was found
        t0 = time.perf_counter()
        win = next((c for c in ranked if c.effect == verdict.missing_effect), None)
        final = win.fit if win is not None else base
        support = _support(final, [e for e in final.effects if e != verdict.missing_effect], final.device, targets,
                           trecs, records, band, resonance, n_starts, seed, n_modes, df_cache, progress)
        timings["support"] = time.perf_counter() - t0

    # 5. after
    ra_after = None
    w = next((c for c in ranked if c.effect == verdict.missing_effect), None)
    shown = w or (ranked[0] if ranked else None)
    if shown is not None:
        res_fr = _resonance(shown.fit, band, records)
        ra_after = analyse(f"+{shown.effect}", records, shown.fit.resid_d, shown.fit.pred_d, resonance_hz=res_fr)
    timings["total"] = time.perf_counter() - t_all
    settings = {"effects": list(base_ids), "free": base.spec.free, "per_rh": base.spec.per_rh,
                "candidates": cand_ids, "force": force, "n_starts": n_starts, "seed": seed, "n_modes": n_modes,
                "sensor_bandwidth": sensor_bandwidth, "rh_tolerance_pct": rh_tolerance, "fs_max_Hz": fs_max,
                "frf": vars(opts).copy(), "noise_floor_given_m": noise_floor,
                "tau_reference": {"model": ref.spec.label, "tau_samples": taus_ref}}
    warns = list(base.warnings)
    return DiagnosisResult(dev, records, base, ranked + others, support, verdict, ra_base, ra_after, feats, noise,
                           resonance, settings, timings, warns, adequacy)


def _candidate_cost(task: dict) -> float:
    """Relative cost of a candidate fit, to start the dearest first: a nonlinear model runs
    the implicit time stepper (~5–10× a linear one); each free parameter adds evaluations."""
    spec = task["spec"]
    linear = ActuatorModel(task["device"], list(spec.effects), n_modes=task["n_modes"]).is_linear
    return (1.0 if linear else 8.0) * (len(spec.free) + len(spec.per_rh) + 1)


def _fit_candidate(task: dict):
    """Fit and score one candidate (a task of :func:`physics.parallel.map_tasks`)."""
    ensure_registered(task["effect_files"])
    t0 = time.perf_counter()
    mf = C.fit_model(task["spec"], task["device"], task["targets"], task["trecs"], n_starts=task["n_starts"],
                     seed=task["seed"], n_modes=task["n_modes"], df_cache=task["df_cache"] if task["df_cache"]
                     is not None else {})
    if mf.ok:
        C.score(mf, task["records"])
    return mf, time.perf_counter() - t0


def _resonance(mf: C.ModelFit, band, records) -> float | None:
    try:
        f = np.geomspace(max(band[0], 0.05), band[1] * 1.5, 400)
        fr = frequency_response(mf.model, None, f, rh=records[0].rh)
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


def _verdict(base: C.ModelFit, ranked: list[CandidateResult], noise: float, noise_d: float, taus_ref) -> Verdict:
    m = max(len(ranked), 1)
    alpha = ALPHA / m
    within_noise = math.isfinite(noise) and base.rmse <= NOISE_MARGIN * noise
    for c in ranked:
        f, cmp = c.fit, c.comparison
        c.passes = {"very_strong_bic": bool(cmp.delta_bic <= -DELTA_BIC_MIN),
                    "p_below_alpha_over_m": bool(math.isfinite(cmp.p_value) and cmp.p_value <= alpha),
                    "error_reduced_10pct": bool(f.rmse <= (1 - MIN_IMPROVEMENT) * base.rmse),
                    "base_above_noise": not within_noise}
    practical = [c for c in ranked if c.passes["error_reduced_10pct"] and c.passes["base_above_noise"]]
    bics = [0.0] + [c.comparison.delta_bic for c in practical]
    weights = stats.bic_weights(bics)
    wmap = {c.effect: float(wt) for c, wt in zip(practical, weights[1:])}
    base_w = float(weights[0])
    eligible = [c for c in ranked if all(c.passes.values())]
    if not eligible:
        if within_noise:
            reason = (f"the base model already fits to within {NOISE_MARGIN}× the noise floor "
                      f"({1e6 * base.rmse:.3g} µm vs {1e6 * noise:.3g} µm): there is nothing left for an effect to explain")
        elif not ranked:
            reason = "no candidate could be evaluated on these data (see not_evaluated)"
        else:
            top = ranked[0]
            failed = [k for k, v in top.passes.items() if not v]
            reason = (f"no candidate passes every criterion; the best, {top.effect}, fails "
                      f"{', '.join(failed)} (ΔBIC {top.comparison.delta_bic:.3g}, p = {top.comparison.p_value:.2g}, "
                      f"RMS {1e6 * base.rmse:.3g} → {1e6 * top.fit.rmse:.3g} µm)")
        return Verdict(None, base_w, _label(base_w), reason, alpha_bonferroni=alpha)
    top = eligible[0]
    if len(eligible) > 1:
        ru = eligible[1]
        pair = C.compare_fits(ru.fit, top.fit, nested=False, taus=taus_ref)
        dist = C.prediction_distance(top.fit, ru.fit)
        if pair.delta_bic > -DISTINCT_BIC or (math.isfinite(noise_d) and dist < noise_d):
            top.indistinguishable_from.append(ru.effect)
            ru.indistinguishable_from.append(top.effect)
            reason = (f"{top.effect} and {ru.effect} both explain the failure and the data cannot tell them apart "
                      f"(ΔBIC between them {pair.delta_bic:.3g}, predictions differ by {1e6 * dist:.3g} µm RMS); "
                      f"{_design_hint(top.effect, ru.effect)}")
            conf = wmap.get(top.effect, 0.0) + wmap.get(ru.effect, 0.0)
            return Verdict(None, conf, _label(conf), reason, ambiguous=[top.effect, ru.effect], alpha_bonferroni=alpha)
    conf = wmap.get(top.effect, 0.0)
    label = _label(conf)
    reason = (f"{top.effect}: ΔBIC {top.comparison.delta_bic:.4g} ({stats.evidence_label(top.comparison.delta_bic)}), "
              f"p = {top.comparison.p_value:.2g} (< {alpha:.2g}), RMS error {1e6 * base.rmse:.4g} → "
              f"{1e6 * top.fit.rmse:.4g} µm")
    score = (top.signature or {}).get("score")
    if score is not None and score == 0:
        label = {"high": "medium", "medium": "low"}.get(label, label)
        reason += "; but its residual signature is not observed, so the confidence label is lowered"
    return Verdict(top.effect, conf, label, reason, alpha_bonferroni=alpha)


def _apply_adequacy(v: Verdict, ad: Adequacy, base: C.ModelFit, noise: float) -> None:
    """Set the verdict's status from the adequacy of the final model (module doc of
    :mod:`.adequacy`): a winner that leaves more than noise only partly explains the
    failure (confidence label "low"); no winner with a base above the noise is a failure
    the catalog does not explain, described by the residual's descriptors."""
    found = ad.remaining()
    described = ("; what remains looks like " + "; and ".join(found)) if found else \
        f"; no simple form ({forms.titles()}) fits what remains"
    template = (" — to model it, `eap diagnose … --draft-effects DIR` drafts effect files for what remains (or write "
                "one like examples/effects/creep.py); pass it back with --effects-path")
    if math.isfinite(noise) and base.rmse <= NOISE_MARGIN * noise:
        v.status = "nothing to explain"
    elif v.ambiguous:
        v.status = "ambiguous"
    elif v.missing_effect is not None:
        if ad.adequate is False:
            v.status = "partly explained"
            v.label = "low"
            v.remaining = (f"after adding {v.missing_effect} the RMS error is still {ad.ratio:.2f}× the noise floor "
                           f"(adequate: ≤ {ADEQUATE_RATIO}×): the catalog explains part of the failure and something "
                           f"else remains" + described + template)
        else:
            v.status = "explained"
    else:
        v.status = "not explained by the catalog"
        level = f"{ad.ratio:.2f}× the noise floor" if math.isfinite(ad.ratio) else f"{1e6 * ad.rmse:.3g} µm"
        v.remaining = f"no catalog effect explains the failure (RMS error {level})" + described + template


def _label(w: float) -> str:
    return "high" if w >= 0.99 else ("medium" if w >= 0.9 else "low")


def _design_hint(a: str, b: str) -> str:
    return (f"to separate them: {a} needs {excitation(a) or '?'}; {b} needs {excitation(b) or '?'}")


def _fmt_params(values: dict, errors: dict) -> str:
    specs = all_param_specs()
    parts = []
    for k, v in values.items():
        unit = specs.get(k.split("@")[0]).unit if specs.get(k.split("@")[0]) else ""
        se = errors.get(k)
        se_txt = f" ± {se:.2g}" if se is not None and math.isfinite(se) else ""
        parts.append(f"{k} = {v:.4g}{se_txt} {unit}".strip())
    return ", ".join(parts)


def _explain(c: CandidateResult, base: C.ModelFit, noise: float) -> str:
    f, cmp = c.fit, c.comparison
    vals = C.effect_values(f, c.effect)
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
        d = C.prediction_distance(f, base)
        txt += (f" Its fitted model predicts the same deflection as the base with re-tuned "
                f"{', '.join(base.spec.free)} (RMS difference {1e6 * d:.3g} µm, below the noise): the data cannot "
                "tell it apart from the base.")
    others = [x for x in c.indistinguishable_from if x != "base"]
    if others:
        txt += f" Cannot be told apart from {', '.join(others)} with these data."
    eff_params = set(C.effect_params(c.effect))
    weak = [w for w in f.warnings if any(p in w for p in eff_params)]
    if weak:
        txt += " Identifiability: " + "; ".join(weak) + "."
    for n in f.spec.notes:
        txt += f" Note: {n}."
    return txt


def _support(base, check_ids, dev_fit, targets, trecs, records, band, resonance, n_starts, seed, n_modes, df_cache,
             progress) -> list[SupportResult]:
    """Switch each effect of ``check_ids`` off in the fitted model ``base`` and refit."""
    out = []
    base_ids = base.effects
    for eff in check_ids:
        if eff == "double_layer":
            continue
        ok, why = revealable(eff, records, resonance)
        if not ok:
            out.append(SupportResult(eff, "not_assessable",
                                     explanation=f"cannot be assessed: the data cannot reveal {eff} ({why})"))
            continue
        try:
            spec = C.removal_spec(eff, base_ids, base.spec.free, base.spec.per_rh, dev_fit, band)
        except (InputError, KeyError) as exc:
            out.append(SupportResult(eff, "failed", explanation=str(exc)))
            continue
        if not spec.free and not spec.per_rh:
            out.append(SupportResult(eff, "failed", explanation="no free parameter left without it"))
            continue
        mf = C.fit_model(spec, dev_fit, targets, trecs, n_starts=n_starts, seed=seed, n_modes=n_modes,
                         df_cache=df_cache)
        if mf.ok:
            C.score(mf, records)
        if not mf.ok:
            out.append(SupportResult(eff, "failed", explanation=f"the model without {eff} failed: {mf.error}"))
            continue
        cmp = C.compare_fits(mf, base, C.is_nested(eff))
        supported = cmp.delta_bic <= -SUPPORT_BIC
        if supported:
            txt = (f"supported: removing {eff} raises the RMS error from {1e6 * base.rmse:.4g} to {1e6 * mf.rmse:.4g} µm "
                   f"(ΔBIC {-cmp.delta_bic:+.4g} against removal)")
        elif cmp.delta_bic <= -2:
            txt = (f"weakly supported: without {eff} the RMS error is {1e6 * mf.rmse:.4g} µm instead of "
                   f"{1e6 * base.rmse:.4g} µm (ΔBIC {-cmp.delta_bic:+.4g}); the data barely need it")
        else:
            txt = (f"not supported by these data: without {eff} the model fits as well ({1e6 * mf.rmse:.4g} vs "
                   f"{1e6 * base.rmse:.4g} µm RMS, ΔBIC {-cmp.delta_bic:+.4g} for removing it)")
        out.append(SupportResult(eff, "assessed", supported, -cmp.delta_bic, cmp.p_value, mf.rmse, txt))
        _log(progress, f"  -{eff:22s} RMS {1e6 * mf.rmse:9.4g} µm  {'supported' if supported else 'not supported'}")
    return out
