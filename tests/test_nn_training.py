"""Training recipes and the Lightning loop (checkpoints, early stopping, time budget)."""
import time

import numpy as np
import pytest
import torch

from physics.errors import InputError
from nnmodel.benchmarks import toy
from nnmodel.models import MODELS
from nnmodel.recipes import load_recipe, make_model

QUIET = dict(progress_bar=False, num_threads=1)


@pytest.mark.parametrize("name", ["ff", "rbf", "narx", "lstm", "gru"])
def test_every_shipped_recipe_loads_and_builds(name):
    rec = load_recipe(name)
    assert rec["model"] == name and rec["description"]
    m = make_model(name, {"seed": 7})
    assert isinstance(m, MODELS[name]) and m.seed == 7 and m.accelerator == "cpu"


def test_unknown_or_invalid_recipe_keys_are_rejected(tmp_path):
    with pytest.raises(InputError, match=r"unknown hyper-parameter\(s\) \['hiden'\]"):
        load_recipe("narx", {"hiden": 16})
    with pytest.raises(InputError, match="lr"):
        load_recipe("narx", {"lr": -1.0})
    with pytest.raises(InputError, match="no training recipe 'transformer'"):
        load_recipe("transformer")
    (tmp_path / "bad.yaml").write_text("model: ff\nhyper_parameters:\n  na: 2\n  layerz: 3\n")
    with pytest.raises(InputError, match=r"bad.yaml: unknown hyper-parameter\(s\) \['layerz'\]"):
        load_recipe("bad", directory=tmp_path)
    (tmp_path / "top.yaml").write_text("model: ff\nparams: {}\n")
    with pytest.raises(InputError, match=r"unknown key\(s\) \['params'\]"):
        load_recipe("top", directory=tmp_path)
    (tmp_path / "kind.yaml").write_text("model: svm\n")
    with pytest.raises(InputError, match="unknown model 'svm'"):
        load_recipe("kind", directory=tmp_path)


def test_checkpoint_is_plain_weights_and_history_tracks_validation(tmp_path):
    train = toy.records("linear2", 1000, seeds=(1,))
    m = MODELS["narx"](na=2, nb=2, arx_init=False, max_epochs=4, horizon=20, stride=10,
                       checkpoint_dir=str(tmp_path), **QUIET).fit(train)
    ck = tmp_path / "best.ckpt"
    assert ck.is_file()
    state = torch.load(ck, weights_only=True)["state_dict"]  # no arbitrary objects inside
    assert all(k.startswith("core.") for k in state)
    epochs = [h for h in m.history_ if h["epoch"] >= 0]
    assert len(epochs) == 4 and all("val_loss" in h and "train_loss" in h for h in epochs)
    # the weights kept are the best ones seen on validation (free run)
    best = min(h["val_loss"] for h in m.history_)
    from nnmodel.training import free_run_error
    from nnmodel.data import split_records
    _, val = split_records(train, m.val_fraction)
    err = free_run_error(m.net_.core, [m._norm_record(r) for r in val])
    assert err == pytest.approx(best, rel=1e-4)


def test_early_stopping_and_time_budget_end_training():
    train = toy.records("linear2", 1000, seeds=(1,))
    # exact least-squares start on noise-free data: nothing left to improve, stops early
    m = MODELS["narx"](na=2, nb=3, layers=0, max_epochs=500, patience=2, horizon=20,
                       stride=10, **QUIET).fit(train)
    assert len(m.history_) < 20
    t0 = time.perf_counter()
    MODELS["lstm"](hidden=8, max_epochs=100000, max_time=2.0, patience=100000, horizon=50,
                   stride=5, **QUIET).fit(train)
    assert time.perf_counter() - t0 < 30


def test_training_never_ends_worse_than_its_least_squares_start():
    train = toy.records("linear2", 1000, seeds=(1,))
    u = toy.excitation(500, seed=4)
    y = toy.linear2(u)
    ls = MODELS["ff"](na=2, nb=3, layers=0, max_epochs=0, **QUIET).fit(train)
    # a deliberately harmful learning rate: the ARX start must be kept
    bad = MODELS["narx"](na=2, nb=3, max_epochs=2, lr=5.0, horizon=20, stride=10, **QUIET).fit(train)
    e_ls = np.sqrt(np.mean((ls.simulate(u) - y) ** 2))
    e_bad = np.sqrt(np.mean((bad.simulate(u) - y) ** 2))
    assert e_bad <= e_ls * 1.01 + 1e-9


def test_budget_is_epochs_and_the_time_guard_is_recorded(tmp_path):
    """Same seed, same epochs → the same weights; a wall-clock guard that ends training is
    recorded in the bundle card and warned about (the result then depends on the machine)."""
    from nnmodel.bundle import save
    train = toy.records("linear2", 1000, seeds=(1,))
    val = toy.records("linear2", 400, seeds=(2,))
    kw = dict(QUIET, na=2, nb=4, hidden=8, horizon=20, stride=20, max_epochs=3, patience=50, max_time=None)
    a = MODELS["narx"](**kw).fit(train, val)
    b = MODELS["narx"](**kw).fit(train, val)
    for k, v in a.net_.state_dict().items():
        assert torch.equal(v, b.net_.state_dict()[k]), k
    card = __import__("json").loads((save(a, tmp_path / "a") / "card.json").read_text())
    assert card["training"]["epochs"] == 3 and card["training"]["time_guard_fired"] is False
    with pytest.warns(RuntimeWarning, match="wall-clock guard"):
        c = MODELS["narx"](**{**kw, "max_epochs": 10000, "max_time": 1.0}).fit(train, val)
    card = __import__("json").loads((save(c, tmp_path / "c") / "card.json").read_text())
    assert card["training"]["time_guard_fired"] is True and card["training"]["epochs"] < 10000


@pytest.mark.slow
def test_two_process_ddp_trains_a_model_of_the_same_quality():
    """Lightning's own DDP strategy on CPU (gloo, two spawned processes), each drawing its
    shard of the windows: the model reaches the quality of the one-process run."""
    from nnmodel.training import execution
    from physics.analysis.metrics import nrmse
    train = toy.records("static_cubic", 4000, seeds=(1, 2))
    val = toy.records("static_cubic", 1000, seeds=(3,))
    test = toy.records("static_cubic", 2000, seeds=(4,))[0]
    kw = dict(QUIET, na=2, nb=4, hidden=16, horizon=50, stride=10, max_epochs=40, patience=100, max_time=None)
    one = nrmse(test.y, MODELS["narx"](**kw).fit(train, val).simulate(test.u))
    with execution(2, "ddp_spawn"):
        two = nrmse(test.y, MODELS["narx"](**kw).fit(train, val).simulate(test.u))
    assert two <= 1.5 * one + 0.02, (one, two)
