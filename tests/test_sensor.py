import warnings
import dataclasses
import math

import numpy as np
import pytest

from physics.errors import InputError
from physics.io.sensor import SensorModel
from physics.io.timeseries import TimeSeries

FS = 1000.0
OFF = SensorModel.ideal()


def record(n=100_000, f=3.0, amp=1e-3, rh=60.0, with_extras=True, fs=FS):
    t = np.arange(n) / fs
    kw = dict(current=1e-2 * np.sin(2 * np.pi * f * t), temperature=np.full(n, 25.0)) if with_extras else {}
    return TimeSeries(time=t, voltage=2.0 * np.sin(2 * np.pi * f * t),
                      deflection=amp * np.sin(2 * np.pi * f * t - 0.3), rh=np.full(n, rh),
                      meta={"device": "IPMC"}, **kw)


def sensor(**kw):
    return dataclasses.replace(OFF, **kw)


def rms_tolerance(n, sigmas=5.0):
    """Relative tolerance of a measured RMS of n Gaussian samples: sigmas · 1/sqrt(2n)."""
    return sigmas / math.sqrt(2 * n)


def test_white_noise_has_requested_rms_mean_and_no_correlation():
    ts = record()
    sigma, offset = 2e-6, 5e-6
    out = sensor(deflection_noise=sigma, deflection_offset=offset).apply(ts, seed=1)
    e = out.deflection - ts.deflection - offset
    assert np.std(e) == pytest.approx(sigma, rel=rms_tolerance(ts.n))
    assert abs(np.mean(e)) < 5 * sigma / math.sqrt(ts.n)
    lag1 = np.dot(e[1:] - e.mean(), e[:-1] - e.mean()) / np.sum((e - e.mean()) ** 2)
    assert abs(lag1) < 5 / math.sqrt(ts.n)


@pytest.mark.parametrize("channel, setting, sigma", [
    ("voltage", "voltage_noise", 3e-3), ("current", "current_noise", 4e-6),
    ("rh", "rh_noise", 0.5), ("temperature", "temperature_noise", 0.1)])
def test_other_channels_noise_rms(channel, setting, sigma):
    ts = record()
    out = sensor(**{setting: sigma}).apply(ts, seed=2)
    e = getattr(out, channel) - getattr(ts, channel)
    assert np.sqrt(np.mean(e**2)) == pytest.approx(sigma, rel=rms_tolerance(ts.n))


def test_quantisation_grid_is_respected():
    step = 0.5e-6
    ts = record(n=5000)
    out = sensor(deflection_step=step, rh_step=0.1).apply(ts, seed=0)
    k = out.deflection / step
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)
    assert np.max(np.abs(out.deflection - ts.deflection)) <= step / 2 * (1 + 1e-12)
    assert len(np.unique(out.deflection)) > 100  # a real grid, not a constant
    np.testing.assert_allclose(out.rh / 0.1, np.round(out.rh / 0.1), atol=1e-9)


def test_daq_16_bit_voltage_grid_and_clipping_with_warning():
    ts = record(n=2000)
    model = sensor(adc_bits=16, voltage_range=1.0, current_range=1.0)  # 2 V amplitude > 1 V range
    with pytest.warns(UserWarning, match="clipped"):
        out = model.apply(ts, seed=0)
    lsb = 2.0 / 2**16
    k = out.voltage / lsb
    np.testing.assert_allclose(k, np.round(k), atol=1e-6)
    assert out.voltage.max() == pytest.approx(1.0 - lsb) and out.voltage.min() == pytest.approx(-1.0)
    inside = np.abs(ts.voltage) < 0.99
    assert np.max(np.abs(out.voltage - ts.voltage)[inside]) <= lsb / 2 * (1 + 1e-9)
    expected = np.count_nonzero((ts.voltage > 1.0 - lsb / 2) | (ts.voltage < -1.0 - lsb / 2))
    assert out.meta["sensor"]["clipped_samples"]["voltage"] == pytest.approx(expected, abs=2)
    assert out.meta["sensor"]["clipped_samples"]["current"] == 0


def test_noise_floor_predicts_residual_rms_with_quantisation():
    sigma = step = 1e-6
    model = sensor(deflection_noise=sigma, deflection_step=step)
    assert model.noise_floor() == pytest.approx(math.sqrt(sigma**2 + step**2 / 12))
    ts = record()
    e = model.apply(ts, seed=5).deflection - ts.deflection
    assert np.sqrt(np.mean(e**2)) == pytest.approx(model.noise_floor(), rel=rms_tolerance(ts.n))


def test_drift_is_a_random_walk_reaching_the_requested_std():
    drift = 3e-6
    ts = record()
    model = sensor(deflection_drift=drift)
    walk = model.apply(ts, seed=3).deflection - ts.deflection
    steps = np.diff(walk)
    # increments are white with std drift/sqrt(n), so the end value has std = drift
    assert np.std(steps) == pytest.approx(drift / math.sqrt(ts.n), rel=rms_tolerance(ts.n))
    assert abs(np.corrcoef(steps[1:], steps[:-1])[0, 1]) < 5 / math.sqrt(ts.n)
    assert model.noise_floor() == pytest.approx(drift / math.sqrt(2))


