"""From a description to an effect file: drafts of the forms that remain after the best model.

Each forward-selected residual form (:mod:`.forms`) that can be written as an effect gives
an :class:`.effect_draft.EffectDraft` (one effect file following the effect contract); here
the drafts are fitted jointly with the model and forward-selected (:func:`draft_effects`).
Passed back with ``--effects-path`` a file is a diagnosis candidate like any other.

:func:`write_drafts` writes the files into a new folder through the package's output
policy (:func:`physics.io.outputs.output_folder`: atomic, never over a user's files) and
checks each one against the contract (:func:`check_draft`) before the folder appears.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

from ..errors import InputError, ModelError
from ..execution.threads import single_threaded
from .confidence import LABELS
from .forms import FormFit, MIN_GAIN, SIGNIFICANT_BIC, describe, form_of, residual_of
from .forms.base import has_response
from .effect_draft import EffectDraft

#: Starts of each fit in a draft round that run to convergence (the others are screened out by a
#: short run, :func:`physics.identify.fitting.fit_lsq` ``keep``): a draft's grid over its unknown
#: scale gives eight starts of a model with ~15 free parameters, which on a low-pass strip all met in
#: one valley at 9–17 thousand evaluations each (over 8 minutes for that one candidate).
DRAFT_KEEP_STARTS = 2


def drafts(forms: Sequence[FormFit], fit, records) -> list[EffectDraft]:
    """A draft of every form of ``forms`` that can be written as an effect, its residual fit
    as the start (the forward-selected first, then by ΔBIC; each version of a form whose
    residual could not choose between them, :meth:`.forms.base.Form.draft`)."""
    res = residual_of(fit, records)
    out, seen = [], set()
    for ff in sorted(forms, key=lambda f: (f.selected_step or 99, f.delta_bic)):
        if ff.form in seen:
            continue
        seen.add(ff.form)
        for each in form_of(ff.form)().draft(ff, res):
            each.seen = f"in the residual of {fit.spec.label} (RMS error {1e6 * fit.rmse:.4g} µm), {ff.full_text}."
            each.evidence = {"residual_form": ff.to_dict()}
            out.append(each)
    return out


def _linear_of_the_chain(res):
    """The last model of the diagnosis ``res`` with a linear response (its base, or a step's
    result; :func:`.forms.base.has_response`), None when none has one."""
    fits = [res.base] + [s.result for s in getattr(res, "steps", [])]
    return next((f for f in reversed(fits) if has_response(getattr(f, "model", None))), None)


def _behind_the_picks(res) -> list[EffectDraft]:
    """Drafts of the forms written through a linear model's response (a map of the drive,
    :attr:`.forms.base.Form.needs_response`) that the residual of the chain's last linear model
    (:func:`_linear_of_the_chain`) shows, when the diagnosis's final model has no such response
    (a large-signal pick): a pick that saturates the charge can stand in for a drive that
    saturates, its own residual cannot show the map, and the drafts compete with the picks
    (:func:`_draft_start`).  Only the significant forms (the final model's residual drafts every
    form it fits)."""
    linear = _linear_of_the_chain(res)
    if has_response(getattr(res.final, "model", None)) or linear is None:
        return []
    return drafts([ff for ff in describe(linear, res.records) if form_of(ff.form).needs_response and ff.significant],
                  linear, res.records)


def _draft_start(res) -> tuple[list, list, object]:
    """(effects, free parameters, device) the draft rounds start from: the draft base's
    (:attr:`.diagnosis.DiagnosisResult.draft_base`, the model without the effects the data do not
    support, its own effects refitted), without the diagnosis's picks when that base holds them
    and is large-signal while the chain has a linear model: the picks then compete with the drafts
    from it (the catalog effects of :func:`draft_effects`), the own effects start at their values
    refitted beside the picks and stay free.  Left in, the pick would take the maps of the drive
    out of the pool (:func:`_hold_maps_of_the_drive`): on a held-out saturating strip whose own
    effects were refitted beside a saturating charge no map was fitted, and the best model stayed
    at 6.41× the true model's error (2.92× from the model without the pick)."""
    from .candidates import map_free
    base = getattr(res, "draft_base", res.base)
    on_top, free = list(base.effects), list(base.spec.free)
    picks = [p.effect for p in res.picks]
    if not has_response(getattr(base, "model", None)) and set(picks) & set(on_top) \
            and _linear_of_the_chain(res) is not None:
        keep = [e for e in on_top if e not in picks]
        return keep, map_free(free, on_top, keep), base.device
    return on_top, free, base.device


@dataclass
class DraftOutcome:
    """The drafts fitted with the model, forward-selected: kept (in order), rejected, and the
    chain of effects added to the base (kept drafts and any catalog pick, in order)."""

    kept: list
    rejected: list                   # (draft, reason)
    rmse_before: float               # the diagnosis's final model (base, or base + its picks)
    chain: list = field(default_factory=list)     # (effect id, RMS after [m]) per step from the base
    notes: list = field(default_factory=list)
    steps: list = field(default_factory=list)     # (effects fitted on, DiagnosisResult) per round
    final: object = None          # the best model the rounds reached (a ModelFit): fitted with every effect on
                                  # the chain, or round 1's refinement of the diagnosis's model; None: no better one

    @property
    def rmse_after(self) -> float:
        return self.chain[-1][1] if self.chain and self.kept else self.rmse_before

    def lines(self) -> list[str]:
        out = [f"{d.file_name}: {d.evidence['text']}" for d in self.kept]
        out += [f"{d.effect_id} not kept: {why}" for d, why in self.rejected]
        return out + self.notes


