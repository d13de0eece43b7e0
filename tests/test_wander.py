"""The records' slow wander: the part they share (a drift of the setup, deterministic) is told
from the part each record has on its own (a sensor's random walk, noise) — physics.diagnose.wander."""
import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from physics.diagnose.wander import SHARED_ALPHA, shared_wander, slow_wander


@dataclass
class _Rec:
    kind: str = "broadband"
    band: tuple = (0.1, 20.0)
    fs_d: float = 20.0
    noise_floor_d: float = 1e-6
    ts: object = None


def _records(n_rec, shared, walk, seed, duration=60.0, fs=20.0, white=1e-6, own=None):
    """``n_rec`` residuals [m] of ``duration`` s: ``shared(t)`` (the same in each) + an
    independent random walk of std ``walk`` at the end + white noise (+ ``own(t, rng)``, drawn
    for each record); nuisance removed like a fit."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * fs)) / fs
    recs, resid, nui = [], [], []
    for k in range(n_rec):
        y = shared(t) + np.cumsum(rng.normal(0.0, walk / math.sqrt(t.size), t.size)) + rng.normal(0, white, t.size)
        y = y + (own(t, rng) if own is not None else 0.0)
        A = np.column_stack([np.ones_like(t), t])
        c = np.linalg.lstsq(A, y, rcond=None)[0]
        recs.append(_Rec("broadband" if k == 0 else "steps", fs_d=fs, noise_floor_d=white,
                         ts=SimpleNamespace(duration=duration)))
        resid.append(y - A @ c)
        nui.append((float(c[0]), float(c[1])))
    return recs, resid, nui


def _split(recs, resid, nui):
    return shared_wander(recs, resid, nui, slow_wander(recs, resid, nui))


def test_independent_wanders_are_noise():
    """Sensor random walks differing per record: rarely called shared (≈ the test's level)."""
    shared = [_split(*_records(2, lambda t: 0 * t, 5e-6, seed)).fraction > 0 for seed in range(40)]
    assert sum(shared) <= 3, sum(shared)             # α = 1 %: ≥ 4 of 40 has probability < 1 %


def test_a_drift_the_records_share_is_told_from_the_sensors_wander():
    """A·(1 − e^(−t/τ)) from each record's start, larger than the independent wander: shared,
    and most of the slow power is the shared part."""
    drift = lambda t: 15e-6 * -np.expm1(-t / 8.0)    # noqa: E731
    splits = [_split(*_records(3, drift, 3e-6, seed)) for seed in range(5)]
    assert all(s.testable and s.p_value < SHARED_ALPHA and s.fraction > 0.5 for s in splits), splits
    assert "common to the 3 records" in splits[0].text() and "likelihood-ratio" in splits[0].text()


def test_the_false_alarm_rate_is_the_tests_level():
    """Under the null (independent random walks of one scale, white noise) the p-values are
    uniform: the rate below 0.05 and below 0.2 stays within binomial bounds (a miscalibrated
    null distribution, e.g. F(1, Rd − 1) at the best τ without the scan, fails the first)."""
    from scipy.stats import binom
    ps = np.array([_split(*_records(2, lambda t: 0 * t, 5e-6, 1000 + s)).p_value for s in range(150)])
    for level in (0.05, 0.2):
        hi = binom.ppf(0.999, ps.size, level)
        lo = binom.ppf(0.001, ps.size, level)
        assert lo <= np.count_nonzero(ps < level) <= hi, (level, np.count_nonzero(ps < level))


def test_a_smooth_wander_of_each_record_is_not_a_shared_drift():
    """The lab suite's per-record wander (doubly low-passed noise, 10 s, from each start, its own
    in every record; not a random walk): called shared no more often than the level allows."""
    from scipy.signal import lfilter
    from scipy.stats import binom
    a = math.exp(-1.0 / (10.0 * 20.0))           # 10 s at 20 Hz

    def own(t, rng):
        w = lfilter([1 - a], [1, -a], lfilter([1 - a], [1, -a], rng.normal(0, 1, t.size)))
        return 12e-6 * w / w.std()
    hits = sum(_split(*_records(2, lambda t: 0 * t, 1e-6, seed, own=own)).fraction > 0 for seed in range(60))
    assert hits <= binom.ppf(0.999, 60, SHARED_ALPHA), hits


def test_a_shared_drift_is_found_with_its_time_constant():
    """The outside suite's drift (|A| 8–20 µm, τ 5–60 s) on two records with 3–10 µm random walks:
    a short τ is found in most seeds, its τ and A near the truth."""
    drift = lambda t: -12e-6 * np.expm1(-t / 6.0)     # noqa: E731
    splits = [_split(*_records(2, drift, 5e-6, seed)) for seed in range(10)]
    found = [s for s in splits if s.fraction > 0]
    assert len(found) >= 7, [s.p_value for s in splits]
    assert np.median([s.tau for s in found]) == pytest.approx(6.0, rel=0.6)
    assert np.median([s.amplitude for s in found]) == pytest.approx(12e-6, rel=0.3)
    # its size after each record's offset and trend (what it adds to an error): the true drift's
    t = np.arange(1200) / 20.0
    x = drift(t) - np.polyval(np.polyfit(t, drift(t), 1), t)
    assert np.median([s.rms for s in found]) == pytest.approx(float(np.sqrt(np.mean(x ** 2))), rel=0.3)


def test_the_wander_left_as_noise_is_the_records_own():
    """With a shared drift found, the wander still counted as noise, wander·sqrt(1 − fraction),
    estimates each record's own random walk after its trend: RMS walk/sqrt(15) (Brownian motion
    theory, :data:`WALK_AFTER_TREND`), in mean square over seeds."""
    from physics.diagnose.records import WALK_AFTER_TREND
    drift = lambda t: -12e-6 * np.expm1(-t / 6.0)    # noqa: E731
    left = []
    for seed in range(30):
        recs, resid, nui = _records(2, drift, 5e-6, seed)
        w = slow_wander(recs, resid, nui)
        s = shared_wander(recs, resid, nui, w)
        if s.fraction > 0:
            left.append(w * math.sqrt(1.0 - s.fraction))
    assert len(left) >= 20
    assert math.sqrt(np.mean(np.square(left))) == pytest.approx(5e-6 * math.sqrt(WALK_AFTER_TREND), rel=0.15)


def test_one_record_cannot_attribute_its_wander():
    s = _split(*_records(1, lambda t: 0 * t, 5e-6, 0))
    assert not s.testable and "one record" in s.text()


def test_a_hint_of_sharing_short_of_the_test_level_is_called_inconclusive():
    from physics.diagnose.wander import HINT_P, WanderSplit
    hint = WanderSplit(0.0, 0.5 * (SHARED_ALPHA + HINT_P), 2, 5)
    assert hint.inconclusive and "cannot confirm" in hint.text()
    assert not WanderSplit(0.0, 0.5, 2, 5).inconclusive and "does not repeat" in WanderSplit(0.0, 0.5, 2, 5).text()
    assert not WanderSplit(0.8, 1e-4, 2, 5).inconclusive


def test_wander_per_trend_is_brownian_motion_theory():
    """The constants against the covariance min(s, t) of a Brownian motion (no sampling):
    mean square left after the least-squares line 1/15, the line's rise (slope × T) 6/5."""
    import numpy as np
    from physics.diagnose.records import WALK_AFTER_TREND
    from physics.diagnose.wander import WANDER_PER_TREND
    n = 800
    t = (np.arange(n) + 0.5) / n
    C = np.minimum.outer(t, t)
    tc = t - t.mean()
    A = np.column_stack([np.ones(n), tc])
    Q = np.eye(n) - A @ np.linalg.pinv(A)
    left = np.trace(Q @ C @ Q) / n
    rise = tc @ C @ tc / (tc @ tc) ** 2
    assert abs(left - WALK_AFTER_TREND) < 2e-3 * WALK_AFTER_TREND
    assert abs(rise - 1.2) < 2e-3
    assert abs(WANDER_PER_TREND - left / rise) < 2e-3 * WANDER_PER_TREND


def test_a_model_is_allowed_no_more_wander_than_its_own_residual_shows():
    """The wander counted beside the floor is measured on the base's residual, which also holds
    the base's slow error: a slow effect the base lacks leaves a transient from each record's
    start (a different one per record: not a shared drift) that reaches the lowest lines and
    would pass for the sensor's wander.  A better model's residual shows the sensor's wander
    without it; beside that model only what its own residual shows is allowed
    (physics.diagnose.diagnosis.allowed_wander), never the base's figure."""
    from physics.diagnose.diagnosis import allowed_wander
    from physics.diagnose.wander import WanderSplit
    rng = np.random.default_rng(4)
    fs, duration = 20.0, 60.0
    t = np.arange(int(duration * fs)) / fs
    recs, walk_only, with_misfit, nui = [], [], [], []
    for amp in (30e-6, -18e-6, 45e-6):             # the missing slow pole's start transient, per record
        walk = np.cumsum(rng.normal(0.0, 2e-6 / math.sqrt(t.size), t.size)) + rng.normal(0, 1e-6, t.size)
        for y, out in ((walk, walk_only), (walk + amp * np.exp(-t / 15.0), with_misfit)):
            A = np.column_stack([np.ones_like(t), t])
            out.append(y - A @ np.linalg.lstsq(A, y, rcond=None)[0])
        recs.append(_Rec(band=(0.05, 20.0), fs_d=fs, ts=SimpleNamespace(duration=duration)))
        nui.append((0.0, 0.0))
    w_walk, w_base = slow_wander(recs, walk_only, nui, trend=False), slow_wander(recs, with_misfit, nui, trend=False)
    assert w_base > 3 * w_walk                     # the base's slow error dominates its lowest lines
    data = SimpleNamespace(estimated=True, wander_split=WanderSplit(0.0, 0.5, 3, 5), wander=w_base, records=recs,
                           wanders={})
    base = SimpleNamespace(resid_d=with_misfit, nuisance=nui, rmse=float(np.std(np.concatenate(with_misfit))))
    better = SimpleNamespace(resid_d=walk_only, nuisance=nui, rmse=float(np.std(np.concatenate(walk_only))))
    assert allowed_wander(data) == w_base and allowed_wander(data, base) == w_base
    assert allowed_wander(data, better) == w_walk
    # the records could not tell whose wander it is: nothing is allowed, whatever the fit
    data.wander_split = WanderSplit(math.nan, math.nan, 3, 5, why="one record")
    assert allowed_wander(data, better) == 0.0
