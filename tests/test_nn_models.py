"""The neural models learn known systems and follow the shared contract.

Every accuracy bound is checked against the closed-form system of
:mod:`nnmodel.benchmarks.toy`, never against a model's own earlier output.  Models are
kept tiny (a few seconds each on one thread).
"""
import warnings

import numpy as np
import pytest
from scipy import signal

from physics.errors import InputError
from nnmodel.benchmarks import toy
from nnmodel.data import Experiment, nrmse
from nnmodel.models import MODELS, NotFittedError

QUIET = dict(progress_bar=False, num_threads=1)


def fit(name, records, **kw):
    return MODELS[name](**QUIET, **kw).fit(records)


# ---------------------------------------------------------------- learning known systems
LINEAR_CASES = {
    # gradient training from scratch (no least-squares start) for the MLP
    "ff": (dict(na=2, nb=3, arx_init=False, lr=1e-2, max_epochs=15), 0.25),
    # ARX start + closed-loop epochs: must stay (near) exact on a noise-free linear system
    "narx": (dict(na=2, nb=3, max_epochs=3, horizon=30, stride=10), 0.02),
    "rbf": (dict(na=2, nb=3, n_centres=20), 0.02),
    "lstm": (dict(max_epochs=30, horizon=100, stride=20, lr=1e-2), 0.12),
    "gru": (dict(max_epochs=30, horizon=100, stride=20, lr=1e-2), 0.12),
}


@pytest.fixture(scope="module")
def linear_models():
    train = toy.records("linear2", 2000, seeds=(1,))
    return {name: fit(name, train, **kw) for name, (kw, _) in LINEAR_CASES.items()}


@pytest.mark.parametrize("name", list(LINEAR_CASES))
def test_every_model_learns_a_linear_second_order_system(linear_models, name):
    u = toy.excitation(1000, seed=9)  # unseen input
    y_true = toy.linear2(u)
    err = nrmse(y_true, linear_models[name].simulate(u))
    assert err < LINEAR_CASES[name][1], f"{name}: free-run NRMSE {err:.3f}"


def test_static_cubic_needs_the_nonlinear_layer():
    train = toy.records("cubic", 2000, seeds=(1,))
    u = toy.excitation(1000, seed=9)
    y = toy.static_cubic(u)
    mlp = fit("ff", train, na=0, nb=1, max_epochs=20, lr=1e-2, batch_size=64)
    rbf = fit("rbf", train, na=0, nb=1, n_centres=20)
    linear = fit("ff", train, na=0, nb=1, layers=0, max_epochs=0)
    assert nrmse(y, mlp.simulate(u)) < 0.08
    assert nrmse(y, rbf.simulate(u)) < 0.05
    assert nrmse(y, linear.simulate(u)) > 0.3  # the cubic is really there


def test_closed_loop_training_removes_the_bias_of_one_step_training():
    # output (measurement) noise: one-step least squares is biased, simulation-error
    # training is not; both are linear models with the same lags
    train = toy.records("linear2", 3000, seeds=(1,), noise=0.5)
    u = toy.excitation(1000, seed=9)
    y_true = toy.linear2(u)
    one_step = fit("ff", train, na=2, nb=3, layers=0, max_epochs=0)
    closed = fit("narx", train, na=2, nb=3, layers=0, max_epochs=30, horizon=100, stride=20,
                 lr=3e-2, patience=30)
    e1, e2 = nrmse(y_true, one_step.simulate(u)), nrmse(y_true, closed.simulate(u))
    assert e2 < 0.5 * e1, (e1, e2)


def test_humidity_input_is_used_on_held_out_humidity():
    train = toy.records("rh", 1500, seeds=(1,), rh_levels=(40.0, 60.0, 80.0))
    test = toy.records("rh", 1000, seeds=(9,), rh_levels=(50.0, 70.0))  # held-out levels
    kw = dict(na=1, nb=2, max_epochs=10, horizon=30, stride=10, lr=1e-2)
    with_rh = fit("narx", train, **kw)
    without = fit("narx", train, inputs="voltage", **kw)
    lstm = fit("lstm", train, max_epochs=30, horizon=100, stride=20, lr=1e-2)
    assert with_rh.inputs_ == ["voltage", "rh"] and without.inputs_ == ["voltage"]
    assert with_rh.rh_range_ == (40.0, 80.0)

    def err(m):
        return np.mean([nrmse(r.y, m.simulate(r.u, rh=r.rh if m.uses_rh else None)) for r in test])
    e_rh, e_no, e_lstm = err(with_rh), err(without), err(lstm)
    assert e_rh < 0.15 and e_lstm < 0.1
    assert e_rh < 0.6 * e_no, (e_rh, e_no)  # a voltage-only model cannot know the gain


