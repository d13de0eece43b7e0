"""The API is the front door (issue 37): the command line only maps flags to arguments, so the
same bad input gets the same refusal from Python and from ``eap`` — the Python message names
the argument, the command's the flag."""
from __future__ import annotations

import numpy as np
import pytest

from nnmodel.app.cli import main
from physics import ActuatorModel
from physics.compare import PhysicsPredictor, compare, load_measurements
from physics.errors import InputError
from physics.io.timeseries import TimeSeries, write_timeseries


def _record(path, n=400, constant=False, fs=100.0):
    t = np.arange(n) / fs
    v = np.sin(2 * np.pi * 1.0 * t)
    y = np.zeros(n) if constant else 1e-4 * np.sin(2 * np.pi * 1.0 * t - 0.3)
    write_timeseries(TimeSeries(time=t, voltage=v, deflection=y, rh=np.full(n, 60.0)), path)
    return path


CASES = {
    "constant output": (lambda d: [_record(d / "c.csv", constant=True)], "is constant"),
    "too short": (lambda d: [_record(d / "s.csv", n=20)], "20 samples"),
    "missing file": (lambda d: [d / "nope.csv"], "not found"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_api_and_the_command_refuse_the_same_bad_measurements(case, tmp_path, capsys):
    make, words = CASES[case]
    files = make(tmp_path)
    with pytest.raises(InputError) as api:
        load_measurements(files)
    assert words in str(api.value)
    rc = main(["compare", *map(str, files), "--model", "ipmc_pt_eg", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err
    assert str(api.value).split(":")[-1].strip()[:30] in err     # the same sentence


def test_compare_called_directly_checks_what_it_is_given(tmp_path):
    n, fs = 20, 100.0
    t = np.arange(n) / fs
    short = TimeSeries(time=t, voltage=np.sin(t), deflection=1e-4 * np.sin(t), rh=np.full(n, 60.0))
    with pytest.raises(InputError, match="20 samples"):
        compare([short], PhysicsPredictor(ActuatorModel("ipmc_pt_eg", "default")))


def test_a_wrong_output_names_the_argument_in_python_and_the_flag_on_the_command_line():
    from physics.io.record import OutputQuantity
    t = np.arange(400) / 100.0
    ts = TimeSeries(time=t, voltage=np.sin(t), deflection=np.cos(t), rh=np.full(400, 60.0),
                    output=OutputQuantity("laser", "V"))
    with pytest.raises(InputError) as api:
        load_measurements([ts])
    assert "the model predicts" in str(api.value) and "give gain (e.g. 2.5mm/V)" in str(api.value)
    assert "sensor_gain" in api.value.params                  # the command line renders it as --sensor-gain
    assert "give --sensor-gain" in api.value.render({"sensor_gain": "--sensor-gain"}.get)


# ------------------------------------------------------------------ output folders: the library owns them

@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A measurement file ``data/meas.csv`` and, computed from it, a comparison, an
    identification and a diagnosis (each well under a second)."""
    import warnings

    from physics import signals, simulate
    from physics.diagnose import SelectionOptions, diagnose
    from physics.identify import identify
    root = tmp_path_factory.mktemp("front_door_outputs")
    sig = signals.sweep(1.0, 0.2, 20.0, 20.0, 100.0)
    y = simulate(ActuatorModel("ipmc_pt_eg", "default"), None, sig.t, sig.v, rh=60.0).deflection
    noise = 1e-7 * np.random.default_rng(0).standard_normal(y.size)
    csv = write_timeseries(TimeSeries(time=sig.t, voltage=sig.v, deflection=y + noise, rh=np.full(y.size, 60.0)),
                           root / "data" / "meas.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {"csv": csv,
                "compare": compare(load_measurements([csv]), PhysicsPredictor(ActuatorModel("ipmc_pt_eg", "default"))),
                "identify": identify([str(csv)], "ipmc_pt_eg", "default", "kf"),
                "diagnose": diagnose([str(csv)], "ipmc_pt_eg", "default", candidates=["thermal"], check_support=False,
                                     selection=SelectionOptions(max_effects=1, backward=False))}


def _writer(which):
    """The library writer of ``which`` and the command line that writes the same folder (to which
    ``--out D`` is added)."""
    from physics.compare import write_comparison_report
    from physics.diagnose import write_diagnosis
    from physics.identify import write_identification
    return {"compare": (write_comparison_report, ["compare", "{csv}", "--model", "ipmc_pt_eg"]),
            "identify": (write_identification, ["identify", "{csv}", "--free", "kf"]),
            "diagnose": (write_diagnosis, ["diagnose", "{csv}", "--candidates", "thermal", "--no-draft",
                                           "--max-effects", "1"])}[which]


def _users_folder(root):
    d = root / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("my notes\n")
    return d


TARGETS = {   # what the output is, whether overwrite is asked for, the reason both must give
    "a user's folder": (_users_folder, False, "already exists and is not empty"),
    "a user's folder, overwrite": (_users_folder, True, "holds files eap did not write"),
    "the input's folder": (lambda root: None, False, "contains the input"),
    "the input file": (lambda root: "csv", False, "exists and is not a folder"),
}


@pytest.mark.parametrize("which", ["compare", "identify", "diagnose"])
@pytest.mark.parametrize("target", sorted(TARGETS))
def test_a_library_writer_and_its_command_refuse_the_same_output_for_the_same_reason(which, target, results,
                                                                                    tmp_path, capsys):
    from nnmodel.app.cli import build_parser, flag_speller
    from physics.io.fileio import sha256_file
    make, overwrite, reason = TARGETS[target]
    csv = results["csv"]
    made = make(tmp_path)
    out = csv if made == "csv" else (csv.parent if made is None else made)
    before = {p: sha256_file(p) for p in [csv, *tmp_path.rglob("*")] if p.is_file()}
    tree = sorted(tmp_path.rglob("*"))
    write, line = _writer(which)
    with pytest.raises(InputError) as api:         # the inputs are not listed: the result names its records
        write(results[which], out, overwrite=overwrite)
    assert reason in str(api.value) and "out_dir" in str(api.value)
    argv = [a.format(csv=csv) for a in line] + ["--out", str(out)] + (["--overwrite"] if overwrite else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"eap {which}: error: {api.value.render(flag_speller(build_parser(), which))}" in err   # word for word
    assert "--out" in err and "out_dir" not in err
    assert {p: sha256_file(p) for p in before} == before                     # the user's files untouched
    assert sorted(tmp_path.rglob("*")) == tree                               # and nothing left beside them
    assert sorted(p.name for p in csv.parent.iterdir()) == ["meas.csv"]


@pytest.mark.parametrize("stop", [RuntimeError, KeyboardInterrupt])
@pytest.mark.parametrize("which, last_step", [("compare", "physics.compare.report._write_page"),
                                              ("identify", "physics.identify.report._write_page"),
                                              ("diagnose", "physics.diagnose.report._html")])
def test_a_writer_stopped_midway_leaves_nothing_that_looks_complete(which, last_step, stop, results, tmp_path,
                                                                   monkeypatch):
    from physics.io.outputs import MARKER
    write, _ = _writer(which)
    done = tmp_path / "done"
    write(results[which], done)                      # a folder eap wrote, to be replaced with overwrite
    kept = {p.relative_to(done): p.read_bytes() for p in done.rglob("*") if p.is_file()}
    assert (done / MARKER).is_file() and (done / "index.html").is_file()

    def fail(*a, **k):
        raise stop("stopped while writing")
    monkeypatch.setattr(last_step, fail)
    for out, overwrite in ((tmp_path / "new", False), (done, True)):
        with pytest.raises(stop):
            write(results[which], out, overwrite=overwrite)
    assert not (tmp_path / "new").exists()                                   # no folder appeared
    assert {p.relative_to(done): p.read_bytes() for p in done.rglob("*") if p.is_file()} == kept   # nor changed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["done"]             # no temporary folder, no lock


def test_a_command_reserves_its_output_and_the_library_writer_takes_the_lock_over(results, tmp_path):
    """``reserve`` (what a command holds while it works) keeps the lock; the writer called inside
    takes it over and puts its folder in place; a lock another run took since is left alone."""
    import json
    import os

    from physics.compare import write_comparison_report
    from physics.io.outputs import LOCK_SUFFIX, reserve
    out, lock = tmp_path / "o", tmp_path / f".o{LOCK_SUFFIX}"
    with reserve(out):
        assert json.loads(lock.read_text())["pid"] == os.getpid()
        write_comparison_report(results["compare"], out)
        assert (out / "index.html").is_file() and not lock.exists()
        lock.write_text(json.dumps({"pid": os.getppid(), "command": "eap compare"}))   # another run's, meanwhile
    assert lock.exists()
