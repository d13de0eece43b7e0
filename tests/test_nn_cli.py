"""`eap predict` and `eap benchmark` end to end (tiny models), Silverbox suite smoke test."""
import json

import numpy as np
import pytest

from physics.io.timeseries import TimeSeries, read_timeseries, write_timeseries
from nnmodel.benchmarks import toy
from nnmodel.bundle import load, save
from nnmodel.app.cli import main
from nnmodel.models import MODELS

QUIET = dict(progress_bar=False, num_threads=1)


@pytest.fixture(scope="module")
def bundle_dir(tmp_path_factory):
    train = toy.records("rh", 600, seeds=(1,), rh_levels=(40.0, 70.0))
    m = MODELS["ff"](na=1, nb=3, max_epochs=2, **QUIET).fit(train)
    return save(m, tmp_path_factory.mktemp("run") / "models" / "ff")


def _write_input(path, fs=toy.FS, rh=None, with_y=False, n=300):
    t = np.arange(n) / fs
    u = toy.excitation(n, seed=5)
    y = toy.rh_system(u, 55.0) if with_y else None
    write_timeseries(TimeSeries(time=t, voltage=u, deflection=y, rh=rh), path)
    return u, y


def test_predict_writes_a_readable_prediction(bundle_dir, tmp_path, capsys):
    inp, out = tmp_path / "in.csv", tmp_path / "pred.csv"
    u, y = _write_input(inp, rh=np.full(300, 55.0), with_y=True)
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(out)]) == 0
    pred = read_timeseries(out)
    # an honest start: the free run is initialised from the measured outputs in the file
    b = load(bundle_dir)
    np.testing.assert_allclose(pred.deflection, b.predict(u, rh=55.0, fs=toy.FS, deflection=y))
    np.testing.assert_array_equal(pred.deflection[:b.model.n_init_], y[:b.model.n_init_])
    np.testing.assert_allclose(pred.voltage, u)
    msg = capsys.readouterr().out
    assert "fit" in msg and str(out) in msg
    rest = tmp_path / "rest.csv"   # --init-samples 0: from rest, as without a measured deflection
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(rest),
                 "--init-samples", "0"]) == 0
    np.testing.assert_allclose(read_timeseries(rest).deflection, b.predict(u, rh=55.0, fs=toy.FS))
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(tmp_path / "p1.csv"),
                 "--init-samples", "1"]) == (0 if b.model.n_init_ <= 1 else 2)
    # a free run from the first measured outputs only (a short record, not streamed)
    k0 = b.model.n_init_ + 2
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(tmp_path / "pk.csv"),
                 "--init-samples", str(k0)]) == 0, capsys.readouterr().err
    np.testing.assert_allclose(read_timeseries(tmp_path / "pk.csv").deflection,
                               b.predict(u, rh=55.0, fs=toy.FS, deflection=y[:k0]))
    # k-step-ahead uses the measured deflection of the input
    out3 = tmp_path / "pred3.csv"
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(out3),
                 "--steps-ahead", "3"]) == 0
    np.testing.assert_allclose(read_timeseries(out3).deflection,
                               load(bundle_dir).predict(u, rh=55.0, fs=toy.FS, steps_ahead=3, deflection=y))


def test_predict_refuses_rate_mismatch_and_warns_on_humidity(bundle_dir, tmp_path, capsys):
    inp = tmp_path / "fast.csv"
    _write_input(inp, fs=2 * toy.FS, rh=np.full(300, 90.0))
    out = tmp_path / "p.csv"
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(out)]) == 2
    assert "trained at 100 Hz" in capsys.readouterr().err and not out.exists()
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(out),
                 "--resample"]) == 0
    assert "outside the range seen in training (40-70 %RH)" in capsys.readouterr().out
    assert read_timeseries(out).n == 300
    # never overwrites its input
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp), "--out", str(inp),
                 "--resample"]) == 2
    # no RH in the file and none given: a humidity model refuses
    inp2 = tmp_path / "norh.csv"
    _write_input(inp2)
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp2), "--out", str(out)]) == 2
    assert "already exists; choose another --out or pass --overwrite" in capsys.readouterr().err
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp2), "--out", str(out),
                 "--overwrite"]) == 2
    assert "relative humidity" in capsys.readouterr().err
    assert main(["predict", "--model", str(bundle_dir), "--input", str(inp2), "--out", str(out),
                 "--rh", "55", "--overwrite"]) == 0


