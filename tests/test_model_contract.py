"""A contract over every entry of the model registry: a model is tested the moment it is
registered (fit, free run, one-step, save/load round trip, NaN refused, seeded)."""
import numpy as np
import pytest
from scipy.signal import lfilter

from nnmodel.bundle import load, save
from nnmodel.data import Record
from nnmodel.models import MODELS
from physics.errors import InputError

FS = 50.0
BRIEF = {"ff": dict(max_epochs=1), "rbf": dict(n_centres=6), "narx": dict(max_epochs=1, horizon=20, stride=20),
         "lstm": dict(max_epochs=1, horizon=20, stride=20, n_init=5), "gru": dict(max_epochs=1, horizon=20,
                                                                                 stride=20, n_init=5),
         "hybrid": dict(max_epochs=1, device="ipmc_pt_eg", effects="none")}


def _records():
    rng = np.random.default_rng(0)
    out = []
    for rh in (40.0, 80.0):
        u = np.convolve(rng.normal(size=600), np.ones(4) / 4, "same")
        y = lfilter([0.05], [1, -0.95], np.tanh(u)) * 1e-3 * (1 + rh / 100)
        out.append(Record(u=u, y=y, rh=np.full(u.size, rh), fs=FS))
    return out


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_registered_model_honours_the_contract(kind, tmp_path):
    kw = dict(progress_bar=False, seed=3, **BRIEF.get(kind, dict(max_epochs=1)))
    recs = _records()
    m = MODELS[kind](**kw).fit(recs[:1], recs[1:])
    u, rh, y = recs[0].u, 40.0, recs[0].y
    free = m.simulate(u, rh)
    assert free.shape == u.shape and np.all(np.isfinite(free))
    one = m.predict(u, rh, y=y, steps_ahead=1)
    assert one.shape == u.shape and np.all(np.isfinite(one))
    b = load(save(m, tmp_path / kind))
    np.testing.assert_allclose(b.predict(u, rh=rh, fs=FS), free, rtol=1e-6, atol=1e-12)
    bad = u.copy()
    bad[10] = np.nan
    with pytest.raises(InputError):
        m.simulate(bad, rh)
    again = MODELS[kind](**kw).fit(recs[:1], recs[1:])
    np.testing.assert_array_equal(again.simulate(u, rh), free)


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_training_settings_live_in_one_config(kind):
    """No constructor repeats the training settings: they are one TrainingConfig
    (model.training), still read, written and validated as flat hyper-parameters."""
    import inspect

    from nnmodel.models.config import TRAINING_FIELDS, TrainingConfig
    cls = MODELS[kind]
    own = set(inspect.signature(cls.__init__).parameters) - {"self", "training"}
    assert not own & set(TRAINING_FIELDS), sorted(own & set(TRAINING_FIELDS))
    m = cls(max_epochs=3, lr=5e-4)
    assert isinstance(m.training, TrainingConfig) and m.training.max_epochs == 3 and m.lr == 5e-4
    m.set_params(patience=4)
    assert m.training.patience == 4 and m.get_params()["patience"] == 4
    assert set(TRAINING_FIELDS) <= set(cls.param_names()) and set(cls.default_params()) == set(cls.param_names())
    with pytest.raises(InputError, match="max_epochs"):
        cls(max_epochs=-1)
    with pytest.raises(InputError, match="unknown hyper-parameter"):
        cls(epochs=3)
