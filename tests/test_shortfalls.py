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
    # a correction that lowered nothing (its trained correction is zero: 23.4 % → 23.4 %) is not
    # said to have lowered the error; its shortfall finding says it was no better at all
    end.update(validation_nrmse_network=0.05, reason="cross-validation over 2 folds: within its uncertainty")
    assert dropped(summary(0.3088)) == []


def test_an_integrator_in_a_closed_loop_is_said_once_with_its_loop():
    """Both findings: the integrator refers to the closed loop instead of guessing one, and the
    k-step-ahead advice is given once."""
    loop = {"share": 0.12, "input_share": 0.02, "F": 27.0, "p": 1e-40, "input_lags": 20, "output_lags": 10,
            "samples": 2000}
    integ = {"pole": 1.0, "time_constant_samples": float("inf"), "record_samples": 1000.0, "static_gain": float("inf")}
    m = _model()
    m.get_params = lambda: {"na": 10}
    (f,) = explain("ff", _row(0.2), RESULTS, m, {**FACTS, "integrating": integ, "feedback": loop})
    (i, cause_i), (c, cause_c) = [(k, x) for k, x in enumerate(f["causes"])
                                  if x["cause"].startswith(("an integrating plant", "a closed loop"))]
    assert "its data come from a closed loop, below" in cause_i["cause"] and "usually" not in cause_i["cause"]
    assert cause_c["cause"].startswith("a closed loop: the input was produced by a controller reacting to the "
                                       "measured output — the past 10 outputs predict 12 %")
    assert "--steps-ahead" in cause_i["action"] and "--steps-ahead" not in cause_c["action"]
    (alone,) = explain("ff", _row(0.2), RESULTS, m, {**FACTS, "feedback": loop})
    assert "with neither, judge it also by k-step-ahead prediction" in alone["causes"][0]["action"]


def _feedback_of(records):
    from nnmodel.linear import fit_linear
    from nnmodel.shortfalls import feedback, feedback_statistic
    lin = fit_linear(records, None, 0.2)
    return feedback(records, lin), feedback_statistic(records, lin)


def test_a_controller_in_the_loop_is_detected_and_an_exogenous_drive_is_not():
    """A positioner under a P controller (tests/test_shortfalls_followed.py) is a closed loop; the
    same plant driven by a signal of the same spectrum, and the loop's reference → output, are not."""
    from nnmodel.data import Experiment
    from test_shortfalls_followed import open_loop_twin, positioner
    closed, stat = _feedback_of([Experiment(*positioner(2000, 1), None, 1.0)])
    assert closed is not None and closed["share"] > 0.05 and closed["p"] < 1e-10
    for data in (open_loop_twin(positioner, 2000, 1), positioner(2000, 1, reference=True)):
        found, stat = _feedback_of([Experiment(*data, None, 1.0)])
        assert found is None and stat["share"] < 0.01


def test_the_example_records_and_a_generated_dataset_are_open_loop(tmp_path):
    """data/tank and data/ipmc_creep (read as `eap dataset` reads them) and an `eap generate`
    dataset: no closed loop."""
    from pathlib import Path

    from nnmodel.dataset import generate, load_dataset
    from nnmodel.measured import ReadOptions, build_dataset
    from physics.io.record import OutputQuantity
    from physics.io.timeseries import parse_column_map
    from test_dataset import TINY
    data = Path(__file__).resolve().parents[1] / "data"
    sets = {"tank": dict(read=ReadOptions(columns=parse_column_map(
                             "time=t [s],voltage=pump [V],level=level [cm]", OutputQuantity.parse("level:cm"))),
                         output="level:cm"),
            "ipmc_creep": dict(read=ReadOptions(columns=parse_column_map(
                "time=Time (s),voltage=Drive (V),deflection=Tip (mm):mm")))}
    folders = [build_dataset(tmp_path / name, train=sorted(str(f) for f in (data / name).glob("*.csv")), **kw)
               for name, kw in sets.items()]
    folders.append(generate(tmp_path / "generated", dict(TINY), progress=False))
    for folder in folders:
        found, stat = _feedback_of(load_dataset(folder).records("train"))
        assert found is None and stat["share"] < 0.01, folder