def rediagnosis(measurements, res, options, *, fs_max: float | None = None,
                progress: Callable[[str], None] | None = None, keep_starts: int | None = DRAFT_KEEP_STARTS):
    """The ``rediagnose`` of :func:`draft_effects` that ``eap diagnose`` uses after the diagnosis
    ``res`` of ``measurements`` with the fit ``options``: each round a forward-only diagnosis with
    the round's candidates, each fit from the diagnosis's starts (``options.n_starts``) and its
    own grid, of which ``keep_starts`` run to convergence (:data:`DRAFT_KEEP_STARTS`), the draft
    base's per-RH parameters and the diagnosis's noise floor, no support test.  One start was
    too few for an effect tried again: behind a drafted sensor low-pass a strip's ``humidity``
    fitted from one start lowered the error from 50.0 to 40.8 µm, from four to 24.0 µm.  From the
    second round on, the base (the model the round before kept, whose pick was refined on the time
    records) is refined on them too.  When a round's pick is large-signal, its best linear rival is
    refined on the time records before the round decides, and a round without a pick refines its best
    linear candidate on them from the base's values (:attr:`.diagnosis.SelectionOptions.refine_rival`).
    The first round's base is refined so too when the draft base was (its own effects refitted on
    the time records): refitted on the FRF alone, a test-bed strip's rough-electrode model went
    from 8.16 µm to 221 µm, and its drafts were fitted on top of that."""
    import dataclasses

    from .diagnosis import AnalysisOptions, SelectionOptions, diagnose
    opts = dataclasses.replace(options, per_rh=",".join(res.draft_base.spec.per_rh) or "none", keep_starts=keep_starts)
    first = set(res.draft_base.effects)
    refined = bool(getattr(res.draft_base, "time_refined", False))
    return lambda dev, eff, free, cands, refit_own=False: diagnose(
        measurements, dev, eff, free, options=opts, candidates=cands, force=True, check_support=False,
        selection=SelectionOptions(max_effects=1, backward=False, refine_base=refined or not set(eff) <= first,
                                   refine_rival=True, refit_own=refit_own),
        analysis=AnalysisOptions(noise_floor=res.noise_floor, fs_max=fs_max), progress=progress)


@single_threaded
def draft_effects(res, rediagnose, max_effects: int = 2,
                  progress: Callable[[str], None] | None = None) -> DraftOutcome:
    """Draft what remains after the final model of the diagnosis ``res`` and select the drafts
    by fitting them with the model: ``rediagnose(device, effects, free, candidates, refit_own=False)``
    runs the diagnosis of the records with ``candidates`` (the drafts, registered meanwhile) on top of
    the model ``device`` (fitted values) + ``effects`` with ``free`` parameters (``refit_own``: the
    model's own effects refitted after it, :func:`_refit_own`).

    The drafts are those of the final model's residual, and, when that model is large-signal,
    those of the maps of the drive the chain's last linear model's residual shows
    (:func:`_behind_the_picks`).
    Nothing is drafted when there is nothing to explain, or when the final model (its own
    effects refitted by the chain when it did) is within the noise without a pick.
    Otherwise, forward from the draft base (:func:`_draft_start`), the drafts compete with the
    catalog effects the diagnosis picked, even when the model with them is adequate (a catalog
    effect can mimic physics it does not model within the noise, e.g. the electrode resistance a
    sensor's low-pass): the
    candidate that lowers the error most (lowest ΔBIC) is taken when it passes ΔBIC ≤ −:data:`.forms.SIGNIFICANT_BIC` and ≥ :data:`.forms.MIN_GAIN` lower RMS error,
    and the others are tried again on top of it (at most ``max_effects`` drafts kept, and no further
    round once the kept model is within the noise: :func:`_within_the_noise`); once a
    draft is kept, the model's own effects the support test removed compete too (:func:`_tried_before`),
    and those still left out are restored when that pays (:func:`_restore_removed`).  A kept
    draft takes the values fitted with the model as its defaults (bounds and starts follow).
    ``progress``: a callback for one-line progress messages (each round refits the model, minutes
    on long records)."""
    import tempfile

    from .candidates import effect_values, map_free
    fit = res.final
    ad = res.adequacy
    if res.verdict.status == "nothing to explain" or (ad is not None and ad.adequate and not res.picks):
        items = []
    else:       # an adequate catalog pick may still be a mimic: the drafts compete with it
        items = drafts(ad.forms if ad is not None and ad.forms else describe(fit, res.records), fit, res.records)
        items += [d for d in _behind_the_picks(res) if d.form not in {i.form for i in items}]
    from ..effects import EFFECTS, load_effects_file, unregister
    # a form whose effect is already registered (the user's own file of an earlier draft) is on offer
    # already: drafting it again would name one effect twice
    items = [d for d in items if d.effect_id not in EFFECTS]
    outcome = DraftOutcome([], [], fit.rmse)
    if not items:
        return outcome
    on_top, free, device = _draft_start(res)
    catalog = [p.effect for p in res.picks if p.effect not in on_top]
    before_drafts, passed_over = _tried_before(res, on_top + catalog), {}
    say = progress or (lambda msg: None)
    with tempfile.TemporaryDirectory(prefix="eap-drafts-") as tmp:
        ids = []
        for d in items:
            path = Path(tmp) / d.file_name
            path.write_text(d.source(), encoding="utf-8")
            ids += load_effects_file(path)
        try:
            pool = list(items)
            fitted: set = set()             # the forms whose drafts a round fitted with the model
            while pool and len(outcome.kept) < max_effects:
                retry = list(before_drafts) if outcome.kept else []
                offered = [d.effect_id for d in pool] + catalog + retry
                say(f"drafts: round {len(outcome.steps) + 1} (at most {max_effects} kept): "
                    f"{', '.join(offered)} fitted with [{', '.join(on_top)}]")
                try:
                    again = rediagnose(device, on_top, free, offered)
                except (InputError, ModelError) as exc:     # the diagnosis stands; the drafts are not tried
                    outcome.rejected += [(d, f"not tried: the model they would join could not be refitted ({exc})")
                                         for d in pool]
                    break
                outcome.steps.append((list(on_top), again))
                fitted.update(d.form for d in pool)
                if not outcome.chain:
                    _refined_further(outcome, again.base, fit)
                if outcome.chain and getattr(again.base, "time_refined", False) and \
                        again.base.rmse < outcome.chain[-1][1]:
                    _went_further(outcome, again.base, len(outcome.steps))
                scored, why = _scored(pool + catalog + retry, again, on_top,
                                      outcome.chain[-1][1] if outcome.chain else None)
                passed_over.update({e: why[e] for e in retry if e in why})
                passed_over.update({k: f"fitted with [{', '.join(on_top)}] it lowers the RMS error to "
                                       f"{1e6 * c_.fit.rmse:.4g} µm (ΔBIC {b:.3g}), less than the round's pick"
                                    for b, k, c_ in scored[1:] if k in retry})
                if not scored:
                    say("drafts: nothing more taken (none lowers the error enough)")
                    outcome.rejected += [(d, why.get(d.effect_id, "")) for d in pool]
                    break
                dbic, key, c = scored[0]
                eid = key if isinstance(key, str) else key.effect_id
                say(f"drafts: {eid} taken, RMS error {1e6 * again.base.rmse:.4g} → {1e6 * c.fit.rmse:.4g} µm")
                _strip_other_drafts(c.fit, items, on_top + [eid])
                values = effect_values(c.fit, eid)
                text = _pick_text(scored, again, on_top)
                if key in catalog:                  # the catalog's pick: on the chain, then the drafts on top
                    outcome.notes.append(f"{eid} (the diagnosis's pick) {text}; the drafts are tried on top of it")
                    catalog.remove(key)
                elif isinstance(key, str):          # a catalog effect that did not help before the drafts did
                    outcome.notes.append(f"{eid} (tried again on top of the kept drafts) {text}")
                    before_drafts.remove(key)
                else:
                    key.refit(values)
                    key.evidence.update({"rmse_before_m": again.base.rmse, "rmse_after_m": c.fit.rmse,
                                         "delta_bic": dbic, "on_top_of": list(on_top), "text": text, "values": values})
                    key.seen += " Fitted jointly, " + text[len("fitted "):] + "."
                    outcome.kept.append(key)
                    pool.remove(key)
                    _drop_siblings(outcome, pool, key)
                outcome.chain.append((eid, c.fit.rmse))
                on_top.append(eid)
                free = map_free(free + [n for n in values if n not in free and "@" not in n], on_top, on_top)
                device = c.fit.device
                outcome.final = c.fit
                if not getattr(getattr(c.fit, "model", None), "is_linear", True):
                    _hold_maps_of_the_drive(outcome, pool, eid)
                if pool and len(outcome.kept) < max_effects and _within_the_noise(again, c):
                    say(f"drafts: [{', '.join(on_top)}] is within the noise: no further round")
                    outcome.rejected += [(d, f"not tried: the model the round kept ([{', '.join(on_top)}]) is "
                                             "within the noise") for d in pool]
                    break
            else:
                outcome.rejected += [(d, "not tried: the forward selection stopped") for d in pool]
            if outcome.kept:
                _refit_own(outcome, rediagnose, device, on_top, free, say)
                _linear_without_picks(res, outcome, rediagnose, free, say)
                _restore_removed(outcome, rediagnose, free, before_drafts, say)
                _relabel_on_written(res, outcome, rediagnose, free, say)
                _left_out_of_written(res, outcome)
                _name_counterparts(res, outcome, rediagnose, free, say)
                _polish(res, outcome, say)
                _remaining_drafted(res, outcome)
            left = {e: w for e, w in passed_over.items() if e in before_drafts}
            if left:
                outcome.notes.append("tried again on top of the kept drafts, not taken: "
                                     + "; ".join(f"{e} ({w})" for e, w in left.items()))
            res.verdict.drafts = {"kept": {d.form: d.effect_id for d in outcome.kept}, "fitted": sorted(fitted),
                                  "rmse_m": outcome.final.rmse if outcome.kept and outcome.final is not None else None}
        finally:
            for i in ids:
                unregister(i)
    return outcome


