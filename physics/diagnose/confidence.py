"""How sure a pick is: the confidence label, from what generalises rather than from record length.

A Schwarz weight (:mod:`.verdict`) grows with the effective sample size: over tens of
thousands of correlated samples every ΔBIC is in the thousands and every weight is 1.000,
whether the pick is the missing physics or a flexible effect that trims a structured misfit
a little.  The label therefore asks what a weight cannot:

* **change** — the error the pick removes, sqrt(rmse_base² − rmse_pick²), in noise floors: an
  effect that barely changes the model in the excited band (a fractional exponent of 0.01,
  a stiffness law re-scaled by a percent) explains nothing a re-tuned base could not;
* **left** — the error the pick leaves, in noise floors: a pick that leaves a large
  structured residual may stand in for physics the catalog lacks (a proxy), and says so;
* **twin** — the share of the excess error power (over the noise floor) that the closest
  rival leaves and the pick removes: a rival that fits nearly as well is a near twin, and
  quality flags do not separate near twins (they are "ambiguous", :func:`.verdict.decide`);
* **records** — the share of records on which the pick lowers the error: fitted on all
  records, a pick that makes some of them worse does not generalise from record to record
  (a leave-one-record-out test at the cost of none);
* **flags** — the quality flags of the fit that question whether the effect is there
  (:func:`.verdict.doubts`: a correlation between two of the pick's own parameters says which of
  its values are determined, not whether it is needed, and is not counted; nor is one with a
  parameter of the rest of the model once the pick's **change** reaches :data:`CHANGE_HIGH`, see
  **undetermined**);
* **pinned** — the pick's own parameters that ended on a bound of their range and are not
  determined (:func:`.verdict.pinned`): the data chose a limit of the effect, not a value, so
  what the fit gained may come from the limit standing in for something else;
* **undetermined** — the pick's own parameters that ended inside their range but are not
  determined (:func:`.verdict.undetermined`): the records do not say how much of the effect there
  is (a creep on the output read as ``layered_beam``: its electrode modulus at 675 % relative
  standard error, correlated −0.998 with the polymer's modulus, which the model already has) —
  all of them when each is correlated beyond |ρ| = 0.99 with a parameter of the rest of the model,
  which can then trade for the whole effect.  A correlation is local: it says the rest can move
  along with a small change of the pick.  Once removing the pick costs at least :data:`CHANGE_HIGH`
  noise floors (**change**) the rest, refitted without it, has shown it cannot stand in for it,
  and the parameters' relative standard errors already carry the trade: such a correlation is
  then neither a flag nor makes a parameter undetermined (still named in the verdict's caution
  line).  On ``circuit_lab`` seed 62's resistive electrodes the pick removed 34 noise floors, its
  resistance ± 0.13 %, and was "low" for a 0.995 correlation with the coupling fitted per RH level;
  the one-relaxation strip's ``layered_beam`` (1.7 noise floors) stays "low";
* **held** — the share of the excess error left by a rival whose own parameter ended on a bound
  of its range (:func:`.verdict.held`) that the pick removes: such a rival's error is what its
  range allowed, an upper bound of what the effect can reach.  It needs the same share as
  **twin** (a held rival once needed more than a free one; since a free rival of another form
  came as close on a held-out strip, every rival needs it) and is named in the reasons.

When the chain refits the model's own effects after a pick (:func:`.diagnosis.select`), a pick
that stays is labelled again with **change**, **left**, **flags**, **pinned** and **undetermined** measured on the
refitted model (:func:`reconfirmed`): before the refit a right pick can leave a large residual, or
a parameter on a bound, only because the device's values of the model's own effects are not the strip's.
When the draft rounds keep a drafted form beside a pick, the pick is labelled again on the model
written (:func:`.draft._relabel_on_written`: a forward step there, its step's rivals fitted again):
a form the catalog lacks beside a right pick is a residual the pick leaves, not one it stands in for,
so that label replaces the pick's only when it is not lower.

* **ahead of** — a pick the chain took only with a second effect on top of it (the look-ahead
  of :func:`.diagnosis.select`): alone it explains too little of the failure, so it is never "high".
* **in place** — a pick named for a kept draft (:func:`.draft._name_counterparts`): the catalog
  effect whose physics shows as the drafted form, fitted in the draft's place on the model written;
  the share of the excess error the draft leaves that it removes needs what **twin** needs (below
  a third: "low"), since the draft is the closest rival it has.
* **chain left** — the error the chain's final model leaves, in noise floors (:func:`at_chain_end`):
  a chain that ends far from the noise with this pick in it explains a part of the failure, and
  what the pick removed may be the share of physics the catalog lacks that its form happens to
  follow (a second-order sensor low-pass read as ``electrode_resistance``, which removed 80 % of
  the excess and left 23-51 noise floors).  Beyond :data:`LEFT_LOW` the pick is "low".

"high" needs all of them (and a weight ≥ :data:`WEIGHT_HIGH`), "low" is a pick that barely
changes the model, has a near twin, is pinned or undetermined, or sits in a chain that ends far
from the noise; everything else is "medium".  The thresholds were chosen on some truth families
and are reported on others (leave-one-family-out, ``bench/diagnose_calibration.py``;
``docs/reference/diagnosis.md`` states what each label has meant on held-out physics).  Without a noise floor no pick is "high".
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

#: Weight a "high" pick needs at least (Schwarz, among the step's base and candidates).
WEIGHT_HIGH = 0.99
#: "high" needs the pick to remove at least this error [noise floors] ...
CHANGE_HIGH = 3.0
#: ... below which the pick barely changes the model ("low").
CHANGE_LOW = 1.5
#: "high" needs the pick to leave at most this error [noise floors]; beyond: a possible proxy.
LEFT_HIGH = 2.0
#: "high" needs the pick to remove at least this share of the excess error its closest rival leaves
#: (0.6 until 2026-12-02, when a rival held on a bound needed 0.95 — chosen on circuit_lab seeds 0-1
#: and pnp_fd seeds 0-4, where the right "high" picks removed ≥ 0.99 of their held rivals' excess and
#: the wrong one 0.85 of a viscoelastic slope held at 0.6; raised to 0.95 for every rival on pnp_fd
#: seed 20, where fractional_coupling was "high" and wrong for a Cole-Cole modulus, removing 0.73 of
#: a free viscoelastic's excess, while the right "high" picks removed ≥ 0.999 of their closest
#: rival's; reported on circuit_lab seed 20).
TWIN_HIGH = 0.95
#: A rival whose excess error the pick reduces by less than this share is a near twin ("low" at best).
TWIN_LOW = 1.0 / 3.0
#: "high" needs the pick to lower the error on at least this share of the records ...
RECORDS_HIGH = 1.0
#: ... where "lower" allows this relative tolerance (a record the pick leaves as it was).
RECORD_TOLERANCE = 0.02
#: A pick in a chain whose final model leaves more than this error [noise floors] is "low" (module
#: doc, **chain left**; chosen with ``bench/diagnose_calibration.py``, whose fold that holds out
#: circuit_lab chose it on pnp_fd seeds 31-32: the value of its grid that turns the most wrong picks
#: "low" less right or acceptable ones, ties to the largest; there four wrong and one near twin's
#: relative).
LEFT_LOW = 20.0
LABELS = ("high", "medium", "low")


def _table(family: str, seeds: str, cases: int, code: str, caveat: str, rule: str | None = None,
           before_low_rules: bool = False, **counts: tuple[int, int, int]) -> dict:
    """One table of :data:`CALIBRATION`: the draws it was measured on, the command that measures it
    again, and per label (right, acceptable, wrong) → those and ``n``, the picks; ``rule``: the
    earlier rule it was measured under (None: the rules in force); ``before_low_rules``: labelled
    before the two "low" rules of 2026-12-05 (**chain left**, **undetermined**) and not read again
    since (its caches are gone), said in the caveat."""
    if before_low_rules:
        caveat += (f"; labelled before a pick in a chain ending beyond {LEFT_LOW:g} noise floors, or with an own "
                   "parameter not determined inside its range, was made \"low\" (which can only turn a \"medium\" "
                   "into a \"low\")")
    out = {"family": family, "cases": cases, "code": code, "seeds": seeds, "caveat": caveat,
           "command": f"python bench/diagnose_lofo.py --families {family} --seeds {seeds.replace(' ', '')} "
                      f"--held-out {family}",
           "labels": {lab: {"n": sum(c), "right": c[0], "acceptable": c[1], "wrong": c[2]}
                      for lab, c in counts.items()}}
    return {**out, "rule": rule} if rule else out


#: What each label has meant on truth families held out of the choice of the thresholds
#: (``bench/diagnose_lofo.py`` then ``bench/diagnose_calibration.py``): per label, the picks and
#: how many named the hidden effect (right), a near twin's relative (acceptable) or another
#: (wrong), given as ``_table(…, high=(right, acceptable, wrong), …)``.  Measured, not assumed;
#: :func:`calibration_text` says it in one sentence.  The first table is the newest fresh draw (seed 94, run at
#: f77d8a0 with every rule in force), the second the one before (seed 91, run at b764382 and again at 428432c).  Of
#: the others, counted from there: the first is a fresh draw run with every rule in force (f0d205b).  The second holds out the rule on stand-ins (a pick left out
#: of the model written for drafts its physics does not make is not named), chosen on the next two, whose labels and
#: the fourth's are read again under it; the second to fifth were measured with the rules in force
#: (the third and fourth at 4a46930, their labels read again from the recorded features under the rule that a correlation
#: with the rest of the model does not question a pick that removes 3 noise floors or more, chosen on the fifth's
#: electrode strip; the fifth as its caveat says); the next four before a lone pick's runner-up was judged in the
#: swap as on the step it lost (7de33c7: it acts only on a
#: chain of one pick outside the noise whose runner-up carries a quality flag; not run on those draws again but the
#: strip it was chosen on); the next three before the look-ahead (add9387: it acts only where no candidate passes alone and a pair removes
#: 90 % of the excess; not run on those draws again), the others before later rules (their caveats say so);
#: ``rule`` marks the tables measured under an earlier rule (kept: more cases, and that rule's change can only turn
#: a "high" into a "medium").
CALIBRATION = (
    _table("circuit_lab", "94", 6, "f77d8a0",
           "seed 94, a fresh draw, its six in-catalog effects, run at f77d8a0 with every rule in force (no rule chosen "
           "on it): all six named right; within 1.5× the true model's error 4 of 6 after the chain (the rough "
           "electrode 7.32×, the saturation 11.6×; for the models written 7.27× and 1.04×), 4 of 6 \"high\" (the "
           "rough electrode and the saturation \"medium\": each leaves a structured residual)",
           high=(4, 0, 0), medium=(2, 0, 0), low=(0, 0, 0)),
    _table("circuit_lab", "91", 6, "b764382, 428432c",
           "seed 91, a fresh draw, its six in-catalog effects, run at b764382 with every rule in force (no rule chosen "
           "on it) and again at 428432c, whose change of the residual forms of the drive (one linear gain per RH level) "
           "was chosen on its saturating strip: all six named right, the labels the same at both; within 1.5× the true "
           "model's error 4 of 6 after the chain (the rough electrode 3.39×, the saturation 5.86×; for the models "
           "written 1.17× and 4.85× at b764382, 1.22× at 428432c), 3 of 6 \"high\" (the other three \"medium\": the "
           "rough electrode and the saturation leave a structured residual, the fractional coupling comes within 73 % "
           "of the relaxing modulus)",
           high=(3, 0, 0), medium=(3, 0, 0), low=(0, 0, 0)),
    _table("circuit_lab", "66", 6, "f0d205b",
           "seed 66, a fresh draw, its six in-catalog effects, run at f0d205b with every rule in force (no rule chosen "
           "on it): all six named right; within 1.5× the true model's error 4 of 6 after the chain (the rough electrode "
           "3.84×, the saturation 10.1×; 2.41× and 1.18× for the models written), 3 of 6 \"high\" (the other three "
           "\"medium\": the rough electrode and the saturation leave a structured residual, the relaxing modulus removes "
           "79 % of the excess error the fractional coupling leaves)",
           high=(3, 0, 0), medium=(3, 0, 0), low=(0, 0, 0)),
    _table("circuit_lab", "64, 65", 10, "d091d56, 65c0510",
           "seeds 64 and 65, fresh draws, 10 strips chosen where the rule that a pick left out of the model written "
           "for drafts its physics does not make is not named can act (seed 64: the sensor low-pass, the dead time, "
           "the saturation, creep, the contact twin, the low-pass + saturation pair, run at d091d56 before the rule and "
           "read again under it, its creep run again at 65c0510; seed 65: the sensor low-pass, the dead time, creep, "
           "the contact twin, run at 65c0510), held out of that rule: it withdrew the three wrong picks of the two "
           "creeps (the layered beam \"low\" on both, the fractional coupling \"medium\" on seed 64; the models "
           "written, a drafted slow pole, 1.01× and 1.03× the true model's error) and kept named both saturating "
           "charges left out beside a drafted saturation of the drive (right); the saturation 6.18× the true "
           "model's error after the chain, 1.02× for the model written",
           high=(0, 2, 0), medium=(1, 0, 0), low=(1, 0, 0)),
    _table("pnp_fd", "63", 16, "4a46930",
           "seed 63, a fresh draw, 16 of its 26 truths (the six in-catalog effects, nothing hidden, creep, the sensor "
           "low-pass, drift, the logger's dead time, two twins, three pairs), run at 4a46930, every issue-34 target line "
           "PASS as run; its labels read again from the recorded features under the rule that a correlation with the "
           "rest of the model does not question a pick removing 3 noise floors or more: one changed, the relaxing "
           "modulus of the modulus + RH pair, right, \"medium\" → \"high\" (in-catalog \"high\" 4 of 6 either way); and "
           "under the rule that a pick left out of the model written for drafts its physics does not make is not named "
           "(chosen on this draw): four picks withdrawn, the electrode's resistance \"low\" for the sensor low-pass and "
           "\"medium\" for the dead time (wrong), \"medium\" for the contact twin and the solvent line \"medium\" for the "
           "relaxation twin (a twin's relative); the one wrong pick left: the solvent line \"low\" for the drift",
           high=(6, 0, 0), medium=(6, 0, 0), low=(0, 0, 1)),
    _table("pnp_sweep", "63", 13, "4a46930",
           "seed 63, a fresh draw, 13 of its truths (nothing hidden, the five in-catalog effects its one RH level can "
           "show, creep, the sensor low-pass, the contact twin, drift, the dead time, two pairs), run at 4a46930; the "
           "rule on correlations with the rest of the model changes none of its labels; in-catalog 4 of 5 within 1.5× "
           "(the saturation 3.29×, 1.26× for the model written), 3 of 5 \"high\"; the rule that a pick left out of the "
           "model written for drafts its physics does not make is not named (chosen on this draw) withdrew the two wrong "
           "\"low\", the electrode's resistance for the sensor low-pass and for the dead time, and its \"medium\" for "
           "the contact twin (a twin's relative)",
           high=(5, 0, 0), medium=(4, 0, 0), low=(0, 0, 0)),
    _table("circuit_lab", "62", 24, "7de33c7, 4a46930",
           "seed 62, a fresh draw, 24 of its 26 truths (the two relaxation twins not run), 14 at 7de33c7 and 10 at "
           "1d98382 and 4a46930 (the same diagnosis), with the rules in force but the one on correlations with the rest "
           "of the model, which was chosen on its electrode strip: run again at 4a46930 and read under that rule it is "
           "\"high\" (\"low\" before); the other picks labelled again on a refitted model were recorded without their "
           "flags there, so that rule, which only ever raises a label, could raise a \"low\" of theirs to \"medium\", "
           "none to \"high\" (each has another reason); the wrong \"medium\": the fractional coupling for the relaxing "
           "modulus (the relaxing modulus taken back for the AC-coupled sensor, wrong \"medium\" as run, is not named "
           "under the rule that an effect of the user's model the support test removed and a later step took back "
           "refitted is not the missing one, chosen on that strip and run again there at f0d205b; held out on seeds 66 and 67's AC-coupled strips: "
           "seed 67's taken-back relaxing modulus, \"medium\", not named as run at f0d205b, seed 66's pick already a "
           "stand-in); the wrong \"low\": the fractional coupling for the "
           "creep, the layered beam (ambiguous) on the route strip; in-catalog 3 of 6 within 1.5× the true model's "
           "error after the chain (4 of 6 for the model written), 3 of 6 right picks \"high\"; held out of the rule "
           "that a pick left out of the model written for drafts its physics does not make is not named, read again "
           "under it: the fractional coupling for the creep withdrawn (wrong \"low\"), the two saturating charges "
           "left out beside a drafted saturation of the drive still named (right)",
           high=(9, 0, 0), medium=(5, 1, 1), low=(2, 0, 1)),
    _table("pnp_fd", "60", 26, "058871b, a253b84",
           "seed 60, a fresh draw, all 26 of its truths, measured at 058871b with the rules in force; the two changes "
           "since (the drafts' frequency-domain filter continued past a record's end, 9f37e2d; the swap of a lone "
           "pick looking ahead with its runner-up, a253b84) run again on all 26 at a253b84: unchanged but the rough "
           "electrode + solvent pair, on which the look-ahead was chosen (the relaxing modulus \"low\", wrong, at 58.6× "
           "the true model's error → the fractional coupling \"medium\" and the solvent line \"high\", 1.00×); "
           "the four wrong \"low\" picks: the electrode's resistance for the sensor low-pass (alone and beside the "
           "saturation) and for the logger's dead time, the solvent line for the AC-coupled sensor",
           high=(7, 0, 0), medium=(9, 3, 0), low=(1, 1, 4)),
    _table("pnp_sweep", "41", 23, "36c7b92, de21935, b6b394d, 51fd590, 5db2cb6, 633290b",
           "seed 41, the first draw of pnp_fd's physics recorded as two records (a sweep and a square pulse train at "
           "one RH), all 23 of its truths (the AC-coupled sensor and the mains hum added on 2026-12-06's second "
           "session, run at 633290b: the solvent line \"low\", wrong, for the AC coupling, \"medium\" before the pick "
           "was labelled against the drafts alone; nothing named for the hum) (the dead time of the deflection channel added on 2026-12-06 and run with "
           "the delay form in, 5db2cb6: the electrode's resistance \"medium\", wrong, left out of the model written, "
           "which keeps a drafted delay at 1.63× the true model's error; 19 others run again there: unchanged, the "
           "saturation + solvent pair not); three rules were chosen on it (a pick's shape refined once picked, on its "
           "solvent strip; the swap of a lone pick, on its rough electrode + solvent strip; every own parameter traded "
           "with the rest of the model counted undetermined, on its one-relaxation strip) and those three strips, five "
           "more where the swap could act and the saturation + solvent pair were run again (at de21935 and b6b394d; the "
           "one-relaxation strip and the pair at 51fd590; the six others unchanged: the pair's solvent line named, its saturation drafted, 1.45× the true "
           "model's error) (the three wrong \"low\": the layered beam second for the one-relaxation polymer, the sensor "
           "low-pass read as the electrode's resistance, alone and beside the saturation)",
           high=(6, 1, 0), medium=(6, 2, 1), low=(0, 0, 4)),
    _table("circuit_lab", "41", 17, "387863f, 5db2cb6, 633290b",
           "seed 41, a fresh draw, 17 of its 26 truths (the six in-catalog effects, the six pairs, nothing hidden, the "
           "partial relaxation; the AC-coupled sensor and the mains hum, added on 2026-12-06's second session and run "
           "at 633290b: the relaxing modulus \"medium\", wrong, for the AC coupling, as at 95db55d; nothing named for "
           "the hum; the dead time of the deflection channel, added on 2026-12-06 and run with the delay "
           "form in, 5db2cb6: nothing named, the model written keeps a drafted delay at 1.01× the true model's error), measured at the start of 2026-12-05's eighth session, before the two rules chosen on "
           "pnp_sweep seed 41 (a pick's shape refined once picked, the swap of a lone pick); its rough electrode, rough "
           "electrode + solvent, partial relaxation, saturation + solvent and electrode + solvent strips (where they "
           "could act) and its electrode + modulus pair (where a pick has a parameter traded with the rest of the model) "
           "run again at b0c7ee0, 51fd590 and 652dbde: unchanged; no rule was chosen on it (all six pairs had both named; the rough electrode at 2.72× and the "
           "saturation at 9.17× the true model's error after the chain, 2.51× and 1.14× for the best model written)",
           high=(9, 0, 0), medium=(6, 1, 1), low=(2, 0, 0)),
    _table("pnp_fd", "40", 26, "4da3232, b6b394d, 5db2cb6, 633290b",
           "seed 40, a fresh draw, all 26 of its truths, measured with the rules in force; one rule was chosen on it "
           "(the AC-coupled sensor, added on 2026-12-06's second session: the solvent line \"high\", wrong, at 95db55d; "
           "a pick labelled against the kept drafts when they alone fit the records was chosen there, and it reads "
           "\"low\" at 633290b; nothing named for the mains hum, also added then) (the dead time of the deflection channel, added on 2026-12-06, run with the delay form in, 5db2cb6: the "
           "electrode's resistance \"low\", wrong, left out of the model written, which keeps a drafted delay at "
           "1.02× the true model's error; \"medium\" and wrong before the form); "
           "ten strips where the two rules chosen on pnp_sweep seed 41 could act were run again with them (b6b394d): "
           "the rough electrode + solvent pair went from the relaxing modulus \"low\" (wrong) at 59.6× the true "
           "model's error to the fractional coupling and the solvent line, both \"high\", at 1.00×, the nine others unchanged "
           "(the four wrong \"medium\" picks: the sensor low-pass read as the electrode's resistance, alone and beside "
           "the saturation; humidity for the play and for the eigen-moment strips)",
           high=(10, 1, 0), medium=(6, 2, 4), low=(1, 1, 2)),
    _table("circuit_lab", "40", 6, "4da3232",
           "seed 40, a fresh draw, 6 of its 23 truths (a creep, a play, the eigen-moment, humidity, the modulus + "
           "humidity pair, the default route's creep + humidity strip), measured with the rules in force; no rule was "
           "chosen on it (the two wrong \"medium\" picks: the electrode's resistance and the fractional coupling for "
           "the eigen-moment strip; the three wrong \"low\": the layered beam for the creep and for the route strip, "
           "the fractional coupling picked before humidity for the modulus + humidity pair, whose relaxing modulus "
           "was not named)",
           high=(1, 0, 0), medium=(1, 0, 2), low=(0, 0, 3)),
    _table("pnp_fd", "36", 23, "b998019",
           "seed 36, a fresh draw, all 23 of its truths, measured with the rules in force; no rule was chosen on it "
           "(the two wrong \"medium\" picks: the layered beam second for the one-relaxation polymer, the fractional "
           "coupling second for the electrode + modulus pair, the relaxing modulus close behind it)",
           high=(8, 0, 0), medium=(6, 3, 2), low=(1, 1, 2)),
    _table("circuit_lab", "35", 7, "85dfd70, c537ee6, b998019",
           "seed 35, a fresh draw, 7 of its 23 truths (a saturation, the low-pass + saturation and saturation + "
           "solvent pairs, a dead zone, a drift, nothing hidden, the default route's creep + humidity strip), "
           "measured with the rules in force; no rule was chosen on it",
           high=(1, 0, 0), medium=(2, 0, 0), low=(0, 0, 1)),
    _table("pnp_fd", "35", 3, "b998019",
           "seed 35, a fresh draw, 3 of its 23 truths (a saturation, the saturation + solvent pair, the default "
           "route's creep + humidity strip), measured with the rules in force; no rule was chosen on it",
           high=(1, 0, 0), medium=(2, 1, 0), low=(0, 0, 0)),
    _table("pnp_fd", "34", 23, "63b6f82",
           "seed 34, a fresh draw, all 23 of its truths, measured with the rules in force (the undetermined "
           "parameter read from the recorded quality flags: no label changed); no rule was chosen on it",
           high=(8, 0, 0), medium=(7, 3, 0), low=(1, 1, 3)),
    _table("circuit_lab", "34", 7, "e42be4c, ec422eb",
           "seed 34, a fresh draw, 7 of its 23 truths (a creep, a second-order sensor low-pass, a saturation, the "
           "low-pass + saturation, saturation + solvent and electrode + solvent pairs, the default route), measured "
           "with the rules in force; no rule was chosen on it (its saturation strip named nothing, 16× the true "
           "model's error; its best model 1.09× since the draft rounds refine their lead, 85dfd70)",
           high=(2, 0, 0), medium=(2, 0, 0), low=(0, 0, 2)),
    _table("pnp_fd", "33", 7, "9312d44, 63b6f82",
           "seed 33, a fresh draw, 7 of its 23 truths (nothing hidden, a saturation, a dead zone, a creep, a "
           "second-order sensor low-pass, the electrode line, solvent diffusion), measured with the rules in force "
           "(the chain-end rule read on the recorded features, its low-pass strip run again with it); no rule was "
           "chosen on it",
           high=(2, 0, 0), medium=(1, 0, 0), low=(0, 0, 1)),
    _table("circuit_lab", "33", 7, "9312d44",
           "seed 33, a fresh draw, the same 7 truths, measured with the rules in force read on the recorded "
           "features (the chain-end rule changed no label; the undetermined parameter was chosen on its creep "
           "strip: its wrong pick \"medium\" → \"low\")",
           high=(2, 0, 0), medium=(1, 0, 0), low=(0, 0, 1)),
    _table("pnp_fd", "32", 23, "add9387",
           "seed 32, a fresh draw, all 23 of its truths, measured at add9387 and read again on the recorded features "
           "with the chain-end rule, which was chosen on it and seed 31 (two wrong \"medium\" picks and one near "
           "twin's relative turned \"low\"), and the undetermined parameter (no change)",
           high=(10, 0, 0), medium=(5, 3, 0), low=(1, 1, 2)),
    _table("circuit_lab", "32", 19, "add9387",
           "seed 32, a fresh draw, 19 of its 23 truths (nothing hidden, the six in-catalog effects, the five "
           "out-of-catalog forms, the eigen-moment and the six pairs; its low-pass + saturation pair named nothing; "
           "the near twins and the default route not run), measured at add9387 and read again with the chain-end "
           "rule and the undetermined parameter (no label changed); the first rule's fold holding out circuit_lab "
           "chose it without this draw",
           high=(6, 0, 0), medium=(9, 0, 0), low=(0, 0, 4)),
    _table("pnp_fd", "31", 23, "08608d1, add9387",
           "seed 31, a fresh draw, all 23 of its truths, run at 08608d1; the look-ahead was then chosen on its "
           "rough electrode + solvent pair (nothing named before, both since: \"low\" and \"high\"), and the five "
           "strips where it runs were measured again with it (the four others unchanged); read again on the "
           "recorded features with the chain-end rule, chosen on it and seed 32 (two wrong \"medium\" picks "
           "turned \"low\"), and the undetermined parameter (no change)",
           high=(7, 1, 0), medium=(8, 3, 0), low=(1, 0, 2)),
    _table("circuit_lab", "26", 16, "c546702",
           "seed 26, a fresh draw, 16 of its 23 truths (nothing hidden, the six in-catalog effects, the five "
           "out-of-catalog forms, the eigen-moment and the three near twins; its six pairs and the default route "
           "not run), measured with the rules in force; no rule was chosen on it",
           before_low_rules=True, high=(3, 1, 0), medium=(3, 2, 2), low=(0, 0, 0)),
    _table("circuit_lab", "25", 23, "ae78d07, a6ab1f0",
           "seed 25, a fresh draw, all 23 of its truths, measured with the rules in force (the last two chosen on "
           "this family's seeds 23 and 24)",
           before_low_rules=True, high=(6, 1, 0), medium=(10, 2, 3), low=(0, 0, 0)),
    #: seed 24 as run at 945fc60, its relaxing-modulus strip run again at ae78d07 (the relabel on the model
    #: written no longer lowers a label: chosen on that strip, "medium" → "high"; the relabel lowered no other)
    _table("circuit_lab", "24", 14, "945fc60, ae78d07",
           "seed 24, a fresh draw, 14 of its 23 truths (nothing hidden, a drift, a creep, the six in-catalog "
           "effects, two near twins, three pairs), measured with the rules in force (the wander allowed beside a "
           "model capped at what its own residual shows was found on this family's seed 23; the relabel on the "
           "model written that no longer lowers a label was chosen on this seed's relaxing modulus)",
           before_low_rules=True, high=(8, 0, 0), medium=(4, 2, 1), low=(0, 0, 0)),
    #: seed 25 as run at c3579c4 (the 12x analysis rate and the jump placement, found on this seed's nothing-hidden
    #: strip); it replaces the same draw's table at f568218/3ad4d27: high (7, 0, 0), medium (6, 4, 4), low (0, 0, 1).
    #: Still the rules in force: this family's records carry sensor metadata, so no wander is allowed (945fc60 acts
    #: only where the floor is estimated)
    _table("pnp_fd", "25", 23, "c3579c4",
           "seed 25, a fresh draw, all 23 of its truths, measured with the rules in force (the label thresholds "
           "were chosen on other families; the one-design reading of RH dependence and the refinement of a pick's "
           "shape last on this family's seeds 22 and 23; the finer analysis rate and the placing of a step's jump "
           "within its sample were found on this seed's nothing-hidden strip)",
           before_low_rules=True, high=(8, 1, 0), medium=(7, 3, 2), low=(1, 0, 1)),
    #: seed 23: 7 strips run at c3579c4, 16 at 456a561 (the withdrawal of a pick not needed within the floor,
    #: which acted on none of them)
    _table("circuit_lab", "23", 23, "c3579c4, 456a561",
           "seed 23, a fresh draw of a family held out of the choice of the rules then in force, all 23 of its "
           "truths, measured before the wander allowed beside a model was capped at what its own residual shows "
           "(found on this seed; it changes where the chain stops on its strips with slow physics hidden)",
           before_low_rules=True, high=(5, 2, 0), medium=(10, 1, 2), low=(1, 0, 1)),
    _table("pnp_fd", "22, 23", 46, "4fdfcda",
           "seeds 22 and 23, fresh draws of a family held out of the choice of the relabel on the model written (its "
           "other seeds were seen when earlier rules were chosen), all 23 of its truths on each, measured at 4fdfcda, "
           "before the one-design reading of RH dependence and the refinement of a pick's shape last, chosen on them "
           "afterwards, and before the finer analysis rate",
           before_low_rules=True, high=(13, 1, 0), medium=(18, 7, 4), low=(1, 0, 0)),
    #: seed 21 as run at 416e7b9, its six cases with a draft kept beside a pick run again at 4fdfcda
    #: (the relabel on the model written, chosen on them, acts nowhere else)
    _table("circuit_lab", "21", 23, "416e7b9, 4fdfcda",
           "seed 21, a fresh draw of a family held out of the choice of the label thresholds, all 23 of its truths "
           "once, measured at 4fdfcda (before the one-design reading of RH dependence, the refinement of a pick's "
           "shape last and the finer analysis rate); the relabel on the model written was chosen on it",
           before_low_rules=True, high=(6, 1, 0), medium=(9, 2, 2), low=(0, 0, 2)),
    _table("circuit_lab", "6, 7", 25, "409893e, ca35c0a",
           "fresh draws (seeds 6 and 7): every one of its 23 truths at least once", rule="60 %",
           before_low_rules=True, high=(7, 1, 0), medium=(11, 2, 3), low=(1, 0, 2)),
    #: an early copy of pnp_fd was among the families the thresholds were chosen on and its seeds
    #: 0-4 were read while later fixes and rules were chosen; these are fresh draws, seed 5 run at
    #: 6ee2a33 (23 cases) and seed 19 at 6e5b198–b4b63ea (23 cases), pooled
    _table("pnp_fd", "5, 19", 46, "6ee2a33 (seed 5), 6e5b198–b4b63ea (seed 19)",
           "fresh draws (seeds 5 and 19); an early copy of it was seen when the thresholds were chosen", rule="60 %",
           before_low_rules=True, high=(11, 1, 0), medium=(18, 7, 4), low=(2, 0, 1)),
)


@dataclass
class Confidence:
    """The features of one pick (module doc) and the label they give."""

    weight: float
    change: float                  # error removed [noise floors] (NaN: no floor)
    left: float                    # error left [noise floors] (NaN: no floor)
    twin: float                    # share of the closest rival's excess the pick removes (1: no rival)
    twin_of: str | None            # that rival
    records: float                 # share of records on which the error falls
    flags: int                     # quality flags
    pinned: int = 0                # own parameters on a bound and not determined
    held: float = 1.0              # share of the excess a rival held on a bound leaves that the pick removes
    held_of: str | None = None     # that rival (None: no rival held on a bound)
    refitted: bool = False         # change and left judged on a later model (own effects refitted, or a swap)
    ahead_of: str | None = None    # picked only with this effect on top (the look-ahead: :func:`.diagnosis.select`)
    chain_left: float = math.nan   # error the chain's final model leaves [noise floors] (NaN: not known)
    undetermined: int = 0          # own parameters inside their range and not determined
    in_place_of: str | None = None  # a kept draft the pick names the physics of, fitted in its place
    in_place: float = 1.0          # share of the excess error that draft leaves which the pick removes
    alone_of: str | None = None    # kept drafts that fit the records within the noise without the pick
    alone: float = 1.0             # share of the excess error they leave which the pick removes
    rest_flags: int = 0            # of ``flags``, correlations of its own parameters with the rest of the model
    traded: int = 0                # of ``undetermined``, those counted only as traded with the rest (module doc)
    label: str = "low"
    why: list[str] = field(default_factory=list)   # what kept it from "high"

    @classmethod
    def from_dict(cls, d: dict) -> "Confidence":
        """The features as :meth:`to_dict` wrote them (``diagnosis.json``: a pick's ``confidence_features``)."""
        def num(k):
            return math.nan if d.get(k) is None else float(d[k])
        return cls(float(d.get("weight") or 0.0), num("change_noise_floors"), num("left_noise_floors"),
                   float(d.get("twin_share", 1.0)), d.get("closest_rival"), float(d.get("records_improved", 1.0)),
                   int(d.get("quality_flags", 0)), int(d.get("pinned_parameters") or 0),
                   float(d.get("held_rival_share", 1.0)), d.get("held_rival"), bool(d.get("on_refitted_model")),
                   d.get("picked_ahead_of"), num("chain_left_noise_floors"), int(d.get("undetermined_parameters") or 0),
                   d.get("in_place_of"), float(d.get("in_place_share", 1.0)), d.get("drafts_alone"),
                   float(d.get("drafts_alone_share", 1.0)), int(d.get("flags_with_the_rest") or 0),
                   int(d.get("traded_parameters") or 0))

    def to_dict(self) -> dict:
        return {"label": self.label, "weight": self.weight, "change_noise_floors": _num(self.change),
                "left_noise_floors": _num(self.left), "twin_share": self.twin, "closest_rival": self.twin_of,
                "records_improved": self.records, "quality_flags": self.flags, "pinned_parameters": self.pinned,
                "undetermined_parameters": self.undetermined, "flags_with_the_rest": self.rest_flags,
                "traded_parameters": self.traded,
                "held_rival_share": self.held, "held_rival": self.held_of, "on_refitted_model": self.refitted,
                "picked_ahead_of": self.ahead_of, "chain_left_noise_floors": _num(self.chain_left),
                "in_place_of": self.in_place_of, "in_place_share": self.in_place,
                "drafts_alone": self.alone_of, "drafts_alone_share": self.alone,
                "not_high_because": self.why}


def _num(x: float):
    return x if math.isfinite(x) else None


def excess_share(before: float, after: float, noise: float) -> float:
    """Share of the excess error power over the noise floor (rmse² − noise²) that going from
    ``before`` to ``after`` [m RMS] removes (noise unknown: of the error power)."""
    n2 = noise ** 2 if math.isfinite(noise) else 0.0
    ex = before ** 2 - n2
    return 1.0 - max(after ** 2 - n2, 0.0) / ex if ex > 0 else 0.0


def features(pick, base, rivals, weight: float, noise: float, flags: int, pinned: int = 0, held=(),
             undetermined: int = 0, rest_flags: int = 0, traded: int = 0) -> Confidence:
    """The confidence features of ``pick`` (a CandidateResult) against ``base`` (the step's
    base fit) and the step's other evaluated candidates ``rivals``; ``flags``: its quality flags
    that question whether its effect is there (:func:`.verdict.doubts`); ``pinned``: its own
    parameters on a bound and not determined (:func:`.verdict.pinned`), ``undetermined`` those inside
    their range and not determined (:func:`.verdict.undetermined`); ``rest_flags`` and ``traded``:
    of those flags and undetermined parameters, the ones that come only from a correlation with the
    rest of the model (:func:`.verdict.with_rest`, :func:`.verdict.traded_only`); ``held``: the effects
    of the rivals whose own parameter ended on a bound (:func:`.verdict.held`)."""
    ok = math.isfinite(noise) and noise > 0
    b, a = base.rmse, pick.fit.rmse
    change = math.sqrt(max(b * b - a * a, 0.0)) / noise if ok else math.nan
    left = a / noise if ok else math.nan
    twin, twin_of = _closest(pick, rivals, noise)
    held_share, held_of = _closest(pick, [r for r in rivals if r.effect in held], noise)
    rb, rc = base.rmse_records, pick.fit.rmse_records
    better = [c <= (1.0 + RECORD_TOLERANCE) * x for x, c in zip(rb, rc)]
    records = sum(better) / len(better) if better else 1.0
    return Confidence(weight, change, left, twin, twin_of, records, flags, pinned, held_share, held_of,
                      undetermined=undetermined, rest_flags=rest_flags, traded=traded)


def reconfirmed(c: Confidence, with_pick: float, without: float, noise: float, flags: int, pinned: int,
                in_model: Sequence[str] = (), undetermined: int = 0, rest_flags: int = 0,
                traded: int = 0) -> Confidence:
    """``c`` labelled again on the model whose own effects were refitted (:func:`.diagnosis.select`):
    the error the pick removes there (``without`` → ``with_pick`` [m RMS], the refitted model
    without and with it), the error that model leaves, and the quality ``flags``, ``pinned`` and
    ``undetermined`` parameters of the pick's own parameters in it (the refit frees them again
    beside the own effects'; ``rest_flags`` and ``traded``: those of them that are correlations
    with the rest there).  Before the refit a pick can leave a large residual, or a parameter on
    a bound, only because the device's values of the model's own effects are not the strip's;
    once they are refitted, what it leaves is what a missing physics could still hide.  Used so
    too on the model after a swap (:func:`.diagnosis._swap_first`): a later pick's step had the
    withdrawn pick in its model.  The rival shares, the records and the weight are the pick's
    step's, but a rival now in the model (``in_model``: its effects) is no alternative to the pick
    any more: after a swap, a rival held on a bound at the pick's step was the effect the swap put in."""
    ok = math.isfinite(noise) and noise > 0
    if c.twin_of in in_model:
        c = replace(c, twin=1.0, twin_of=None)
    if c.held_of in in_model:
        c = replace(c, held=1.0, held_of=None)
    change = math.sqrt(max(without ** 2 - with_pick ** 2, 0.0)) / noise if ok else math.nan
    return label(replace(c, change=change, left=with_pick / noise if ok else math.nan, flags=flags, pinned=pinned,
                         undetermined=undetermined, rest_flags=rest_flags, traded=traded, why=[], refitted=True))


def at_chain_end(c: Confidence, final_rmse: float, noise: float) -> Confidence:
    """``c`` labelled again knowing the error the chain's final model leaves (``final_rmse`` [m RMS],
    :func:`.diagnosis.build_verdict`): beyond :data:`LEFT_LOW` noise floors the pick is "low" (module
    doc, **chain left**).  A copy: the step's own label is not changed."""
    if not (math.isfinite(noise) and noise > 0):
        return c
    return label(replace(c, chain_left=final_rmse / noise, why=[]))


def _closest(pick, rivals, noise: float) -> tuple[float, str | None]:
    """The smallest share of a rival's excess error the pick removes, and that rival; (1, None)
    when no rival keeps any of its excess from the pick (a share is at most 1: ties name none)."""
    shares = [(excess_share(r.fit.rmse, pick.fit.rmse, noise), r.effect) for r in rivals if r is not pick]
    return min([(1.0, None)] + shares, key=lambda x: x[0])


def label(c: Confidence, th: dict | None = None) -> Confidence:
    """Fill ``c.label`` and ``c.why`` (module doc); ``th``: thresholds replacing those of
    :func:`thresholds` (the calibration bench tries others on the recorded features)."""
    t = {**thresholds(), **(th or {})}
    ch_hi, ch_lo, left_hi = t["change_high_noise_floors"], t["change_low_noise_floors"], t["left_high_noise_floors"]
    left_lo = t["left_low_noise_floors"]
    twin_hi, twin_lo, rec_hi, w_hi = t["twin_high_share"], t["twin_low_share"], t["records_high_share"], t["weight_high"]
    why = []
    if not math.isfinite(c.change):
        why.append("no noise floor to judge the pick's size against")
    else:
        if c.change < ch_hi:
            why.append(f"it removes only {c.change:.2g}× the noise floor of error (it barely changes the model in "
                       f"the excited band; 'high' needs {ch_hi:g}×)")
        if c.left > left_hi:
            why.append(f"it leaves {c.left:.3g}× the noise floor, a structured residual it does not explain: it may "
                       "stand in for physics the catalog lacks (a proxy)")
    bound = "ended with a parameter on a bound of its range, so its error is only what the range allowed"
    if c.twin < twin_hi and c.twin_of:
        why.append(f"{c.twin_of} comes close (the pick removes {100 * c.twin:.2g} % of the excess error "
                   f"{c.twin_of} leaves; 'high' needs {100 * twin_hi:.0f} %)"
                   + (f"; {c.twin_of} {bound}" if c.held_of == c.twin_of else ""))
    if c.held_of and c.held < twin_hi and c.held_of != c.twin_of:
        why.append(f"{c.held_of} {bound}; the pick removes {100 * c.held:.3g} % of the excess error it leaves "
                   f"('high' needs {100 * twin_hi:.0f} %)")
    if c.in_place_of and c.in_place < twin_hi:
        how = (f"removes only {100 * c.in_place:.2g} % of the excess error that draft leaves" if c.in_place > 0
               else "fits the records no better than that draft")
        why.append(f"it names the physics of the draft {c.in_place_of}, fitted in its place, and {how} ('high' "
                   f"needs {100 * twin_hi:.0f} % of it): the records confirm the form, not the catalog's law for it")
    if c.alone_of and c.alone < twin_hi:
        why.append(f"without it the kept drafts {c.alone_of} fit the records within the noise, and it removes only "
                   f"{100 * max(c.alone, 0.0):.2g} % of the excess error they leave ('high' needs {100 * twin_hi:.0f} %): "
                   "the records need the form the drafts describe, not this effect")
    if c.records < rec_hi:
        why.append(f"it lowers the error on only {100 * c.records:.3g} % of the records (fitted on all of them, it "
                   "does not generalise from record to record)")
    decisive = math.isfinite(c.change) and c.change >= ch_hi      # removing it costs what no trade can give back
    flags = c.flags - (c.rest_flags if decisive else 0)
    undetermined = c.undetermined - (c.traded if decisive else 0)
    if flags:
        why.append(f"{flags} quality flag(s)")
    if undetermined:
        why.append(f"{undetermined} of its parameters {'is' if undetermined == 1 else 'are'} not determined inside "
                   "its range, or only in combination with the rest of the model's (the records do not say how much "
                   "of the effect there is)")
    if c.pinned:
        why.append(f"{c.pinned} of its parameters ended on a bound and are not determined (the data chose a "
                   "limit of the effect, not a value)")
    if c.weight < w_hi:
        why.append(f"its weight {c.weight:.3g} is below {w_hi}")
    if c.ahead_of:
        why.append(f"{AHEAD_WHY}: it was picked only with {c.ahead_of} on top of it")
    far = c.chain_left > left_lo          # False for NaN
    if far:
        why.append(f"{FAR_WHY} {c.chain_left:.3g}× the noise floor ('low' beyond {left_lo:g}×): it "
                   "explains a part of the failure, and that part may be physics the catalog lacks that the "
                   "pick's form happens to follow")
    c.why = why
    if not why:
        c.label = "high"
    elif (math.isfinite(c.change) and c.change < ch_lo) or (c.twin < twin_lo and c.twin_of) or c.pinned \
            or (c.in_place < twin_lo and c.in_place_of) or (c.alone < twin_lo and c.alone_of) \
            or undetermined or far:
        c.label = "low"
    else:
        c.label = "medium"
    return c


#: How the reasons the verdict gives a line of their own begin (:func:`told_apart`).
AHEAD_WHY, FAR_WHY, TWIN_WHY = "alone it explains too little of the failure", "the chain ends leaving", "a near twin,"


def told_apart(c: Confidence) -> list[str]:
    """The reasons ``c`` is not "high" that the verdict's text does not already give on a line of
    their own (a look-ahead's or a swap's lead, a chain ending far from the noise, a near twin)."""
    return [w for w in c.why if not w.startswith((AHEAD_WHY, FAR_WHY, TWIN_WHY))]


def thresholds() -> dict:
    """The label's thresholds, for the report."""
    return {"weight_high": WEIGHT_HIGH, "change_high_noise_floors": CHANGE_HIGH, "change_low_noise_floors": CHANGE_LOW,
            "left_high_noise_floors": LEFT_HIGH, "left_low_noise_floors": LEFT_LOW, "twin_high_share": TWIN_HIGH,
            "twin_low_share": TWIN_LOW, "records_high_share": RECORDS_HIGH, "record_tolerance": RECORD_TOLERANCE}


#: What the pages say while :data:`CALIBRATION` holds no draw.
UNCALIBRATED = "The confidence labels have not been calibrated on held-out physics yet."


def calibration_text() -> str:
    """One sentence: what "high", "medium" and "low" have meant on held-out families
    (:data:`CALIBRATION`), the tables of an earlier rule marked as such."""
    if not CALIBRATION:
        return UNCALIBRATED
    now = [c for c in CALIBRATION if not c.get("rule")]
    before = [c for c in CALIBRATION if c.get("rule")]
    text = " ".join(f"On {c['family']} ({c['cases']} cases; {c['caveat']}): {_per_label(c['labels'])}." for c in now)
    if before:
        rules = sorted({c["rule"] for c in before})
        text += (f" Measured while \"high\" asked {' or '.join(rules)} of a free rival's excess error (the rule "
                 f"since, {100 * TWIN_HIGH:.0f} %, can only turn a \"high\" into a \"medium\") and before a pick "
                 "kept beside a drafted effect was labelled again on the model written: "
                 + "; ".join(f"on {c['family']} seeds {c['seeds']} ({c['cases']} cases) {_per_label(c['labels'])}"
                             for c in before) + ".")
    return text.strip()


def calibration_pooled() -> dict:
    """Every draw of :data:`CALIBRATION` summed: ``draws``, ``cases`` and per label ``n``, ``right``,
    ``acceptable`` (a near twin's relative) and ``wrong`` picks.  Each draw counts under the rules in
    force when it was measured (an earlier rule is named in its row), so the sum says what the labels
    have meant across the rules' history, not only under today's."""
    labels = {lab: {k: sum(c["labels"][lab][k] for c in CALIBRATION) for k in ("n", "right", "acceptable", "wrong")}
              for lab in LABELS}
    return {"draws": len(CALIBRATION), "cases": sum(c["cases"] for c in CALIBRATION), "labels": labels}


def calibration_summary() -> str:
    """One sentence for the pages and the README: :func:`calibration_pooled` per label, with the share
    of picks that named the hidden effect or its near twin's relative."""
    if not CALIBRATION:
        return UNCALIBRATED
    pool = calibration_pooled()

    def said(lab: str) -> str:
        x = pool["labels"][lab]
        if not x["n"]:
            return f"\"{lab}\" never given"
        share = 100.0 * (x["right"] + x["acceptable"]) / x["n"]
        wrong = "none wrong" if not x["wrong"] else f"{x['wrong']} wrong"
        return (f"\"{lab}\" {x['n']} picks, {x['right']} right, {x['acceptable']} a near twin's relative, "
                f"{wrong} ({share:.0f} % right or a relative)")
    return (f"Summed over the table's {pool['draws']} draws ({pool['cases']} strips; each counted under the rules in "
            "force when it was measured, and a draw on which a later rule was chosen says so in its note): "
            + "; ".join(said(lab) for lab in LABELS) + ".")


def calibration_rows() -> list[dict]:
    """:data:`CALIBRATION` as the rows of a page's table, one per held-out draw, in its order:
    family, seeds, cases, the code it was measured at, per label "k of n" picks right (a near twin's
    relative counted right, and said), and the rules it was measured under.  The draws' caveats are
    the table's footnotes (:func:`calibration_notes`)."""
    rows = []
    for c in CALIBRATION:
        row = {"family": c["family"], "seeds": c["seeds"], "cases": c["cases"], "measured at": c["code"]}
        row.update({f"\"{lab}\" right": _right_of(c["labels"][lab]) for lab in LABELS})
        row["rules"] = "in force" if not c.get("rule") else f"\"high\" at {c['rule']} of a rival's excess"
        rows.append(row)
    return rows


def calibration_notes() -> list[str]:
    """One footnote per row of :func:`calibration_rows`: which truths, and what changed since."""
    return [f"{c['family']} seed{'s' if ',' in c['seeds'] else ''} {c['seeds']}: {c['caveat']}"
            + (f" (measured under an earlier rule: \"high\" asked {c['rule']} of a free rival's excess error; the "
               f"rule since, {100 * TWIN_HIGH:.0f} %, can only turn a \"high\" into a \"medium\")" if c.get("rule") else "")
            for c in CALIBRATION]


def _right_of(x: dict, what: str = "") -> str:
    """'k of n' (+ ``what``) picks right, a near twin's relative counted right and said; or 'never given'."""
    if not x["n"]:
        return "never given"
    return f"{x['right'] + x['acceptable']} of {x['n']}{what}" + (f" ({x['acceptable']} a near twin's relative)"
                                                                   if x["acceptable"] else "")


def _per_label(labels: dict) -> str:
    """'"high": k of n picks right (…), …' for one family's table."""
    return ", ".join(f"\"{lab}\": {_right_of(labels[lab], ' picks right')}" for lab in LABELS)


__all__ = ["Confidence", "features", "label", "excess_share", "thresholds", "calibration_text", "calibration_rows",
           "calibration_notes", "calibration_pooled", "calibration_summary", "CALIBRATION",
           "LABELS"]
