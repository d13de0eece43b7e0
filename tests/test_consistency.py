"""One rule everywhere (issue 35 item 4/5): the start-up rule in train-compare, predict and
compare; the linear row as a bundle; one vs-linear format; engineering units; the batch-size
message; RH levels grouped with the hygrometer's tolerance; the accelerator choice; a grey box
never below its better parent; the cross-validation protocol on the card."""
import json
import re
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from scipy.signal import lfilter

from nnmodel.bundle import load, save
from nnmodel.app.cli import main
from nnmodel.data import Experiment
from nnmodel.linear import fit_linear
from nnmodel.models.ff import as_network
from nnmodel.recipes import make_model
from nnmodel.startup import START_SAMPLES, free_run
from nnmodel.traincompare import (_fallbacks, _linear_runner, _physics_base_row, format_table, network_runner,
                                  page_rows, rh_levels, vs_linear_text)
from physics.errors import InputError
from physics.io.timeseries import TimeSeries, read_timeseries, write_timeseries

FS = 10.0


def _record(n, seed, rh=50.0):
    """A lag with a mild cubic, random steps, an output in mm-sized metres, RH constant."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n), rng.integers(2, 12, n))[:n]
    a = np.exp(-1 / (FS * 1.5))
    x = lfilter([1 - a], [1, -a], u)
    y = 2e-3 * (x - 0.2 * x ** 3) + 1e-5 * rng.normal(size=n) + 3e-4
    return Experiment(u, y, np.full(n, rh), FS)


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    """A quickly fitted network (least squares, NARX form with output feedback) and a test CSV."""
    d = tmp_path_factory.mktemp("consistency")
    train = [_record(1500, 1)]
    m = make_model("ff", {"max_epochs": 0, "structures": None, "na": 4, "nb": 6, "memory_filters": 0,
                          "inputs": "voltage", "progress_bar": False, "cv_folds": 1})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m.fit(train, None)
    path = save(m, d / "ff", output=("deflection", "m"))
    rec = _record(800, 7)
    csv = d / "test.csv"
    write_timeseries(TimeSeries(time=np.arange(rec.u.size) / FS, voltage=rec.u, deflection=rec.y, rh=rec.rh), csv)
    twin = load(path).model     # the same network again, playing a grey box that validates alike
    twin.reference_start_ = {"reference": "physics", "end": {"kept": "physics"}}
    return SimpleNamespace(dir=d, path=path, model=m, rec=rec, csv=csv, train=train, model_copy=twin)


def test_predict_compare_and_train_compare_start_a_network_alike_and_score_it_alike(bundle, capsys):
    """The same bundle on the same record: train-compare's runner, `eap predict` and
    `eap compare` hand it the first max(50, n_init) measured outputs and score the rest; the
    three RMSE agree (they differed when compare started from rest and predict scored the
    samples it was handed)."""
    rec = bundle.rec
    yh, w = network_runner(load(bundle.path).model)(rec)
    assert w == max(START_SAMPLES, bundle.model.n_init_)
    np.testing.assert_array_equal(yh[:w], rec.y[:w])
    rmse_tc = float(np.sqrt(np.mean((rec.y[w:] - yh[w:]) ** 2)))
    out = bundle.dir / "pred.csv"
    assert main(["predict", "--model", str(bundle.path), "--input", str(bundle.csv), "--out", str(out),
                 "--overwrite"]) == 0
    printed = capsys.readouterr().out
    np.testing.assert_allclose(read_timeseries(out).deflection, yh, rtol=0, atol=1e-12)
    meta = (out.with_suffix(".yaml")).read_text()
    assert f"initialised_from_measured_samples: {w}" in meta
    assert f"after the first {w} samples" in printed
    cmp = bundle.dir / "cmp"
    assert main(["compare", str(bundle.csv), "--model", str(bundle.path), "--out", str(cmp), "--quiet"]) == 0
    rep = json.loads((cmp / "report.json").read_text())
    tm = rep["records"][0]["time_metrics"]
    assert tm["rmse"] == pytest.approx(rmse_tc, rel=1e-9) and tm["offset_removed_m"] == 0.0
    assert rep["settings"]["offset"] == "start"


def test_the_offset_rule_shifts_a_model_started_from_rest_by_its_window_error():
    y = np.r_[np.full(50, 1.0), np.linspace(1, 2, 50)]
    yh, w = free_run(lambda y0: np.zeros_like(y) if y0 is None else None, y, 0)
    assert w == 50 and np.allclose(yh, 1.0)     # the physics row: the sensor's zero from the window
    with pytest.raises(InputError, match="at least 52"):
        free_run(lambda y0: y, y[:51], 0)


def test_the_linear_row_is_a_bundle_that_predict_runs_and_scores_the_same(bundle, capsys):
    lin = fit_linear(bundle.train, None, 0.2)
    net = as_network(lin, bundle.train)
    a, w = _linear_runner(lin)(bundle.rec)
    b, w2 = network_runner(net)(bundle.rec)
    assert w == w2
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-6 * np.std(bundle.rec.y))
    path = save(net, bundle.dir / "linear", output=("deflection", "m"), overwrite=True)
    out = bundle.dir / "lin.csv"
    assert main(["predict", "--model", str(path), "--input", str(bundle.csv), "--out", str(out), "--overwrite"]) == 0
    np.testing.assert_allclose(read_timeseries(out).deflection, a, rtol=0, atol=1e-6 * np.std(bundle.rec.y))


def test_engineering_units_in_predict_and_everywhere_quantity_is_used(bundle, capsys):
    from physics.pages.columns import quantity
    assert quantity(2.9e-3, "m") == "2.90 mm" and quantity(3.11e-5, "m") == "31.1 µm"
    assert quantity(0.0012, "V") == "1.20 mV" and quantity(35.0, "V") == "35.0 V"
    big = bundle.dir / "big.csv"   # an error of millimetres reads in mm, not thousands of µm
    rec = bundle.rec
    write_timeseries(TimeSeries(time=np.arange(rec.u.size) / FS, voltage=rec.u, deflection=rec.y + 3e-3 * np.sign(
        np.sin(np.arange(rec.u.size) / 40.0)), rh=rec.rh), big)
    assert main(["predict", "--model", str(bundle.path), "--input", str(big), "--out", str(bundle.dir / "b.csv"),
                 "--overwrite"]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"RMSE \d\.\d\d mm", printed), printed


def test_vs_linear_reads_the_same_on_the_page_and_in_the_terminal():
    assert vs_linear_text(13.8) == "+13.8 %" and vs_linear_text(-4.24) == "−4.2 %" and vs_linear_text(None) == "–"
    row = lambda nrmse, vs: {"kind": "a row", "n_parameters": 10, "train_time_s": 1.0, "inference_samples_per_s": 1e5,  # noqa: E731
                             "free_run": {"test": {"nrmse": nrmse, "rmse_m": nrmse * 1e-4}}, "vs_linear_pct": vs}
    models = {"linear": row(0.30, None), "ff": row(0.34, 13.8)}
    table = format_table({"models": models, "output": {"name": "deflection", "unit": "m"}})
    assert "+13.8 %" in table and "RMSE µm" in table and " 34.0 " in table
    page = {r["model"]: r for r in page_rows(models)}
    assert page["ff"]["vs linear"] == "+13.8 %" and page["ff"]["rmse_test_m"] == pytest.approx(3.4e-5)


def test_the_batch_size_message_says_what_the_windows_allow():
    from nnmodel.training import batch_message
    assert batch_message(5, 32, 1) == ("5 training windows: batch size 32 lowered to 1, one window per optimizer "
                                       "step, 5 steps per epoch (8 would need 8 windows)")
    assert batch_message(100, 256, 12) == ("100 training windows: batch size 256 lowered to 12, so that an epoch "
                                           "has at least 8 optimizer steps (9)")


def test_rh_levels_are_grouped_within_the_hygrometer_tolerance():
    entries = [{"path": p, "rh_pct": v} for p, v in (("a", 69.999), ("b", 70.0003), ("c", 40.2), ("d", 41.5))]
    assert rh_levels(entries) == {"a": 70.0, "b": 70.0, "c": 40.0, "d": 42.0}
    assert rh_levels(entries, 2.0) == {"a": 70.0, "b": 70.0, "c": 41.0, "d": 41.0}


def test_eap_dataset_lists_one_training_level_for_hygrometer_jitter(tmp_path):
    from nnmodel.measured import build_dataset
    files = []
    for k, rh in enumerate((69.999, 70.0003, 40.0)):
        r = _record(300, k + 1, rh)
        files.append(tmp_path / f"r{k}.csv")
        write_timeseries(TimeSeries(time=np.arange(300) / FS, voltage=r.u, deflection=r.y, rh=r.rh), files[-1])
    ds = build_dataset(tmp_path / "ds", train=[str(f) for f in files])
    assert json.loads((ds / "dataset.json").read_text())["rh_levels"]["train"] == [40.0, 70.0]


def test_accelerator_auto_takes_a_gpu_only_when_torch_sees_one(monkeypatch):
    from nnmodel import training
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert training.resolve_accelerator("auto") == "cpu" and training.resolve_accelerator("cpu") == "cpu"
    with pytest.raises(InputError, match="torch sees no GPU"):
        training.resolve_accelerator("gpu")
    with pytest.raises(InputError, match="expected one of auto, cpu, gpu"):
        training.resolve_accelerator("tpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda i=0: "Fake H100")
    assert training.resolve_accelerator("auto") == "gpu" and training.resolve_accelerator("cpu") == "cpu"
    assert training.device_name("gpu") == "gpu (Fake H100)" and training.device_name("cpu") == "cpu"


def test_train_compare_passes_the_accelerator_to_every_model_unless_set(monkeypatch, tmp_path):
    import nnmodel.traincompare as tc
    seen = {}

    def fake(ds, dataset, models, out, overrides, *rest):
        seen["args"] = rest
        return {}
    monkeypatch.setattr(tc, "_train_compare", fake)
    monkeypatch.setattr(tc, "load_dataset", lambda p: None)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    tc.train_compare(tmp_path / "nothing", ["ff"], tmp_path / "out", progress=False)
    assert seen["args"][-1] == "cpu"


def test_same_seed_and_device_give_the_same_weights():
    train = [_record(600, 3)]
    states = []
    for _ in range(2):
        m = make_model("narx", {"max_epochs": 2, "hidden": 8, "horizon": 20, "stride": 20, "memory_filters": 0,
                                "inputs": "voltage", "progress_bar": False, "cv_folds": 1, "accelerator": "cpu"})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m.fit(train, None)
        states.append(m.net_.state_dict())
        assert m.training_summary_["device"] == "cpu"
    assert all(torch.equal(states[0][k], states[1][k]) for k in states[0])


def test_a_physics_part_already_shown_by_the_physics_row_is_not_repeated():
    pm = SimpleNamespace(device=SimpleNamespace(name="dev"), effect_ids=["a", "b"])
    hybrid = SimpleNamespace(_physics_model=lambda: pm)
    assert _physics_base_row(hybrid, {"device": "dev", "effects": ["a", "b"]}, None, []) is None


def test_a_grey_box_that_validates_worse_than_a_pure_network_falls_back_to_it(bundle, tmp_path):
    grey = make_model("ff", {"max_epochs": 0, "structures": None, "na": 0, "nb": 2, "memory_filters": 0,
                             "inputs": "voltage", "progress_bar": False, "cv_folds": 1, "linear_start": False})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        grey.fit(bundle.train, None)
    grey.reference_start_ = {"reference": "physics", "end": {"kept": "physics"}}
    results = {"ff": {"kind": "ff", "free_run": {"test": {"nrmse": 0.1}}, "validation": {"nrmse": 0.05},
                      "n_parameters": 1, "train_time_s": 1.0},
               "hybrid": {"kind": "hybrid", "free_run": {"test": {"nrmse": 0.3}}, "validation": {"nrmse": 0.2},
                          "n_parameters": 2, "train_time_s": 1.0}}
    ds = SimpleNamespace(hash="h", output=SimpleNamespace(name="deflection", unit="m"),
                         records=lambda split: bundle.train if split == "train" else [])
    assert _fallbacks(results, {"ff": bundle.model, "hybrid": grey}, tmp_path, ds) == ["hybrid"]
    assert results["hybrid"]["falls_back_to"] == "ff" and results["hybrid"]["free_run"]["test"]["nrmse"] == 0.1
    assert results["hybrid"]["own"]["validation"]["nrmse"] == 0.2
    assert "standard errors" in results["hybrid"]["fallback_evidence"]   # beyond the keep rule's uncertainty
    assert json.loads((tmp_path / "models" / "hybrid" / "card.json").read_text())["falls_back_from"] == "hybrid"
    from nnmodel.explain import hybrid as hybrid_note
    (n,) = hybrid_note({"models": results})
    assert "falls back to ff" in n["text"]
    # a parent that validates lower only within the uncertainty is not fallen back to
    same = {k: {**v, "validation": {"nrmse": 0.2 if k == "hybrid" else 0.19}} for k, v in results.items()
            if k in ("ff",)}
    same["hybrid"] = {"kind": "hybrid", "free_run": {"test": {"nrmse": 0.3}}, "validation": {"nrmse": 0.2},
                      "n_parameters": 2, "train_time_s": 1.0}
    assert _fallbacks(same, {"ff": bundle.model, "hybrid": bundle.model_copy}, tmp_path / "2", ds) == []
    assert same["hybrid"]["parent_not_better"].startswith("ff validates lower (19 % against 20 %) but not beyond")
