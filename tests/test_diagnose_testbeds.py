"""The diagnosis loop on the test beds of issue 24 (physics.testbeds.cases): lab-like records
(mm columns, offsets, drift, hygrometer jitter, no excitation metadata) and a perturbed
simulator.  A small fast subset runs by default; the seed survey is ``-m slow``."""
from __future__ import annotations

import html
import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physics.diagnose import diagnose
from physics.diagnose.confidence import label
from physics.testbeds.cases import lab_case, make_case, perturbed_case, truths
from physics.diagnose.verdict import STATUSES, UNATTRIBUTED, decide

CREEP = Path(__file__).resolve().parents[1] / "examples" / "effects" / "creep.py"


def _quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


# ------------------------------------------------------------------ fast: the loop as a user runs it


def test_lab_records_on_the_command_line(tmp_path, capsys):
    """Lab exports with electrode_resistance left out: the command names it with high confidence,
    the error after the pick is within 1.5× the true model's, the page shows the terminal's
    verdict text in full and readable, and suggested commands name final paths."""
    from nnmodel.app.cli import main
    case = lab_case("electrode_resistance", seed=0)
    files = [str(f) for f in case.write(tmp_path / "lab")]
    out = tmp_path / "dx"
    rc = main(["diagnose", *files, "--device", "ipmc_pt_eg", *case.param_args(), "--effects", case.effects,
               "--candidates", "electrode_resistance,fractional_coupling", "--no-support", "--out", str(out),
               "--apply", "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "Which effect: electrode_resistance (confidence high" in text, text
    d = json.loads((out / "diagnosis.json").read_text())
    v = d["verdict"]
    assert v["chain"][0]["effect"] == "electrode_resistance"
    assert v["chain"][-1]["rmse_after_m"] <= 1.5 * case.true_error()
    assert v["adequacy"]["adequate"] is True and v["status"] == "explained"
    # one verdict text: terminal = diagnosis.json = page
    for line in v["text"]:
        assert line in text
    page = (out / "index.html").read_text()
    for line in v["text"]:
        assert html.escape(line, quote=False) in page or html.escape(line) in page, line
    assert "\\u0394" not in page and ".eap-tmp-" not in page and ".eap-tmp-" not in text
    assert str(out / "ipmc_pt_eg_electrode_resistance.yaml") in text
    # the noise floor was estimated from the records and said so; the nuisance terms reported
    assert "estimated from the records' deflection spectra" in text
    assert "Nuisance terms (estimated per record, not physics)" in text
    # the time printed is the command's, the diagnosis and its draft rounds within it
    import re
    took = re.search(r"PNGs in ([\d.]+) s \(the diagnosis ([\d.]+) s, its draft rounds ([\d.]+) s\)", text)
    assert took, text[-400:]
    whole, diag, rounds = map(float, took.groups())
    assert whole >= diag + rounds - 0.2
    assert d["timings_s"]["draft rounds"] == pytest.approx(rounds, abs=0.06)


def test_nothing_hidden_gives_nothing_to_explain_without_a_confidence():
    case = lab_case("none", seed=0)
    res = _quiet(diagnose, case.measurements, case.device, case.effects, candidates="fractional_coupling",
                 check_support=False)
    v = res.verdict
    assert v.status == "nothing to explain" and v.picks == [] and v.confidence is None and v.label is None
    assert v.status in STATUSES
    assert "none is needed" in " ".join(v.lines())


class Fit:
    """Stand-ins for a fitted candidate in :func:`decide` (its quality flags given)."""

    def __init__(self, rmse):
        self.rmse = rmse
        self.rmse_records = [rmse, rmse]


class Cmp:
    def __init__(self, d):
        self.delta_bic, self.p_value = d, 1e-30


class Cand:
    def __init__(self, effect, d, rmse, flags):
        self.effect, self.comparison, self.fit, self._flags = effect, Cmp(d), Fit(rmse), flags
        self.indistinguishable_from, self.quality, self.passes = [], [], {}
        self.signature = None


def test_an_effect_switched_off_reads_on_its_bound_without_a_warning():
    """A candidate replaced by the base with its effect off carries the off value (0) of a
    log-scaled parameter: that is on the bound, and no 'divide by zero in log' reaches the user."""
    from physics.diagnose.candidates import on_bound
    from physics.identify.free_parameters import FreeParameter
    prm = FreeParameter("tau", 1.0, 1e-3, 1e3, "log", "s")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert on_bound(prm, 0.0) and on_bound(prm, 1e-3) and on_bound(prm, 2e3)
        assert not on_bound(prm, 1.0)
        assert on_bound(prm, 1e-3 * (1 + 1e-4))        # within the tolerance of ln θ


def _flags_only(monkeypatch, V):
    """The fake candidates' quality is their ``_flags`` (none a correlation with the rest of the
    model); one is held on a bound when a flag says so."""
    monkeypatch.setattr(V, "quality", lambda c, own_pairs=True: list(c._flags))
    monkeypatch.setattr(V, "with_rest", lambda c: [])
    monkeypatch.setattr(V, "pinned", lambda c: [])
    monkeypatch.setattr(V, "undetermined", lambda c: [])
    monkeypatch.setattr(V, "traded_only", lambda c: [])
    monkeypatch.setattr(V, "held", lambda c: [q for q in c._flags if "bound" in q])


def test_near_twins_are_ambiguous_whatever_their_quality_flags(monkeypatch):
    """Two candidates lower the error alike: near twins, "ambiguous" with the record that
    separates them — even when one has its parameters on bounds and correlated (issue 34: flags
    pushed the right twin out and the other was "high").  A rival clearly worse on fit does not
    make a pick ambiguous, and the pick is "high" only when its features say so."""
    from physics.diagnose import verdict as V

    base = Fit(50e-6)
    flexible = Cand("flexible", -5020.0, 2.00e-6, ["a on a bound", "a and b correlated", "signature absent"])
    user = Cand("user_creep", -5000.0, 2.01e-6, [])
    _flags_only(monkeypatch, V)
    monkeypatch.setattr(V, "separating_record", lambda a, b, r, n: "a square pulse held 60 s would separate them")
    dec = decide(base, [flexible, user], 1.5e-6, [1.0], [], lambda *a, **k: Cmp(-5.0), lambda a, b: 1e-6)
    assert set(dec.ambiguous) == {"user_creep", "flexible"} and "pulse" in dec.separating
    # the chain carries on with the twin of stronger evidence (flags count against it), never "high"
    assert dec.pick is user and dec.confidence.label == "low" and "near twin" in dec.confidence.why[0]
    # a rival far worse on fit: the clean candidate is picked, "high"
    worse = Cand("flexible", -3000.0, 20e-6, ["a on a bound"])
    dec = decide(base, [worse, user], 1.5e-6, [1.0], [], lambda *a, **k: Cmp(-3000.0), lambda a, b: 1e-6)
    assert dec.pick is user and dec.ambiguous == []
    assert dec.weights["user_creep"] > 0.99 and dec.confidence.label == "high"
    # a rival held on a bound that comes closer (the pick removes 73 % of the excess it leaves;
    # 'high' needs 95 % against a held rival, whose error is only what its range allowed): medium
    held = Cand("flexible", -3000.0, 3.0e-6, ["a on a bound"])
    dec = decide(base, [held, user], 1.5e-6, [1.0], [], lambda *a, **k: Cmp(-3000.0), lambda a, b: 1e-6)
    assert dec.pick is user and dec.confidence.label == "medium" and dec.confidence.held_of == "flexible"
    assert any("ended with a parameter on a bound" in w for w in dec.confidence.why)
    # close on fit *and* quality: ambiguous too
    twin = Cand("twin", -5001.0, 2.0e-6, [])
    dec = decide(base, [user, twin], 1.5e-6, [1.0], [], lambda *a, **k: Cmp(-1.0), lambda a, b: 1e-6)
    assert dec.pick is twin and set(dec.ambiguous) == {"user_creep", "twin"} and "pulse" in dec.separating
    assert dec.confidence.label == "low"


def test_a_clearly_better_fit_is_not_ambiguous_though_within_the_noise(monkeypatch):
    """Close on fit is judged on the error each leaves above the noise floor, not on whether
    their predictions differ by less than the noise (a systematic difference below the noise is
    plain over thousands of samples): 3.21 against 3.84 µm on a 3.1 µm floor — the first removes
    86 % of the excess the second leaves — is a pick; 3.30 against 3.35 µm (21 %) is ambiguous."""
    from physics.diagnose import verdict as V

    _flags_only(monkeypatch, V)
    monkeypatch.setattr(V, "separating_record", lambda a, b, r, n: "a sweep would separate them")
    base, floor, near = Fit(40e-6), 3.1e-6, lambda a, b: 0.5e-6      # predictions 0.5 µm apart
    draft, mimic = Cand("draft", -9000.0, 3.21e-6, []), Cand("mimic", -8500.0, 3.84e-6, [])
    dec = decide(base, [draft, mimic], floor, [1.0], [], lambda *a, **k: Cmp(-500.0), near)
    assert dec.pick is draft and dec.ambiguous == []
    a, b = Cand("a", -9000.0, 3.30e-6, []), Cand("b", -8990.0, 3.35e-6, [])
    dec = decide(base, [a, b], floor, [1.0], [], lambda *a, **k: Cmp(-40.0), near)
    assert dec.pick is a and set(dec.ambiguous) == {"a", "b"} and "% of the error" in dec.reason


def test_a_later_pick_must_be_free_of_quality_flags(monkeypatch):
    """On top of a pick the error left is mostly the base's own mismatch: a flexible effect
    that lowers it a lot (huge ΔBIC) but with its signature absent is picked on the first step,
    never on a later one; a clean one is — and so is a flagged one that removes nearly all the
    failure left (a hidden pair's second effect on top of the first: 87.5 → 3.8 µm on a 1.5 µm
    floor, its signature masked by the first pick), which no trim of a mismatch does."""
    from physics.diagnose import verdict as V

    _flags_only(monkeypatch, V)
    base, floor = Fit(1.7e-6), 1.04e-6
    mimic = Cand("mimic", -13000.0, 1.22e-6, ["its residual signature (phase lag) is absent"])
    args = (floor, [1.0], [], lambda *a, **k: Cmp(-5.0), lambda a, b: 1e-6)
    assert decide(base, [mimic], *args).pick is mimic
    later = decide(base, [mimic], *args, after_pick=True)
    assert later.pick is None and "it has quality flags after a pick" in later.reason
    clean = Cand("clean", -40.0, 1.3e-6, [])
    assert decide(base, [mimic, clean], *args, after_pick=True).pick is clean
    assert V.excess_share(1.7e-6, 1.22e-6, floor) < V.AFTER_PICK_SHARE          # the mimic: 78 % of the excess
    second = Cand("second", -20000.0, 3.84e-6, ["its residual signature (back-relaxation) is absent"])
    dec = decide(Fit(87.5e-6), [second], 1.5e-6, [1.0], [], lambda *a, **k: Cmp(-5.0), lambda a, b: 1e-6,
                 after_pick=True)
    assert dec.pick is second and dec.confidence.label != "high"


def test_a_step_without_a_pick_looks_ahead_with_its_best_and_takes_the_pair_as_never_high(monkeypatch):
    """pnp_fd seed 31, rough electrodes and solvent back-relaxation hidden: no candidate passes
    alone — solvent_diffusion, the best, takes 132 → 114 µm on a 1.5 µm floor (25 % of the excess
    error power, not a third).  The lead the chain looks ahead with fails that criterion only (a candidate that
    is not very strong is none, however low its error); with fractional_coupling picked on top of it
    (→ 1.6 µm) the step's decision becomes the lead, never "high", its reason giving both shares."""
    from physics.diagnose import verdict as V

    _flags_only(monkeypatch, V)
    base, floor = Fit(132e-6), 1.5e-6
    solvent = Cand("solvent_diffusion", -161.0, 114e-6, [])
    weak = Cand("weak", +12.0, 100e-6, [])               # lower error, evidence not very strong
    electrode = Cand("electrode_resistance", -97.0, 120e-6, [])
    dec = decide(base, [solvent, weak, electrode], floor, [1.0], [], lambda *a, **k: Cmp(-5.0),
                 lambda a, b: 1e-6)
    assert dec.pick is None and "removes less than a third of the error above the noise floor" in dec.reason
    assert set(V.FAILED) == set(V.CRITERIA)             # every criterion has its sentence
    assert V.lead_of(dec, [solvent, weak, electrode]) is solvent
    assert V.lead_of(dec, [weak]) is None
    second = Cand("fractional_coupling", -4000.0, 1.6e-6, [])
    taken = V.ahead(dec, solvent, second, base, [solvent, weak, electrode], floor)
    assert taken.pick is solvent and dec.pick is None                    # a new decision, the step's kept
    assert taken.confidence.label != "high" and taken.confidence.ahead_of == "fractional_coupling"
    assert "25 %" in taken.reason and "fractional_coupling" in taken.reason


def test_identify_keeps_the_start_when_the_fit_is_worse(tmp_path):
    """A fit that makes the time records worse than its start is not written as the result."""
    from physics.identify import identify, write_identification
    from physics.identify.result import _check_against_start
    case = lab_case("none", seed=2)
    res = _quiet(identify, case.measurements[:1], case.device, case.effects, "kf,beta_f", n_starts=1)
    assert not res.kept_start and res.check["time_rmse_fitted_m"] <= res.check["time_rmse_start_m"]
    bad = res.fit
    bad.theta = np.array([res.problem.theta0[0] * 1.5, res.problem.theta0[1]])
    chk = _check_against_start(res.problem, bad)
    assert chk["kept_start"] and "worse than its start" in chk["message"]
    res.check = chk
    res.device = res.problem.device_for(res.problem.theta0)
    out = write_identification(res, tmp_path / "id")
    text = (tmp_path / "id" / out["device_written"]).read_text()
    assert text.startswith("# WARNING: the fit is worse than its start") and "start value kept" in text


def test_identify_on_lab_records_brackets_the_truth():
    """identify with exactly the true effects on lab exports (a sweep and a pulse, no metadata):
    the time error reaches the true model's and every 95 % interval holds the true value (the
    pulse's whole-record FRF leaked and excluded the truth; it is now used in time only)."""
    from physics.identify import identify
    case = lab_case("solvent_diffusion", seed=0)
    res = _quiet(identify, case.measurements, case.device, "default", "kf,beta_f,D_solvent")
    assert [t.use_frf for t in res.problem.targets] == [True, False]
    assert res.check["time_rmse_fitted_m"] <= 1.1 * case.true_error()
    for row in res.param_rows():
        truth = case.truth_params[row["name"]]
        assert row["ci95_lo"] <= truth <= row["ci95_hi"], (row, truth)


# ------------------------------------------------------------------ slow: the survey of the Tests section

SEEDS = (0, 1, 2)


@pytest.mark.slow
@pytest.mark.parametrize("suite", ["lab", "perturbed"])
@pytest.mark.parametrize("truth", sorted(set(truths("lab")) & set(truths("perturbed")) - {"none", "creep", "lowpass",
                                                                                            "drift", "play"}))
def test_catalog_effect_named_with_high_confidence_in_most_seeds(suite, truth):
    """Named first and within 1.5× the true model's error in most seeds, "high" — or held back
    only because a rival came within the share 'high' asks (confidence.TWIN_HIGH, chosen on
    pnp_fd seed 20): labelled with that share set aside, the pick is "high"."""
    hits, rows = 0, []
    for seed in SEEDS:
        case = make_case(suite, truth, seed)
        res = _quiet(diagnose, case.measurements, case.device, case.effects, seed=seed, check_support=False)
        v = res.verdict
        c = v.picks[0].confidence if v.picks else None
        why = c.why if c else []
        rival_only = c is not None and label(replace(c), {"twin_high_share": 0.0}).label == "high"
        ok = bool(v.picks) and v.picks[0].effect == truth and (v.label == "high" or rival_only) and \
            v.final_rmse <= 1.5 * case.true_error()
        hits += ok
        rows.append((seed, v.status, v.chain, v.label, why, 1e6 * v.final_rmse, 1e6 * case.true_error()))
    assert hits >= 2, rows


@pytest.mark.slow
@pytest.mark.parametrize("suite", ["lab", "perturbed"])
def test_nothing_hidden_is_nothing_to_explain(suite):
    statuses = []
    for seed in SEEDS:
        case = make_case(suite, "none", seed)
        res = _quiet(diagnose, case.measurements, case.device, case.effects, seed=seed, check_support=False)
        statuses.append(res.verdict.status)
    assert statuses.count("nothing to explain") >= 2, statuses


@pytest.mark.slow
def test_creep_with_the_example_file_is_creep():
    from physics.effects import effect_classes_in_file, register, unregister
    (cls,) = effect_classes_in_file(CREEP)
    register(cls)
    try:
        for seed in SEEDS[:2]:
            case = perturbed_case("creep", seed)
            res = _quiet(diagnose, case.measurements, case.device, case.effects, seed=seed, check_support=False)
            v = res.verdict
            assert v.picks and v.picks[0].effect == "creep" and v.label == "high", v.lines()
            tau = v.picks[0].parameters["creep_tau"]
            assert tau["value"] == pytest.approx(case.truth_params["creep_tau_s"], rel=0.2)
            assert not any("on a bound" in q for q in v.picks[0].quality)
    finally:
        unregister("creep")


@pytest.mark.slow
def test_forward_selection_finds_two_missing_effects():
    """The lab device with two of its default effects left out: the chain names both."""
    case = lab_case("electrode_resistance", seed=0)
    res = _quiet(diagnose, case.measurements, case.device, "default,-electrode_resistance,-solvent_diffusion",
                 check_support=False)
    assert res.verdict.chain[:2] == ["electrode_resistance", "solvent_diffusion"] or \
        set(res.verdict.chain) == {"electrode_resistance", "solvent_diffusion"}, res.verdict.lines()
    assert math.isfinite(res.verdict.final_rmse) and res.verdict.final_rmse <= 1.5 * case.true_error()


def test_a_shared_drift_within_the_noise_is_still_something_to_explain(monkeypatch):
    """A base within 1.3× the floor has nothing to explain — unless its residual holds a drift
    the records share (deterministic structure, however small): then a candidate that removes
    it can be picked."""
    from physics.diagnose import verdict as V

    _flags_only(monkeypatch, V)
    base, floor = Fit(4.06e-6), 3.57e-6                   # 1.14× the floor
    drift = Cand("drift", -11.5, 3.57e-6, [])
    args = (floor, [1.0], [], lambda *a, **k: Cmp(-5.0), lambda a, b: 1e-6)
    quiet = decide(base, [drift], *args)
    assert quiet.pick is None and "already fits to within" in quiet.reason
    assert decide(base, [drift], *args, structure=True).pick is drift


def test_a_wander_beyond_the_sensors_stated_drift_is_named_not_called_a_base_mismatch():
    """Sensor metadata state a 1 µm white noise and a 1 µm drift; each record also wanders by
    ~4.7 µm, differently in each (the perturbed simulator's ``drift``).  The verdict does not
    call that an unstructured mismatch of the base: it names the wander, beyond the stated
    drift and independent of the input, and is within the noise only if it is not physics."""
    case = perturbed_case("drift", seed=0)
    res = _quiet(diagnose, case.measurements, case.device, case.effects, candidates="electrode_resistance",
                 check_support=False)
    v = res.verdict
    text = " ".join(v.lines())
    assert v.status == UNATTRIBUTED and v.picks == [] and v.confidence is None
    assert "base mismatch" not in v.remaining_kind and "the sensor's stated drift" in text
    wander = res.settings["noise"]["wander_beyond_stated_drift_m"]
    drift = case.truth_params["drift_rms_m"]
    assert 0.6 * drift < wander < 1.4 * drift, (wander, drift)
    assert v.noise_floor == pytest.approx(res.noise_floor)      # one floor, from the measurement (issue 34)
    assert f"within 1.3× {1e6 * math.hypot(res.noise_floor, wander):.3g} µm" in text   # the wander counted beside it
