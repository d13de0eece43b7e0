"""Records and training windows (nnmodel.data)."""
from types import SimpleNamespace

import numpy as np
import pytest

from physics.errors import InputError
from nnmodel.data import Experiment, check_records, cut_windows, split_records, window_starts, rh_range


def test_record_broadcasts_constant_rh_and_slices_like_an_array():
    r = Experiment(np.arange(10.0), np.arange(10.0) * 2, 55.0, 100.0, "a")
    assert r.rh.shape == (10,) and np.all(r.rh == 55.0)
    s = r[2:5]
    assert isinstance(s, Experiment) and len(s) == 3 and s.fs == 100.0
    assert np.array_equal(s.u, [2, 3, 4]) and np.array_equal(s.y, [4, 6, 8]) and np.all(s.rh == 55)
    a, b = r.split(0.7)
    assert (len(a), len(b)) == (7, 3)
    with pytest.raises(InputError, match="step"):
        r[::2]


@pytest.mark.parametrize("kwargs, match", [
    (dict(u=[0.0, np.nan, 1.0], fs=10), "not finite"),
    (dict(u=[0.0, 1.0], y=[0.0], fs=10), "samples"),
    (dict(u=[0.0, 1.0], rh=120.0, fs=10), "0–100"),
    (dict(u=[0.0, 1.0]), "fs"),
    (dict(u=[0.0, 1.0], fs=-1), "positive"),
    (dict(u=np.zeros((2, 2)), fs=10), "1-D"),
    (dict(u=[], fs=10), "empty"),
])
def test_record_rejects_bad_input(kwargs, match):
    with pytest.raises(InputError, match=match):
        Experiment(**kwargs)


def test_from_timeseries_is_duck_typed():
    ts = SimpleNamespace(time=np.arange(5) / 50.0, voltage=np.ones(5), deflection=np.zeros(5),
                         rh=np.full(5, 40.0), fs=50.0)
    r = Experiment.from_timeseries(ts, name="x")
    assert r.fs == 50.0 and np.all(r.rh == 40.0) and r.name == "x"
    with pytest.raises(InputError, match="voltage"):
        Experiment.from_timeseries(SimpleNamespace(fs=1.0))


def test_check_records_refuses_mixed_rates_and_mixed_humidity():
    a = Experiment(np.zeros(5), np.zeros(5), 50, 10.0)
    with pytest.raises(InputError, match="sampling rates"):
        check_records([a, Experiment(np.zeros(5), np.zeros(5), 50, 20.0)])
    with pytest.raises(InputError, match="humidity"):
        check_records([a, Experiment(np.zeros(5), np.zeros(5), None, 10.0)])
    with pytest.raises(InputError, match="no measured output"):
        check_records([Experiment(np.zeros(5), None, None, 10.0)])
    assert rh_range([a, Experiment(np.zeros(5), np.zeros(5), 80, 10.0)]) == (50.0, 80.0)


def test_windows_cover_records_and_hold_the_right_samples():
    assert list(window_starts(10, 4, 3)) == [0, 3, 6]
    assert list(window_starts(11, 4, 3)) == [0, 3, 6, 7]  # last window ends at the end
    assert window_starts(3, 4, 1).size == 0
    r = Experiment(np.arange(20.0), 100 + np.arange(20.0), None, 1.0)
    w = cut_windows([r], n_init=2, horizon=3, stride=5)
    assert w["u"].shape == (4, 5) and "rh" not in w
    assert np.array_equal(w["u"][1], [5, 6, 7, 8, 9]) and np.array_equal(w["y"][1], 105 + np.arange(5.0))
    tr, va = split_records([r], 0.25, min_len=3)
    assert len(tr[0]) == 15 and len(va[0]) == 5 and va[0].u[0] == 15


def test_from_the_physics_timeseries_class():
    from physics.io.timeseries import TimeSeries

    ts = TimeSeries(time=np.arange(50) / 200.0, voltage=np.sin(np.arange(50)),
                    deflection=np.zeros(50), rh=np.full(50, 65.0))
    r = Experiment.from_timeseries(ts)
    assert r.fs == pytest.approx(200.0) and len(r) == 50 and np.all(r.rh == 65.0)
    assert np.array_equal(r.u, ts.voltage)