def _within_the_noise(again, c) -> bool:
    """Whether the model the round ``again`` kept (candidate ``c``) is adequate, as the round's own
    verdict judged it (:func:`.adequacy.assess`: the noise floor, the records' wander and any
    structure they share); only when that verdict ended on the same fit.  Once the kept model is
    within the noise the drafts have competed with the picks already, and a further round would
    only fit the rest of the noise, as drafting on an adequate model without a pick would."""
    ad = getattr(again, "adequacy", None)
    return ad is not None and bool(ad.adequate) and getattr(again, "final", None) is c.fit


def _tried_before(res, taken: list) -> list[str]:
    """The model's own effects that the draft base leaves out (the support test removed them),
    none of ``taken``: tried again on top of a kept draft.  A missing effect can hide another:
    behind an unmodelled sensor low-pass a strip's ``solvent_diffusion`` was found unsupported, and
    fitted on top of the drafted low-pass it took the place of a drafted slow pole.  The catalog
    candidates the diagnosis evaluated are not tried again: each adds a round of fits on the time
    records, and on the held-out strips they bought little for it (one taken, the best model 3.22
    → 3.08 µm against a true model's 2.98 µm, for a command that took 1256 s instead of 581 s)."""
    base = getattr(res, "draft_base", res.base)
    return [e for e in res.base.effects if e not in base.effects and e not in taken]


def _refit_own(outcome: DraftOutcome, rediagnose, device, on_top: list, free: list, say) -> None:
    """The model's own effects refitted beside the kept drafts (``rediagnose`` with no candidate and
    ``refit_own``, :func:`.diagnosis.refine_own`), as the diagnosis refits them beside its picks: their
    values were fitted without the drafts, and a draft that takes over part of the misfit leaves them
    compensating for it (a held-out strip whose drive saturates softly: its drafted map 12.4 µm with the
    electrode, solvent and polymer at their values fitted without it, 6.3 µm refitted).  Taken when it
    lowers the chain's error; linear models only (a large-signal refit runs the implicit stepper)."""
    if not getattr(getattr(outcome.final, "model", None), "is_linear", False):
        return
    say(f"drafts: the own effects of [{', '.join(on_top)}] refitted beside the kept drafts")
    try:
        again = rediagnose(device, on_top, free, [], refit_own=True)
    except (InputError, ModelError) as exc:
        outcome.notes.append(f"the own effects were not refitted beside the kept drafts ({exc})")
        return
    step = next((s for s in again.steps if s.refit is not None), None)
    before = outcome.chain[-1][1]
    if step is not None and step.refit.rmse < before:
        _carry(outcome, step.refit, f"the own effects refitted beside the kept drafts ({', '.join(step.refitted)}): "
                                    f"RMS error {1e6 * before:.4g} → {1e6 * step.refit.rmse:.4g} µm")


