"""The neural state-space network ``ss``: contract with its linear start, the linear start's
realisation against the ARX model it realises, the encoder's initial state, seeds and bundles."""
import json

import numpy as np
import pytest
import torch
from scipy.signal import lfilter

import nnmodel
from nnmodel.bundle import CARD, load, save
from nnmodel.data import Experiment
from nnmodel.linear import LinearModel
from nnmodel.models import MODELS
from nnmodel.models.ss import SSModel, StateSpaceCore, realise
from physics.errors import InputError

QUIET = dict(progress_bar=False, num_threads=1)
FS = 10.0


def linear_plant(n: int, seed: int, rh: float):
    """A resonant 2nd-order plant (poles 0.8 +/- 0.2j) whose gain and offset depend on RH,
    with 0.1 % output noise: an ARX model with RH as a linear input describes it."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, n), 3)[:n] + 0.3
    y = lfilter([0.02, 0.03], [1.0, -1.6, 0.68], u) * (1 + rh / 200) + 0.1 + rh / 1000
    return Experiment(u, y + 1e-3 * np.std(y) * rng.normal(size=n), np.full(n, rh), FS)


def wiener_plant(n: int, seed: int):
    """A first-order lag behind a saturation (slow pole 0.95): the state matters for ~60 samples."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-2.0, 2.0, n), 5)[:n]
    return Experiment(u, np.tanh(lfilter([0.05], [1.0, -0.95], u) * 2.0), None, FS)


def test_contract_holds_with_the_linear_start():
    """nnmodel.check_model with the realisation of the linear start (the registry test runs the
    class defaults, which have none)."""
    assert nnmodel.check_model(SSModel, {"linear_start": True})[-1] == "check_seeded"


def test_a_linear_plant_is_matched_from_the_linear_start():
    """Untrained, the network with its linear start is the ARX model it realises: its free run
    equals the ARX free run (float32 rounding) and fits the plant to its noise."""
    train, val = [linear_plant(1500, 1, 40.0), linear_plant(1500, 2, 80.0)], [linear_plant(500, 3, 60.0)]
    m = SSModel(linear_start=True, max_epochs=0, **QUIET).fit(train, val)
    lin = m.features_.linear
    test = linear_plant(800, 5, 60.0)
    k = m.n_init_
    y_ss = m.simulate(test.u, test.rh, y_init=test.y[:k])
    y_lin = lin.simulate(test.u, test.rh, y_init=test.y[:k])
    sd = np.std(test.y)
    assert np.max(np.abs(y_ss - y_lin)) < 1e-5 * sd
    assert np.sqrt(np.mean((y_ss - test.y)[k:] ** 2)) < 0.01 * sd
    assert m.realisation_["form"] == "balanced" and m.net_.core.n_lin >= 2


@pytest.mark.parametrize("a", [[1.0], [1.6, -0.68], [1.2, 0.1, -0.36]])
def test_the_realisation_reproduces_the_arx_free_run(a):
    """realise() against LinearModel.simulate_norm for a stable ARX (balanced form) and an
    integrator (not balanceable: observer form), in other normalisation scales than the ARX's."""
    a = np.asarray(a)
    lin = LinearModel(len(a), 3, 1, a, np.array([0.3, -0.1, 0.05]), 0.02, None,
                      {"u_mean": 0.1, "u_std": 2.0, "y_mean": -0.3, "y_std": 0.5})
    net_scale = {"u": (0.4, 1.5), "y": (0.2, 0.7)}
    n0 = 6
    r = realise(lin, net_scale.__getitem__, n0, 0, 0)
    assert r["form"] == ("observer" if a.sum() >= 1.0 else "balanced")
    core = StateSpaceCore(r["n"], 0, 4, 1, "tanh", n0, 4)
    core.set_start(r["a"], r["b"], r["c"], r["d"], r["e_w"], r["e_b"])
    rng = np.random.default_rng(0)
    u = np.cumsum(rng.normal(size=200)) * 0.05 if a.sum() >= 1.0 else rng.normal(size=200)
    ul = (u - 0.1) / 2.0                                              # the ARX's own units
    yl = lfilter(np.r_[0.0, lin.b], np.r_[1.0, -a], ul) + lfilter([lin.c], np.r_[1.0, -a], np.ones(u.size))
    np.testing.assert_allclose(lin.simulate_norm(ul, None, yl[:n0])[n0:], yl[n0:], rtol=1e-9, atol=1e-9)
    y = yl * 0.5 - 0.3                                                # physical units
    un, yn = (u - 0.4) / 1.5, (y - 0.2) / 0.7                         # the network's units
    with torch.no_grad():
        t = lambda x: torch.as_tensor(x, dtype=torch.float32)[None]  # noqa: E731
        out = core.simulate(core.init_state(t(un[:n0]), t(yn[:n0]), None), t(un[n0:]), None)[0].double().numpy()
    np.testing.assert_allclose(out * 0.7 + 0.2, y[n0:], atol=1e-4 * np.ptp(y))


