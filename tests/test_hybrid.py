"""Grey-box hybrid: physics simulator + neural correction.

The data are built from the physics itself with a known discrepancy, so the tests know
what the correction must do (and fail if it does nothing)."""
import json

import numpy as np
import pytest

import nnmodel
import physics
from physics import signals
from physics.errors import InputError
from nnmodel.bundle import CARD, save
from nnmodel.data import Experiment, nrmse
from nnmodel.models import MODELS

FS = 100.0
DEVICE = "ip2c_pedot_water"
QUIET = dict(progress_bar=False, num_threads=1)
GAIN = 0.6   # the "measured" actuator bends 60 % as far as the physics says


def _records(seeds, rhs, duration=8.0):
    out = []
    for s in seeds:
        rng = np.random.default_rng(s)
        sig = signals.noise(0.6, 0.1, 20.0, duration, FS, seed=s)
        v = sig.v + 0.3 * np.sin(2 * np.pi * rng.uniform(0.2, 1.0) * sig.t)
        v *= np.minimum(1.0, sig.t / 0.5)   # from rest at 0 V, as a free run without history assumes
        for rh in rhs:
            y = physics.simulate(DEVICE, "default", sig.t, v, rh=rh).deflection
            out.append(Experiment(v, GAIN * y, rh, FS, f"s{s}-rh{rh:g}"))
    return out


@pytest.fixture(scope="module")
def data():
    return {"train": _records((1, 2), (40.0, 100.0)), "val": _records((3,), (40.0, 100.0)),
            "test": _records((4,), (70.0,))}


@pytest.fixture(scope="module")
def hybrid(data):
    # least-squares correction only (no gradient epochs): deterministic and fast
    return MODELS["hybrid"](nb=3, max_epochs=0, **QUIET).fit(data["train"], data["val"])


def test_hybrid_learns_the_discrepancy_its_physics_alone_misses(hybrid, data):
    r = data["test"][0]                      # held-out RH 70 %
    y_phys, _ = hybrid.physics_output(r.u, r.rh)
    e_phys = nrmse(r.y, y_phys)
    e_hyb = nrmse(r.y, hybrid.simulate(r.u, rh=r.rh))
    assert e_phys > 0.5                      # the physics alone is 1/0.6 too large
    assert e_hyb < 0.01, (e_hyb, e_phys)


def test_a_correction_that_does_not_validate_better_than_its_physics_is_dropped(data):
    """A grey box is never worse than its physics prior on validation: a correction fitted
    to a training-only offset (the validation records are the physics itself) is set to
    zero, and the hybrid simulates its physics; where the correction does help (the GAIN
    discrepancy in every split) it is kept."""
    val = [Experiment(r.u, r.y / GAIN, r.rh, FS, r.name) for r in data["val"]]
    off = 0.3 * np.std(val[0].y)
    train = [Experiment(r.u, r.y / GAIN + off, r.rh, FS, r.name) for r in data["train"]]
    m = MODELS["hybrid"](nb=3, max_epochs=0, **QUIET).fit(train, val)
    assert m.reference_start_["start"]["kept"] == "physics" and m.reference_start_["end"]["kept"] == "physics"
    r = val[0]
    e_phys = nrmse(r.y, m.physics_output(r.u, r.rh)[0])
    assert nrmse(r.y, m.simulate(r.u, rh=r.rh, y_init=r.y[:m.n_init_])) <= e_phys + 1e-4
    assert MODELS["hybrid"](nb=3, max_epochs=0, **QUIET).fit(data["train"], data["val"]) \
        .reference_start_["end"]["kept"] == "network"


def test_a_zero_correction_reproduces_the_physics_exactly(data):
    m = MODELS["hybrid"](nb=2, layers=0, arx_init=False, max_epochs=0, **QUIET).fit(data["train"], data["val"])
    r = data["test"][0]
    t = np.arange(len(r)) / FS
    y = physics.simulate(DEVICE, "default", t, r.u, rh=70.0).deflection
    # initialised from the record (no rest padded in front): the physics run is the same
    np.testing.assert_allclose(m.simulate(r.u, rh=70.0, y_init=y[:m.n_init_]), y, rtol=0, atol=1e-5 * np.std(y))
    # from rest: the physics also sees the rest samples in front (same up to the input hold)
    assert nrmse(y, m.simulate(r.u, rh=70.0)) < 0.01


def test_bundle_keeps_the_physics_and_predicts_identically(hybrid, data, tmp_path):
    path = save(hybrid, tmp_path / "hybrid")
    card = json.loads((path / CARD).read_text())
    ph = card["physics"]
    assert ph["device"] == DEVICE and ph["device_document"]["name"] == DEVICE
    assert ph["effects"] == list(physics.ActuatorModel(DEVICE, "default").effect_ids)
    assert ph["parameters_SI"]["kf"] == pytest.approx(physics.load_device(DEVICE)["kf"])
    b = nnmodel.load(path)
    r = data["test"][0]
    np.testing.assert_array_equal(b.predict(r.u, rh=70.0, fs=FS), hybrid.simulate(r.u, rh=70.0))
    # a card whose parameters disagree with its device document is refused
    ph["parameters_SI"]["kf"] *= 2
    (path / CARD).write_text(json.dumps(card))
    with pytest.raises(InputError, match="differ"):
        nnmodel.load(path)


def test_the_hybrid_needs_humidity_for_its_physics(hybrid, data):
    r = data["test"][0]
    with pytest.raises(InputError, match="relative humidity"):
        hybrid.simulate(r.u)
    with pytest.raises(InputError, match="relative humidity"):
        MODELS["hybrid"](max_epochs=0, **QUIET).fit([Experiment(r.u, r.y, None, FS)])
    with pytest.raises(InputError, match="inputs"):
        MODELS["hybrid"](inputs="voltage", max_epochs=0, **QUIET).fit(data["train"])
    with pytest.raises(InputError, match="physics_states"):
        MODELS["hybrid"](physics_states=["temperature"])
    with pytest.raises(InputError, match="physics_inputs"):
        MODELS["hybrid"](physics_inputs=["v^3", "v^3"])


def test_physics_inputs_identify_a_static_input_nonlinearity(data):
    """Data from the physics driven through phi(V) = V - 0.4 V|V| (a saturating front-end):
    the physics of V alone misses it; with physics_inputs ["v|v|"] the least-squares bypass
    finds the weights and the held-out error falls to the level of the pure-gain case."""
    def bent(recs):
        out = []
        for r in recs:
            t = np.arange(len(r)) / FS
            y = physics.simulate(DEVICE, "default", t, r.u - 0.4 * r.u * np.abs(r.u), rh=r.rh).deflection
            out.append(Experiment(r.u, y, r.rh, FS, r.name))
        return out
    train, val, test = bent(data["train"]), bent(data["val"]), bent(data["test"])[0]
    plain = MODELS["hybrid"](nb=3, layers=0, max_epochs=0, **QUIET).fit(train, val)
    hamm = MODELS["hybrid"](nb=3, layers=0, max_epochs=0, physics_inputs=["v|v|"], **QUIET).fit(train, val)
    e_plain = nrmse(test.y, plain.simulate(test.u, rh=test.rh))
    e_hamm = nrmse(test.y, hamm.simulate(test.u, rh=test.rh))
    assert e_plain > 0.05, e_plain           # the linear correction cannot undo the nonlinearity
    assert e_hamm < 0.2 * e_plain and e_hamm < 0.01, (e_hamm, e_plain)
    with pytest.raises(InputError, match="physics_inputs"):
        MODELS["hybrid"](physics_inputs=["v^2"])
