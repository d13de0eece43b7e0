"""Saved model bundles: round trip, no pickled code, and the checks of Bundle.predict."""
import json
import os
import warnings

import numpy as np
import pytest
import torch

import nnmodel
from physics.errors import InputError
from nnmodel.benchmarks import toy
from nnmodel.bundle import CARD, WEIGHTS, load, resample, save
from nnmodel.models import MODELS

QUIET = dict(progress_bar=False, num_threads=1)


@pytest.fixture(scope="module")
def rh_model():
    train = toy.records("rh", 800, seeds=(1,), rh_levels=(40.0, 60.0, 80.0))
    return MODELS["narx"](na=1, nb=2, max_epochs=2, horizon=20, stride=10, **QUIET).fit(train)


@pytest.fixture(scope="module")
def gru_model():
    train = toy.records("linear2", 800, seeds=(1,))
    return MODELS["gru"](hidden=8, n_init=5, max_epochs=2, horizon=50, stride=25, **QUIET).fit(train)


@pytest.fixture()
def saved(rh_model, tmp_path):
    return save(rh_model, tmp_path / "narx", dataset_hash="abc123", metrics={"nrmse": np.float64(0.1)})


def test_round_trip_gives_identical_predictions_and_a_complete_card(rh_model, gru_model, saved, tmp_path):
    u = toy.excitation(300, seed=7)
    y = toy.rh_system(u, 55.0)
    b = nnmodel.load(saved)
    np.testing.assert_array_equal(b.predict(u, rh=55.0, fs=toy.FS), rh_model.simulate(u, rh=55.0))
    np.testing.assert_array_equal(b.predict(u, rh=55.0, fs=toy.FS, steps_ahead=3, deflection=y),
                                  rh_model.predict(u, rh=55.0, y=y, steps_ahead=3))
    card = json.loads((saved / CARD).read_text())
    assert card["model"] == "narx" and card["fs_hz"] == toy.FS
    assert card["rh_range_pct"] == [40.0, 80.0]
    assert [i["name"] for i in card["inputs"]] == ["voltage", "rh"]
    assert card["output"] == {"name": "deflection", "unit": "m"}
    assert card["n_parameters"] == rh_model.n_parameters
    assert card["dataset_hash"] == "abc123" and card["metrics"] == {"nrmse": 0.1}
    assert card["hyper_parameters"]["na"] == 1 and card["package_version"]
    # a recurrent model without humidity
    gb = load(save(gru_model, tmp_path / "gru"))
    np.testing.assert_array_equal(gb.predict(u, fs=toy.FS), gru_model.simulate(u))
    assert sorted(os.listdir(tmp_path)) == ["gru", "narx"]  # no temporary folder left


def test_save_is_atomic_and_does_not_clobber(rh_model, saved, tmp_path):
    with pytest.raises(InputError, match="already exists"):
        save(rh_model, saved)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "x.csv").write_text("precious")
    with pytest.raises(InputError, match="not a model bundle"):
        save(rh_model, tmp_path / "data", overwrite=True)
    assert (tmp_path / "data" / "x.csv").read_text() == "precious"
    save(rh_model, saved, overwrite=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "narx"]