def _refitted_beside_drafts(rediagnose, outcome: DraftOutcome, fit, effects: list, free: list, failed: str):
    """The model ``effects`` from ``fit``'s values (a ModelFit of the model written), its own effects
    refitted beside the kept drafts (``rediagnose`` with no candidate and ``refit_own``): the refit,
    or the round's base where the refit did not pay; None, with the note "``failed`` (why)", when
    that model cannot be fitted."""
    from .candidates import map_free
    try:
        again = rediagnose(fit.device, effects, map_free(free, list(fit.effects), effects), [], refit_own=True)
    except (InputError, ModelError) as exc:
        outcome.notes.append(f"{failed} ({exc})")
        return None
    step = next((s for s in again.steps if s.refit is not None), None)
    return step.refit if step is not None else again.base


def _linear_without_picks(res, outcome: DraftOutcome, rediagnose, free: list, say) -> None:
    """When the picks of the diagnosis ``res`` make the model written large-signal, so that
    :func:`_refit_own` could not refit its own effects beside the kept drafts: the model written less
    those picks (linear) with its own effects refitted beside the drafts (``rediagnose`` with
    ``refit_own``) is written instead unless the picks earn their parameters on top of it (ΔBIC ≤
    −:data:`.forms.SIGNIFICANT_BIC`, the test a pick meets beside drafts that fit alone,
    :func:`_drafts_suffice`); :func:`_left_out_of_written` then says so on their lines.  A large-signal
    pick is fitted before the drafts on a model whose own effects still sit at the device's values,
    and once it is in, nothing refits them: on a strip seen through a sensor whose characteristic is
    bowed (``circuit_lab`` seed 69, y + b·y²/S with b = −5 %) the chain named ``nonlinear_charge``, the
    rounds kept a drafted bow beside it, and the model written stayed at 5.87 µm (2.25× the noise
    floor); the base with the bow alone and its own effects refitted fits to 3.34 µm.  The user's own
    effects and picks taken back into the model are not left out."""
    from .candidates import compare_fits
    from ..effects import LINEAR_EFFECTS
    fit = outcome.final
    if fit is None or getattr(getattr(fit, "model", None), "is_linear", True):
        return
    large = [p.effect for p in res.verdict.picks if p.effect in fit.effects and not p.own
             and p.effect not in LINEAR_EFFECTS]
    keep = [e for e in fit.effects if e not in large]
    if not large:
        return
    say(f"drafts: [{', '.join(keep)}] without {', '.join(large)}, its own effects refitted beside the kept drafts")
    new = _refitted_beside_drafts(rediagnose, outcome, fit, keep, free,
                                  f"the model written was not refitted without {', '.join(large)}")
    if new is None or not getattr(getattr(new, "model", None), "is_linear", False):
        return
    cmp = compare_fits(new, fit, False)
    text = (f"without {', '.join(large)}, the model written with its own effects refitted beside the kept drafts "
            f"fits the records to {1e6 * new.rmse:.4g} µm ({1e6 * fit.rmse:.4g} µm with "
            f"{'them' if len(large) > 1 else 'it'}, ΔBIC {cmp.delta_bic:+.3g} for "
            f"{'their' if len(large) > 1 else 'its'} parameters)")
    if cmp.delta_bic <= -SIGNIFICANT_BIC:
        outcome.notes.append(text + f": {', '.join(large)} kept")
        return
    _carry(outcome, new, text + f": {', '.join(large)} left out of the model written")
    say(f"drafts: {text}")


def _restore_removed(outcome: DraftOutcome, rediagnose, free: list, removed: list, say) -> None:
    """Each of the model's own effects that the support test removed and the rounds did not take
    back (``removed``, updated in place), restored beside the kept drafts at the device's values
    with the model's own effects, its own included, refitted (as :func:`_refit_own` refits them):
    kept when that lowers the chain's error by :data:`.forms.MIN_GAIN` with ΔBIC ≤
    −:data:`.forms.SIGNIFICANT_BIC` (:func:`.candidates.compare_fits`, the restored effect's
    parameters counted).  The support test judged the effect on a model that still missed what the
    drafts model, and tried again as a candidate its parameters are fitted on the frequency
    response alone, with the others held: on a held-out strip whose drive saturates
    (``circuit_lab`` seed 32) the solvent's back-relaxation over hours was removed at 20.8 against
    20.98 µm, tried again on top of the drafted saturation its diffusion constant went to the
    bound where it vanishes (4.85 µm against 4.36 without it), while restored with the own effects
    refitted the model written reached 2.50 µm (true model 2.07 µm).  Linear models only, as
    :func:`_refit_own`."""
    from .candidates import compare_fits
    for eid in list(removed):
        fit = outcome.final
        if fit is None or not getattr(getattr(fit, "model", None), "is_linear", False):
            return
        on = list(fit.effects) + [eid]
        say(f"drafts: {eid} (removed before the drafts) restored beside them, the own effects refitted")
        new = _refitted_beside_drafts(rediagnose, outcome, fit, on, free,
                                      f"{eid} was not restored beside the kept drafts")
        if new is None:
            continue
        cmp = compare_fits(fit, new, nested=False)
        text = (f"{eid} (removed before the drafts) restored beside them at the device's values, the own effects "
                f"refitted: RMS error {1e6 * fit.rmse:.4g} → {1e6 * new.rmse:.4g} µm (ΔBIC {cmp.delta_bic:.3g})")
        if cmp.delta_bic <= -SIGNIFICANT_BIC and new.rmse <= (1.0 - MIN_GAIN) * fit.rmse:
            outcome.chain.append((eid, fit.rmse))
            _carry(outcome, new, text)
            removed.remove(eid)
            say(f"drafts: {text}")
        else:
            outcome.notes.append(text + ": not kept")


#: Where a pick is labelled again when the draft rounds keep a draft beside it (:func:`_relabel_on_written`).
WRITTEN = "the model written, beside the drafts kept"


