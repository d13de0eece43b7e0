"""One record type (issue 37): a measured or simulated record is a
:class:`physics.io.record.TimeSeries`; the shapes other modules need are views of it that share
its arrays, and a dataset keeps what it has read."""
from __future__ import annotations

import dataclasses

import numpy as np

import physics.diagnose.diagnosis as dx
import physics.diagnose.records as dr
from nnmodel.data import Experiment
from physics.io.record import TimeSeries


def _ts(n=200, fs=50.0, phase=0.0):
    t = np.arange(n) / fs
    return TimeSeries(time=t, voltage=np.sin(t + phase), deflection=1e-4 * np.cos(t + phase), rh=np.full(n, 60.0),
                      source="r.csv")


def test_the_networks_view_shares_the_records_arrays_both_ways():
    ts = _ts()
    e = Experiment.from_timeseries(ts)
    assert np.shares_memory(e.u, ts.voltage) and np.shares_memory(e.y, ts.deflection)
    back = e.to_timeseries()
    assert isinstance(back, TimeSeries) and np.shares_memory(back.voltage, ts.voltage)
    assert back.fs == ts.fs and back.n == ts.n and back.source == "r.csv"


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
