"""Each shortfall finding, followed: on a small synthetic plant that raises it, doing what the
finding says moves the result the way it says (nnmodel/shortfalls.py).

The plants are written here (not with the package): a Wiener plant (first-order lag, then a
tanh saturation or a hard clip) driven by random steps, an integrator in a closed loop (a
P controller on the measured output, random reference steps), and a mass on a spring under a
P controller (:func:`positioner`).  Sampled at 1 Hz; every test record is 2 000 samples from its own
seed."""
import re
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

from nnmodel.data import Experiment
from nnmodel.linear import fit_linear
from nnmodel.recipes import make_model
from nnmodel.shortfalls import explain, facts, feedback, saturation
from nnmodel.traincompare import _linear_runner, network_runner


def _steps(n, seed, hold=(1, 11), amp=1.0):
    rng = np.random.default_rng(seed)
    holds = rng.integers(*hold, n)
    return np.repeat(rng.uniform(-amp, amp, n), holds)[:n]


def wiener(n, seed, clip=None, amp=1.0):
    """x = first-order lag (8 s) of random steps; y = tanh(2x), or x clipped at ±clip; 1 % noise."""
    u = _steps(n, seed, amp=amp)
    a = np.exp(-1 / 8)
    x = lfilter([1 - a], [1, -a], u)
    y = np.tanh(2 * x) if clip is None else np.clip(x, -clip, clip)
    return u, y + 0.01 * np.std(y) * np.random.default_rng(seed + 100).normal(size=n)


def loop(n, seed):
    """y[t+1] = y[t] + 0.05 u[t], u[t] = 0.5 (r[t] - y_measured[t]); reference steps held 20-60 s."""
    r = _steps(n, seed, hold=(20, 60))
    rng = np.random.default_rng(seed + 100)
    y, u, ym = np.zeros(n), np.zeros(n), np.zeros(n)
    for t in range(n):
        ym[t] = y[t] + 0.02 * rng.normal()
        u[t] = 0.5 * (r[t] - ym[t])
        if t + 1 < n:
            y[t + 1] = y[t] + 0.05 * u[t]
    return u, ym


def positioner(n, seed, reference=False, drive=None, noise=0.05):
    """A mass on a spring (resonance 0.2 rad/s, damping ratio 0.1; semi-implicit Euler steps of 1 s)
    under a P controller u[t] = r[t] - y_measured[t], the position measured with 0.05 noise,
    reference steps held 20-60 s.  Returns (u, y), or (r, y) with ``reference``; ``drive``: the
    input instead of the controller's (open loop)."""
    r = _steps(n, seed, hold=(20, 60))
    rng = np.random.default_rng(seed + 100)
    u, ym = np.zeros(n), np.zeros(n)
    x = v = 0.0
    for t in range(n):
        ym[t] = x + noise * rng.normal()
        u[t] = r[t] - ym[t] if drive is None else drive[t]
        v += 0.04 * (u[t] - x) - 0.04 * v
        x += v
    return (r if reference else u), ym


def open_loop_twin(plant, n, seed, **kw):
    """``plant`` driven in open loop by a random-phase signal with the amplitude spectrum of the
    input its controller produced (same range and bandwidth, not computed from the output)."""
    u, _ = plant(n, seed, **kw)
    spectrum = np.abs(np.fft.rfft(u - u.mean()))
    phase = np.exp(2j * np.pi * np.random.default_rng(seed + 7).uniform(size=spectrum.size))
    return plant(n, seed, drive=np.fft.irfft(spectrum * phase, n) + u.mean(), **kw)


def _nrmse(run, recs):
    e2 = v2 = 0.0
    for r in recs:
        yh, w = run(r)
        e2 += float(np.sum((r.y[w:] - yh[w:]) ** 2))
        v2 += float(np.sum((r.y[w:] - r.y[w:].mean()) ** 2))
    return float(np.sqrt(e2 / v2))


def case(plant, name, overrides, n, seed=1, **kw):
    """Train ``name`` on ``n`` samples of ``plant`` (``seed``), score it and the linear row on a
    test record (seed 3) under the start-up rule; returns (network NRMSE, linear NRMSE, causes,
    actions)."""
    train = [Experiment(*plant(n, seed, **kw), None, 1.0)]
    test = [Experiment(*plant(2000, 3, **kw), None, 1.0)]
    model = make_model(name, {"progress_bar": False, **overrides})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(train, None)
    lin = fit_linear(train, None, model.val_fraction)
    rows = {"linear": {"free_run": {"test": {"nrmse": _nrmse(_linear_runner(lin), test)}}},
            name: {"free_run": {"test": {"nrmse": _nrmse(network_runner(model), test)}}}}
    found = explain(name, rows[name], rows, model, facts(train, test, None, {"name": "y", "unit": "V"}, 0, lin))
    causes = [c for f in found for c in f["causes"]]
    return (rows[name]["free_run"]["test"]["nrmse"], rows["linear"]["free_run"]["test"]["nrmse"],
            [c["cause"] for c in causes], [c["action"] for c in causes])


def test_an_integrating_plant_needs_a_state_that_can_integrate():
    """Closed-loop integrator, an NFIR network without a linear start: far above the linear row;
    the finding names the integrator and says --set ff.linear_start=true; followed, the error
    falls to the linear row's level."""
    bare = {"structures": None, "max_epochs": 0, "linear_start": False}
    net, lin, causes, actions = case(loop, "ff", bare, 1000)
    i = next(k for k, c in enumerate(causes) if c.startswith("an integrating plant"))
    assert net > 5 * lin and "`--set ff.linear_start=true`" in actions[i]
    followed, lin2, causes2, _ = case(loop, "ff", {**bare, "linear_start": True}, 1000)
    assert followed < net / 5 and followed <= 1.01 * lin2