# ---------------------------------------------------------------- free run vs k-step
def test_one_step_prediction_not_worse_than_free_run_for_equation_error_data():
    rng = np.random.default_rng(5)
    u = toy.excitation(3000, seed=3)
    e = 0.2 * rng.standard_normal(u.size)
    # ARX-type noise: y = B/A u + 1/A e, where the one-step predictor with true outputs is optimal
    y = toy.SCALE * (signal.lfilter(toy.LIN2_B, toy.LIN2_A, u) + signal.lfilter([1.0], toy.LIN2_A, e))
    m = fit("ff", [Experiment(u, y, None, toy.FS)], na=2, nb=3, layers=0, max_epochs=0)
    u2 = toy.excitation(1500, seed=4)
    e2 = 0.2 * rng.standard_normal(u2.size)
    y2 = toy.SCALE * (signal.lfilter(toy.LIN2_B, toy.LIN2_A, u2) + signal.lfilter([1.0], toy.LIN2_A, e2))
    err = {k: nrmse(y2, m.predict(u2, y=y2, steps_ahead=k)) for k in (1, 5)}
    err[None] = nrmse(y2, m.predict(u2, y=y2))
    assert err[1] <= err[5] <= err[None]


@pytest.mark.parametrize("name", list(LINEAR_CASES))
def test_k_step_prediction_uses_only_the_past(linear_models, name):
    m = linear_models[name]
    u = toy.excitation(400, seed=11)
    y = toy.linear2(u)
    t0, k = 200, 7
    y_bad = y.copy()
    y_bad[t0:] += 5e-3  # corrupt the measurements from t0 on
    p, p_bad = m.predict(u, y=y, steps_ahead=k), m.predict(u, y=y_bad, steps_ahead=k)
    np.testing.assert_allclose(p[:t0 + k], p_bad[:t0 + k], rtol=0, atol=1e-12)
    assert np.max(np.abs(p[t0 + k:] - p_bad[t0 + k:])) > 1e-6  # and later ones do use it
    # a horizon longer than the record is a free run from the steady state of the first
    # measured samples (input u[0], output y[0] held before the record)
    P = m.n_init_
    held = m.simulate(np.r_[np.full(P, u[0]), u], y_init=np.full(P, y[0]))[P:]
    np.testing.assert_allclose(m.predict(u, y=y, steps_ahead=len(u)), held,
                               rtol=1e-4, atol=1e-4 * np.std(y))  # float32 batch vs float64 fast path


def test_free_run_uses_measured_outputs_only_to_initialise(linear_models):
    m = linear_models["narx"]
    u = toy.excitation(300, seed=12)
    y = toy.linear2(u)
    sim = m.simulate(u, y_init=y[:50])
    np.testing.assert_array_equal(sim[:50], y[:50])
    y_bad = y.copy()
    y_bad[60:] = 1.0
    np.testing.assert_array_equal(m.predict(u, y=y), m.predict(u, y=y_bad))
    with pytest.raises(InputError, match="shorter"):
        m.simulate(u[:10], y_init=y[:10])


# ---------------------------------------------------------------- determinism, contract
@pytest.mark.parametrize("name", ["ff", "narx", "gru"])
def test_same_seed_gives_identical_weights(name):
    train = toy.records("linear2", 800, seeds=(2,))
    kw = dict(max_epochs=2, seed=3)
    if name != "gru":
        kw.update(na=2, nb=2, arx_init=False)
    else:
        kw.update(horizon=50, stride=25, hidden=8)
    u = toy.excitation(200, seed=5)
    a, b = fit(name, train, **kw).simulate(u), fit(name, train, **kw).simulate(u)
    np.testing.assert_array_equal(a, b)
    c = fit(name, train, **{**kw, "seed": 4}).simulate(u)
    assert not np.array_equal(a, c)


