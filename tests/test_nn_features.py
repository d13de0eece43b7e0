"""Input front-ends: memory filters (long input memory) and RH scheduling of the bypass.

Each capability is checked on a closed-form system that needs it, against a model
without it (so the test fails if the feature does nothing)."""
import numpy as np
import pytest
from scipy import signal

import nnmodel
from physics.errors import InputError, InputNotice
from nnmodel.benchmarks import toy
from nnmodel.bundle import save
from nnmodel.data import Experiment, nrmse
from nnmodel.models import MODELS
from nnmodel.models.features import auto_knots, memory_filters, memory_taus, rh_hats

QUIET = dict(progress_bar=False, num_threads=1)
FS = toy.FS


def slow_system(u, from_rest=False):
    """Slow first-order lag (time constant 4 s = 400 samples) plus a fast part (m), in
    equilibrium with u[0] at the start (as the memory filters of a training record), or
    at rest at 0 V (as a free run without measured history)."""
    a = np.exp(-1.0 / (FS * 4.0))
    slow, _ = signal.lfilter([1 - a], [1, -a], u, zi=[0.0 if from_rest else a * u[0]])
    return toy.SCALE * (slow + 0.3 * u)


def test_memory_filters_are_exact_first_order_lags_started_in_equilibrium():
    u = np.r_[np.full(50, 2.0), np.zeros(450)]
    taus = memory_taus(3, 0.1, 10.0)
    np.testing.assert_allclose(taus, [0.1, 1.0, 10.0])
    m = memory_filters(u, taus, FS)
    np.testing.assert_allclose(m[:50], 2.0)                      # equilibrium with u[0]
    k = np.arange(1, 451)
    np.testing.assert_allclose(m[50:, 1], 2.0 * np.exp(-1.0 / (FS * 1.0)) ** k, rtol=1e-12)


def test_rh_hats_interpolate_linearly_and_clip_outside():
    h = rh_hats(np.array([30.0, 40.0, 50.0, 60.0, 75.0, 100.0, 110.0]), [40, 60, 100])
    np.testing.assert_allclose(h.sum(1), 1.0)
    np.testing.assert_allclose(h[2], [0.5, 0.5, 0.0])
    np.testing.assert_allclose(h[4], [0.0, 25 / 40, 15 / 40])
    np.testing.assert_allclose(h[0], [1, 0, 0])
    np.testing.assert_allclose(h[-1], [0, 0, 1])


def test_auto_knots_are_the_constant_rh_levels_widened_to_the_drift_range():
    rng = np.random.default_rng(0)
    recs = [40 + 0.3 * rng.standard_normal(100), 60 + 0.3 * rng.standard_normal(100),
            np.linspace(35, 80, 100)]
    assert auto_knots(recs) == [35.0, 40.0, 60.0, 80.0]
    assert auto_knots([np.full(10, 50.0)]) == []
    assert auto_knots([np.linspace(40, 100, 50)]) == [40.0, 60.0, 80.0, 100.0]


def test_memory_filters_give_an_nfir_model_the_slow_dynamics_a_delay_line_misses():
    u = toy.excitation(6000, seed=1, pole=0.95)
    train = [Experiment(u, slow_system(u), None, FS)]
    u2 = toy.excitation(3000, seed=2, pole=0.95)
    y2 = slow_system(u2, from_rest=True)
    kw = dict(na=0, nb=5, layers=0, max_epochs=0, val_fraction=0.0, **QUIET)
    plain = MODELS["ff"](**kw).fit(train)
    # 9 filters 1/16 .. 16 s (factor 2 apart, one of them at 4 s): the system is in the span
    mem = MODELS["ff"](memory_filters=9, memory_min_s=0.0625, memory_max_s=16.0, **kw).fit(train)
    # 6 filters that miss 4 s: still a close approximation (a sum of neighbouring lags)
    near = MODELS["ff"](memory_filters=6, memory_min_s=0.05, memory_max_s=40.0, **kw).fit(train)
    e_plain, e_mem, e_near = (nrmse(y2, m.simulate(u2)) for m in (plain, mem, near))
    assert e_mem < 1e-3 and e_near < 0.1 and e_plain > 0.3, (e_mem, e_near, e_plain)


