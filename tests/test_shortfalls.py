"""Why a network falls short, in plain words: each finding is tied to the evidence that
triggers it (and none is given when a network falls short nowhere)."""
from types import SimpleNamespace

from nnmodel.shortfalls import BIAS_RATIO, explain


def _row(test, one_rmse=1.0, one_bias=0.0):
    return {"free_run": {"test": {"nrmse": test}}, "one_step": {"test": {"rmse_m": one_rmse, "mean_error": one_bias}}}


def _model(n_parameters=100, uses_rh=True, memory=None):
    return SimpleNamespace(n_parameters=n_parameters, uses_rh=uses_rh, memory_filters=16 if memory else 0,
                           memory_max_s=200.0, memory_range_=memory)


FACTS = dict(train_samples=100_000, record_s=60.0, rh_levels=[40.0, 60.0, 80.0], train_mean=0.0, test_mean=0.0,
             output_std=1e-3, unit="m", quantity="deflection", train_windows=5000.0)
RESULTS = {"linear": _row(0.10), "physics": _row(0.05)}


def test_no_finding_when_the_network_beats_linear_and_physics_without_bias():
    assert explain("ff", _row(0.04, one_bias=0.1), RESULTS, _model(), FACTS) == []


def test_worse_than_linear_with_few_independent_windows_says_so_and_what_to_do():
    f = explain("narx", _row(0.2), RESULTS, _model(n_parameters=50_000), {**FACTS, "train_windows": 20.0})
    assert len(f) == 1 and "above the linear model's (10.00 %)" in f[0]["finding"]
    assert f[0]["causes"][0]["cause"].startswith("too few independent windows: the training data hold 20 (the "
                                                 "output's correlation time is 5000 samples)")
    assert "about 250,000 training samples give 50 windows" in f[0]["causes"][0]["action"]


def test_a_dropped_correction_is_named_and_gets_no_window_advice():
    """A network whose correction was dropped ties the linear row: the finding says so, gives
    the reason, and does not blame its size (its parameters were never used)."""
    m = _model(n_parameters=50_000)
    m.reference_start_ = {"reference": "linear", "start": {"kept": "network"},
                          "end": {"kept": "linear", "validation_nrmse_reference": 0.30, "validation_nrmse_network": 0.25,
                                  "reason": "cross-validation over 3 folds: its NRMSE gain is not larger than its spread"}}
    (f,) = explain("ff", _row(0.10), RESULTS, m, {**FACTS, "train_windows": 20.0})
    assert f["finding"].startswith("ff: it is its linear start (free-run test error 10.00 %)")
    causes = [c["cause"] for c in f["causes"]]
    assert causes[0].startswith("its correction was dropped: on validation it lowered the error below its linear "
                                "start (30 % → 25 %), but cross-validation over 3 folds")
    assert "record more" in f["causes"][0]["action"] and not any("windows" in c for c in causes)


def test_saturation_and_an_integrator_are_named_from_their_evidence():
    facts = {**FACTS, "saturation": {"kind": "saturates", "share": 0.8, "range": [-1, 1]},
             "integrating": {"pole": 0.9999, "time_constant_samples": 1e4, "record_samples": 1000.0,
                             "static_gain": 300.0}}
    (f,) = explain("ff", _row(0.2), RESULTS, _model(), facts)
    causes = [c["cause"] for c in f["causes"]]
    assert causes[0].startswith("the output saturates: a cubic term of the linear model's output explains 80 %")
    assert causes[1].startswith("an integrating plant: the linear model's slowest pole (0.9999) decays over 10,000 "
                                "samples, against training records of 1,000 samples")


def test_a_biased_residual_with_shifted_output_means_is_an_offset_not_removed():
    facts = {**FACTS, "test_mean": 2e-3}
    f = explain("ff", _row(0.04, one_rmse=2e-3, one_bias=(BIAS_RATIO + 0.4) * 2e-3), RESULTS, _model(), facts)
    assert "one-step residual is biased: it sits 1.80 mm off zero (90 % of its RMS)" in f[0]["finding"]
    cause = f[0]["causes"][0]
    assert cause["cause"].startswith("offset not removed") and "by 2.00 mm (2.0 standard deviations)" in cause["cause"]
    assert "subtract its rest value" in cause["action"]


def test_too_few_rh_levels_and_short_records_for_slow_dynamics():
    facts = {**FACTS, "rh_levels": [40.0, 80.0], "record_s": 30.0}
    f = explain("lstm", _row(0.08), RESULTS, _model(memory=(0.01, 15.0)), facts)
    causes = [c["cause"] for c in f[0]["causes"]]
    assert any(c.startswith("too few RH levels: trained at 2 (40, 80 %)") for c in causes)
    assert any(c.startswith("records may be too short for slow dynamics") for c in causes)
    assert all("physics model's (5.00 %)" in x["finding"] for x in f)
    other = explain("lstm", _row(0.08), RESULTS, _model(uses_rh=False), {**facts, "record_s": 1e4})
    assert not any(c["cause"].startswith("too few RH levels") for c in other[0]["causes"])


def test_a_shortfall_without_a_cause_in_the_data_points_to_tuning():
    f = explain("gru", _row(0.2), RESULTS, _model(), FACTS)
    (cause,) = f[0]["causes"]
    assert cause["cause"].startswith("no cause found in the data") and "--models gru --tune 20" in cause["action"]


def test_a_network_kept_on_validation_but_worse_on_test_says_the_validation_did_not_foresee_it():
    m = _model()
    m.reference_start_ = {"reference": "linear", "end": {"kept": "network", "validation_nrmse_reference": 0.05,
                                                          "validation_nrmse_network": 0.04, "validation_gain": 9e-4,
                                                          "validation_gain_se": 3e-4}}
    f = explain("narx", _row(0.12), RESULTS, m, {**FACTS, "validation_records": 0})
    cause = f[0]["causes"][0]
    assert cause["cause"].startswith("its validation data could not foresee it: there it beat its linear start "
                                     "(5.00 % → 4.00 % NRMSE, a gain of 3.0 standard errors) on the tails of the "
                                     "training records")
    assert "--validation FILE" in cause["action"]


def test_a_correction_dropped_within_its_uncertainty_is_said_on_the_page():
    """"Equals its linear start" only where the row scores the linear row's test error; a row
    that scores otherwise (31.08 % against 30.88 %) is never said to equal it."""
    from nnmodel.explain import dropped
    end = {"kept": "linear", "validation_nrmse_reference": 0.05, "validation_nrmse_network": 0.049,
           "validation_gain": 1e-4, "validation_gain_se": 1e-4, "reason": "within 2 standard errors"}

    def summary(narx_test):
        return {"models": {"linear": {"kind": "linear ARX", "free_run": {"test": {"nrmse": 0.3088}}},
                           "narx": {"kind": "narx", "free_run": {"test": {"nrmse": narx_test}},
                                    "reference_start": {"reference": "linear", "end": end}},
                           "ff": {"kind": "ff", "reference_start": {"reference": "linear", "end": {"kept": "network"}}}}}
    (n,) = dropped(summary(0.3088))
    assert n["text"].startswith("narx equals its linear start (the linear row, 30.9 % test NRMSE): its correction "
                                "lowered the validation error (5.00 % → 4.90 % NRMSE) but was dropped: within 2")
    (n,) = dropped(summary(0.3108))
    assert n["text"].startswith("narx runs its linear start (31.1 % test NRMSE against the linear row's 30.9 %)")
    assert "equals" not in n["text"]