def _relabel_on_written(res, outcome: DraftOutcome, rediagnose, free: list, say) -> None:
    """Each pick of the diagnosis ``res`` that the model written holds beside a kept draft
    (:attr:`DraftOutcome.final`), labelled again there: a forward step on that model less the pick,
    the pick offered with the rivals its step evaluated (those not in the model), and the pick's
    line in the verdict (label, errors without → with it, ΔBIC, values) becomes that step's when it
    picks the pick again.  A right pick may leave a large residual merely because a form the
    catalog lacks is missing beside it: on a test-bed strip with solvent diffusion (``circuit_lab``
    seed 21) the pick left 4.2 noise floors ("medium"), the drafted slow pole kept beside it brought
    the model to 1.19 floors, and there the pick lowers the error 24.9 → 2.95 µm with every rival of
    its step fitted again.  Only beside a kept draft, and with the rivals fitted again: on a model
    only refined further on the time records, a wrong pick of a bending eigen-moment offered alone
    read "high".  A pick that is not picked again (another candidate is, or none is while the model
    without it is still outside the noise), or that has a near twin, keeps its label; the notes say
    so.  So does a pick labelled lower there than on the chain: the drafts answer the residual a
    pick left, they do not question a pick that held without them (a viscoelastic modulus,
    ``circuit_lab`` seed 24, "high" on its refitted model, read "medium" beside a drafted slow pole
    only for two quality flags the pole brought: its loss correlated with a solvent constant, its
    signature no longer seen beside the pole); its verdict line still says what that step found.
    When the model without it is within the noise (the drafts alone fit the records), the pick is
    labelled against those drafts, and left out of the model written when it does not earn its
    parameters beside them (:func:`_drafts_suffice`)."""
    from .candidates import effect_rows, map_free
    fit = outcome.final
    if not outcome.kept or fit is None or fit.rmse >= res.final.rmse:
        return
    steps = {s.index: s for s in res.steps}
    for p in res.verdict.picks:
        fit = outcome.final
        if p.effect not in fit.effects or p.twin or p.step not in steps:
            continue
        rivals = [c.effect for c in steps[p.step].ranking if c.effect != p.effect and c.effect not in fit.effects]
        keep = [e for e in fit.effects if e != p.effect]
        say(f"drafts: {p.effect} labelled again on {WRITTEN} (offered with {', '.join(rivals) or 'no rival'})")
        try:
            again = rediagnose(fit.device, keep, map_free(free, list(fit.effects), keep), [p.effect] + rivals)
        except (InputError, ModelError) as exc:
            outcome.notes.append(f"{p.effect} was not labelled again on {WRITTEN} ({exc})")
            continue
        q = next(iter(again.verdict.picks), None)
        if q is None and again.verdict.status == "nothing to explain":
            _drafts_suffice(res, p, outcome, again.base, say)
            continue
        if q is None or q.effect != p.effect or q.twin:
            what = (f"{q.effect} is picked in its place" if q is not None and q.effect != p.effect
                    else f"it is ambiguous with {q.twin}" if q is not None
                    else f"no candidate is picked ({again.verdict.status})")
            outcome.notes.append(f"without {p.effect} on {WRITTEN}, {what}: {p.effect} keeps its confidence ({p.label})")
            continue
        c = q.confidence
        p.reason += (f"; on {WRITTEN} it lowers the RMS error {1e6 * q.rmse_before:.4g} → {1e6 * q.rmse_after:.4g} µm "
                     f"against {', '.join(rivals) or 'no rival'} fitted there too: confidence {q.label}"
                     + (": " + "; ".join(c.why) if c is not None and c.why else ""))
        if LABELS.index(q.label) > LABELS.index(p.label):
            p.reason += f"; it keeps its confidence ({p.label}): the drafts answer what a pick left, not whether it holds"
            outcome.notes.append(f"{p.effect} on {WRITTEN} reads {q.label}, lower than on the chain: it keeps its "
                                 f"confidence ({p.label})")
            continue
        p.confidence, p.weight, p.on = c, q.weight, WRITTEN
        p.rmse_before, p.rmse_after, p.delta_bic = q.rmse_before, q.rmse_after, q.delta_bic
        p.quality = list(q.quality)
        p.parameters = effect_rows(fit, p.effect)
        outcome.notes.append(f"{p.effect} labelled again on {WRITTEN}: confidence {q.label}")
        say(f"drafts: {p.effect} on {WRITTEN}: confidence {q.label}")


def _drafts_suffice(res, p, outcome: DraftOutcome, without, say) -> None:
    """The model written less the pick ``p`` (``without``: refitted, within the noise by its own
    verdict) — the kept drafts alone fit the records.  The pick is labelled with those drafts as
    its rival (:class:`.confidence.Confidence` ``alone``: the share of the excess error they leave
    that it removes; the twin's thresholds, none new), and when it does not earn its parameters
    beside them (ΔBIC > −:data:`.forms.SIGNIFICANT_BIC` for adding it back) the simpler model is
    written; :func:`_left_out_of_written` then says so on the pick's verdict line.  Chosen on a
    strip seen through a 0.012 Hz AC-coupled sensor: the chain named ``solvent_diffusion`` (2.26 µm,
    noise floor 1.49 µm), a drafted slow pole relaxing back completely fitted the records alone
    to 1.50 µm, and the model written kept both."""
    from .candidates import compare_fits, effect_values
    from .confidence import excess_share, label
    fit, was = outcome.final, p.label
    drafts = ", ".join(d.effect_id for d in outcome.kept)
    share = excess_share(without.rmse, fit.rmse, res.noise_floor)
    if p.confidence is not None:
        p.confidence = label(replace(p.confidence, alone_of=drafts, alone=share, why=[]))
    outcome.notes.append(f"without {p.effect} on {WRITTEN}, the drafts alone fit the records within the noise "
                         f"({1e6 * without.rmse:.4g} µm; {1e6 * fit.rmse:.4g} µm with it): it removes "
                         f"{100 * max(share, 0.0):.2g} % of the excess error they leave, confidence {was}"
                         + ("" if p.label == was else f" → {p.label}"))
    cmp = compare_fits(without, fit, True)
    if cmp.delta_bic <= -SIGNIFICANT_BIC:
        return
    outcome.final = without
    for d in outcome.kept:
        d.refit(effect_values(without, d.effect_id))
    text = (f"{p.effect} left out of the model written: without it the kept drafts fit the records within the "
            f"noise ({1e6 * without.rmse:.4g} µm; {1e6 * fit.rmse:.4g} µm with it, ΔBIC {cmp.delta_bic:+.3g} for its "
            "parameters)")
    outcome.notes.append(text)
    say(f"drafts: {text}")