def test_benchmark_rejects_bad_options(tmp_path, capsys):
    assert main(["benchmark", "--suite", "silverbox", "--out", str(tmp_path), "--models", "svm"]) == 2
    assert "unknown model" in capsys.readouterr().err
    assert main(["benchmark", "--suite", "silverbox", "--out", str(tmp_path), "--models", "ff",
                 "--set", "narx.lr=0.1"]) == 2
    assert "not among the models" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["benchmark", "--suite", "nosuch", "--out", str(tmp_path)])


def test_silverbox_suite_smoke_on_a_slice_of_the_real_file(tmp_path, capsys):
    from nnmodel.benchmarks import silverbox
    try:
        silverbox.find_data()
    except Exception as exc:  # InputError with the places looked at
        pytest.skip(f"Silverbox data file absent: {exc}")
    out = tmp_path / "sb"
    rc = main(["benchmark", "--suite", "silverbox", "--out", str(out), "--models", "ff,narx",
               "--limit", "1500", "--no-progress", "--set", "ff.max_epochs=1", "--set", "ff.hidden=4",
               "--set", "narx.max_epochs=1", "--set", "narx.hidden=4", "--set", "narx.horizon=20"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "LSTM baseline (published)" in text and "SMOKE RUN" in text
    rep = json.loads((out / "silverbox.json").read_text())
    rows = {r["model"]: r for r in rep["results"]}
    assert {"ff", "narx"} <= set(rows) and rep["target"]["met"] is False
    lin = rows["linear ARX, least squares (ours)"]["rmse_mv"]
    poly = rows["polynomial NARX deg. 3, least squares (ours)"]["rmse_mv"]
    # the cubic terms matter on this Duffing-like system, even on a small slice
    assert poly["multisine"] < 0.5 * lin["multisine"]
    for f in ("index.html", "silverbox.html", "silverbox_rmse.png", "silverbox_errors.png", "silverbox.csv"):
        assert (out / f).stat().st_size > 0
    assert "data:image/png;base64," in (out / "index.html").read_text()
    from browser_check import CHROMIUM, assert_clean, render
    if CHROMIUM:   # the benchmark page in a real browser
        check, _ = render(out / "index.html")
        assert_clean(check, out / "index.html")
    b = load(out / "models" / "narx")
    assert b.card["output"] == {"name": "V2", "unit": "V"} and b.fs == silverbox.FS


def test_silverbox_suite_on_two_workers_gives_the_serial_figures(tmp_path, capsys):
    """`eap benchmark --workers 2`: one task per model (and reference), the same figures."""
    from nnmodel.benchmarks import silverbox
    try:
        silverbox.find_data()
    except Exception as exc:  # InputError with the places looked at
        pytest.skip(f"Silverbox data file absent: {exc}")
    reps = []
    for workers in ("1", "2"):
        out = tmp_path / f"w{workers}"
        assert main(["benchmark", "--suite", "silverbox", "--out", str(out), "--models", "ff", "--limit", "1500",
                     "--no-progress", "--no-save-models", "--set", "ff.max_epochs=1", "--set", "ff.hidden=4",
                     "--workers", workers]) == 0
        reps.append({r["model"]: r["rmse_mv"] for r in json.loads((out / "silverbox.json").read_text())["results"]})
    assert len(reps[0]) >= 3 and reps[0] == reps[1]
