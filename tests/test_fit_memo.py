"""The fits' memo of model evaluations (:mod:`physics.execution.memo`): a finite-difference
Jacobian column of a parameter fitted per RH level re-evaluates only that level's targets and
records, and every number is the one a fresh evaluation gives; the modal stepper's start-up
state is scipy's ``lfiltic``."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.signal import lfiltic

from physics import signals, simulate
from physics.device import load_device
from physics.diagnose import candidates as C
from physics.diagnose.diagnosis import read_records
from physics.identify import problem as P
from physics.identify.options import FitOptions
from physics.io.timeseries import TimeSeries
from physics.solvers.lti import _initial_state


@pytest.fixture(scope="module")
def two_levels():
    """Two multisine records at RH 40 and 60 % of the thesis IPMC (1 µm noise) and their
    prepared records and FRF targets."""
    dev = load_device("ipmc_pt_eg")
    rng = np.random.default_rng(3)
    recs = []
    for i, rh in enumerate((40.0, 60.0)):
        sig = signals.multisine(0.5, 0.1, 20.0, 10.0, 2, 200.0, seed=i)
        y = simulate(dev, "default", sig.t, sig.v, rh=rh).deflection
        recs.append(TimeSeries(sig.t, sig.v, y + 1e-6 * rng.standard_normal(y.size), rh=np.full(sig.t.size, rh),
                               meta={"signal": sig.describe(), "sensor": {"noise_rms_m": 1e-6}}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        data = read_records(recs, FitOptions())
    return dev, data


def _counting(monkeypatch, module, name):
    calls = []
    real = getattr(module, name)

    def wrapped(*a, **kw):
        calls.append(1)
        return real(*a, **kw)
    monkeypatch.setattr(module, name, wrapped)
    return calls


def test_a_per_rh_column_recomputes_only_its_level(two_levels, monkeypatch):
    dev, data = two_levels
    ids = tuple(C.resolve_effects("default", dev))
    problem = P.IdentificationProblem(dev, ids, data.targets, ["beta_f"], ["Y", "kf"])
    levels = [t.level for t in data.targets]
    assert sorted(set(levels)) == [40.0, 60.0]
    calls = _counting(monkeypatch, P, "response_per_volt")
    theta = problem.theta0
    centre = problem.responses(theta)       # (the problem's check of its parameters evaluated it already)
    i = problem.labels.index("Y@RH40")
    moved = theta.copy()
    moved[i] *= 1.01
    calls.clear()
    out = problem.responses(moved)
    assert len(calls) == levels.count(40.0)             # the RH 60 target is the centre's
    fresh = P.IdentificationProblem(dev, ids, data.targets, ["beta_f"], ["Y", "kf"]).responses(moved)
    for a, b, lv, c in zip(out, fresh, levels, centre):
        assert np.array_equal(a, b)                     # bit for bit what a fresh evaluation gives
        assert (lv == 40.0) != np.array_equal(a, c)     # and the RH 40 target did change
    calls.clear()
    shared = theta.copy()
    shared[problem.labels.index("beta_f")] *= 1.01
    problem.responses(shared)
    assert len(calls) == len(data.targets)              # a shared parameter moves every target


def test_a_time_refinement_gives_the_numbers_it_gave_without_the_memo(two_levels, monkeypatch):
    """The records at the level a column does not touch are taken from the memo; the refined
    values and errors are those of a refinement that simulates every record every time."""
    dev, data = two_levels
    ids = tuple(C.resolve_effects("default", dev))
    spec = C.ModelSpec("base", ids, ["beta_f"], ["Y", "kf"], start={"beta_f": 2e-3})

    def refined():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = C.fit_model(spec, dev, data.targets, data.target_records, n_starts=1)
            C.score(fit, data.records)
            moved = C.refine_on_time(fit, data.records, sims=40)
        return fit, moved
    sims = _counting(monkeypatch, C, "predict")
    memo, moved = refined()
    with_memo = len(sims)
    monkeypatch.setattr(C, "remembered", lambda memo, key, compute: compute())
    sims.clear()
    plain, moved_plain = refined()
    assert moved == moved_plain
    assert memo.values == plain.values and memo.rmse == plain.rmse
    assert with_memo < len(sims)                       # and it simulated fewer records


@pytest.mark.parametrize("real", [True, False])
@pytest.mark.parametrize("taps", [1, 2, 4])
@pytest.mark.parametrize("past", [0, 2, 6])
def test_the_modal_start_up_state_is_lfiltic(real, taps, past):
    rng = np.random.default_rng(taps * 10 + past)

    def draw(*shape):
        x = rng.standard_normal(shape)
        return x if real else x + 1j * rng.standard_normal(shape)
    b, y0, x_past = draw(taps), draw(3), rng.standard_normal((3, past))
    a = 0.9 if real else 0.9 + 0.1j
    den = np.array([1.0, -a])
    ref = np.stack([lfiltic(b, den.real if real else den, [y0[k]], x_past[k]) for k in range(3)])
    got = _initial_state(b, a, y0, x_past, real)
    assert got.shape == ref.shape and got.dtype == ref.dtype
    np.testing.assert_allclose(got, ref, rtol=1e-14, atol=1e-300)


def test_the_memo_stays_within_its_size_and_bytes(monkeypatch):
    from physics.execution import memo as M
    memo = {}
    for k in range(M.SIZE + 5):
        M.remembered(memo, k, lambda: np.zeros(10))
    assert len(memo) == M.SIZE and 0 not in memo and M.SIZE + 4 in memo      # the oldest went first
    monkeypatch.setattr(M, "MAX_BYTES", 250)
    memo = {}
    for k in range(4):
        M.remembered(memo, k, lambda: np.zeros(10))                           # 80 B each
    assert list(memo) == [1, 2, 3]
    big = M.remembered(memo, "big", lambda: np.zeros(100))                    # over the cap alone: kept alone
    assert list(memo) == ["big"] and not big.flags.writeable
    calls = []
    M.remembered(memo, "big", lambda: calls.append(1) or np.zeros(100))
    assert not calls                                                          # a hit computes nothing


def test_a_time_residual_takes_the_untouched_level_from_the_memo(two_levels, monkeypatch):
    """``identify --residual time``: a per-RH column re-simulates only its level's record, and
    the errors are those of a fresh problem."""
    dev, data = two_levels
    ids = tuple(C.resolve_effects("default", dev))
    targets = data.targets
    problem = P.IdentificationProblem(dev, ids, targets, ["beta_f"], ["Y", "kf"], residual="time")
    theta = problem.theta0
    problem.time_errors(theta)
    import physics.solvers.timedomain as T
    sims = _counting(monkeypatch, T, "simulate")
    moved = theta.copy()
    moved[problem.labels.index("kf@RH60")] *= 1.02
    got = problem.time_errors(moved)
    assert len(sims) == sum(t.record is not None and t.level == 60.0 for t in targets) == 1
    assert len(got) == 2
    fresh = P.IdentificationProblem(dev, ids, targets, ["beta_f"], ["Y", "kf"], residual="time").time_errors(moved)
    assert all(np.array_equal(a, b) for a, b in zip(got, fresh))


def test_an_rh_series_has_no_key():
    from physics.model import ActuatorModel
    m = ActuatorModel(load_device("ipmc_pt_eg"), "default")
    assert m.key_at(np.array([59.0, 61.0])) is None
    assert m.key_at(60.0) == m.key_at(60.0) != m.key_at(61.0)
