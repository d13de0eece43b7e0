"""Dataset generation and loading (issue 6)."""
import json

import numpy as np
import pytest

from nnmodel import dataset as dsmod
from nnmodel.dataset import generate, load_config, load_dataset
from physics.errors import InputError

TINY = dict(fs_Hz=100.0, f_max_Hz=20.0, duration_s=4.0, train_rh_pct=[40, 100], heldout_rh_pct=[70],
            excitations=["sweep", "noise", "square"], validation_per_rh=1, test_per_train_rh=1,
            test_per_heldout_rh=1, varying_rh={"train": 1, "test": 1, "range_pct": [40, 100]},
            measurement_like={"effects": ["nonlinear_charge"], "count": 1, "rh_pct": [55]})


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return generate(tmp_path_factory.mktemp("d") / "tiny", dict(TINY), progress=False)


def test_splits_rh_levels_and_hashes(tiny):
    ds = load_dataset(tiny)
    assert ds.meta["schema"] == "eap-dataset/1" and ds.fs == 100.0
    assert len(ds.entries("train")) == 2 * 3 + 1 and len(ds.entries("validation")) == 2
    held = ds.entries("test", heldout=True)
    assert [e["rh_pct"] for e in held] == [70.0]
    assert all(not e["heldout_rh"] for e in ds.entries("train") + ds.entries("validation"))
    train_rh = {e["rh_pct"] for e in ds.entries("train") if not isinstance(e["rh_pct"], dict)}
    assert train_rh == {40.0, 100.0}
    ml = ds.entries(measurement_like=True)
    assert len(ml) == 1 and "nonlinear_charge" in ml[0]["effects"] and ml[0]["split"] == "test"
    assert "nonlinear_charge" not in ds.meta["generator"]["effects"]
    recs = ds.records("train")
    assert all(r.fs == pytest.approx(100.0) and r.u.size == 400 for r in recs)


def test_every_record_starts_at_rest(tiny):
    """Excitations ramp in from 0 V (fade_in_s): the first samples are 0 V up to the
    voltage channel's noise, whatever the excitation (a bipolar square starts at -A and a
    multisine or noise anywhere without the ramp)."""
    ds = load_dataset(tiny)
    for e in ds.meta["files"]:
        r = ds.record(e)
        assert np.max(np.abs(r.u[:3])) < 0.01 * np.max(np.abs(r.u)), e["path"]
    with pytest.raises(InputError, match="fade_in_s"):
        load_config("default", {"fade_in_s": 100.0})


def test_varying_rh_records_drift_within_range(tiny):
    ds = load_dataset(tiny)
    var = [e for e in ds.meta["files"] if isinstance(e["rh_pct"], dict)]
    assert len(var) == 2
    for e in var:
        rh = ds.record(e).rh
        assert rh.min() >= 40 - 1 and rh.max() <= 100 and np.ptp(rh) > 5


def test_records_carry_realistic_sensor_noise(tiny):
    ds = load_dataset(tiny)
    e = ds.entries("train")[0]
    rec = ds.record(e)
    step = np.diff(rec.y)
    floor = ds.meta["noise_floor_m"]
    assert 1e-7 < floor < 1e-5
    # high-pass residual of a 100 Hz record of a smooth sweep is dominated by the sensor noise
    assert np.std(step[:50]) > 0.5 * floor


def test_same_seed_same_files_other_seed_differs(tmp_path):
    a = generate(tmp_path / "a", dict(TINY, seed=3), progress=False)
    b = generate(tmp_path / "b", dict(TINY, seed=3), progress=False)
    c = generate(tmp_path / "c", dict(TINY, seed=4), progress=False)
    ha = [e["sha256"] for e in load_dataset(a).meta["files"]]
    assert ha == [e["sha256"] for e in load_dataset(b).meta["files"]]
    assert ha != [e["sha256"] for e in load_dataset(c).meta["files"]]


def test_tampering_and_missing_files_are_detected(tiny, tmp_path):
    import shutil
    d = tmp_path / "copy"
    shutil.copytree(tiny, d)
    first = load_dataset(d).entries("train")[0]["path"]
    with open(d / first, "a") as fh:
        fh.write("0.0,0,0,40,0\n")
    with pytest.raises(InputError, match="differs from the SHA-256"):
        load_dataset(d)
    (d / first).unlink()
    with pytest.raises(InputError, match="is missing"):
        load_dataset(d)
    with pytest.raises(InputError, match="not a dataset folder"):
        load_dataset(tmp_path)


def test_existing_output_and_unknown_options_are_refused(tiny):
    before = (tiny / "dataset.json").read_text()
    with pytest.raises(InputError, match="already exists"):
        generate(tiny, dict(TINY), progress=False)
    assert (tiny / "dataset.json").read_text() == before
    with pytest.raises(InputError, match="unknown dataset option"):
        load_config("default", {"samplerate": 5})


def test_a_crash_halfway_leaves_nothing(tmp_path, monkeypatch):
    calls = {"n": 0}
    real = dsmod.write_timeseries

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("disk full")
        return real(*a, **k)

    monkeypatch.setattr(dsmod, "write_timeseries", flaky)
    with pytest.raises(RuntimeError):
        generate(tmp_path / "broken", dict(TINY), progress=False)
    assert list(tmp_path.iterdir()) == []


def test_cli_generate(tmp_path, capsys):
    from nnmodel.app.cli import main
    cfg = tmp_path / "c.yaml"
    import yaml
    cfg.write_text(yaml.safe_dump(TINY))
    assert main(["generate", "--config", str(cfg), "--out", str(tmp_path / "ds"), "--seed", "1"]) == 0
    assert "train / " in capsys.readouterr().out
    assert json.loads((tmp_path / "ds" / "dataset.json").read_text())["seed"] == 1
