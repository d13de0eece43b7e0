"""Model-vs-measurement comparison: metrics that tell a right model from a wrong one, J_err
of eq. 13, errors by band and by RH, predictors (physics, callables, bundles), the CLI."""
from __future__ import annotations

import json
import math
import re
import warnings

import numpy as np
import pytest

from physics import signals, simulate
from physics.analysis import metrics
from physics.compare import (CallablePredictor, PhysicsPredictor, cluster_rh, compare,
                             default_bands, load_measurements, model_rh, parse_bands, residual_by_band,
                             thin_log, write_comparison_report)
from physics.errors import InputError
from physics.solvers.frequency import frequency_response
from physics.io.frfdata import FRFData, write_frf
from physics.model import ActuatorModel
from physics.io.sensor import SensorModel
from physics.io.timeseries import TimeSeries, write_timeseries


def periodic_record(model, rh, *, seed=0, sensor=None, period=10.0, periods=3, fs=1000.0):
    sig = signals.multisine(0.5, 0.1, 50.0, period, 1, fs, seed=seed)
    y = simulate(model, None, sig.t, sig.v, rh=rh, periodic=True).deflection
    n = periods * sig.t.size
    ts = TimeSeries(np.arange(n) / fs, np.tile(sig.v, periods), np.tile(y, periods), rh=np.full(n, float(rh)),
                    meta={"signal": {**sig.describe(), "periods": periods}}, source=f"rec_rh{rh:g}.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return (sensor or SensorModel()).apply(ts, seed=seed + 100)


@pytest.fixture(scope="module")
def model():
    return ActuatorModel("ipmc_pt_eg", "default")


@pytest.fixture(scope="module")
def records(model):
    return [periodic_record(model, rh, seed=i) for i, rh in enumerate((40.0, 80.0))]


@pytest.fixture(scope="module")
def result(model, records):
    return compare(records, PhysicsPredictor(model))


def test_right_model_scores_well_and_wrong_model_badly(model, records, result):
    wrong = PhysicsPredictor(ActuatorModel(model.device.with_params(kf=1.5 * model.device["kf"]), "default"))
    bad = compare(records, wrong)
    for good_r, bad_r in zip(result.records, bad.records):
        g, b = good_r.summary, bad_r.summary
        assert g["time_metrics"]["correlation"] > 0.999
        assert g["time_metrics"]["fit_percent"] > 90
        assert b["time_metrics"]["fit_percent"] < g["time_metrics"]["fit_percent"] - 30
        # a 50 % gain error is 3.5 dB on every frequency
        assert b["frf_metrics"]["log_mag_rms_dB"] == pytest.approx(20 * math.log10(1.5), rel=0.05)
        assert g["frf_metrics"]["log_mag_rms_dB"] < 0.1
        assert b["frf_metrics"]["j_err_m_per_V"] > 50 * g["frf_metrics"]["j_err_m_per_V"]


def test_metrics_follow_their_definitions(result):
    r = result.records[0]
    tm = r.summary["time_metrics"]
    assert tm["fit_percent"] == pytest.approx(metrics.fit_percent(r.measured - r.offset, r.predicted))
    assert tm["correlation"] == pytest.approx(metrics.correlation(r.measured, r.predicted))
    assert np.mean(r.measured - r.offset - r.predicted) == pytest.approx(0.0, abs=1e-12)   # best offset removed
    assert tm["offset_removed_m"] == r.offset
    v = r.valid
    j = math.sqrt(np.mean((np.abs(r.H_meas[v]) - np.abs(r.H_model_closed[v])) ** 2))   # eq. 13
    assert r.summary["frf_metrics"]["j_err_m_per_V"] == pytest.approx(j)
    assert r.summary["frf_metrics"]["j_err_reference"] == "closed form"


def test_offset_handling(model):
    """A laser zero offset of 0.3 mm: removed by default (same fit as without it), kept
    with offset='none' (much worse fit, same correlation)."""
    recs = [periodic_record(model, 60.0, seed=5, sensor=SensorModel(deflection_offset=off), periods=2)
            for off in (0.0, 3e-4)]
    pred = PhysicsPredictor(model)
    clean, shifted = (compare([r], pred).records[0].summary["time_metrics"] for r in recs)
    raw = compare([recs[1]], pred, offset="none").records[0].summary["time_metrics"]
    assert shifted["offset_removed_m"] - clean["offset_removed_m"] == pytest.approx(3e-4, rel=1e-3)
    assert shifted["fit_percent"] == pytest.approx(clean["fit_percent"], abs=0.05)
    assert raw["fit_percent"] < shifted["fit_percent"] - 20
    assert raw["correlation"] == pytest.approx(shifted["correlation"])    # correlation ignores offsets


def test_errors_by_rh_and_band(result):
    assert [row["rh_pct"] for row in result.by_rh] == [40.0, 80.0]
    assert all(row["records"] == 1 for row in result.by_rh)
    bands = result.settings["bands_Hz"]
    assert bands[0][0] == pytest.approx(0.1) and bands[-1][1] == pytest.approx(50.0)
    rows = result.records[0].summary["bands"]
    assert [row["band_Hz"] for row in rows] == bands
    assert sum(row["n_points"] for row in rows) == result.records[0].summary["frf_metrics"]["n_points"]


def test_residual_by_band_is_parseval():
    fs, n = 100.0, 1000
    t = np.arange(n) / fs
    e = 1.0 * np.sin(2 * np.pi * 2.0 * t) + 0.1 * np.sin(2 * np.pi * 20.0 * t)
    rows = residual_by_band(e, 10 * e, fs, [(0.5, 5.0), (5.0, 50.0)])
    assert rows[0]["residual_rms_m"] == pytest.approx(1 / math.sqrt(2), rel=1e-9)
    assert rows[1]["residual_rms_m"] == pytest.approx(0.1 / math.sqrt(2), rel=1e-9)
    assert rows[0]["nrmse_in_band"] == pytest.approx(0.1)
    def part(r, m):            # the residual given by its interleaved samples: the same sums
        return e[r::m].copy()
    assert residual_by_band(part, 10 * e, fs, [(0.5, 5.0), (5.0, 50.0)]) == rows


def test_residual_by_band_in_parts_matches_the_whole_spectrum(monkeypatch):
    """A long residual's band powers come from its spectrum assembled in parts, the residual
    given lazily (never formed whole): the whole-FFT values to rounding, an odd length too."""
    import physics.analysis.frf_estimation as fe
    rng = np.random.default_rng(7)
    bands = [(0.05, 1.0), (1.0, 10.0), (10.0, 50.0)]
    for n in (6000, 6003):
        y = np.cumsum(rng.normal(size=n)) * 1e-6
        yhat = 0.9 * y + 1e-7 * rng.normal(size=n) + 3e-6
        e = y - yhat - 2e-6
        whole = residual_by_band(e, y, 100.0, bands)
        monkeypatch.setattr(fe, "SPLIT_SPECTRUM", 64)
        monkeypatch.setattr(fe, "_LINES", 101)

        def part(r, m):
            d = y[r::m] - yhat[r::m]
            d -= 2e-6
            return d
        for got in (residual_by_band(part, y, 100.0, bands), residual_by_band(e, y, 100.0, bands)):
            for a, b in zip(got, whole):
                assert a["band_Hz"] == b["band_Hz"]
                assert a["residual_rms_m"] == pytest.approx(b["residual_rms_m"], rel=1e-12)
                assert a["nrmse_in_band"] == pytest.approx(b["nrmse_in_band"], rel=1e-12)
        monkeypatch.undo()


def test_compare_holds_few_record_long_arrays(monkeypatch, tmp_path):
    """Memory per sample of compare on a record read from a CSV (constant RH column, a tone
    like bench/memory_long_records.py), with every blocked computation in blocks of 2^12 so
    that both records span many (the fixed part cancels in the difference): tracemalloc's
    peak during compare grows by less than 3.4 float64 per extra sample (the model output,
    the voltage less its median and one partition copy of it; 2.8 measured, 4.0 before the
    residual, its centred copies and the aligned measurement were dropped), and the record
    itself keeps 3 (time, voltage, deflection: the constant RH is one value, 4 before).
    tracemalloc does not see the FFT library's own buffers; bench/memory_long_records.py
    measures the process (VmHWM)."""
    import tracemalloc
    from scipy.signal import lfilter
    from physics.analysis import frf_estimation, stats
    from physics.compare import FRFOptions
    from physics.io.timeseries import read_timeseries
    for mod, name in ((frf_estimation, "SPLIT_SPECTRUM"), (frf_estimation, "WELCH_BLOCK"), (frf_estimation, "_BLOCK"),
                      (metrics, "BLOCK"), (stats, "LAG_BLOCK")):
        monkeypatch.setattr(mod, name, 1 << 12)
    monkeypatch.setattr(frf_estimation, "_LINES", 1 << 10)
    predictor = CallablePredictor(lambda v, rh, fs: lfilter([1e-6], [1, -0.99], v), name="filter")
    kept, peaks = [], []
    for n in (100_000, 200_000):
        t = np.arange(n) / 1000.0
        v = np.sin(2 * np.pi * 1.3 * t)
        path = tmp_path / f"r{n}.csv"
        with open(path, "w") as fh:
            fh.write("time_s,voltage_V,deflection_m,rh_pct\n")
            np.savetxt(fh, np.column_stack([t, v, lfilter([1.1e-6], [1, -0.99], v) + 1e-5, np.full(n, 60.0)]),
                       delimiter=",", fmt="%.9g")
        tracemalloc.start()
        ts = read_timeseries(path)
        kept.append(tracemalloc.get_traced_memory()[0])
        tracemalloc.reset_peak()
        res = compare([ts], predictor, frf_options=FRFOptions(nperseg=1024))
        peaks.append(tracemalloc.get_traced_memory()[1] - kept[-1])
        tracemalloc.stop()
        assert res.records[0].summary["time_metrics"]["n"] == n
        del ts, res
    per_sample = (peaks[1] - peaks[0]) / 100_000 / 8
    record = (kept[1] - kept[0]) / 100_000 / 8
    assert per_sample < 3.4, f"compare: {per_sample:.2f} float64 per sample"
    assert record < 3.5, f"the record read: {record:.2f} float64 per sample"


def test_callable_predictor_and_frf_files(model, records, tmp_path):
    """A model without a closed form (e.g. a neural bundle) is compared through the H1
    estimate of its simulated output; an FRF file then cannot be compared."""
    physics_model = PhysicsPredictor(model)
    half = CallablePredictor(lambda u, rh, fs: 0.5 * physics_model(u, rh, fs), name="half", info={"k": 1})
    f = np.logspace(-1, np.log10(50), 50)
    H = frequency_response(model, None, f, rh=60.0).deflection
    frf_path = write_frf(FRFData(f, H, rh=60.0), tmp_path / "frf.csv")
    ms = load_measurements([records[0], str(frf_path)])
    res = compare(ms, half)
    assert len(res.records) == 1 and "skipped" in res.warnings[0]
    s = res.records[0].summary
    assert s["frf_metrics"]["j_err_reference"] == "H1 estimate of the simulated output"
    assert s["frf_metrics"]["log_mag_rms_dB"] == pytest.approx(20 * math.log10(2), rel=0.02)
    assert s["time_metrics"]["correlation"] > 0.999
    assert res.predictor == {"name": "half", "kind": "callable", "k": 1}
    # the FRF file with the physics model: exact
    res2 = compare(ms[1:], physics_model)
    assert res2.records[0].summary["frf_metrics"]["j_err_m_per_V"] < 1e-12


def test_bad_inputs(model, records):
    with pytest.raises(InputError, match="needs a Predictor"):
        compare(records, model)
    bad_len = CallablePredictor(lambda u, rh, fs: u[:-1], name="short")
    with pytest.raises(InputError, match="returned .* samples"):
        compare(records[:1], bad_len)
    nan_out = CallablePredictor(lambda u, rh, fs: u * np.nan, name="nan")
    with pytest.raises(InputError, match="NaN"):
        compare(records[:1], nan_out)
    no_defl = TimeSeries(records[0].time, records[0].voltage, rh=records[0].rh, source="x.csv")
    with pytest.raises(InputError, match="x.csv: has no deflection"):
        compare([no_defl], PhysicsPredictor(model))
    with pytest.raises(InputError, match="offset"):
        compare(records, PhysicsPredictor(model), offset="median")
    with pytest.raises(InputError, match="band edges"):
        parse_bands("0.1,a")
    with pytest.raises(InputError, match="increasing"):
        parse_bands("10,1")
    with pytest.raises(InputError, match="no measurement"):
        load_measurements([])


def test_helpers():
    # grouped within the tolerance, labelled by the nominal value (whole percent), never 60.0003
    assert cluster_rh([40.2, 59.8, 40.0, 60.6, 80.0], 2.5) == [40.0, 60.0, 40.0, 60.0, 80.0]
    assert cluster_rh([70.0003, 70.0019, 69.6, 70.4], 1.0) == [70.0] * 4
    assert cluster_rh([60.0, 60.4], 0.2) == [60.0, 60.4]                 # a fine tolerance keeps 0.1 %
    jitter = 60.0 + np.random.default_rng(0).normal(0.0, 0.15, 2000)
    assert model_rh(jitter, 100.0, 1.0) == pytest.approx(60.0, abs=0.02)   # hygrometer jitter: one value
    assert default_bands(0.1, 50) == [(0.1, 1.0), (1.0, 10.0), (10.0, 50)]
    f = np.linspace(0.1, 50, 500)
    idx = thin_log(f, 100)
    assert 50 < idx.size <= 100 and idx[0] == 0 and idx[-1] == 499
    rh = np.full(1000, 60.0)
    rh[::2] = 60.3
    assert model_rh(rh, 100.0) == pytest.approx(60.15)                 # sensor noise: one value
    ramp = np.linspace(40, 80, 2000)
    out = model_rh(ramp, 10.0)
    assert out.shape == ramp.shape and np.all(np.diff(out) >= 0) and np.all(np.mod(out, 0.5) == 0)
    # the smoothing is the centred 10 s moving mean, the ends held at the first and last values:
    # against that mean written as a convolution, on a step between two RH levels at 50 Hz
    step = np.r_[np.full(1500, 40.0), np.full(1500, 80.0)] + np.random.default_rng(1).normal(0.0, 0.4, 3000)
    k = 500
    mean = np.convolve(np.pad(step, (k // 2, k - 1 - k // 2), mode="edge"), np.ones(k) / k, mode="valid")
    np.testing.assert_array_equal(model_rh(step, 50.0), np.clip(np.round(mean / 0.5) * 0.5, 0, 100))
    step[700] = np.nan
    with pytest.raises(InputError, match="RH channel has 1 non-finite"):
        model_rh(step, 50.0)


def test_report_files(result, tmp_path):
    out = write_comparison_report(result, tmp_path, provenance={"command": "test"})
    data = json.loads((tmp_path / "report.json").read_text())
    assert data["overall"]["records"] == 2 and len(data["records"]) == 2
    for rec in data["records"]:
        for png in rec["plots"]:
            assert (tmp_path / png).read_bytes().startswith(b"\x89PNG")
    html = (tmp_path / "index.html").read_text()
    srcs = re.findall(r"src='([^']*)'", html)
    assert srcs and all(s.startswith("data:image/png;base64,") for s in srcs)   # self-contained
    assert "rh.png" in out["plots"] and (tmp_path / "metrics.csv").is_file()


def test_cli_compare_device_and_bundle(model, records, tmp_path, capsys, monkeypatch):
    from nnmodel.app.cli import main
    paths = [write_timeseries(r, tmp_path / f"m{i}.csv") for i, r in enumerate(records)]
    code = main(["compare", str(paths[0]), "--model", "ipmc_pt_eg", "--points", "100",
                 "--out", str(tmp_path / "dev")])
    text = capsys.readouterr().out
    assert code == 0 and "fit" in text and "J_err" in text
    assert (tmp_path / "dev" / "index.html").is_file()
    # a folder that is not a bundle: a clear error, no traceback
    empty = tmp_path / "notabundle"
    empty.mkdir()
    assert main(["compare", str(paths[0]), "--model", str(empty), "--out", str(tmp_path / "x")]) == 2
    assert str(empty) in capsys.readouterr().err
    # the bundle extension point: anything nnmodel.load returns with .predict(voltage, rh=, fs=)
    import nnmodel
    physics_model = PhysicsPredictor(model)

    class FakeBundle:
        card = {"model": "fake", "fs_hz": 1000.0}

        def predict(self, voltage, rh=None, fs=None, resample=False):
            return physics_model(voltage, rh, fs)

    monkeypatch.setattr(nnmodel, "load", lambda path: FakeBundle(), raising=False)
    code = main(["compare", str(paths[0]), "--model", str(empty), "--points", "100", "--out", str(tmp_path / "nn")])
    assert code == 0
    data = json.loads((tmp_path / "nn" / "report.json").read_text())
    assert data["model"]["kind"] == "neural bundle" and data["model"]["model"] == "fake"
    assert data["records"][0]["time_metrics"]["fit_percent"] > 90


def test_residual_tests_tell_white_from_structured():
    """99 % bands ±2.576/√n: white noise passes; an AR(1) residual is not white; a residual
    that is a filtered input is correlated with it."""
    from scipy.signal import lfilter
    from physics.compare.comparison import residual_tests
    rng = np.random.default_rng(0)
    u = rng.normal(size=20000)
    white = residual_tests(rng.normal(size=20000), u)
    assert white["white"] and white["independent_of_input"]
    ar = residual_tests(lfilter([1], [1, -0.8], rng.normal(size=20000)), u)
    assert not ar["white"]
    dep = residual_tests(lfilter([0.2], [1, -0.5], u) + rng.normal(size=20000), u)
    assert not dep["independent_of_input"] and dep["cross_correlation_outside"] >= 3


def test_lagged_products_in_blocks_match_the_whole_record(monkeypatch):
    """The residual tests' lagged products of a long record are summed a block at a time
    (no centred copies): the whole-record values to rounding, a lag reaching across a
    block edge included; a record of one block gives exactly the whole-record values."""
    from scipy.signal import lfilter
    from physics.analysis import stats
    from physics.compare.comparison import residual_tests
    rng = np.random.default_rng(5)
    u = rng.normal(size=9000) + 0.3
    e = lfilter([0.2], [1, -0.9], u) + rng.normal(size=9000) + 5.0
    uc, ec = u - u.mean(), e - e.mean()
    n, K = u.size, 12
    acf = np.array([ec[:n - k] @ ec[k:] for k in range(K + 1)])
    ccf = np.array([uc[-k:] @ ec[:n + k] if k < 0 else uc[:n - k] @ ec[k:] for k in range(-K, K + 1)])
    ccf /= math.sqrt((uc @ uc) * (ec @ ec))
    whole = residual_tests(e, u, K)
    np.testing.assert_array_equal(stats.autocorrelation(e, K), acf / acf[0])
    for block in (1000, 997, 13):
        monkeypatch.setattr(stats, "LAG_BLOCK", block)
        np.testing.assert_allclose(stats.autocorrelation(e, K), acf / acf[0], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(stats.cross_correlation(u, e, K)[1], ccf, rtol=1e-12, atol=1e-14)
        assert residual_tests(e, u, K) == pytest.approx(whole, rel=1e-12)