def _left_out_of_written(res, outcome: DraftOutcome) -> None:
    """Each pick of the diagnosis ``res`` that the model written (:attr:`DraftOutcome.final`, better
    than the diagnosis's final model) leaves out says so on its verdict line (:attr:`.verdict.Pick.left_out`)
    and in the notes: the pick competed with the drafts and the model fitted better with them in its
    place, so it may have stood in for a form the catalog lacks.  On a test-bed strip seen through a
    second-order sensor low-pass the verdict named ``electrode_resistance`` (179.8 → 57.7 µm) while the
    model written held a drafted low-pass instead (1.88 µm) and the page said nothing of it.  The label
    stays: a rule making these picks "low" was tried on the recorded chains and did not make the labels
    more reliable on a held-out family (there the picks left out were right ones: a catalog saturation
    of the charge beside a drafted saturation of the drive).

    Where none of the kept drafts' forms is one the pick's physics makes (its spec's ``shows_as``),
    the pick is not named (:attr:`.verdict.Pick.stood_in`): the verdict says no catalog effect
    explains the records and lists the pick as a stand-in.  Chosen on ``pnp_fd`` and ``pnp_sweep``
    seed 63 (a sensor's low-pass or dead time named ``electrode_resistance``, left out for a drafted
    low-pass or delay); held out on ``circuit_lab`` seed 62, where it withdrew a creep's
    ``fractional_coupling`` and kept both saturating charges left out for a drafted saturation of
    the drive, which ``nonlinear_charge`` makes."""
    from .specs import shown_as
    fit = outcome.final
    if not outcome.kept or fit is None or fit.rmse >= res.final.rmse:
        return
    # what the written model adds to the user's: an own effect the support test removed and the
    # rounds restored is not what the pick stood in for
    added = [e for e in fit.effects if e not in res.final.effects and e not in res.base.effects]
    drafts = [d for d in outcome.kept if d.effect_id in fit.effects]
    for p in res.verdict.picks:
        if p.effect in fit.effects:
            continue
        p.left_out = (f"[{', '.join(fit.effects)}] fits the records better without it ({1e6 * fit.rmse:.4g} µm "
                      f"against {1e6 * res.final.rmse:.4g} µm with it), so {p.effect} may have stood in for "
                      f"{' and '.join(added) or 'what the drafts model'}")
        outcome.notes.append(f"{p.effect} (the diagnosis's pick) is left out of the model written: {p.left_out}")
        if added and not any(p.effect in shown_as(d.form) for d in drafts):
            p.stood_in = " and ".join(added)
            outcome.notes.append(f"{p.effect} is not named: the drafts' forms are none its physics makes")
    picks = res.verdict.picks        # none named but stand-ins (and own effects taken back, :attr:`.verdict.Pick.own`)
    if any(p.stood_in for p in picks) and all(p.stood_in or p.own for p in picks):
        res.verdict.status = "not explained by the catalog"


def _name_counterparts(res, outcome: DraftOutcome, rediagnose, free: list, say) -> None:
    """Each kept draft whose form a catalog effect's physics produces (its spec's ``shows_as``,
    :func:`.specs.shown_as`),
    named by that effect when it is picked in the draft's place: a forward step on the model written
    (:attr:`DraftOutcome.final`) less the draft, the counterpart its one candidate.  The pick joins the
    verdict's chain, labelled as the step labels it with the draft as its closest rival
    (:class:`.confidence.Confidence` ``in_place``: the share of the excess error the draft leaves that
    it removes), and left out of the model written, which keeps the draft.  The drafts describe a
    form, the catalog names physics: on a held-out strip seen through a sensor low-pass whose double
    layer saturates (``pnp_fd`` seed 36) the rounds kept a drafted low-pass and a drafted soft
    saturation of the drive (1.52 µm, noise floor 1.50 µm) while the verdict named only the
    electrode's resistance, left out of that model; ``nonlinear_charge`` in the saturation's place
    gives 5.24 µm.  Not tried when the verdict names the effect already."""
    from .candidates import map_free
    from .confidence import excess_share, label
    from .specs import shown_as
    fit = outcome.final
    if not outcome.kept or fit is None or fit.rmse >= res.final.rmse:
        return
    for d in outcome.kept:
        for eid in shown_as(d.form):
            if d.effect_id not in fit.effects or eid in fit.effects or any(p.effect == eid for p in res.verdict.picks):
                continue
            keep = [e for e in fit.effects if e != d.effect_id]
            say(f"drafts: {eid} fitted in place of {d.effect_id} (the catalog's physics of its form)")
            try:
                again = rediagnose(fit.device, keep, map_free(free, list(fit.effects), keep), [eid])
            except (InputError, ModelError) as exc:
                outcome.notes.append(f"{eid} was not fitted in place of {d.effect_id} ({exc})")
                continue
            q = next(iter(again.verdict.picks), None)
            if q is None or q.effect != eid or q.confidence is None:
                outcome.notes.append(f"{eid} fitted in place of {d.effect_id} is not picked "
                                     f"({again.verdict.status}): {d.effect_id} is not named by the catalog")
                continue
            share = excess_share(fit.rmse, q.rmse_after, res.noise_floor)
            q.confidence = label(replace(q.confidence, in_place_of=d.effect_id, in_place=share, why=[]))
            q.step, q.on = max((p.step for p in res.verdict.picks), default=0) + 1, f"the model written less {d.effect_id}"
            q.left_out = (f"in place of {d.effect_id} it fits the records to {1e6 * q.rmse_after:.4g} µm, the draft to "
                          f"{1e6 * fit.rmse:.4g} µm: {eid} names the physics of the drafted form, and the model "
                          "written keeps the draft")
            q.own = any(r["effect"] == eid for r in res.verdict.removed)     # your model's, taken back refitted
            res.verdict.picks.append(q)
            if res.verdict.status == "not explained by the catalog" and not q.own:
                res.verdict.status = "partly explained"
            outcome.notes.append(f"{eid} named for {d.effect_id}: in its place it lowers the RMS error "
                                 f"{1e6 * q.rmse_before:.4g} → {1e6 * q.rmse_after:.4g} µm (the draft: "
                                 f"{1e6 * fit.rmse:.4g} µm), confidence {q.label}")
            say(f"drafts: {eid} named for {d.effect_id}: confidence {q.label}")


