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