def test_the_encoder_state_beats_a_zero_state_on_the_first_samples():
    """Trained without a linear start (everything learned), the encoder's estimate of the state
    from the 10 samples before a window lowers the error of the window's first samples against
    the same network started from the zero state."""
    m = SSModel(nx=2, hidden=16, encoder_hidden=16, n_init=10, max_epochs=15, horizon=30, stride=5, lr=5e-3,
                batch_size=32, **QUIET).fit([wiener_plant(2000, 1)], [wiener_plant(400, 2)])
    core, net = m.net_.core, m.net_
    rec = wiener_plant(3000, 3)
    starts = np.arange(200, 2900, 97)
    e_enc = e_zero = 0.0
    with torch.no_grad():
        for s in starts:
            un = torch.as_tensor(net.norm("u", rec.u[s - 10:s + 20]), dtype=torch.float32)[None]
            yn = torch.as_tensor(net.norm("y", rec.y[s - 10:s + 20]), dtype=torch.float32)[None]
            x0 = core.init_state(un[:, :10], yn[:, :10], None)
            y_enc = core.simulate(x0, un[:, 10:], None)
            y_zero = core.simulate(torch.zeros_like(x0), un[:, 10:], None)
            e_enc += float(((y_enc - yn[:, 10:]) ** 2).sum())
            e_zero += float(((y_zero - yn[:, 10:]) ** 2).sum())
    assert e_enc < 0.25 * e_zero


def test_same_seed_same_weights_other_seed_other_weights():
    recs = [wiener_plant(600, 1)]
    kw = dict(nx=2, hidden=8, encoder_hidden=8, n_init=5, max_epochs=2, horizon=20, stride=10, linear_start=True,
              **QUIET)
    w = [SSModel(seed=s, **kw).fit(recs).net_.state_dict() for s in (4, 4, 5)]
    assert all(torch.equal(w[0][k], w[1][k]) for k in w[0])
    assert any(not torch.equal(w[0][k], w[2][k]) for k in w[0] if w[0][k].dtype.is_floating_point)


def test_bundle_round_trip_card_and_size_cap(tmp_path):
    train = [linear_plant(800, 1, 40.0), linear_plant(800, 2, 80.0)]
    m = SSModel(nx=2, hidden=8, encoder_hidden=8, n_init=8, max_epochs=1, horizon=20, stride=10, linear_start=True,
                **QUIET).fit(train)
    path = save(m, tmp_path / "ss")
    b = load(path)
    u = linear_plant(300, 9, 60.0).u
    np.testing.assert_allclose(b.predict(u, rh=60.0, fs=FS), m.simulate(u, 60.0), rtol=1e-6, atol=1e-12)
    card = json.loads((path / CARD).read_text())
    sizes = card["state_space"]
    core = m.net_.core
    assert sizes["states"] == core.n_state == sizes["linear_states"] + sizes["free_states"]
    assert sizes["free_states"] == 2 and sizes["encoder_samples"] == core.n_init
    assert sizes["linear_realisation"] == m.realisation_
    assert b.model.realisation_ == m.realisation_
    card["hyper_parameters"]["nx"] = 10 ** 6
    (path / CARD).write_text(json.dumps(card))
    with pytest.raises(InputError, match=r"nx=1000000 is invalid; expected at most 1,000"):
        load(path)


def test_no_state_is_refused_with_a_clear_message():
    with pytest.raises(InputError, match="nx"):
        SSModel(nx=0, max_epochs=0, **QUIET).fit([wiener_plant(300, 1)])
    assert "ss" in MODELS


def test_silverbox_benchmark_runs_ss_on_a_slice_of_the_real_file(tmp_path, capsys):
    """`eap benchmark --suite silverbox` trains ss by default and saves a bundle that loads."""
    from nnmodel.benchmarks import SUITES, silverbox
    from nnmodel.app.cli import main
    assert "ss" in SUITES["silverbox"].default_models
    try:
        silverbox.find_data()
    except InputError as exc:
        pytest.skip(f"Silverbox data file absent: {exc}")
    out = tmp_path / "sb"
    rc = main(["benchmark", "--suite", "silverbox", "--out", str(out), "--models", "ss", "--limit", "1500",
               "--no-progress", "--set", "ss.max_epochs=1", "--set", "ss.hidden=4", "--set", "ss.horizon=20"])
    assert rc == 0
    rep = json.loads((out / "silverbox.json").read_text())
    row = next(r for r in rep["results"] if r["model"] == "ss")
    assert all(np.isfinite(v) for v in row["rmse_mv"].values())
    assert load(out / "models" / "ss").card["state_space"]["encoder_samples"] == silverbox.N_INIT
