"""One record type (issue 37): a measured or simulated record is a
:class:`physics.io.record.TimeSeries`; the shapes other modules need are views of it that share
its arrays, and a dataset keeps what it has read."""
from __future__ import annotations

import dataclasses
import pickle
import re

import numpy as np
import pytest

import physics.diagnose.diagnosis as dx
import physics.diagnose.records as dr
from nnmodel.data import Experiment, check_records
from physics.errors import InputError
from physics.io.record import TimeSeries


def _ts(n=200, fs=50.0, phase=0.0):
    t = np.arange(n) / fs
    return TimeSeries(time=t, voltage=np.sin(t + phase), deflection=1e-4 * np.cos(t + phase), rh=np.full(n, 60.0),
                      source="r.csv")


def test_the_networks_view_holds_the_record_and_stores_nothing_else():
    ts = _ts()
    e = Experiment.from_timeseries(ts)
    assert Experiment.__slots__ == ("ts",) and not hasattr(e, "__dict__")
    assert e.ts is ts and e.to_timeseries() is ts
    assert e.u is ts.voltage and e.y is ts.deflection and e.rh is ts.rh
    assert e.fs == ts.fs and len(e) == ts.n and e.name == "r.csv"
    with pytest.raises(AttributeError):
        e.u = np.zeros(ts.n)             # a view: its channels are the record's
    named = Experiment.from_timeseries(ts, name="train/r.csv")   # a label of its own, the arrays shared
    assert named.name == "train/r.csv" and ts.source == "r.csv" and named.ts.voltage is ts.voltage


def test_a_record_built_from_arrays_is_a_timeseries_underneath():
    u, y = np.sin(np.arange(40.0)), np.cos(np.arange(40.0))
    e = Experiment(u, y, 55.0, 610.35, "a")
    assert isinstance(e.ts, TimeSeries) and e.ts.voltage is e.u and e.ts.deflection is e.y
    assert np.shares_memory(e.u, u) and np.shares_memory(e.y, y)
    assert e.fs == 610.35 and e.ts.fs == 610.35 and e.ts.source == "a"      # the rate exactly as given
    part = e[7:31]
    assert np.shares_memory(part.u, u) and part.fs == 610.35 and part.name == "a" and len(part) == 24
    one = Experiment([1.5], fs=3.0)      # a one-sample record, as before (a file needs two)
    assert len(one) == 1 and one.fs == 3.0 and one.name == ""
    back = pickle.loads(pickle.dumps(part))          # what a Dask worker receives
    assert np.array_equal(back.u, part.u) and np.array_equal(back.rh, part.rh) and back.fs == 610.35


@pytest.mark.parametrize("kwargs, message", [
    (dict(u=[0.0, np.nan, 1.0], fs=10), "record 'a', sample 1, voltage u: value nan is not finite; expected a "
                                        "finite number"),
    (dict(u=[0.0, 1.0], rh=120.0, fs=10), "record 'a', sample 0, relative humidity rh: value 120.0 is outside "
                                          "0–100 % (relative humidity)"),
    (dict(u=[0.0, 1.0]), "record 'a': the sampling rate fs (Hz) is required"),
    (dict(u=[1.0, 2.0], y=[1.0, np.inf], fs=10), "record 'a', sample 1, output y: value inf is not finite; "
                                                 "expected a finite number"),
])
def test_the_constructor_refuses_bad_values_with_the_same_messages(kwargs, message):
    with pytest.raises(InputError, match=f"^{re.escape(message)}$"):
        Experiment(name="a", **kwargs)


def test_any_output_quantity_is_a_networks_output_but_a_deflection_file_keeps_its_rule(tmp_path):
    from physics.io.timeseries import read_timeseries, write_timeseries
    n = 50
    volts = 5.0 + np.sin(np.arange(n))               # a plant's output in V: absurd as metres of deflection
    e = Experiment(np.sin(np.arange(n)), volts, 50.0, 100.0, "silverbox-like")
    assert np.array_equal(e.y, volts)
    write_timeseries(e.to_timeseries(), tmp_path / "r.csv")      # written as deflection_m, as before
    with pytest.raises(InputError, match=re.escape("column 'deflection_m': value 5.0 is outside -1–1 m "
                                                   "(tip deflection of a strip)")):
        read_timeseries(tmp_path / "r.csv")


def test_training_takes_a_timeseries_at_the_boundary():
    from nnmodel.linear import fit_linear
    ts = _ts(n=400)
    (e,) = check_records(ts)
    assert isinstance(e, Experiment) and e.ts is ts
    a, b = fit_linear([ts], na_grid=(2,), nb_grid=(2,)), fit_linear([Experiment.from_timeseries(ts)],
                                                                    na_grid=(2,), nb_grid=(2,))
    assert (a.na, a.nb) == (b.na, b.nb) == (2, 2) and np.array_equal(a.a, b.a) and np.array_equal(a.b, b.b)


def test_a_declared_rate_must_match_the_time_column():
    t = np.arange(10) / 50.0
    assert TimeSeries(t, np.zeros(10), rate_hz=50.0).fs == 50.0
    with pytest.raises(InputError, match="rate_hz"):
        TimeSeries(t, np.zeros(10), rate_hz=60.0)


def test_the_diagnosis_holds_the_record_itself_and_the_old_record_types_are_gone():
    fields = {f.name: f.type for f in dataclasses.fields(dr.PreparedRecord)}
    assert fields["ts"] in (TimeSeries, "TimeSeries")
    for gone in ("Record", "Data", "Run"):
        assert not hasattr(dr, gone) and not hasattr(dx, gone)


def test_a_dataset_reads_each_file_once(tmp_path, monkeypatch):
    from nnmodel import dataset as ds_mod
    from nnmodel.dataset import load_dataset
    from physics.io.timeseries import write_timeseries
    recs = tmp_path / "recs"
    recs.mkdir()
    for k, split in enumerate(("train", "test")):
        write_timeseries(_ts(phase=k), recs / f"{split}.csv")
    out = tmp_path / "ds"
    from nnmodel.measured import build_dataset
    build_dataset(out, train=[str(recs / "train.csv")], test=[str(recs / "test.csv")], val_fraction=0.2)
    ds = load_dataset(out)
    calls = []
    real = ds_mod.read_timeseries
    monkeypatch.setattr(ds_mod, "read_timeseries", lambda *a, **k: calls.append(a) or real(*a, **k))
    first = ds.records("train")
    again = ds.records("train")
    assert len(calls) == len(first) == 1
    assert np.shares_memory(first[0].u, again[0].u) and not first[0].u.flags.writeable