def test_inputs_are_checked(linear_models):
    m = linear_models["ff"]
    u = toy.excitation(100, seed=1)
    with pytest.raises(InputError, match="not finite"):
        m.simulate(np.r_[u, np.nan])
    with pytest.raises(InputError, match="1-D"):
        m.simulate(np.zeros((3, 3)))
    with pytest.raises(InputError, match="steps_ahead"):
        m.predict(u, y=u, steps_ahead=0)
    with pytest.raises(InputError, match="measured output"):
        m.predict(u, steps_ahead=1)
    with pytest.warns(RuntimeWarning, match="without humidity"):
        m.simulate(u, rh=50.0)


def test_humidity_model_needs_rh_and_warns_outside_the_trained_range():
    m = fit("ff", toy.records("rh", 500, rh_levels=(40.0, 60.0)), na=1, nb=2, max_epochs=1)
    u = toy.excitation(100, seed=1)
    with pytest.raises(InputError, match="relative humidity"):
        m.simulate(u)
    with pytest.raises(InputError, match="0–100"):
        m.simulate(u, rh=150.0)
    with pytest.warns(RuntimeWarning, match=r"outside the range seen in training \(40-60 %RH\)"):
        m.simulate(u, rh=90.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m.simulate(u, rh=np.linspace(40, 60, 100))  # inside: no warning


def test_hyper_parameters_follow_the_estimator_conventions():
    m = MODELS["narx"](na=3)
    assert m.get_params()["na"] == 3 and "num_threads" in m.get_params()
    assert not any(k.endswith("_") for k in vars(m))  # nothing learned yet
    with pytest.raises(NotFittedError):
        m.simulate(np.zeros(10))
    with pytest.raises(InputError, match="unknown hyper-parameter"):
        m.set_params(n_layers=3)
    with pytest.raises(InputError, match="na=-1"):
        MODELS["narx"](na=-1)
    with pytest.raises(InputError, match="activation"):
        MODELS["ff"](activation="swish2")
    with pytest.raises(InputError, match="humidity"):
        MODELS["ff"](inputs="voltage+rh", **QUIET).fit(toy.records("linear2", 300))
    short = MODELS["narx"](horizon=500, **QUIET)
    with pytest.raises(InputError, match="shorter than one training window"):
        short.fit(toy.records("linear2", 300))
    assert not [k for k in vars(short) if k.endswith("_")]  # no half-trained state left


def test_parameter_counts_match_the_architecture(linear_models):
    ff = linear_models["ff"]  # na=2, nb=3, hidden 32, 2 layers, linear bypass
    h, d_y, d_x = 32, 2, 3
    expected = (d_y * h) + (d_x * h + h) + (h * h + h) + (h + 1) + d_y + (d_x + 1)
    assert ff.n_parameters == expected


@pytest.mark.parametrize("activation, poly", [("tanh", 1), ("tanh", 3), ("relu", 2), ("gelu", 1),
                                              ("silu", 1), ("elu", 1), ("sigmoid", 1)])
def test_fast_numpy_free_run_matches_the_torch_loop(activation, poly):
    import torch
    from nnmodel.models.lag import LagSimulator, MLPMap

    torch.manual_seed(0)
    core = LagSimulator(3, 4, 1, MLPMap(3, 5, 16, 2, activation, poly_degree=poly))
    with torch.no_grad():
        for p in core.parameters():
            p.normal_(0, 0.3)
        if core.fmap.lin_y is not None:
            core.fmap.lin_y.weight.mul_(0.2)  # keep the recursion stable
    k, T = core.n_init, 300
    u, y, rh = torch.randn(1, k + T), torch.randn(1, k), torch.randn(1, k + T)
    with torch.no_grad():
        state = core.init_state(u[:, :k], y, rh[:, :k])
        fast = core.simulate(state, u[:, k:], rh[:, k:])
        core.fast_inference = False
        slow = core.simulate(state, u[:, k:], rh[:, k:])
    assert fast.shape == slow.shape == (1, T)
    np.testing.assert_allclose(fast.numpy(), slow.numpy(), rtol=1e-4, atol=1e-4)


def test_fast_numpy_free_run_matches_the_torch_loop_for_rbf():
    import torch
    from nnmodel.models.lag import LagSimulator, RBFMap

    torch.manual_seed(1)
    core = LagSimulator(2, 3, 0, RBFMap(2, 3, 12))
    with torch.no_grad():
        core.fmap.centres.normal_()
        core.fmap.weight.normal_(0, 0.5)
        core.fmap.lin.normal_(0, 0.2)
    k, T = core.n_init, 200
    u, y = torch.randn(1, k + T), torch.randn(1, k)
    with torch.no_grad():
        state = core.init_state(u[:, :k], y, None)
        fast = core.simulate(state, u[:, k:], None)
        core.fast_inference = False
        slow = core.simulate(state, u[:, k:], None)
    np.testing.assert_allclose(fast.numpy(), slow.numpy(), rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("kind", ["ff", "narx", "lstm", "rbf"])
def test_free_run_in_chunks_equals_one_piece(kind, monkeypatch):
    """Long records are simulated in pieces (bounded memory); the pieces must continue exactly."""
    import nnmodel.models.base as base
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    from scipy.signal import lfilter
    rng = np.random.default_rng(1)
    u = np.convolve(rng.normal(size=2000), np.ones(5) / 5, "same")
    y = lfilter([0.05], [1, -0.95], np.tanh(u)) * 1e-3
    rec = Experiment(u=u, y=y, rh=np.full(u.size, 50.0), fs=100.0)
    kw = {"ff": dict(max_epochs=2), "narx": dict(max_epochs=1, horizon=20, stride=20),
          "lstm": dict(max_epochs=1, horizon=50, stride=50), "rbf": dict(n_centres=8)}[kind]
    m = MODELS[kind](progress_bar=False, **kw)
    m.fit([rec], [rec])
    whole = m.simulate(u, 50.0)
    monkeypatch.setattr(base, "SIM_CHUNK", 37)
    pieces = m.simulate(u, 50.0)
    assert np.max(np.abs(pieces - whole)) <= 1e-5 * np.max(np.abs(whole))
    if m.streams:     # a record longer than base.PIECE: its pieces written into one output, y_init first
        start = m.simulate(u, 50.0, y_init=y[:12])
        monkeypatch.setattr(base, "PIECE", 301)
        for y0, ref in ((None, whole), (y[:12], start)):
            long = m.simulate(u, 50.0, y_init=y0)
            assert long.shape == u.shape and np.max(np.abs(long - ref)) <= 1e-5 * np.max(np.abs(ref))


def test_without_output_feedback_one_step_equals_free_run_from_any_start():
    """FF has no output feedback (na = 0): k-step prediction and free run are the same model
    evaluation, also on a record that does not start at rest (filters start in the steady
    state of the first input sample on both paths)."""
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    from scipy.signal import lfilter
    rng = np.random.default_rng(2)
    u = 0.8 + np.convolve(rng.normal(size=1500), np.ones(5) / 5, "same")   # far from 0 V at the start
    y = lfilter([0.05], [1, -0.95], np.tanh(u)) * 1e-3
    m = MODELS["ff"](na=0, nb=6, memory_filters=4, max_epochs=1, progress_bar=False)
    m.fit([Experiment(u=u, y=y, rh=None, fs=100.0)])
    k = m.n_init_
    free = m.simulate(u, y_init=y[:k])
    one = m.predict(u, y=y, steps_ahead=1)
    np.testing.assert_allclose(one[k:], free[k:], rtol=1e-5, atol=1e-9)


def _resonant_records(n=3000, fs=100.0):
    """A lightly damped resonance (10 Hz, ζ = 0.05) driven by filtered noise: an input
    delay line of 5 samples cannot hold its memory, output feedback can."""
    b, a = signal.cheby1(2, 1, 5.0, fs=fs)
    wn, z = 2 * np.pi * 10.0, 0.05
    bd, ad = signal.cont2discrete(([wn ** 2], [1, 2 * z * wn, wn ** 2]), 1 / fs)[:2]
    out = []
    for seed in (1, 2):
        u = signal.lfilter(b, a, np.random.default_rng(seed).normal(size=n))
        y = signal.lfilter(np.ravel(bd), ad, u)
        out.append(Experiment(u=u, y=y + 1e-3 * np.std(y) * np.random.default_rng(seed + 10).normal(size=n),
                          rh=None, fs=fs))
    return out


def test_structure_selection_keeps_the_best_free_run_on_validation(tmp_path):
    """`structures` are each fitted; the one with the lowest free-run validation NRMSE is
    kept, every score is in the card, and a bundle round trip keeps the chosen form."""
    from nnmodel.bundle import load, save
    train, test = _resonant_records()
    m = MODELS["rbf"](na=0, nb=5, n_centres=20, memory_filters=0, progress_bar=False,
                      structures=[{}, {"na": 4, "nb": 4}])
    m.fit([train])
    search = m.structure_search_
    assert [s["structure"] for s in search] == [{}, {"na": 4, "nb": 4}]
    scores = [s["validation_free_run_nrmse"] for s in search]
    assert scores[1] < 0.5 * scores[0]                     # the resonance needs feedback ...
    assert m.na == 4 and m.structures == [{}, {"na": 4, "nb": 4}]   # ... and that form was kept
    fixed = MODELS["rbf"](na=4, nb=4, n_centres=20, memory_filters=0, progress_bar=False).fit([train])
    y_sel = m.simulate(test.u, y_init=test.y[:m.n_init_])
    np.testing.assert_allclose(y_sel, fixed.simulate(test.u, y_init=test.y[:fixed.n_init_]), rtol=1e-6, atol=1e-9)
    b = load(save(m, tmp_path / "rbf"))
    assert b.card["structure_search"][1]["validation_free_run_nrmse"] == pytest.approx(scores[1])
    np.testing.assert_allclose(b.model.simulate(test.u, y_init=test.y[:4]), y_sel, rtol=1e-6, atol=1e-9)


def test_structures_naming_unknown_parameters_are_refused_before_fitting():
    train, _ = _resonant_records(n=600)
    m = MODELS["rbf"](n_centres=10, progress_bar=False, structures=[{}, {"na": 3, "nx": 4}])
    with pytest.raises(InputError, match=r"structures entry .* unknown hyper-parameter\(s\) \['nx'\]"):
        m.fit([train])
    with pytest.raises(InputError, match="structures"):
        MODELS["ff"](structures="na=3")


def test_ff_scores_structures_by_their_least_squares_start_and_trains_only_the_winner():
    train, _ = _resonant_records(n=1500)
    m = MODELS["ff"](na=0, nb=5, hidden=8, layers=1, memory_filters=0, max_epochs=2, progress_bar=False,
                     structures=[{}, {"na": 4, "nb": 4}])
    m.fit([train])
    assert all(s["scored_as"] == "linear least-squares start" for s in m.structure_search_)
    assert m.na == 4 and m.layers == 1 and m.max_epochs == 2   # the winner, with the recipe's own training
    assert m.training_summary_["epochs_run"] >= 1


@pytest.mark.parametrize("kind", ["narx", "ff"])
def test_a_linear_start_continues_across_pieces(kind):
    """simulate_pieces carries the linear start's free run over (its filter state and past
    inputs) as it does the memory filters: the pieces give the whole-record output."""
    from nnmodel.data import Experiment
    from nnmodel.models import MODELS
    from scipy.signal import lfilter
    rng = np.random.default_rng(2)
    u = np.convolve(rng.normal(size=1500), np.ones(5) / 5, "same")
    y = lfilter([0.05], [1, -0.95], np.tanh(u)) * 1e-3
    rec = Experiment(u=u, y=y, rh=np.full(u.size, 50.0), fs=100.0)
    m = MODELS[kind](progress_bar=False, linear_start=True, max_epochs=1, memory_filters=2,
                     **({"horizon": 20, "stride": 20} if kind == "narx" else {}))
    m.fit([rec], [rec])
    assert m.features_.linear is not None and m.streams
    for y0 in (None, y[:12]):
        whole = m.simulate(u, 50.0, y_init=y0)
        cuts = [0, 30, 33, 700, 1500]
        parts = np.concatenate(list(m.simulate_pieces(((u[a:b], np.full(b - a, 50.0))
                                                       for a, b in zip(cuts, cuts[1:])), y0)))
        assert np.max(np.abs(parts - whole)) <= 1e-5 * np.max(np.abs(whole))
