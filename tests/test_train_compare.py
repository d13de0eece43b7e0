"""eap train-compare on a tiny dataset (structure, physics reference, bundles)."""
import json

import numpy as np
import pytest

from nnmodel.app.commands.train_compare import parse_overrides
from nnmodel.dataset import generate
from nnmodel.traincompare import format_table, train_compare
from physics.errors import InputError

TINY = dict(fs_Hz=100.0, f_max_Hz=20.0, duration_s=6.0, train_rh_pct=[40, 100], heldout_rh_pct=[70],
            excitations=["sweep", "noise"], validation_per_rh=1, test_per_train_rh=1, test_per_heldout_rh=1,
            varying_rh={"train": 0, "test": 1, "range_pct": [40, 100]},
            measurement_like={"effects": ["nonlinear_charge"], "count": 1, "rh_pct": [55]})


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("tc")
    ds = generate(d / "ds", dict(TINY), progress=False)
    summary = train_compare(ds, ["rbf", "ff"], d / "run", progress=False,
                            overrides={"rbf": {"n_centres": 20, "nb": 10},
                                       "ff": {"max_epochs": 2, "hidden": 8, "nb": 10}})
    return d / "run", summary


def test_outputs_and_groups(run):
    out, summary = run
    for f in ("compare.json", "metrics.csv", "index.html", "bode.png", "error_by_rh.png", "overlay_heldout_rh.png"):
        assert (out / f).is_file(), f
    data = json.loads((out / "compare.json").read_text())
    assert set(data["models"]) == {"physics", "linear", "rbf", "ff"}
    for name in ("rbf", "ff"):
        m = data["models"][name]
        assert {"train_rh", "heldout_rh", "varying_rh", "measurement_like", "test"} <= set(m["free_run"])
        assert m["n_parameters"] > 0 and m["inference_samples_per_s"] > 0 and m["train_time_s"] > 0
        assert m["rh_range_trained_pct"] == [pytest.approx(40, abs=1), pytest.approx(100, abs=1)]
    assert "model" in data["best_heldout"]
    assert "physics" in format_table(summary)


def test_every_row_is_measured_against_the_linear_yardstick(run):
    """The linear row is the best ARX on the same split (orders chosen on validation data),
    scored like the networks; every other row says how far below or above it it lies."""
    from nnmodel.linear import NA_GRID, NB_GRID
    _, summary = run
    models = summary["models"]
    lin = models["linear"]
    card = lin["linear"]
    assert card["na"] in NA_GRID and card["nb"] in NB_GRID and lin["n_parameters"] == card["na"] + card["nb"] + 2
    scores = card["report"]["scores"]
    chosen = scores[f"{card['na']},{card['nb']}"]
    assert len(scores) == len(NA_GRID) * len(NB_GRID)
    assert chosen <= 1.01 * min(v for v in scores.values() if v is not None)
    ref = lin["free_run"]["test"]["nrmse"]
    for name in ("physics", "rbf", "ff"):
        ratio = models[name]["free_run"]["test"]["nrmse"] / ref
        assert models[name]["vs_linear_pct"] == pytest.approx(100 * (ratio - 1))
    assert "vs linear" in format_table(summary) and summary["best_heldout"]["model"] in ("rbf", "ff")


def test_physics_reference_scores_at_the_noise_floor_except_measurement_like(run):
    _, summary = run
    ph = summary["models"]["physics"]["free_run"]
    floor = summary["noise_floor_m"]
    # the simulator that generated the data: its residual is the sensor (noise + drift)
    assert ph["heldout_rh"]["rmse_m"] < 3 * floor
    # the measurement-like record has physics (nonlinear_charge) the generator lacked
    assert ph["measurement_like"]["rmse_m"] > 10 * ph["heldout_rh"]["rmse_m"]


def test_bundles_are_saved_with_the_dataset_hash_and_reload(run):
    import nnmodel
    out, summary = run
    b = nnmodel.load(out / "models" / "rbf")
    card = json.loads((out / "models" / "rbf" / "card.json").read_text())
    assert card["dataset_hash"] == summary["dataset_hash"]
    y = b.predict(np.zeros(300), rh=60.0, fs=100.0)
    assert y.shape == (300,) and np.all(np.isfinite(y))


def test_override_parsing():
    assert parse_overrides(["narx.hidden=64", "ff.lr=1e-3"]) == {"narx": {"hidden": 64}, "ff": {"lr": 1e-3}}
    with pytest.raises(InputError, match="MODEL.KEY=VALUE"):
        parse_overrides(["hidden=3"])


