"""Diagnosis: a hidden effect in sensor-corrupted synthetic measurements must rank first and
its addition must cut the error; no hidden effect, no verdict; the statistics, the residual
checks and the command line behave."""
from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest
import yaml

from physics import signals
from physics.device import load_device
from physics.diagnose import SelectionOptions, diagnose, excitation, write_diagnosis
from physics.analysis import stats
from physics.diagnose.candidates import candidate_spec, default_free, map_free, translate_start
from physics.testbeds.demo import hidden_effect_case, hidden_effects
from physics.diagnose.records import amplitude_levels, classify, find_steps, prepare_records
from physics.diagnose.residuals import analyse
from physics.diagnose.verdict import ADEQUATE_RATIO
from physics.diagnose.signatures import revealable
from physics.errors import InputError
from physics.io.frfdata import FRFData, write_frf
from physics.io.timeseries import TimeSeries, write_timeseries


def _diagnose(case, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose(case.measurements, case.device, case.base_effects, **kw)


def _check_found(case, res):
    """The contract of the issue: the hidden effect ranks first, the error after adding it
    falls by at least half (or to within 1.2× the noise floor), and the verdict names it."""
    top = res.ranking[0]
    assert top.effect == case.hidden, [(c.effect, c.comparison.delta_bic) for c in res.ranking]
    assert top.fit.rmse <= 0.5 * res.base.rmse or top.fit.rmse <= 1.2 * case.noise_floor
    assert res.verdict.missing_effect == case.hidden, res.verdict.reason
    assert res.verdict.confidence > 0.99
    assert top.comparison.delta_bic < -10 and top.comparison.p_value < 0.01 / len(res.ranking)
    # the label is computed on the error the verdict reports (after the refinement on the time records)
    c = res.steps[0].decision.confidence
    assert c.left == pytest.approx(top.fit.rmse / res.noise_floor, rel=1e-9), (c.left, top.fit.rmse)


# ---------------------------------------------------------------------------- hidden effects (one seed each)


# The large-signal case takes minutes (its describing-function fits): it runs with the heavier
# tests, beside its rate over seeds (test_diagnose_slow.py); the large-signal fit itself is
# checked by the default suite in test_diagnose_fit_starts.py.
@pytest.mark.parametrize("effect", [pytest.param(e, marks=pytest.mark.slow) if e == "nonlinear_charge" else e
                                    for e in hidden_effects()])
def test_hidden_effect_is_found(effect):
    case = hidden_effect_case(effect, seed=0)
    res = _diagnose(case, check_support=False)
    _check_found(case, res)
    # the base fails far above the noise, the winner brings it near the noise floor
    assert res.base.rmse > 5 * case.noise_floor
    assert res.best.fit.rmse < 3 * case.noise_floor
    # its own parameters are recovered (where they are identifiable)
    truth = case.truth_params
    vals = res.best.fit.values
    for name in ("Rs", "D_solvent", "frac_a", "dma_scale"):
        if name in truth and name in vals:
            assert vals[name] == pytest.approx(truth[name], rel=0.05), name


def test_no_hidden_effect_gives_no_verdict():
    case = hidden_effect_case(None, seed=0)
    res = _diagnose(case)
    assert res.verdict.missing_effect is None
    assert "noise floor" in res.verdict.reason
    # no candidate is even close to very strong evidence
    assert all(c.comparison.delta_bic > -10 for c in res.ranking)


def test_base_with_effects_support_and_the_missing_one():
    """A richer base (the IPMC's electrode line, solvent, DMA) lacking fractional coupling:
    the missing one is found and the model's own effects are checked for support."""
    case = hidden_effect_case("fractional_coupling", seed=1,
                              base_effects="electrode_resistance,solvent_diffusion,viscoelastic")
    res = _diagnose(case)
    _check_found(case, res)
    sup = {s.effect: s for s in res.support}
    assert set(sup) == {"electrode_resistance", "solvent_diffusion", "viscoelastic"}
    assert sup["electrode_resistance"].supported and sup["viscoelastic"].supported


def test_effect_the_data_do_not_support_is_removed():
    """The model has electrode_resistance but the device truly has equipotential electrodes:
    the data do not support it, so the stepwise selection removes it (issue 34: it was only
    reported) and the verdict says so; forward-only, it is reported as not supported."""
    case = hidden_effect_case(None, seed=2)
    res = _diagnose(case, candidates="solvent_diffusion")
    assert res.support == []                       # the base has no effect to check
    with_rs = type(case)(**{**case.__dict__, "base_effects": ("double_layer", "electrode_resistance")})
    res = _diagnose(with_rs, candidates="solvent_diffusion")
    removed = {r["effect"]: r for r in res.verdict.removed}
    assert "electrode_resistance" in removed and "not supported" in removed["electrode_resistance"]["reason"]
    assert "electrode_resistance" not in res.final.effects and res.final.rmse <= res.base.rmse
    res = _diagnose(with_rs, candidates="solvent_diffusion", selection=SelectionOptions(backward=False))
    sup = {s.effect: s for s in res.support}
    assert sup["electrode_resistance"].supported is False
    assert "not supported" in sup["electrode_resistance"].explanation


def _rs_case(hidden, factor=3.0):
    """A strip whose electrode resistance is ``factor``× the device's, ``hidden`` missing from the model."""
    dev = load_device("ipmc_pt_eg")
    return dev, hidden_effect_case(hidden, seed=0, device=dev.with_params(Rs=factor * dev["Rs"]),
                                   base_effects="electrode_resistance")


@pytest.mark.slow
def test_a_pick_that_stood_in_for_the_devices_values_is_withdrawn_once_they_are_refitted():
    """The strip's electrode resistance is 3× the device's and nothing is missing.  The base
    misfits by ~80 noise floors, so `viscoelastic` lowers the error and is picked; no candidate
    passes on top of it, so the chain refits the model's own effects (the device's value is a
    start, not the strip's): the refit recovers the strip's Rs and, on the refitted model, the
    model without `viscoelastic` is within the noise floor, where a forward step picks nothing
    (however significant the ΔBIC of the 0.2 % it still removes over ~25 000 samples): it is
    withdrawn and the verdict names no effect.  With ``--free`` the user's list is all that is fitted."""
    dev, case = _rs_case(None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = diagnose(case.measurements, "ipmc_pt_eg", case.base_effects, candidates="viscoelastic",
                       check_support=False)
        fixed = diagnose(case.measurements, "ipmc_pt_eg", case.base_effects, candidates="viscoelastic",
                         check_support=False, free="kf,Y,beta_f")
    assert [s.kind for s in res.steps] == ["add", "refit", "withdraw"]
    assert res.steps[0].decision.pick.effect == "viscoelastic" and not res.picks and res.winner is None
    assert res.base.rmse > 10 * case.noise_floor and res.final.rmse < 1.5 * case.noise_floor
    v = res.verdict
    assert v.status == "explained" and v.missing_effect is None and v.chain == []
    assert [w["effect"] for w in v.withdrawn] == ["viscoelastic"] and v.removed == []
    assert v.withdrawn[0]["rmse_after_m"] < ADEQUATE_RATIO * res.noise_floor
    assert v.refitted["Rs"]["device"] == dev["Rs"]
    assert v.refitted["Rs"]["refined"] == pytest.approx(3 * dev["Rs"], rel=0.1)
    assert any(line.startswith("Which effect: none is missing") for line in v.lines())
    assert any(line.startswith("Withdrawn: viscoelastic") for line in v.lines())
    d = res.to_dict()
    assert [s["kind"] for s in d["steps"]] == ["add", "refit", "withdraw"]
    assert d["settings"]["own_refined"] == v.refitted and d["verdict"]["withdrawn"][0]["effect"] == "viscoelastic"
    assert "refit" not in [s.kind for s in fixed.steps] and fixed.settings["own_refined"] == {}
    assert fixed.verdict.chain == ["viscoelastic"] and fixed.final.rmse > 10 * case.noise_floor


def test_a_pick_the_refitted_model_needs_is_labelled_again_on_it():
    """Solvent diffusion is missing and the strip's electrode resistance is 3× the device's.
    The pick leaves ~50 noise floors (a possible proxy, "medium") until the model's own effects
    are refitted; on the refitted model it stays (the data need it) and is labelled on what it
    removes and leaves there."""
    _, case = _rs_case("solvent_diffusion")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = diagnose(case.measurements, "ipmc_pt_eg", case.base_effects, candidates="solvent_diffusion",
                       check_support=False)
    assert [s.kind for s in res.steps][:2] == ["add", "refit"] and res.verdict.chain == ["solvent_diffusion"]
    pick = res.verdict.picks[0]
    assert res.steps[0].decision.pick.fit.rmse > 10 * case.noise_floor > 10 * res.final.rmse / 1.5
    # its line of the verdict reads on the refitted model (without it → with it there), not on its step
    assert pick.on == "the model with its own effects refitted" and pick.rmse_after == res.final.rmse
    assert pick.rmse_before > 3 * pick.rmse_after and pick.delta_bic < 0
    c = pick.confidence
    assert c.refitted and c.left == pytest.approx(res.final.rmse / res.noise_floor)
    assert c.change > 3 and c.label == "high", c.why
    assert "on the model with its own effects refitted" in pick.reason


def test_a_pick_s_refine_parameter_is_fitted_once_picked_before_the_next_candidates(monkeypatch):
    """Solvent diffusion hidden with its solvent released in a layer at each face 5 % of the
    membrane thick (δ = 9 µm, the closed form checked against a finite-volume solve in
    test_physics_effects.py): the chain picks it with δ held at the device's 0 (the classical law);
    the next step fits δ on that model, before fractional_coupling is tried on top of it (a
    flexible law that would otherwise trim what the layer leaves), which brings the error to the
    noise and δ near the truth, so no candidate is tried after it.  The same strip with δ = 0 keeps
    no such step (the extra parameter buys nothing)."""
    from physics.effects import EFFECTS
    cls = EFFECTS["solvent_diffusion"]
    draw = cls.draw_truth

    def with_layer(share):
        def drawn(device, rng):
            dev, own = draw(device, rng)
            delta = share * device.params["t_polymer"]
            return dev.with_params(solvent_layer=delta), {**own, "solvent_layer": delta}
        return staticmethod(drawn)

    found = {}
    for share in (0.05, 0.0):
        monkeypatch.setattr(cls, "draw_truth", with_layer(share))
        case = hidden_effect_case("solvent_diffusion", seed=1)
        res = _diagnose(case, candidates="solvent_diffusion,fractional_coupling", check_support=False)
        assert res.verdict.chain == ["solvent_diffusion"], res.verdict.reason
        found[share] = (case, res)
    case, res = found[0.05]
    last, pick = res.steps[-1], res.steps[0].decision.pick
    assert [s.kind for s in res.steps] == ["add", "refit"], [s.kind for s in res.steps]
    assert last.kind == "refit" and list(last.refitted) == ["solvent_layer"] and last.picks_refined
    assert "before the next candidates" in last.decision.reason
    assert "solvent_layer" not in pick.fit.spec.free          # not freed while the candidates competed
    delta = case.truth_params["solvent_layer"]
    assert last.refitted["solvent_layer"]["refined"] == pytest.approx(delta, rel=0.15)
    assert pick.fit.rmse > 1.5 * res.final.rmse and res.final.rmse < 1.3 * case.noise_floor
    assert "solvent_layer" in res.verdict.refined and not res.verdict.refitted
    # the pick is labelled again on the refined model: its line reads there (without it → with it)
    line = res.verdict.picks[0]
    assert line.on == "the model with the picks' shape refined" and line.rmse_after == res.final.rmse
    assert line.confidence.refitted and line.confidence.left == pytest.approx(res.final.rmse / res.noise_floor)
    assert any(line.startswith("The picks' shape refined once picked") and "solvent_layer 0 → 9" in line
               for line in res.verdict.lines())
    case, res = found[0.0]
    assert not any(s.picks_refined for s in res.steps) and not res.verdict.refined


_SLOW_CREEP = """
from physics.effects import OutputEffect
from physics.parameters import ParamSpec


class SlowCreep(OutputEffect):
    id = "slow_creep_test"
    summary = "tip load x (1 + r/(1 + s tau)); tau refined only once picked, no diagnosis bounds for it"
    params = (ParamSpec("sct_r", "1", -0.9, 10.0, "fraction", optional=True, default=0.0),
              ParamSpec("sct_tau", "s", 0.01, 1e4, "time constant", optional=True, default=2.0))
    diagnosis = {"free": ("sct_r",), "refine": ("sct_tau",), "bounds": {"sct_r": (-0.9, 5.0)},
                 "starts": [{"sct_r": 0.3}], "nested": True, "off": {"sct_r": 0.0},
                 "excitation": "a step held 10 s", "signature": [("step_creep", 1.0)]}

    @classmethod
    def draw_truth(cls, device, rng):
        return device.with_params(sct_r=0.4, sct_tau=12.0), {"sct_r": 0.4, "sct_tau": 12.0}

    def output_tf(self, p):
        r, tau = self.value(p, "sct_r"), self.value(p, "sct_tau")
        return [tau, 1.0 + r], [tau, 1.0]
"""


def test_a_user_effect_s_refine_parameter_without_bounds_is_fitted_within_its_declared_range(tmp_path):
    """A user effect may name a ``refine`` parameter without diagnosis bounds: it is held at the
    device's value (2 s) while the candidate is fitted and refitted last within its declared
    range, where it finds the strip's 12 s."""
    from physics.effects import load_effects_file, unregister
    path = tmp_path / "slow_creep_test.py"
    path.write_text(_SLOW_CREEP, encoding="utf-8")
    ids = load_effects_file(path)
    try:
        case = hidden_effect_case("slow_creep_test", seed=0, design=("sweep", "pulse"))
        res = _diagnose(case, candidates="slow_creep_test", check_support=False)
    finally:
        for i in ids:
            unregister(i)
    assert res.verdict.chain == ["slow_creep_test"]
    assert res.verdict.refined["sct_tau"]["device"] == 2.0
    assert res.verdict.refined["sct_tau"]["refined"] == pytest.approx(12.0, rel=0.1)
    assert res.final.rmse < 0.9 * res.steps[0].decision.pick.fit.rmse


# ---------------------------------------------------------------------------- what the data can reveal


def test_one_rh_level_and_one_amplitude_cannot_reveal_humidity_or_nonlinear_charge():
    case = hidden_effect_case("humidity", seed=0, design=("sweep",))
    res = _diagnose(case, check_support=False)
    ne = {c.effect: c for c in res.candidates if not c.evaluated}
    assert "one RH level cannot reveal humidity" in ne["humidity"].reason
    assert "one amplitude cannot reveal nonlinear_charge" in ne["nonlinear_charge"].reason
    assert ne["humidity"].row(res.base)["excitation_needed"] == excitation("humidity")
    # and the verdict does not guess another effect for what is really an RH change it cannot see
    assert res.verdict.missing_effect in (None,)


def test_revealable_rules():
    case = hidden_effect_case("solvent_diffusion", seed=0)
    recs = prepare_records(case.measurements)
    assert revealable("solvent_diffusion", recs)[0]
    assert revealable("electrode_resistance", recs)[0]
    assert not revealable("humidity", recs)[0]
    assert revealable("viscoelastic", recs, resonance_hz=20.0)[0]
    ok, why = revealable("viscoelastic", recs, resonance_hz=200.0)
    assert not ok and "does not span the first resonance" in why
    pulse_only = [r for r in recs if r.kind == "steps"]
    ok, why = revealable("electrode_resistance", pulse_only)
    assert not ok


# ---------------------------------------------------------------------------- statistics


def test_integrated_time_of_ar1():
    """τ_int of an AR(1) process with coefficient φ is (1 + φ)/(1 − φ)."""
    rng = np.random.default_rng(0)
    for phi in (0.0, 0.5, 0.9):
        e = np.zeros(200_000)
        w = rng.standard_normal(e.size)
        for i in range(1, e.size):
            e[i] = phi * e[i - 1] + w[i]
        assert stats.integrated_time(e) == pytest.approx((1 + phi) / (1 - phi), rel=0.1)


def test_bic_does_not_reward_a_useless_parameter():
    """Noise-only data: a model with an extra regressor fits a little better, but ΔBIC must
    (almost always) be positive and the LR p-value uniform-ish (not small)."""
    rng = np.random.default_rng(1)
    wins, ps = 0, []
    for _ in range(200):
        n = 400
        y = rng.standard_normal(n)
        x = rng.standard_normal(n)
        rss0 = float(np.sum((y - y.mean()) ** 2))
        X = np.column_stack([np.ones(n), x])
        r = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        rss1 = float(r @ r)
        d = stats.bic([rss1], [n], [n], 2) - stats.bic([rss0], [n], [n], 1)
        wins += d < -10
        ps.append(stats.lr_pvalue([rss0], [rss1], [n], 1))
    assert wins == 0
    assert 0.35 < np.mean(ps) < 0.65            # p-values ~ U(0, 1) under the null
    assert np.mean(np.array(ps) < 0.01) < 0.03


def test_vuong_is_symmetric_and_detects_a_better_model():
    rng = np.random.default_rng(2)
    e = rng.standard_normal(5000)
    assert stats.vuong_pvalue([e], [e], [1.0]) == pytest.approx(0.5)
    better = 0.5 * e
    assert stats.vuong_pvalue([e], [better + 0.01 * rng.standard_normal(5000)], [1.0]) < 1e-6


def test_coherence_threshold_matches_simulation():
    rng = np.random.default_rng(3)
    n_avg = 8
    g = []
    for _ in range(4000):
        a = rng.standard_normal(n_avg) + 1j * rng.standard_normal(n_avg)
        b = rng.standard_normal(n_avg) + 1j * rng.standard_normal(n_avg)
        g.append(abs(np.sum(a * np.conj(b))) ** 2 / (np.sum(abs(a) ** 2) * np.sum(abs(b) ** 2)))
    thr = float(stats.coherence_threshold(n_avg, 0.01))
    assert np.mean(np.array(g) > thr) == pytest.approx(0.01, abs=0.006)


def test_evidence_labels():
    assert stats.evidence_label(-50) == "very strong"
    assert stats.evidence_label(-7) == "strong"
    assert stats.evidence_label(-3) == "positive"
    assert stats.evidence_label(5).startswith("against")
    w = stats.bic_weights([0.0, -20.0])
    assert w[1] > 0.99


# ---------------------------------------------------------------------------- residual analysis


def test_residual_checks_white_vs_missing_dynamics():
    """A white residual stays in the 99 % bands; a residual that is a filtered copy of the
    input leaves them and shows above its noise floor in the residual FRF."""
    case = hidden_effect_case(None, seed=3)
    recs = prepare_records(case.measurements)
    r = recs[0]
    rng = np.random.default_rng(4)
    white = rng.standard_normal(r.y_d.size) * 1e-6
    ra = analyse("white", recs, [white], [r.y_d - white])
    assert ra.acf_outside < 0.05 and ra.ccf_outside < 0.05
    assert not ra.frf.significant.any() or ra.frf.significant.mean() < 0.1
    assert any("passes the whiteness" in f or "no systematic" in f for f in ra.findings)
    from scipy.signal import lfilter
    leak = lfilter([0.0, 2e-5], [1.0, -0.9], r.v_d) + white
    ra2 = analyse("leaky", recs, [leak - leak.mean()], [r.y_d - leak])
    assert ra2.ccf_outside > 0.05
    assert ra2.frf.significant.mean() > 0.5
    assert any("correlated with the input" in f for f in ra2.findings)


def test_a_misfit_that_moves_with_humidity_is_read_from_records_of_one_design_even_when_the_gain_ratio_holds():
    """The same multisine at RH 40 % and at RH 80 %: a model that misses a narrow band (a resonance
    that moved) at RH 80 % only keeps the median measured/model gain within 5 % at both levels, yet
    the residual beyond the noise differs many-fold between the two records of one design: the RH
    dependence is present.  A model whose whole gain is 10 % low at RH 80 % only is one too.  The
    same misfit at both levels, or a misfit on a record of another design, is not RH dependence;
    nor is a contrast read when the model has parameters per RH level (each level then has its
    own fit)."""
    from scipy import signal as ssig
    from physics.diagnose.signatures import features
    rng = np.random.default_rng(7)
    recs = []
    for k, (amp, rh, f_hi) in enumerate([(0.3, 40.0, 20.0), (0.3, 80.0, 20.0), (0.6, 60.0, 10.0)]):
        sig = signals.multisine(amp, 0.1, f_hi, 20.0, periods=3, fs=100.0, seed=k)
        y = 1e-3 * np.convolve(sig.v, np.exp(-np.arange(40) / 8.0) / 8.0)[:sig.v.size]
        recs.append(TimeSeries(sig.t, sig.v, y + 1e-6 * rng.standard_normal(sig.t.size),
                               rh=np.full(sig.t.size, rh), source=f"ms{k}"))
    recs = prepare_records(recs)
    sos = ssig.butter(2, [5.0, 7.0], btype="bandpass", fs=recs[0].fs_d, output="sos")

    def feats(missed, per_rh=False, gains=(1.0, 1.0, 1.0)):
        preds, resid = [], []
        for r, m, g in zip(recs, missed, gains):
            pred = (r.y_d - m * ssig.sosfilt(sos, r.y_d)) / g
            e = r.y_d - pred + r.noise_floor_d * rng.standard_normal(r.y_d.size)
            preds.append(pred)
            resid.append(e - e.mean())
        ra = analyse("m", recs, resid, preds, per_rh=per_rh)
        return ra, features(ra, recs, None)

    ra, f = feats([0.0, 0.5, 0.0])
    [c] = ra.rh_contrast
    assert abs(c["gain_change"]) < 0.05                 # the gain ratio alone would not see it
    assert (c["rh_low_pct"], c["rh_high_pct"]) == (40.0, 80.0) and c["depends_on_rh"] and c["contrast"] > 5
    assert f["rh_dependence"]["present"] is True
    assert any("at RH 40 %" in x and "depends on humidity" in x for x in ra.findings)
    for missed in ([0.5, 0.5, 0.0], [0.0, 0.0, 0.5]):
        ra, f = feats(missed)
        assert not ra.rh_contrast[0]["depends_on_rh"] and f["rh_dependence"]["present"] is False, missed
    ra, f = feats([0.0, 0.0, 0.0], gains=(1.0, 1.1, 1.0))     # the model's gain 10 % low at RH 80 % only
    assert f["rh_dependence"]["present"] is True and ra.rh_contrast[0]["gain_change"] > 0.05
    ra, f = feats([0.0, 0.5, 0.0], per_rh=True)
    assert ra.rh_contrast == [] and f["rh_dependence"]["present"] is None      # not readable there


def test_amplitude_dependence_is_read_at_one_humidity_and_harmonics_above_the_noise():
    """A model whose gain is off at RH 40 % only, on a linear strip driven at two amplitudes at
    RH 60 %: no gain that depends on the amplitude (the misfit differs by humidity, not by
    amplitude), and a residual at the noise floor shows no harmonic distortion — the features
    once pooled 0.3 V records across humidities and counted white noise at the quiet
    frequencies as harmonics.  A gain that drops at the higher amplitude, and a cubic term in
    the residual, are then found."""
    from physics.diagnose.signatures import features
    rng = np.random.default_rng(5)
    recs = []
    for k, (amp, rh) in enumerate([(0.3, 40.0), (0.3, 60.0), (0.75, 60.0)]):
        sig = signals.multisine(amp, 0.1, 10.0, 20.0, periods=3, fs=100.0, seed=k)
        y = 1e-3 * np.convolve(sig.v, np.exp(-np.arange(40) / 8.0) / 8.0)[:sig.v.size]
        recs.append(TimeSeries(sig.t, sig.v, y + 1e-6 * rng.standard_normal(sig.t.size),
                               rh=np.full(sig.t.size, rh), source=f"ms{k}"))
    recs = prepare_records(recs)
    assert [r.kind for r in recs] == ["broadband"] * 3 and len({r.amplitude_level for r in recs}) == 2

    def feats(gains, cubic=0.0):
        preds, resid = [], []
        for r, g in zip(recs, gains):
            white = r.noise_floor_d * rng.standard_normal(r.y_d.size)
            pred = r.y_d / g
            e = r.y_d - pred + white + cubic * (r.v_d / np.abs(r.v_d).max()) ** 3
            preds.append(pred)
            resid.append(e - e.mean())
        ra = analyse("m", recs, resid, preds)
        return ra, features(ra, recs, None)

    ra, f = feats([1.25, 1.0, 1.0])
    assert [c["rh_pct"] for c in ra.amplitude_contrast] == [60.0]
    assert f["amplitude_dependence"]["present"] is False and abs(ra.amplitude_contrast[0]["change"]) < 0.01
    assert f["harmonics"]["present"] is False and f["harmonics"]["share"] < 0.01
    assert not any("depends on the amplitude" in x or "harmonic" in x for x in ra.findings)
    ra, f = feats([1.25, 1.0, 0.85])
    assert f["amplitude_dependence"]["present"] is True and ra.amplitude_contrast[0]["change"] < -0.1
    assert any("at RH 60 %" in x and "depends on the amplitude" in x for x in ra.findings)
    ra, f = feats([1.0, 1.0, 1.0], cubic=50e-6)         # ~2.5 µm RMS of cubic products, a 1 µm floor
    assert f["harmonics"]["present"] is True and f["amplitude_dependence"]["present"] is False


def test_findings_are_phrased_for_a_person():
    case = hidden_effect_case("solvent_diffusion", seed=0)
    res = _diagnose(case, candidates="solvent_diffusion", check_support=False)
    text = " ".join(res.analysis_base.findings)
    assert "estimates the gain" in text and "leads the model" in text        # droop + phase lead at low f
    assert "relaxes back" in text                                              # back-relaxation after the step


# ---------------------------------------------------------------------------- records and specs


def test_records_classification_and_levels():
    s = signals.sweep(0.3, 0.1, 50.0, 20.0, 500.0)
    ts = TimeSeries(s.t, s.v, 0 * s.v, rh=np.full(s.t.size, 50.0))       # no metadata: from the voltage
    kind, band, _, _ = classify(ts)
    assert kind == "broadband" and band[0] < 0.2 and 40 < band[1] <= 60
    q = signals.square(1.0, t_on=5.0, t_off=5.0, cycles=2, fs=200.0)
    ts2 = TimeSeries(q.t, q.v, 0 * q.v, rh=np.full(q.t.size, 50.0))
    assert classify(ts2)[0] == "steps"
    assert find_steps(q.v, 200.0).size == 4          # the first edge at t = 0 included
    t = signals.tone(0.5, 2.0, 10.0, 200.0)
    assert classify(TimeSeries(t.t, t.v, 0 * t.v, rh=np.full(t.t.size, 50.0)))[0] == "tone"
    assert amplitude_levels([0.1, 0.11, 0.4]) == pytest.approx([math.sqrt(0.1 * 0.11)] * 2 + [0.4])


def test_parameter_roles_follow_the_effects():
    dev = load_device("ipmc_pt_eg")
    assert default_free(("double_layer",)) == ["kf", "Y", "beta_f"]
    assert map_free(["kf", "Y", "beta_f", "Rs"], ("double_layer", "electrode_resistance"),
                    ("double_layer", "fractional_coupling", "viscoelastic")) == ["kf0", "dma_scale", "beta_f"]
    st = translate_start(dev, ("double_layer",), ("double_layer", "fractional_coupling"), (0.1, 50.0))
    assert st["frac_a"] == 0.3 and st["kf0"] > dev["kf"]
    spec = candidate_spec("humidity", ("double_layer",), ["kf", "Y", "beta_f"], [], dev, (0.1, 50.0), 3)
    assert spec.per_rh == ["kf", "Y", "beta_f"] and spec.free == []     # per RH, never also shared
    spec = candidate_spec("solvent_diffusion", ("double_layer",), ["kf", "Y", "beta_f"], [], dev, (0.1, 50.0), 1)
    lo, hi = spec.bounds["D_solvent"]
    h = 0.5 * dev["t_polymer"]
    assert h * h / hi == pytest.approx(0.2) and h * h / lo == pytest.approx(1e5)


# ---------------------------------------------------------------------------- bad input


def test_bad_input_messages(tmp_path):
    case = hidden_effect_case(None, seed=0)
    with pytest.raises(InputError, match="free: Rs has no effect"):
        diagnose(case.measurements, "ipmc_pt_eg", "none", free="kf,Rs")
    with pytest.raises(InputError, match="candidates: unknown"):
        diagnose(case.measurements, "ipmc_pt_eg", "none", candidates="electrode_resistence")
    with pytest.raises(InputError, match="already in the model"):
        diagnose(case.measurements, "ipmc_pt_eg", "electrode_resistance", candidates="electrode_resistance")
    f = np.geomspace(0.1, 50, 20)
    path = write_frf(FRFData(f, np.ones(20, complex) * 1e-3, rh=50.0), tmp_path / "frf.csv")
    with pytest.raises(InputError, match="frequency-response file"):
        diagnose([path], "ipmc_pt_eg", "none")
    sq = signals.square(0.2, t_on=5.0, t_off=5.0, cycles=1, fs=200.0)
    ts = TimeSeries(sq.t, sq.v, 1e-3 * sq.v, rh=np.full(sq.t.size, 50.0), meta={"signal": sq.describe()})
    with pytest.raises(InputError, match="at least one broadband"):
        diagnose([ts], "ipmc_pt_eg", "none")


# ---------------------------------------------------------------------------- outputs and command line


def test_report_and_apply(tmp_path):
    case = hidden_effect_case("electrode_resistance", seed=1)
    res = _diagnose(case)
    out = write_diagnosis(res, tmp_path / "d", apply=True)
    d = json.loads((tmp_path / "d" / "diagnosis.json").read_text())
    assert set(d["base"]) >= {"effects", "rmse", "fit_pct", "bic"}
    for row in d["ranking"]:
        assert set(row) >= {"effect", "rmse_after", "fit_pct_after", "delta_bic", "p_value", "evidence", "explanation"}
    assert [r["weight"] for r in d["ranking"]] == sorted((r["weight"] for r in d["ranking"]), reverse=True)
    assert d["verdict"]["missing_effect"] == "electrode_resistance" and 0 <= d["verdict"]["confidence"] <= 1
    html = (tmp_path / "d" / "index.html").read_text()
    assert "data:image/png;base64" in html and "src='http" not in html
    for f in ("where_it_fails.png", "ranking.png", "overlay.png", "error_breakdown.png"):
        assert (tmp_path / "d" / f).stat().st_size > 1000
    dev = load_device(tmp_path / "d" / out["applied"]["written"])
    assert "electrode_resistance" in dev.default_effects
    assert dev["Rs"] == pytest.approx(case.truth_params["Rs"], rel=0.05)


def test_cli_diagnose(tmp_path, capsys):
    from nnmodel.app.cli import main
    case = hidden_effect_case("solvent_diffusion", seed=2)
    paths = []
    for k, m in enumerate(case.measurements):
        paths.append(str(write_timeseries(m, tmp_path / f"rec{k}.csv")))
    rc = main(["diagnose", *paths, "--device", "ipmc_pt_eg", "--effects", "none", "--out", str(tmp_path / "o"),
               "--apply", "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "Verdict: explained." in text and "Which effect: solvent_diffusion (confidence high" in text, text
    assert "Is the model adequate: yes" in text
    raw = yaml.safe_load(next((tmp_path / "o").glob("*.yaml")).read_text())
    assert "solvent_diffusion" in raw["default_effects"]
    rc = main(["diagnose", paths[0], "--effects", "none", "--free", "kf,nonsense", "--out", str(tmp_path / "x")])
    assert rc == 2
    assert "unknown parameter 'nonsense'" in capsys.readouterr().err


def test_cli_demo(tmp_path, capsys):
    from nnmodel.app.cli import main
    rc = main(["demo", "hidden-effect", "--effect", "viscoelastic", "--seed", "1", "--out", str(tmp_path / "demo")])
    assert rc == 0
    text = capsys.readouterr().out
    assert "step 1: candidates, most to least supported" in text
    assert "Which effect: viscoelastic" in text
    assert "-> correct" in text
    assert (tmp_path / "demo" / "index.html").exists()


def test_identify_extra_starts_backwards_compatible():
    """The one addition to physics.identify: fit_lsq(..., extra_starts=[θ, ...])."""
    from physics.compare import FRFOptions
    from physics.identify import IdentificationProblem, build_targets, fit_lsq
    case = hidden_effect_case(None, seed=0)
    targets = build_targets(case.measurements, frf_options=FRFOptions())
    prob = IdentificationProblem("ipmc_pt_eg", "none", targets, ["kf", "beta_f"])
    f1 = fit_lsq(prob, n_starts=2)
    f2 = fit_lsq(prob, n_starts=2, extra_starts=[[0.002, 1e-3]])
    assert len(f2.starts) == len(f1.starts) + 1
    assert f2.starts[-1]["theta_start"] == pytest.approx([0.002, 1e-3])
    assert f2.theta == pytest.approx(f1.theta, rel=1e-4)
    with pytest.raises(InputError, match="one value per free parameter"):
        fit_lsq(prob, n_starts=1, extra_starts=[[0.002]])


def test_lag_by_lag_correlations_equal_the_fft_ones(monkeypatch):
    """Long records with few lags are correlated lag by lag (no 2n FFT buffers); both
    routes are the same estimator."""
    rng = np.random.default_rng(4)
    e = rng.normal(size=20_000)
    u = np.convolve(rng.normal(size=e.size), np.ones(7), "same") + 0.5 * e
    assert stats._direct(e.size, 30) and not stats._direct(e.size, 5000)
    direct = stats.autocorrelation(e, 30), stats.cross_correlation(u, e, 30)[1]
    monkeypatch.setattr(stats, "_direct", lambda n, m: False)
    fft = stats.autocorrelation(e, 30), stats.cross_correlation(u, e, 30)[1]
    np.testing.assert_allclose(direct[0], fft[0], atol=1e-12)
    np.testing.assert_allclose(direct[1], fft[1], atol=1e-12)
    assert abs(direct[1][30]) > 5 * 2.576 / np.sqrt(e.size)   # lag 0: u contains e, far outside the 99 % band


def test_a_diagnosis_with_no_candidate_refits_the_own_effects_or_stands_still():
    """The draft rounds refit the model's own effects beside the kept drafts through a diagnosis
    with no candidate (``refit_own``): it returns one step, the model as fitted when nothing is
    refitted, and a verdict (an empty selection once ended in an IndexError)."""
    case = hidden_effect_case("solvent_diffusion", seed=0, duration=20.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = diagnose(case.measurements, case.device, case.base_effects, candidates=[], check_support=False,
                       selection=SelectionOptions(max_effects=1, backward=False, refit_own=True))
    assert len(res.steps) == 1 and res.steps[0].decision.pick is None
    assert res.final.rmse <= res.base.rmse and res.verdict.status and json.dumps(res.to_dict(), default=str)


def test_the_analysis_rate_keeps_the_models_own_error_below_the_noise():
    """A 1 kHz multisine record (0.1–20 Hz, three periods) of the bare thesis strip, its exact
    periodic response from the closed-form frequency response and 1 µm noise: the diagnosis's
    prediction at its analysis rate (decimated for speed) stays within 0.1 % of the exactly
    decimated response, below the noise.  At 5× the excited band (the old rate, 111 Hz) the cubic
    hold's droop near the resonance made it 1.5 % (13 µm on a 0.9 mm RMS motion)."""
    import physics
    from physics.diagnose.candidates import predict
    from physics.diagnose.records import PAD, _decimate
    from physics.model import ActuatorModel
    fs, period = 1000.0, 20.0
    sig = signals.multisine(0.5, 0.1, 20.0, period, periods=3, fs=fs, seed=1)
    n = int(round(period * fs))
    f, V = np.fft.rfftfreq(n, 1 / fs), np.fft.rfft(sig.v[:n])
    on = np.abs(V) > 1e-9 * np.abs(V).max()
    H = np.zeros(f.size, complex)
    H[on] = physics.frequency_response("ipmc_pt_eg", "none", f[on], rh=60).deflection
    y = np.tile(np.fft.irfft(H * V, n), 3)
    noisy = y + 1e-6 * np.random.default_rng(0).standard_normal(y.size)
    [rec] = prepare_records([TimeSeries(sig.t, sig.v, noisy, rh=np.full(y.size, 60.0), source="ms")])
    assert rec.q > 1                                     # decimated: the test is about the analysis rate
    yh = predict(ActuatorModel("ipmc_pt_eg", "none"), rec)
    yd = _decimate(y, rec.q)[PAD:]
    err = np.sqrt(np.mean((yh - yd) ** 2))
    assert err < 1e-3 * np.sqrt(np.mean(yd ** 2)) and err < 0.5e-6


def test_a_jump_is_placed_within_its_sample_but_a_real_delay_stays_in_the_error(monkeypatch):
    """A 0.5 V step logged at 250 Hz whose edge falls 1/8 or 7/8 of a sample after the last
    sample at 0 V (simulated on a grid 8× finer): the samples cannot say where the jump was, the
    ringing of the resonance after it can.  Shifting the prediction by δ ≤ ½ sample (2 ms) to
    first order leaves the second-order term, ~ω δ/2 ≤ 0.15 of the first-order error for the
    strip's ~20 Hz ringing: so in the first 0.5 s after the edge the placed prediction errs by less
    than 0.15× the prediction with the jump at the interval's middle (measured: 2.1 and 0.56 µm
    against 29 and 21 µm).  A response 1.5 samples late (6 ms, a lag the records resolve) cannot be
    taken by a shift bounded to half a sample: that removes at most about a third of the
    first-order error (½ of 1.5 samples), so more than half of it stays (0.70; unbounded: 0.36)."""
    import physics
    import physics.diagnose.candidates as cand
    from physics.model import ActuatorModel
    fs, over = 250.0, 8
    tf = np.arange(int(12 * fs * over)) / (fs * over)
    model = ActuatorModel("ipmc_pt_eg", "none")
    for k0, late in ((8 * 500 + 1, 0), (8 * 500 + 7, 0), (8 * 500 + 4, 12)):
        vf = np.where((tf >= tf[k0]) & (tf < tf[k0] + 5.0), 0.5, 0.0)
        yf = physics.simulate("ipmc_pt_eg", "none", tf, np.roll(vf, late), rh=60, hold="linear").deflection
        t, v, y = tf[::over], vf[::over], yf[::over]
        noisy = y + 1e-6 * np.random.default_rng(1).standard_normal(y.size)
        [rec] = prepare_records([TimeSeries(t, v, noisy, rh=np.full(t.size, 60.0), source="step")])
        assert rec.kind == "steps" and rec.q == 1 and rec.steps.size == 2
        errs = []
        for placed in (True, False):
            with monkeypatch.context() as m:
                if not placed:
                    m.setattr(cand, "place_edges", lambda yh, rec: yh)
                yh = cand.predict(model, rec)
            w = (t[:yh.size] >= 2.0) & (t[:yh.size] < 2.5)
            errs.append(np.sqrt(np.mean((y[:yh.size] - yh)[w] ** 2)))
        if late:
            assert errs[0] > 0.5 * errs[1], errs
        else:
            assert errs[0] < 0.15 * errs[1], (k0, errs)