def test_a_clipped_output_is_named_and_recording_within_range_lets_the_linear_row_follow():
    """Output clipped at ±0.4 (the lag's output reaches ±1): the finding names the clip; followed
    (a drive of ±0.4, within the range), the clip evidence is gone and the linear row's error falls."""
    bare = {"structures": None, "max_epochs": 0}
    net, lin, causes, actions = case(wiener, "ff", bare, 1000, clip=0.4)
    i = next(k for k, c in enumerate(causes) if c.startswith("the output is clipped"))
    assert "record within the output's range" in actions[i]
    train = [Experiment(*wiener(1000, 1, clip=0.4, amp=0.4), None, 1.0)]
    assert saturation(train, fit_linear(train, None, 0.2)) is None
    _, lin_within, causes2, _ = case(wiener, "ff", bare, 1000, clip=0.4, amp=0.4)
    assert lin_within < 0.5 * lin and not any(c.startswith("the output is clipped") for c in causes2)


@pytest.mark.slow
def test_a_dropped_correction_on_few_data_is_kept_when_more_is_recorded():
    """300 samples: the RBF network's correction lowers the validation error but cross-validation
    cannot tell it from chance, so it is dropped (the row is the linear row); the finding says
    record more; with 900 samples it is kept and the row falls well below the linear row."""
    over = {"structures": None, "na": 10, "nb": 10}
    net, lin, causes, actions = case(wiener, "rbf", over, 300)
    assert net == pytest.approx(lin, rel=1e-3)
    assert causes[0].startswith("its correction was dropped: on validation it lowered the error")
    assert actions[0].startswith("record more") and not any(c.startswith("too few independent") for c in causes)
    followed, lin2, _, _ = case(wiener, "rbf", over, 900)
    assert followed < 0.5 * lin2 and followed < 0.5 * net


@pytest.mark.slow
def test_a_saturating_plant_is_named_and_more_data_let_a_network_follow_it():
    """tanh saturation, the default RBF recipe on 200 samples ties the linear row; the finding
    names the saturation (a cubic term explains most of the linear residual) and says how many
    samples to record; followed, the network falls well below the linear row, which still cannot
    follow the saturation (the median over five training draws: a few hundred samples leave a
    network's fit to the draw)."""
    net, lin, causes, actions = case(wiener, "rbf", {}, 200)
    i = next(k for k, c in enumerate(causes) if c.startswith("the output saturates"))
    assert net == pytest.approx(lin, rel=1e-3) and "record more" in actions[i]
    advised = int(re.search(r"about ([\d,]+) training samples", actions[i]).group(1).replace(",", ""))
    assert advised > 200
    followed = [case(wiener, "rbf", {}, advised, seed=seed)[:2] for seed in (1, 2, 4, 5, 6)]
    assert np.median([net / lin for net, lin in followed]) < 0.6 and min(lin for _, lin in followed) > 0.1


@pytest.mark.slow
def test_too_few_independent_windows_recording_longer_lowers_the_error():
    """One split (cv_folds 1) on 300 samples keeps an RBF correction that tests far above the
    linear row; the finding counts the independent windows and says record longer; with 900
    samples the error falls below the linear row."""
    net, lin, causes, actions = case(wiener, "rbf", {"cv_folds": 1}, 300)
    i = next(k for k, c in enumerate(causes) if c.startswith("too few independent windows"))
    assert net > lin and actions[i].startswith("record longer")
    followed, lin2, _, _ = case(wiener, "rbf", {"cv_folds": 1}, 900)
    assert followed < net / 2 and followed < lin2


def _trained(plant, n, seed, **kw):
    """``ff`` (no training epochs: its linear start) and the linear row on ``n`` samples of ``plant``."""
    train = [Experiment(*plant(n, seed, **kw), None, 1.0)]
    model = make_model("ff", {"progress_bar": False, "structures": None, "max_epochs": 0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(train, None)
    return model, fit_linear(train, None, model.val_fraction), train


def test_a_closed_loop_is_named_and_recording_in_open_loop_lowers_the_error_on_free_drives():
    """A positioner under a P controller with a noisy position sensor: the finding names the
    closed loop and says record in open loop (or model the reference → output); followed (the same
    plant driven by a signal of the same spectrum, not computed from the output), the finding is
    gone and the error on an open-loop test drive falls by more than 10 %.  The reference → output
    data do not raise it either."""
    noisy = dict(noise=0.2)
    *_, causes, actions = case(positioner, "ff", {"structures": None, "max_epochs": 0}, 2000, **noisy)
    i = next(k for k, c in enumerate(causes) if c.startswith("a closed loop"))
    assert "record it in open loop" in actions[i] and "--columns voltage=REFERENCE" in actions[i]

    def twin(n, seed, **kw):
        return open_loop_twin(positioner, n, seed, **kw)
    test = [Experiment(*twin(2000, 3, **noisy), None, 1.0)]
    errors = {}
    for name, plant in (("closed", positioner), ("open", twin)):
        model, lin, train = _trained(plant, 2000, 1, **noisy)
        errors[name] = _nrmse(network_runner(model), test)
        assert (feedback(train, lin) is None) == (name == "open")
    assert errors["open"] < 0.9 * errors["closed"]
    model, lin, train = _trained(positioner, 2000, 1, reference=True, **noisy)
    assert feedback(train, lin) is None
