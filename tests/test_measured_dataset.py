"""A lab's own measurements end to end: `eap dataset` → `eap train-compare` (no physics row,
no validation split, no RH), `--check`, and the errors on bad combinations."""
import json

import numpy as np
import pytest
from scipy.signal import lfilter

from nnmodel.app.cli import main
from nnmodel.dataset import load_dataset


def _plant(path, n=1500, fs=0.25, seed=0):
    """A slow saturating plant sampled at 0.25 Hz (time constant ~1 min), arbitrary units."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 15 + 1), 15)[:n]
    x = lfilter([1 - np.exp(-1 / (60 * fs))], [1, -np.exp(-1 / (60 * fs))], u)
    y = np.tanh(2 * x) + 0.01 * rng.normal(size=n)
    path.write_text("t;u;y\n" + "\n".join(f"{i / fs};{a};{b}" for i, (a, b) in enumerate(zip(u, y))) + "\n")
    return path


def test_dataset_from_measurements_and_train_compare(tmp_path, capsys):
    a, b = _plant(tmp_path / "a.csv"), _plant(tmp_path / "b.csv", seed=1)
    ds = tmp_path / "ds"
    assert main(["dataset", "--train", f"{a}[0:1200]", "--test", str(b), "--columns", "time=t,voltage=u,deflection=y",
                 "--out", str(ds)]) == 0
    assert "no relative humidity" in capsys.readouterr().out
    meta = json.loads((ds / "dataset.json").read_text())
    assert meta["schema"] == "eap-dataset/1" and meta["rh_levels"] is None and meta["fs_Hz"] == pytest.approx(0.25)
    assert [e["split"] for e in meta["files"]] == ["train", "test"]
    assert meta["files"][0]["samples"] == 1200 and meta["files"][0]["source"]["samples"] == [0, 1200]
    assert main(["dataset", "--check", str(ds)]) == 0
    out = tmp_path / "run"
    assert main(["train-compare", str(ds), "--models", "ff", "--set", "ff.max_epochs=2", "--out", str(out),
                 "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "held-out" not in text and "physics" not in text.split("\n")[2]
    summary = json.loads((out / "compare.json").read_text())
    assert "physics" not in summary["models"] and summary["physics"] is None
    assert summary["best_heldout"]["group"] == "test records"
    assert np.isfinite(summary["models"]["ff"]["free_run"]["test"]["nrmse"])


def test_check_names_a_changed_file_and_a_changed_source(tmp_path, capsys):
    a = _plant(tmp_path / "a.csv")
    ds = tmp_path / "ds"
    assert main(["dataset", "--train", f"{a}[0:1000]", "--test", f"{a}[1000:1500]", "--columns",
                 "time=t,voltage=u,deflection=y", "--out", str(ds)]) == 0
    _plant(a, seed=3)  # the source changes after the dataset was built
    assert main(["dataset", "--check", str(ds)]) == 0
    assert "changed since the dataset was built" in capsys.readouterr().out
    f = next((ds / "train").glob("*.csv"))
    f.write_text(f.read_text() + "\n")  # the dataset's own copy is edited
    assert main(["dataset", "--check", str(ds)]) == 2
    assert f.name in capsys.readouterr().err


def test_bad_combinations_are_refused(tmp_path, capsys):
    a = _plant(tmp_path / "a.csv")
    assert main(["dataset", "--train", f"{a}[0:5]", "--columns", "time=t,voltage=u,deflection=y",
                 "--out", str(tmp_path / "x")]) == 2
    assert "at least 16" in capsys.readouterr().err
    assert main(["dataset", "--train", str(a), "--columns", "time=t,voltage=u,deflection=y", "--holdout-rh", "50",
                 "--out", str(tmp_path / "y")]) == 2
    assert "--holdout-rh needs records with a relative humidity" in capsys.readouterr().err
    ds = tmp_path / "ds"
    leak = ["dataset", "--train", str(a), "--test", str(a), "--columns", "time=t,voltage=u,deflection=y", "--out",
            str(ds)]
    assert main(leak) == 2 and "share samples 0:1500 of the same file" in capsys.readouterr().err
    assert main(leak + ["--allow-overlap"]) == 0 and "1 pair(s) of records share samples" in capsys.readouterr().out
    assert json.loads((ds / "dataset.json").read_text())["overlap"][0]["samples"] == [0, 1500]
    assert main(["train-compare", str(ds), "--models", "hybrid", "--out", str(tmp_path / "h")]) == 2
    assert "--physics" in capsys.readouterr().err
    assert load_dataset(ds).has_rh is False