class _Payload:
    """Unpickling this would create a marker file (stands for arbitrary code)."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_loading_never_unpickles_code(saved, tmp_path):
    marker = tmp_path / "pwned"
    wfile = saved / WEIGHTS
    torch.save({"core.x": _Payload(str(marker))}, wfile)
    # even with a matching checksum in the card, the payload is refused
    card = json.loads((saved / CARD).read_text())
    import hashlib
    card["weights"]["sha256"] = hashlib.sha256(wfile.read_bytes()).hexdigest()
    (saved / CARD).write_text(json.dumps(card))
    with pytest.raises(InputError, match="holds more than plain tensors") as err:
        load(saved)
    assert not marker.exists()
    assert "weights_only=False" not in str(err.value)  # never the advice a user must not follow


def test_tampered_or_foreign_bundles_are_refused(saved, tmp_path):
    wfile = saved / WEIGHTS
    state = torch.load(wfile, weights_only=True)
    state["core.fmap.lin_x.bias"] += 1.0
    torch.save(state, wfile)
    with pytest.raises(InputError, match="SHA-256"):
        load(saved)
    with pytest.raises(InputError, match="not a model bundle"):
        load(tmp_path)
    card = json.loads((saved / CARD).read_text())
    card["model"] = "transformer"
    (saved / CARD).write_text(json.dumps(card))
    with pytest.raises(InputError, match="unknown model type"):
        load(saved)


def test_predict_refuses_other_rates_unless_resampling(saved, rh_model):
    b = load(saved)
    t = np.arange(600) / toy.FS
    u = np.sin(2 * np.pi * 1.5 * t) + 0.5 * np.sin(2 * np.pi * 4.0 * t)  # smooth, well below Nyquist
    with pytest.raises(InputError, match="trained at 100 Hz.*resample"):
        b.predict(u, rh=60.0, fs=2 * toy.FS)
    with pytest.raises(InputError, match="sampling rate"):
        b.predict(u, rh=60.0)
    # the same signal sampled twice as fast, resampled in and out
    t2 = np.arange(1199) / (2 * toy.FS)
    u2 = np.sin(2 * np.pi * 1.5 * t2) + 0.5 * np.sin(2 * np.pi * 4.0 * t2)
    ref = b.predict(u, rh=60.0, fs=toy.FS)
    out = b.predict(u2, rh=60.0, fs=2 * toy.FS, resample=True)
    assert out.shape == u2.shape
    scale = np.std(ref)
    assert np.sqrt(np.mean((out[::2] - ref) ** 2)) < 0.05 * scale
    # a rate equal within rounding of printed timestamps is accepted as is
    np.testing.assert_array_equal(b.predict(u, rh=60.0, fs=toy.FS * (1 + 1e-7)), ref)


def test_predict_checks_values_shapes_and_humidity(saved):
    b = load(saved)
    u = toy.excitation(200, seed=3)
    with pytest.raises(InputError, match="not finite"):
        b.predict(np.r_[u, np.nan], rh=50.0, fs=toy.FS)
    with pytest.raises(InputError, match="1-D"):
        b.predict(u.reshape(2, -1), rh=50.0, fs=toy.FS)
    with pytest.raises(InputError, match="one value per voltage sample"):
        b.predict(u, rh=np.full(5, 50.0), fs=toy.FS)
    with pytest.raises(InputError, match="pass rh="):
        b.predict(u, fs=toy.FS)
    with pytest.warns(RuntimeWarning, match=r"95 % is outside the range seen in training \(40-80 %RH\)"):
        b.predict(u, rh=95.0, fs=toy.FS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        b.predict(u, rh=50.0, fs=toy.FS)


def test_resample_preserves_a_slow_sine():
    t = np.arange(1000) / 1000.0
    x = np.sin(2 * np.pi * 3 * t)
    y = resample(x, 1000.0, 250.0)
    np.testing.assert_allclose(y, np.sin(2 * np.pi * 3 * np.arange(y.size) / 250.0), atol=2e-2)


@pytest.mark.parametrize("change, match", [
    ({"layers": 100_000_000}, r"layers=100000000 is invalid; expected at most 64"),
    ({"hidden": 4096, "layers": 64}, r"network of [\d,]+ parameters, more than the 50,000,000"),
    ({"nb": 10 ** 9}, r"nb=1000000000 is invalid; expected at most 1,000"),
])
def test_an_oversized_card_is_refused_before_anything_is_allocated(saved, change, match):
    """A card is input: sizes are capped and the network is sized on torch's meta device
    before the weights are read (a card `layers: 100000000` once ran for minutes and GBs)."""
    import resource
    import time
    card = json.loads((saved / CARD).read_text())
    card["hyper_parameters"].update(change)
    (saved / CARD).write_text(json.dumps(card))
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=match):
        load(saved)
    assert time.perf_counter() - t0 < 30      # a guard against hanging, not a speed target
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0 < 200_000   # kB: no allocation of the network