def test_drift_end_value_std_over_seeds():
    drift, seeds = 2e-6, 400
    ts = record(n=64, with_extras=False)
    ends = [sensor(deflection_drift=drift).apply(ts, seed=s).deflection[-1] - ts.deflection[-1]
            for s in range(seeds)]
    assert np.std(ends) == pytest.approx(drift, rel=rms_tolerance(seeds))


@pytest.mark.parametrize("f", [10.0, 40.0, 80.0])
def test_bandwidth_is_a_first_order_low_pass(f):
    # fs = 10 kHz: f/fs <= 0.008, where the bilinear frequency warping ((pi f/fs)^2/3) is 2e-4
    fc = 40.0
    ts = record(n=20_000, f=f, with_extras=False, fs=10_000.0)
    out = sensor(bandwidth=fc).apply(ts, seed=0)
    t, keep = ts.time, ts.time > 0.5  # well after any start-up transient
    basis = np.column_stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)])[keep]
    ratio = complex(*np.linalg.lstsq(basis, out.deflection[keep], rcond=None)[0] * [1, -1]) / \
        complex(*np.linalg.lstsq(basis, ts.deflection[keep], rcond=None)[0] * [1, -1])
    expected = 1 / (1 + 1j * f / fc)
    assert abs(ratio) == pytest.approx(abs(expected), rel=2e-3)
    assert np.degrees(np.angle(ratio)) == pytest.approx(np.degrees(np.angle(expected)), abs=0.2)
    assert abs(out.deflection[0] - ts.deflection[0]) < 1e-12  # no start-up transient


def test_rh_stays_physical_at_saturation():
    """RH pinned at 100 % is physics, not an over-range sensor: counted, but no warning."""
    ts = record(n=5000, rh=99.9, with_extras=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = sensor(rh_noise=1.0).apply(ts, seed=0)
    assert out.rh.max() == 100.0 and out.rh.min() >= 0
    assert out.meta["sensor"]["clipped_samples"]["rh"] > 0


def test_seed_reproducible_and_input_untouched():
    ts = record(n=3000)
    before = {k: getattr(ts, k).copy() for k in ("time", "voltage", "deflection", "rh", "current")}
    model = SensorModel()
    a, b, c = model.apply(ts, seed=11), model.apply(ts, seed=11), model.apply(ts, seed=12)
    for name in before:
        np.testing.assert_array_equal(a.__dict__[name], b.__dict__[name])
        np.testing.assert_array_equal(getattr(ts, name), before[name])
    assert not np.array_equal(a.deflection, c.deflection)
    assert ts.meta == {"device": "IPMC"}


def test_channels_use_independent_streams():
    ts = record(n=3000)
    base = sensor(deflection_noise=1e-6)
    a = base.apply(ts, seed=4)
    b = dataclasses.replace(base, current_noise=1e-5, voltage_noise=1e-3).apply(ts, seed=4)
    np.testing.assert_array_equal(a.deflection, b.deflection)


def test_zero_noise_settings_return_the_input_unchanged():
    ts = record(n=3000)
    out = OFF.apply(ts, seed=9)
    for name in ("time", "voltage", "deflection", "rh", "current", "temperature"):
        np.testing.assert_array_equal(getattr(out, name), getattr(ts, name))
    assert out.meta["device"] == "IPMC" and out.meta["sensor"]["seed"] == 9
    assert OFF.noise_floor() == 0.0


def test_settings_recorded_and_measurement_not_measured_twice():
    ts = record(n=1000, with_extras=False)
    model = SensorModel()
    out = model.apply(ts, seed=1)
    recorded = out.meta["sensor"]
    assert recorded["deflection_noise"] == model.deflection_noise
    assert recorded["bandwidth"] == model.bandwidth and recorded["adc_bits"] == 16
    assert recorded["noise_floor_m"] == model.noise_floor()
    with pytest.raises(InputError, match="already has sensor settings"):
        model.apply(out, seed=2)


def test_defaults_are_documented_magnitudes():
    m = SensorModel()
    assert m.deflection_noise == 1e-6
    assert m.deflection_step == pytest.approx(20 / 2**16 * 1e-3)  # ±10 V, 16 bit, 1 mm/V
    assert 1e-6 < m.noise_floor() < 2e-6


@pytest.mark.parametrize("kw, field", [
    (dict(deflection_noise=-1e-6), "deflection_noise"), (dict(bandwidth=0.0), "bandwidth"),
    (dict(adc_bits=0), "adc_bits"), (dict(voltage_range=-1.0), "voltage_range"),
    (dict(rh_step=float("nan")), "rh_step"),
    (dict(voltage_range=math.inf), "finite voltage_range")])
def test_invalid_settings_are_rejected(kw, field):
    with pytest.raises(InputError, match=field):
        SensorModel(**kw)
