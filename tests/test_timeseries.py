from pathlib import Path

import numpy as np
import pytest
import scipy.io
import yaml

from physics.errors import InputError
from physics.io.timeseries import (TimeSeries, parse_column_map, read_timeseries,
                                write_timeseries)

SILVERBOX = Path(__file__).resolve().parents[2] / "shared" / "benchmarks" / "silverbox" / "SNLS80mV.csv"

GOOD = "time_s,voltage_V,deflection_m,rh_pct\n0.0,0.5,1e-5,50\n0.001,1.0,2e-5,50\n0.002,1.5,3e-5,50\n"


def write(tmp_path, text, name="rec.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def record(n=200, fs=1000.0, seed=0, **extra):
    rng = np.random.default_rng(seed)
    return TimeSeries(time=np.arange(n) / fs, voltage=rng.normal(size=n),
                      deflection=1e-4 * rng.normal(size=n), rh=np.full(n, 60.0), **extra)


# ----------------------------------------------------------------- reading good files

def test_reads_stored_units(tmp_path):
    ts = read_timeseries(write(tmp_path, GOOD))
    assert ts.n == 3
    assert ts.fs == pytest.approx(1000.0)
    assert ts.duration == pytest.approx(0.003)
    np.testing.assert_array_equal(ts.voltage, [0.5, 1.0, 1.5])
    np.testing.assert_array_equal(ts.deflection, [1e-5, 2e-5, 3e-5])
    np.testing.assert_array_equal(ts.rh, [50, 50, 50])
    assert ts.current is None and ts.temperature is None
    assert ts.source == str(tmp_path / "rec.csv") and ts.meta == {}


def test_converts_every_accepted_unit(tmp_path):
    text = ("time_ms,voltage_mV,deflection_um,rh_pct,current_mA,temperature_K\n"
            "0,500,10,40,2,298.15\n2,-250,-20,41,-4,300.15\n")
    ts = read_timeseries(write(tmp_path, text))
    np.testing.assert_allclose(ts.time, [0.0, 0.002])
    np.testing.assert_allclose(ts.voltage, [0.5, -0.25])
    np.testing.assert_allclose(ts.deflection, [10e-6, -20e-6])
    np.testing.assert_allclose(ts.current, [2e-3, -4e-3])
    np.testing.assert_allclose(ts.temperature, [25.0, 27.0])
    np.testing.assert_array_equal(ts.rh, [40, 41])


def test_mm_deflection_and_trailing_blank_lines(tmp_path):
    ts = read_timeseries(write(tmp_path, "time_s,voltage_V,deflection_mm,rh_pct\n0,1,2,50\n1,1,3,50\n\n\n"))
    np.testing.assert_allclose(ts.deflection, [2e-3, 3e-3])
    assert ts.n == 2


def test_windows_line_endings_and_byte_order_mark(tmp_path):
    p = tmp_path / "win.csv"
    p.write_bytes(b"\xef\xbb\xbftime_s,voltage_V,deflection_mm,rh_pct\r\n0,1,2,50\r\n1,1,3,50\r\n")
    ts = read_timeseries(p)
    np.testing.assert_array_equal(ts.deflection, [2e-3, 3e-3])


def test_model_input_may_omit_deflection(tmp_path):
    p = write(tmp_path, "time_s,voltage_V\n0,1\n0.5,2\n")
    ts = read_timeseries(p, rh=70, require_deflection=False)
    assert ts.deflection is None
    np.testing.assert_array_equal(ts.rh, [70, 70])
    with pytest.raises(InputError, match="missing column deflection_m"):
        read_timeseries(p, rh=70)


def test_small_timestamp_rounding_is_uniform_enough(tmp_path):
    # steps 0.9999 ms / 1.0001 ms: within the 1 % tolerance
    t = np.array([0.0, 0.9999, 2.0, 2.9999, 4.0])
    text = "time_ms,voltage_V,deflection_m,rh_pct\n" + "".join(f"{x},1,0,50\n" for x in t)
    ts = read_timeseries(write(tmp_path, text))
    assert ts.fs == pytest.approx(1000.0)


def test_column_map_and_sampling_rate_for_benchmark_style_file(tmp_path):
    # public-benchmark layout: quoted names, trailing separator -> nameless empty column
    p = write(tmp_path, '"V1","V2",\n0.1,0.01,\n0.2,0.02,\n0.3,0.03,\n', "bench.csv")
    ts = read_timeseries(p, columns={"voltage": "V1", "deflection": "V2"}, fs=4.0, rh=45.0)
    np.testing.assert_allclose(ts.time, [0.0, 0.25, 0.5])
    np.testing.assert_array_equal(ts.voltage, [0.1, 0.2, 0.3])
    np.testing.assert_array_equal(ts.deflection, [0.01, 0.02, 0.03])
    np.testing.assert_array_equal(ts.rh, [45.0] * 3)


def test_column_map_reads_mapped_time_and_ignores_other_columns(tmp_path):
    p = write(tmp_path, "t,u,d,junk\n0,1,5,x\n0.5,2,6,y\n")
    ts = read_timeseries(p, columns=parse_column_map("time=t, voltage=u, deflection=d:V"), rh=30)
    np.testing.assert_array_equal(ts.time, [0.0, 0.5])
    np.testing.assert_array_equal(ts.deflection, [5.0, 6.0])
    assert ts.output.to_dict() == {"name": "deflection", "unit": "V"}
    # without a unit a mapped output is a tip deflection in metres: 5 m is refused at once, with the way out
    with pytest.raises(InputError, match=r"line 2, column 'd' \(output\): value 5.0 is outside -1–1 m .*output level:V"):
        read_timeseries(p, columns=parse_column_map("time=t, voltage=u, deflection=d"), rh=30)


@pytest.mark.skipif(not SILVERBOX.is_file(), reason="shared Silverbox benchmark not available")
def test_reads_real_silverbox_benchmark():
    ts = read_timeseries(SILVERBOX, columns={"voltage": "V1", "deflection": "V2"},
                         fs=610.35, rh=50.0)
    assert ts.n == 131072  # README: 131072 samples at 610.35 Hz
    assert ts.fs == pytest.approx(610.35)
    # first data line of the file: 0.0057756,0.0093978,
    assert (ts.voltage[0], ts.deflection[0]) == (0.0057756, 0.0093978)


def test_parse_column_map():
    assert parse_column_map("time=t,voltage=V1,deflection=V2") == \
        {"time": "t", "voltage": "V1", "deflection": "V2"}
    for bad, msg in [("voltage", "quantity=column"), ("voltage=V1,voltage=V2", "twice"),
                     ("force=F", "unknown quantity 'force'"), ("", "empty"), ("=V1", "quantity=column")]:
        with pytest.raises(InputError, match=msg):
            parse_column_map(bad)


def test_sidecar_is_read_and_its_rh_used_when_no_column(tmp_path):
    p = write(tmp_path, "time_s,voltage_V,deflection_m\n0,1,0\n1,1,0\n")
    (tmp_path / "rec.yaml").write_text("device: IP2C\nrh_pct: 80\nexcitation: {type: sine, f_Hz: 1}\n")
    ts = read_timeseries(p)
    np.testing.assert_array_equal(ts.rh, [80, 80])
    assert ts.meta == {"device": "IP2C", "rh_pct": 80, "excitation": {"type": "sine", "f_Hz": 1}}


def test_explicit_rh_wins_over_column_and_sidecar(tmp_path):
    p = write(tmp_path, GOOD)
    (tmp_path / "rec.yaml").write_text("rh_pct: 80\n")
    with pytest.raises(InputError, match=r"sidecar rec\.yaml says rh_pct=80 but the column 'rh_pct' averages 50"):
        read_timeseries(p)  # a contradiction is an error naming both, never a silent choice
    np.testing.assert_array_equal(read_timeseries(p, rh=65).rh, [65, 65, 65])
    (tmp_path / "rec.yaml").write_text("rh_pct: 52\n")  # agrees within 5 %: the column is used
    np.testing.assert_array_equal(read_timeseries(p).rh, [50, 50, 50])


def test_a_constant_rh_is_stored_once(tmp_path):
    """A constant RH (the column, the sidecar or rh=) is one value seen by every sample: a
    read-only view, not a record-long column (the table's other columns are separate arrays,
    so the RH column read is freed); a varying RH column is kept as read.  The record then
    behaves as before: copies and slices are writable, it writes back the same file."""
    p = write(tmp_path, GOOD)
    for ts, value in ((read_timeseries(p), 50.0), (read_timeseries(p, rh=65), 65.0)):
        assert ts.rh.strides == (0,) and not ts.rh.flags.writeable
        np.testing.assert_array_equal(ts.rh, np.full(3, value))
        owner = ts.voltage if ts.voltage.base is None else ts.voltage.base
        assert ts.voltage.flags.writeable and owner.ndim == 1      # its own array, not a row of the table
        part, copy = ts.slice(0, 2), ts.copy()
        assert part.rh.flags.writeable and copy.rh.flags.writeable
        np.testing.assert_array_equal(copy.rh, ts.rh)
    out = write_timeseries(read_timeseries(p), tmp_path / "out.csv")
    back = read_timeseries(out)
    np.testing.assert_array_equal(back.rh, [50, 50, 50])
    np.testing.assert_array_equal(back.voltage, [0.5, 1.0, 1.5])
    varying = read_timeseries(write(tmp_path, GOOD.replace("0.002,1.5,3e-5,50", "0.002,1.5,3e-5,51"), "v.csv"))
    assert varying.rh.flags.writeable and varying.rh.strides == (8,)
    np.testing.assert_array_equal(varying.rh, [50, 50, 51])
    side = write(tmp_path, "time_s,voltage_V,deflection_m\n0,1,0\n1,1,0\n", "s.csv")
    (tmp_path / "s.yaml").write_text("rh_pct: 80\n")
    assert read_timeseries(side).rh.strides == (0,)


def test_resample_to_median_step_records_it(tmp_path):
    t = [0.0, 0.1, 0.2, 0.35, 0.4, 0.5]  # one long step (0.15) and one short (0.05)
    v = [2 * x + 1 for x in t]  # linear: interpolation must be exact
    text = "time_s,voltage_V,deflection_m,rh_pct\n" + "".join(f"{a},{b},{a},50\n" for a, b in zip(t, v))
    p = write(tmp_path, text)
    with pytest.raises(InputError, match="uniform"):
        read_timeseries(p)
    ts = read_timeseries(p, resample=True)
    np.testing.assert_allclose(ts.time, np.arange(6) * 0.1, atol=1e-12)
    np.testing.assert_allclose(ts.voltage, 2 * ts.time + 1)
    np.testing.assert_allclose(ts.deflection, ts.time)
    assert ts.meta["resampled"]["step_s"] == pytest.approx(0.1)
    assert ts.meta["resampled"]["samples_before"] == 6


def test_mat_file_with_named_variables_and_with_column_map(tmp_path):
    p = tmp_path / "rec.mat"
    scipy.io.savemat(p, {"time_ms": np.array([[0.0, 1.0, 2.0]]), "voltage_V": np.array([1.0, 2, 3]),
                         "deflection_mm": np.array([[1.0], [2.0], [3.0]]), "rh_pct": np.array([55.0, 55, 55])})
    ts = read_timeseries(p)
    np.testing.assert_allclose(ts.time, [0, 1e-3, 2e-3])
    np.testing.assert_allclose(ts.deflection, [1e-3, 2e-3, 3e-3])
    q = tmp_path / "raw.mat"
    scipy.io.savemat(q, {"u": np.array([1.0, 2, 3]), "y": np.array([4.0, 5, 6])})
    ts = read_timeseries(q, columns={"voltage": "u", "deflection": "y:V"}, fs=10.0, rh=40.0)
    np.testing.assert_array_equal(ts.deflection, [4, 5, 6])
    np.testing.assert_allclose(ts.time, [0, 0.1, 0.2])


# ----------------------------------------------------------------- writing

def test_write_read_round_trip_is_exact_with_sidecar(tmp_path):
    n = 500
    rng = np.random.default_rng(3)
    ts = TimeSeries(time=12.3 + np.arange(n) / 1234.5, voltage=rng.normal(size=n),
                    deflection=rng.normal(scale=1e-4, size=n), rh=np.linspace(40, 41, n),
                    current=rng.normal(scale=1e-3, size=n), temperature=25 + rng.normal(size=n),
                    meta={"device": "IPMC", "gain": np.float64(2.5), "geometry": {"L_mm": (21, 5)}})
    out = write_timeseries(ts, tmp_path / "out.csv")
    back = read_timeseries(out)
    for name in ("time", "voltage", "deflection", "rh", "current", "temperature"):
        np.testing.assert_array_equal(getattr(back, name), getattr(ts, name), err_msg=name)
    assert back.meta == {"device": "IPMC", "gain": 2.5, "geometry": {"L_mm": [21, 5]}}
    assert yaml.safe_load((tmp_path / "out.yaml").read_text())["device"] == "IPMC"


def test_write_in_chosen_units(tmp_path):
    ts = record()
    out = write_timeseries(ts, tmp_path / "o.csv", units={"deflection": "um", "time": "ms"})
    assert out.read_text().splitlines()[0] == "time_ms,voltage_V,deflection_um,rh_pct"
    back = read_timeseries(out)
    np.testing.assert_allclose(back.deflection, ts.deflection, rtol=1e-14)
    np.testing.assert_allclose(back.time, ts.time, rtol=1e-14, atol=1e-18)
    with pytest.raises(InputError, match="cannot parse unit 'cm'"):
        write_timeseries(ts, tmp_path / "p.csv", units={"deflection": "cm"})


def test_write_without_meta_writes_no_sidecar_and_removes_stale_one(tmp_path):
    (tmp_path / "o.yaml").write_text("device: old\n")
    (tmp_path / "o.csv").write_text("old")
    write_timeseries(record(), tmp_path / "o.csv", overwrite=True)
    assert not (tmp_path / "o.yaml").exists()
    assert read_timeseries(tmp_path / "o.csv").meta == {}


def test_writer_never_overwrites_inputs_or_existing_files(tmp_path):
    src = write(tmp_path, GOOD)
    ts = read_timeseries(src)
    with pytest.raises(InputError, match="input file"):
        write_timeseries(ts, src, overwrite=True, protect=(src,))
    with pytest.raises(InputError, match="already exists"):
        write_timeseries(ts, src)
    (tmp_path / "new.yaml").write_text("x: 1\n")  # an existing sidecar counts too
    with pytest.raises(InputError, match="new.yaml already exists"):
        write_timeseries(record(meta={"a": 1}), tmp_path / "new.csv")
    with pytest.raises(InputError, match=r"\.csv"):
        write_timeseries(ts, tmp_path / "out.txt")
    assert src.read_text() == GOOD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.yaml", "rec.csv"]


def test_writer_rejects_unstorable_metadata(tmp_path):
    with pytest.raises(InputError, match="meta.obj"):
        write_timeseries(record(meta={"obj": object()}), tmp_path / "o.csv")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------- the record object

def test_record_properties_slice_and_copy():
    ts = record(n=100, fs=50.0, meta={"device": {"name": "IPMC"}})
    assert (ts.n, ts.fs, ts.duration) == (100, pytest.approx(50.0), pytest.approx(2.0))
    part = ts.slice(10, 30)
    assert part.n == 20 and part.time[0] == ts.time[10]
    part.voltage[0] = 99.0
    assert ts.voltage[10] != 99.0
    dup = ts.copy()
    dup.meta["device"]["name"] = "other"
    dup.deflection[0] = 1.0
    assert ts.meta["device"]["name"] == "IPMC" and ts.deflection[0] != 1.0


@pytest.mark.parametrize("kwargs, msg", [
    (dict(voltage=np.ones(3)), "voltage has 3 samples but time has 4"),
    (dict(deflection=np.array([0, np.nan, 0, 0])), "sample 1, deflection: value nan"),
    (dict(time=np.array([0.0, 1, 1, 2])), "sample 2, time: 1.0 s is not after"),
    (dict(rh=np.array([50, 50, 100.5, 50])), "sample 2, rh: value 100.5"),
    (dict(voltage=np.ones((4, 1))), "1-D"),
], ids=["length", "nan", "increasing", "rh", "ndim"])
def test_record_validates_on_construction(kwargs, msg):
    base = dict(time=np.arange(4.0), voltage=np.ones(4))
    with pytest.raises(InputError, match=msg):
        TimeSeries(**{**base, **kwargs})


# ----------------------------------------------------------------- bad input: one test per rule

H = "time_s,voltage_V,deflection_m,rh_pct\n"
BAD = {  # id: (file text, read kwargs, substrings the message must contain)
    "missing-deflection": ("time_s,voltage_V,rh_pct\n0,1,50\n1,1,50\n", {},
                           ["missing column deflection_m"]),
    "missing-voltage": ("time_s,deflection_m,rh_pct\n0,1,50\n1,1,50\n", {},
                        ["missing column voltage_V"]),
    "missing-time": ("voltage_V,deflection_m,rh_pct\n1,0,50\n1,0,50\n", {},
                     ["missing column time_s", "sampling rate with fs"]),
    "unknown-column": ("time_s,voltage_V,deflection_m,rh_pct,force_N\n0,1,0,50,1\n1,1,0,50,1\n", {},
                       ["unknown column 'force_N'", "deflection_mm"]),
    "unparseable-unit": ("time_s,voltage_V,deflection_cm,rh_pct\n0,1,0,50\n1,1,0,50\n", {},
                         ["column 'deflection_cm'", "cannot parse unit 'cm'", "m, mm, um"]),
    "no-unit": ("time,voltage_V,deflection_m,rh_pct\n0,1,0,50\n1,1,0,50\n", {},
                ["column 'time'", "unit '(none)'", "s, ms"]),
    "nan": (H + "0,1,0,50\n1,1,0,50\n2,nan,0,50\n", {},
            ["line 4", "column 'voltage_V'", "nan", "not finite"]),
    "infinite": (H + "0,1,0,50\n1,1,-inf,50\n", {},
                 ["line 3", "column 'deflection_m'", "-inf", "not finite"]),
    "not-a-number": (H + "0,1,0,50\n1,abc,0,50\n", {},
                     ["line 3", "column 'voltage_V'", "'abc' is not a number"]),
    "empty-cell": (H + "0,1,0,50\n1,1,,50\n", {}, ["line 3", "column 'deflection_m'", "empty cell"]),
    "time-not-increasing": (H + "0,1,0,50\n1,1,0,50\n2,1,0,50\n2,1,0,50\n", {},
                            ["line 5", "column 'time_s'", "2.0 s is not after", "strictly increasing"]),
    "time-not-uniform": (H + "0,1,0,50\n1,1,0,50\n2,1,0,50\n4,1,0,50\n5,1,0,50\n", {},
                         ["line 5", "column 'time_s'", "step 2.0 s", "median step 1.0 s",
                          "uniform"]),
    "rh-above-100": (H + "0,1,0,50\n1,1,0,100.5\n", {}, ["line 3", "column 'rh_pct'", "100.5", "0–100"]),
    "rh-below-0": (H + "0,1,0,-1\n1,1,0,50\n", {}, ["line 2", "column 'rh_pct'", "-1.0", "0–100"]),
    "rh-argument": ("time_s,voltage_V,deflection_m\n0,1,0\n1,1,0\n", {"rh": 120},
                    ["rh=120", "0–100"]),
    "rh-missing": ("time_s,voltage_V,deflection_m\n0,1,0\n1,1,0\n", {},
                   ["no relative humidity", "rh_pct"]),
    "empty-file": ("", {}, ["empty file"]),
    "header-only": (H, {}, ["empty file", "data row"]),
    "single-sample": (H + "0,1,0,50\n", {}, ["at least 2 samples"]),
    "duplicate-quantity": ("time_s,time_ms,voltage_V,deflection_m,rh_pct\n0,0,1,0,50\n1,1000,1,0,50\n", {},
                           ["'time_s' and 'time_ms'", "both give time"]),
    "duplicate-name": ("time_s,voltage_V,voltage_V,deflection_m,rh_pct\n0,1,1,0,50\n1,1,1,0,50\n", {},
                       ["column 'voltage_V' appears twice"]),
    "nameless-data": ("time_s,voltage_V,deflection_m,rh_pct,\n0,1,0,50,7\n1,1,0,50,\n", {},
                      ["column 5 has data but no name"]),
    "extra-field": (H + "0,1,0,50\n1,1,0,50,9\n", {}, ["line 3", "5 fields but the header has 4"]),
    "map-rh-out-of-range": ("V1,V2,H\n1,0.2,50\n3,0.4,-3\n", {"columns": {"voltage": "V1", "deflection": "V2",
                                                                    "rh": "H"}, "fs": 10.0},
                            ["line 3", "column 'H' (rh)", "-3.0", "0–100"]),
    "map-missing-column": ("V1,V2\n1,2\n3,4\n", {"columns": {"voltage": "V1", "deflection": "V3"},
                                                "fs": 10.0, "rh": 50},
                           ["column 'V3' (mapped to deflection) is missing", "'V1', 'V2'"]),
    "map-bad-value": ("V1,V2\n1,2\nx,4\n", {"columns": {"voltage": "V1", "deflection": "V2"},
                                           "fs": 10.0, "rh": 50},
                      ["line 3", "column 'V1'", "'x' is not a number"]),
    "fs-and-time": (GOOD, {"fs": 100.0}, ["time column", "sampling rate"]),
    "bad-fs": ("voltage_V,deflection_m,rh_pct\n1,0,50\n1,0,50\n", {"fs": -5.0}, ["fs -5.0"]),
}


@pytest.mark.parametrize("rule", list(BAD))
def test_bad_csv_is_rejected_with_a_precise_message(tmp_path, rule):
    text, kwargs, parts = BAD[rule]
    p = write(tmp_path, text, f"{rule}.csv")
    with pytest.raises(InputError) as err:
        read_timeseries(p, **kwargs)
    message = str(err.value)
    assert str(p) in message, message
    for part in parts:
        assert part in message, f"{part!r} not in {message!r}"


def test_file_not_found(tmp_path):
    with pytest.raises(InputError, match=r"missing\.csv: file not found"):
        read_timeseries(tmp_path / "missing.csv")


def test_wrong_extension(tmp_path):
    p = write(tmp_path, GOOD, "rec.txt")
    with pytest.raises(InputError, match=r"rec\.txt: unsupported file type '\.txt'; expected \.csv or \.mat"):
        read_timeseries(p)


def test_bad_sidecar(tmp_path):
    p = write(tmp_path, "time_s,voltage_V,deflection_m\n0,1,0\n1,1,0\n")
    side = tmp_path / "rec.yaml"
    for text, msg in [("rh_pct: 140\n", "rh_pct: 140 is not valid"), ("rh_pct: wet\n", "rh_pct: 'wet' is not valid"),
                      ("- a\n- b\n", "expected a mapping"), ("a: [1\n", "invalid YAML")]:
        side.write_text(text)
        with pytest.raises(InputError, match=msg) as err:
            read_timeseries(p)
        assert str(side) in str(err.value)


def test_bad_mat_variable(tmp_path):
    p = tmp_path / "rec.mat"
    scipy.io.savemat(p, {"time_s": np.arange(3.0), "voltage_V": np.ones((3, 3)),
                         "deflection_m": np.zeros(3), "rh_pct": np.full(3, 50.0)})
    with pytest.raises(InputError, match=r"rec\.mat: variable 'voltage_V' must be a real numeric vector"):
        read_timeseries(p)
    scipy.io.savemat(p, {"time_s": np.arange(3.0), "voltage_V": np.array([1.0, np.inf, 1]),
                         "deflection_m": np.zeros(3), "rh_pct": np.full(3, 50.0)})
    with pytest.raises(InputError, match=r"rec\.mat, element 2, column 'voltage_V': value inf"):
        read_timeseries(p)


def test_binary_file_is_rejected(tmp_path):
    p = tmp_path / "rec.csv"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00\x00")
    with pytest.raises(InputError, match=r"rec\.csv: not a UTF-8 text file"):
        read_timeseries(p)


def test_parser_error_message_is_one_line(tmp_path):
    # the CLI prints messages as they are: pandas' multi-line text must be flattened
    p = write(tmp_path, H + "0,1,0,50\n1,1,0,50,9\n")
    with pytest.raises(InputError) as err:
        read_timeseries(p)
    assert "\n" not in str(err.value)