def test_rh_scheduled_bypass_interpolates_an_rh_dependent_gain_at_held_out_rh():
    train = toy.records("rh", 1500, seeds=(1,), rh_levels=(40.0, 60.0, 80.0))
    test = toy.records("rh", 800, seeds=(9,), rh_levels=(50.0, 70.0))
    kw = dict(na=1, nb=2, layers=0, max_epochs=0, val_fraction=0.0, **QUIET)
    sched = MODELS["narx"](rh_knots=[40, 60, 80], **kw).fit(train)
    plain = MODELS["narx"](**kw).fit(train)

    def err(m):
        return max(nrmse(r.y, m.simulate(r.u, rh=r.rh)) for r in test)
    # the gain is linear in RH, so knot interpolation is exact; an unscheduled linear model
    # can only fit one average gain
    assert err(sched) < 1e-3 and err(plain) > 0.05, (err(sched), err(plain))


@pytest.mark.parametrize("name", ["ff", "rbf", "narx", "lstm"])
def test_auto_knots_and_memory_survive_a_bundle_round_trip(name, tmp_path):
    train = toy.records("rh", 600, seeds=(1,), rh_levels=(40.0, 60.0, 80.0))
    kw = dict(rh_knots="auto", memory_filters=3, memory_min_s=0.05, memory_max_s=2.0, max_epochs=1, **QUIET)
    kw.update({"rbf": dict(n_centres=10, max_epochs=0), "lstm": dict(hidden=4, horizon=30, stride=30,
                                                                        skip_init=True)}.get(name, {}))
    m = MODELS[name](**kw).fit(train)
    assert m.rh_knots_ == [40.0, 60.0, 80.0]
    b = nnmodel.load(save(m, tmp_path / name))
    u = toy.excitation(200, seed=5)
    np.testing.assert_array_equal(b.predict(u, rh=55.0, fs=FS), m.simulate(u, rh=55.0))
    assert b.card["rh_knots_pct"] == [40.0, 60.0, 80.0]


def test_invalid_knots_and_memory_settings_are_refused():
    with pytest.raises(InputError, match="rh_knots"):
        MODELS["ff"](rh_knots=[60, 40])
    with pytest.raises(InputError, match="rh_knots"):
        MODELS["narx"](rh_knots=[50])
    with pytest.raises(InputError, match="memory_filters"):
        MODELS["ff"](memory_filters=-1)
    with pytest.raises(InputError, match="memory_min_s"):
        MODELS["lstm"](memory_min_s=0.0)


def test_scheduled_fast_numpy_free_run_matches_the_torch_loop():
    import torch
    from nnmodel.models.lag import LagSimulator, MLPMap

    torch.manual_seed(0)
    K = 3
    core = LagSimulator(2, 3, 1 + K, MLPMap(2, 3 + 2 + 1 + K, 8, 1, "tanh", n_sched=K), n_mem=2)
    with torch.no_grad():
        for p in core.parameters():
            p.normal_(0, 0.3)
        core.fmap.lin_y.weight.mul_(0.2)
    k, T = core.n_init, 200
    u = torch.randn(1, k + T, 3)
    rh = torch.cat([torch.randn(1, k + T, 1), torch.softmax(torch.randn(1, k + T, K), -1)], -1)
    y = torch.randn(1, k)
    with torch.no_grad():
        state = core.init_state(u[:, :k], y, rh[:, :k])
        fast = core.simulate(state, u[:, k:], rh[:, k:])
        core.fast_inference = False
        slow = core.simulate(state, u[:, k:], rh[:, k:])
    np.testing.assert_allclose(fast.numpy(), slow.numpy(), rtol=1e-4, atol=1e-4)


def test_memory_filters_adapt_to_the_sampling_rate_and_record_length(tmp_path):
    """A slow plant at 0.25 Hz: filters below 2 sample periods (8 s) or above half a record
    are not used; the chosen range is warned about, stored in the card and restored."""
    import json
    from scipy.signal import lfilter
    from nnmodel.bundle import load, save
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    fs, n = 0.25, 1200
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1, 1, n // 12 + 1), 12)[:n]
    a = np.exp(-1 / (120 * fs))
    y = np.tanh(2 * lfilter([1 - a], [1, -a], u))
    rec = Experiment(u=u, y=y, rh=None, fs=fs)
    m = MODELS["ff"](nb=4, memory_filters=6, memory_min_s=0.01, memory_max_s=1e5, max_epochs=1, progress_bar=False)
    with pytest.warns(InputNotice, match="memory filters 0.01–100000 s do not fit these data"):
        m.fit([rec])
    lo, hi = m.memory_range_
    assert lo == pytest.approx(2 / fs) and hi == pytest.approx(0.5 * n / fs)
    b = save(m, tmp_path / "ff")
    assert json.loads((b / "card.json").read_text())["memory_range_s"] == [lo, hi]
    np.testing.assert_allclose(load(b).predict(u, fs=fs), m.simulate(u), rtol=1e-6, atol=1e-9)