def _polish(res, outcome: DraftOutcome, say) -> None:
    """The model written (:attr:`DraftOutcome.final`) refined on the time records with every free
    parameter at once, the kept drafts' among them (:func:`.candidates.polish_on_time`), when that
    lowers its error: the rounds fit a draft's parameters with the rest held and then the rest with
    the draft's held, and a play and the gain it hides end apart from their joint optimum.  After
    the rounds' comparisons, which were made on equal terms; their notes keep the errors they
    compared."""
    from .candidates import polish_on_time
    fit = outcome.final
    if fit is None or not getattr(getattr(fit, "model", None), "is_linear", False):
        return
    say(f"drafts: the model written, [{', '.join(fit.effects)}], refined on the time records with every free "
        "parameter at once")
    better = polish_on_time(fit, res.records)
    if better is not None:
        _carry(outcome, better, f"the model written refined on the time records with every free parameter at once "
                                f"(the drafts' too): RMS error {1e6 * fit.rmse:.4g} → {1e6 * better.rmse:.4g} µm")


def _remaining_drafted(res, outcome: DraftOutcome) -> None:
    """Where the verdict found no residual form describing what its final model leaves
    (:meth:`.verdict.Verdict._remaining_text`, "base mismatch") and the draft rounds kept a draft
    that lowers the error, the verdict's "What remains" says what they found
    (:attr:`.verdict.Verdict.drafted_remaining`) instead of calling the rest a mismatch of the base.
    The forms are fitted to the final model's residual, the drafts with the model: behind a
    large-signal pick the forms of a map of the drive are not fitted at all (they need the linear
    model's response), and a circuit_lab strip whose drive saturates read "an unstructured mismatch
    of the model's own base forms" at 22.95 µm while its drafted saturation of the drive, fitted
    with the model, reached 3.064 µm (2.29 µm noise floor) on the same page."""
    fit = outcome.final
    if not outcome.kept or fit is None or fit.rmse >= res.final.rmse or res.verdict.remaining_kind != "base mismatch":
        return
    res.verdict.drafted_remaining = (f"[{', '.join(fit.effects)}] fits the records to {1e6 * fit.rmse:.4g} µm "
                                     f"against {1e6 * res.final.rmse:.4g} µm, with "
                                     + " and ".join(d.effect_id for d in outcome.kept))


def _strip_other_drafts(fit, items: list, kept: list[str]) -> None:
    """Take the parameters of drafts not in ``kept`` out of ``fit``'s device (in place): a fit taken
    from a swap is the model without the draft it replaced, whose parameters stay in its device at
    their off values, and a draft not kept is unregistered after the rounds, so the device written
    could not name them.  A name a kept draft shares stays (the two orders of a low-pass share their
    time constant: taken out, a kept second-order low-pass lost its fitted τ, and the next round
    refitted the model from the draft's default, 12.08 → 33.3 µm on pnp_sweep seed 70's test strip)."""
    params = getattr(fit.device, "params", None) or {}
    drafted = [d for d in items if isinstance(d, EffectDraft)]
    stray = ({p.name for d in drafted if d.effect_id not in kept for p in d.params}
             - {p.name for d in drafted if d.effect_id in kept for p in d.params}) & set(params)
    if not stray:
        return
    dev = replace(fit.device, params={k: v for k, v in fit.device.params.items() if k not in stray})
    fit.device = fit.result.device = dev
    fit.values = {k: v for k, v in fit.values.items() if k not in stray}


def _drop_siblings(outcome: DraftOutcome, pool: list, kept) -> None:
    """Take the other versions of the kept draft's residual form (a low-pass of the other order)
    out of ``pool``: they were offered because the residual could not choose, and the fit with
    the model chose ``kept``."""
    for d in [d for d in pool if d.form == kept.form]:
        pool.remove(d)
        outcome.rejected.append((d, f"not tried on top of {kept.effect_id}: another version of the same residual "
                                    f"form ({d.form}), and the fit with the model chose {kept.effect_id}"))


def _hold_maps_of_the_drive(outcome: DraftOutcome, pool: list, eid: str) -> None:
    """Take the drafts that map the drive (:attr:`.forms.base.Form.needs_response`) out of
    ``pool`` once ``eid`` made the model large-signal: each evaluation of their threshold would
    simulate every record through it with the implicit stepper (a held-out saturating strip ran
    past 40 minutes so), and their form was read through a linear model's response."""
    for d in [d for d in pool if form_of(d.form).needs_response]:
        pool.remove(d)
        outcome.rejected.append((d, f"not tried on top of {eid}: the model is large-signal, and fitting a map of "
                                    "the drive there simulates every record at each evaluation"))


def _went_further(outcome: DraftOutcome, base, round_no: int) -> None:
    """The model the round before kept, refined further on the time records as round
    ``round_no``'s base (``base``, a ModelFit), replaces it: the chain's last error, the best model
    and the kept drafts' values become that base's."""
    _carry(outcome, base, f"round {round_no} refined the model the round before kept on the time records: "
                          f"RMS error {1e6 * outcome.chain[-1][1]:.4g} → {1e6 * base.rmse:.4g} µm")


def _refined_further(outcome: DraftOutcome, base, fit) -> None:
    """Round 1's base ``base`` (a ModelFit), when it is the diagnosis's final model ``fit`` refined
    further on the time records and fits better, becomes :attr:`DraftOutcome.final` until a round
    takes an effect.  A held-out strip with rough electrodes: the diagnosis's model 8.16 µm, round
    1's refinement of it 7.98 µm, no draft kept, and 8.16 µm was written."""
    if getattr(base, "time_refined", False) and tuple(base.effects) == tuple(fit.effects) and base.rmse < fit.rmse:
        outcome.final = base
        outcome.notes.append(f"round 1 refined the diagnosis's model on the time records: RMS error "
                             f"{1e6 * fit.rmse:.4g} → {1e6 * base.rmse:.4g} µm")