def test_models_trained_on_two_workers_match_the_serial_run(run, tmp_path):
    """One task per model on the execution layer: same scores, same weights as in one process."""
    from physics.execution.parallel import ParallelSettings
    out, summary = run
    data = json.loads((out / "compare.json").read_text())["dataset"]
    par = train_compare(data, ["rbf", "ff"], tmp_path / "par", progress=False, settings=ParallelSettings(2),
                        overrides={"rbf": {"n_centres": 20, "nb": 10}, "ff": {"max_epochs": 2, "hidden": 8, "nb": 10}})
    for name in ("rbf", "ff"):
        assert par["models"][name]["free_run"] == summary["models"][name]["free_run"]
        a = json.loads((out / "models" / name / "card.json").read_text())["weights"]["sha256"]
        b = json.loads((tmp_path / "par" / "models" / name / "card.json").read_text())["weights"]["sha256"]
        assert a == b, name


def test_devices_and_workers_are_exclusive(run, capsys):
    from nnmodel.app.cli import main
    out, _ = run
    data = json.loads((out / "compare.json").read_text())["dataset"]
    assert main(["train-compare", data, "--devices", "2", "--workers", "2", "--out", str(out.parent / "x")]) == 2
    assert "use one of them" in capsys.readouterr().err


def test_tuning_gives_the_same_trials_and_bundle_on_one_and_two_workers(run, tmp_path):
    """--tune: seeded TPE asked and told in fixed batches, trials on the execution layer; the
    trials, scores and the saved bundle are the same for one and two workers, every trial is
    in the card and on the page, and the bundle holds the best trial's settings."""
    from physics.execution.parallel import ParallelSettings
    out, _ = run
    data = json.loads((out / "compare.json").read_text())["dataset"]
    kw = dict(progress=False, tune=6, overrides={"rbf": {"n_centres": 20}})
    one = train_compare(data, ["rbf"], tmp_path / "one", **kw)
    two = train_compare(data, ["rbf"], tmp_path / "two", settings=ParallelSettings(2), **kw)
    t1, t2 = one["models"]["rbf"]["tuning"], two["models"]["rbf"]["tuning"]
    assert len(t1["trials"]) == 6 and "n_centres" not in t1["trials"][0]["params"]   # a --set value stays fixed
    assert t1["trials"][0]["params"]["structure"] == "search"      # the first trial is the recipe itself
    assert [(r["params"], r["validation_nrmse"]) for r in t1["trials"]] == \
        [(r["params"], r["validation_nrmse"]) for r in t2["trials"]]
    cards = [json.loads((d / "models" / "rbf" / "card.json").read_text()) for d in (tmp_path / "one", tmp_path / "two")]
    assert cards[0]["weights"]["sha256"] == cards[1]["weights"]["sha256"]
    best = t1["best"]
    from nnmodel.tuning import choose    # the lowest score, or (cross-validated) the rule that beats the spread
    assert best["trial"] == choose(t1["trials"])[0]["trial"] and t1["rule"] == choose(t1["trials"])[1]
    assert best["validation_nrmse"] <= t1["trials"][0]["validation_nrmse"]      # never worse than the recipe
    hp = cards[0]["hyper_parameters"]
    from nnmodel.recipes import load_recipe
    # with the recipe's own structure search ('search') the structure entry it picks sets its keys
    searched = {k for entry in load_recipe("rbf")["hyper_parameters"]["structures"] for k in entry} \
        if best["params"].get("structure") == "search" else set()
    assert all(hp[k] == v for k, v in best["overrides"].items() if k not in searched)
    assert hp["n_centres"] == 20
    assert len(cards[0]["tuning"]["trials"]) == 6
    assert (tmp_path / "one" / "tuning.png").is_file() and "Tuning on the validation data" in \
        (tmp_path / "one" / "index.html").read_text()


def test_ctrl_c_during_network_training_exits_130_and_leaves_nothing(run, tmp_path, monkeypatch, capsys):
    """Lightning turns Ctrl-C into a 'graceful shutdown' and sys.exit(1) with SIGINT ignored;
    the command must instead end as on any Ctrl-C: 130, one line, no output folder, and the
    SIGINT handler restored."""
    import signal

    from nnmodel import training
    from nnmodel.app.cli import main

    def interrupted(self, batch, batch_idx):
        raise KeyboardInterrupt
    monkeypatch.setattr(training.SimulationTask, "training_step", interrupted)
    out, _ = run
    data = json.loads((out / "compare.json").read_text())["dataset"]
    handler = signal.getsignal(signal.SIGINT)
    code = main(["train-compare", data, "--models", "narx", "--set", "narx.max_epochs=3", "--quiet",
                 "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 130 and err[-1] == f"eap train-compare: interrupted; nothing written to {tmp_path / 'x'}"
    assert not (tmp_path / "x").exists() and signal.getsignal(signal.SIGINT) is handler


def test_group_captions_name_humidity_only_when_the_records_have_it():
    from nnmodel.traincompare import group_label
    assert group_label("train_rh", True) == "trained-RH test"
    assert group_label("heldout_rh", True) == "held-out-RH test"
    assert group_label("train_rh", False) == "test"   # a plant without a humidity channel