def _carry(outcome: DraftOutcome, fit, note: str) -> None:
    """``fit`` (a ModelFit of the chain's last model, fitted further) replaces it: the chain's last
    error, the best model and the kept drafts' values become its own, and ``note`` says why."""
    from .candidates import effect_values
    eid, _ = outcome.chain[-1]
    outcome.chain[-1] = (eid, fit.rmse)
    outcome.final = fit
    for d in outcome.kept:
        d.refit(effect_values(fit, d.effect_id))
    outcome.notes.append(note)


def _round_fits(again) -> dict:
    """{effect: candidate} of a round's diagnosis ``again``: its first step's, or — where it swapped
    its first pick for the runner-up, which fits better in its place — the runner-up as fitted
    there, on the same model.  The first step refines its pick alone on the time records, so its
    runner-up's error is the frequency fit's: on `pnp_sweep` seed 41's backlash, with a trial second
    law for the play beside it, the trial law read 3.65 µm (the pick, refined) and the play 6.17 µm,
    the swap refined the play to 1.95 µm, and the round took the trial law."""
    by_id = {c.effect: c for c in again.candidates}
    steps = list(getattr(again, "steps", []))
    for s, nxt in zip(steps, steps[1:]):
        c = nxt.decision.pick
        if not s.swapped_for or c is None or c.effect != s.swapped_for or not c.evaluated \
                or set(nxt.base.effects) != set(again.base.effects):
            continue
        old = by_id.get(c.effect)
        if old is None or not old.evaluated or c.fit.rmse < old.fit.rmse:
            by_id[c.effect] = c
    return by_id


def _scored(keys, again, on_top, before: float | None = None) -> tuple[list, dict]:
    """The candidates ``keys`` (drafts, or catalog effect ids) of the diagnosis ``again`` that
    pass ΔBIC ≤ −:data:`.forms.SIGNIFICANT_BIC` and ≥ :data:`.forms.MIN_GAIN` lower RMS error,
    as (ΔBIC, key, candidate) sorted by ΔBIC, and {effect id: why not} for the others.  The error
    to lower is that of the round's refitted base, or ``before`` [m] when lower: the model the
    previous round kept (refitted without a time refinement of its own, the base can lose what
    that round gained, and a draft must never leave the chain worse than it was)."""
    by_id = _round_fits(again)
    ref = min(again.base.rmse, before) if before is not None else again.base.rmse
    scored, why = [], {}
    for key in keys:
        eid = key if isinstance(key, str) else key.effect_id
        c = by_id.get(eid)
        if c is None or not c.evaluated:
            why[eid] = c.reason if c is not None else "not evaluated"
            continue
        gain = 1.0 - c.fit.rmse / ref if ref > 0 else 0.0
        dbic = c.comparison.delta_bic
        if dbic <= -SIGNIFICANT_BIC and gain >= MIN_GAIN:
            scored.append((dbic, key, c))
        else:
            a, b = f"{1e6 * ref:.4g}", f"{1e6 * c.fit.rmse:.4g}"
            if a == b:          # equal as printed: neither "lowers" nor "raises" reads true
                of = "" if ref == again.base.rmse else ", that of the model the previous round kept"
                why[eid] = f"fitted with [{', '.join(on_top)}] it leaves the RMS error at {a} µm{of} (ΔBIC {dbic:.3g})"
                continue
            how = "lowers the RMS error only" if c.fit.rmse <= ref else "raises the RMS error"
            of = "" if ref == again.base.rmse else " (the model the previous round kept)"
            why[eid] = f"fitted with [{', '.join(on_top)}] it {how} from {a}{of} to {b} µm (ΔBIC {dbic:.3g})"
    scored.sort(key=lambda x: x[0])
    return scored, why


def _pick_text(scored, again, on_top) -> str:
    """What the best of ``scored`` does, and the rivals that fit almost as well."""
    dbic, _, c = scored[0]
    text = (f"fitted with [{', '.join(on_top)}] it lowers the RMS error from {1e6 * again.base.rmse:.4g} "
            f"to {1e6 * c.fit.rmse:.4g} µm (ΔBIC {dbic:.4g})")
    rivals = [(b, k) for b, k, _ in scored[1:] if b - dbic < SIGNIFICANT_BIC]
    if rivals:
        text += "; " + ", ".join(f"{k if isinstance(k, str) else k.effect_id} (ΔBIC {b:.4g})"
                                 for b, k in rivals) + " fits almost as well: these records hardly tell them apart"
    return text


@single_threaded
def check_draft(path: Path) -> list[str]:
    """The contract (:func:`physics.effects.check_effect`) run on a written draft; [] when it passes."""
    from ..effects import check_effect, effect_classes_in_file
    classes = effect_classes_in_file(path)
    problems = []
    for cls in classes:
        report = check_effect(cls)
        if not report.ok:
            problems.append(f"{path.name}: {report}")
    return problems


def write_drafts(items: Sequence[EffectDraft], out, *, overwrite: bool = False, inputs: Sequence = ()) -> dict:
    """Write ``items`` into the new folder ``out`` (atomic; refused over a folder eap did not
    write) with ``README.txt``; each file is checked first.  Returns {file: problems}."""
    from ..io.outputs import component, output_folder
    out = Path(out)
    for d in items:
        component(d.file_name, "--draft-effects", "a drafted effect file")
    report = {}
    with output_folder(out, inputs=inputs, overwrite=overwrite, flag="--draft-effects") as tmp:
        lines = []
        for d in items:
            path = tmp / d.file_name
            path.write_text(d.source(), encoding="utf-8")
            problems = check_draft(path)
            report[d.file_name] = problems
            lines.append(f"{d.file_name}: {d.summary}; contract check "
                         + ("passed" if not problems else "FAILED: " + "; ".join(problems)))
        (tmp / "README.txt").write_text(
            "Effect files drafted by eap diagnose --draft-effects from what remained after the best model.\n"
            "Pass one back with --effects-path FILE.py to test it as a candidate.\n\n" + "\n".join(lines) + "\n",
            encoding="utf-8")
    return report


__all__ = ["DRAFT_KEEP_STARTS", "DraftOutcome", "drafts", "draft_effects", "rediagnosis", "write_drafts", "check_draft"]
