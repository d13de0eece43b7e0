"""The test beds of the diagnosis (physics.testbeds.cases) and what lab-like records need:
the excitation read from the voltage, the noise floor from the deflection, the coherence of a
one-average FRF estimate from the output noise, the per-record nuisance terms."""
from __future__ import annotations

import math

import numpy as np
import pytest

from physics import signals
from physics.diagnose.records import prepare_records
from physics.analysis.metrics import nuisance_terms, remove_nuisance
from physics.testbeds.cases import OUTSIDE, lab_case, perturbed_case, truths
from physics.analysis.frf_estimation import detect_excitation, estimate_frf, noise_level
from physics.io.timeseries import read_timeseries


def _daq(v, seed=0):
    """A voltage as a 16-bit DAQ reads it (0.1 mV noise, 0.3 mV steps)."""
    v = v + np.random.default_rng(seed).normal(0.0, 1e-4, v.size)
    return np.round(v / 3.05e-4) * 3.05e-4


@pytest.mark.parametrize("sig, kind", [
    (signals.sweep(0.2, 0.1, 50.0, 60.0, 200.0), "sweep"),
    (signals.sweep(0.2, 1.0, 40.0, 30.0, 200.0, method="linear"), "sweep"),
    (signals.square(0.2, 20.0, 40.0, 1, 200.0), "steps"),
    (signals.steps([1.0, 5.0, 9.0], [0.1, -0.2, 0.3], 20.0, 200.0), "steps"),
    (signals.multisine(0.2, 0.1, 50.0, 20.0, 3, 200.0), "periodic"),
    (signals.noise(0.2, 0.1, 50.0, 60.0, 200.0), "noise"),
    (signals.tone(1.0, 2.0, 30.0, 200.0), "tone")])
def test_excitation_is_read_from_the_voltage(sig, kind):
    ex = detect_excitation(_daq(sig.v), 200.0)
    assert ex.kind == kind, ex.how
    if kind == "periodic":
        assert ex.period_s == pytest.approx(20.0, rel=1e-3)
    if kind == "sweep":
        assert ex.band[1] == pytest.approx(sig.params["f_stop_Hz"], rel=0.1)


def test_noise_level_and_one_average_coherence():
    """The white level of a noisy response is found where the response has fallen away, and a
    whole-record estimate gets its coherence (hence its weights) from it."""
    fs, sigma = 200.0, 3e-6
    sig = signals.sweep(1.0, 0.1, 50.0, 60.0, fs)
    from scipy.signal import lfilter
    y = lfilter([0.02], [1.0, -0.98], sig.v) * 1e-3          # a slow first-order response
    y = y + np.random.default_rng(1).normal(0.0, sigma, y.size)
    level, f_resp, _ = noise_level(y, fs)
    assert math.sqrt(level * fs / 2) == pytest.approx(sigma, rel=0.15)
    est = estimate_frf(sig.v, y, fs, nperseg=y.size, window="boxcar", overlap=0.0, noise_psd=level)
    lo, hi = est.freq < 1.0, (est.freq > 30.0) & est.excited
    assert np.median(est.coherence[lo & est.excited]) > 0.99        # strong response: coherent
    assert np.median(est.coherence[hi]) < np.median(est.coherence[lo & est.excited])


def test_nuisance_terms_remove_offset_and_linear_drift():
    t = np.linspace(0.0, 60.0, 1201)
    e = 5e-5 + 2e-7 * t + 1e-6 * np.sin(2 * np.pi * 0.5 * t)
    off, slope = nuisance_terms(e, t)
    assert off == pytest.approx(5e-5, rel=0.02) and slope == pytest.approx(2e-7, rel=0.05)
    assert np.std(remove_nuisance(e, t)) == pytest.approx(1e-6 / math.sqrt(2), rel=0.05)


def test_lab_case_exports_like_an_instrument(tmp_path):
    case = lab_case("electrode_resistance", seed=3)
    assert case.effects == "default,-electrode_resistance" and case.hidden == "electrode_resistance"
    assert set(case.device_params) == {"L_total", "width"} and case.param_args()[0] == "--param"
    files = case.write(tmp_path)
    assert "deflection_mm" in files[0].read_text().splitlines()[0]
    ts = read_timeseries(files[0])
    assert "signal" not in ts.meta and "sensor" not in ts.meta           # the sidecar says neither
    assert np.allclose(ts.deflection, case.measurements[0].deflection, atol=1e-9)
    assert 0.05 < np.std(ts.rh) < 0.4                                   # hygrometer jitter
    assert abs(np.mean(ts.deflection[:3])) > 2e-5                        # the sensor's offset (at rest)
    recs = prepare_records(case.measurements)
    assert [r.kind for r in recs] == ["broadband", "steps"]              # read from the voltage
    for r in recs:                                                       # noise floor from the records
        assert r.noise_floor == pytest.approx(case.noise_floor, rel=0.2), r.noise_source
        assert "estimated from the deflection spectrum" in r.noise_source
        assert r.fs_d >= 150.0                                           # the step's ringing is kept
    assert case.true_error() < 1.6 * case.noise_floor


def test_perturbed_simulator_differs_a_little():
    """The perturbed base is not ours: the true model's records differ from our simulator's
    (same parameters) by more than nothing but by far less than the signal."""
    case = perturbed_case("none", seed=0)
    assert case.effects == "none" and "mode2_shift" in case.truth_params
    from physics.model import ActuatorModel
    from physics.solvers.timedomain import simulate
    m = case.measurements[0]
    dev = case.device.with_params(**{k: case.truth_params[k] for k in ("kf", "beta_f", "Y")})
    ours = case.measurements[0].deflection * 0 + simulate(ActuatorModel(dev, "none"), None, m.time, m.voltage,
                                                          rh=float(np.median(m.rh))).deflection
    from physics.io.sensor import SensorModel
    diff = remove_nuisance(case.clean[0] - SensorModel()._lowpass(ours, m.fs))
    rms = float(np.sqrt(np.mean(diff ** 2)))
    assert 0.2e-6 < rms < 0.01 * np.std(case.clean[0])


def test_truths_cover_the_catalog_and_outside_physics():
    assert truths("lab")[0] == "none" and set(OUTSIDE) <= set(truths("perturbed"))
    assert len(truths("perturbed")) > len(truths("lab"))


def _clipped_multisine(clip: float, sigma: float = 3e-6, seed: int = 2):
    """Three 20 s periods of a multisine (0.05–20 Hz, 200 Hz) through a 20 Hz low-pass [m], the
    sensor clipped at ``clip`` × the peak, then white noise ``sigma`` [m]."""
    from scipy.signal import butter, lfilter
    fs = 200.0
    sig = signals.multisine(1.0, 0.05, 20.0, 20.0, 3, fs)
    y = lfilter(*butter(2, 20.0, fs=fs), sig.v) * 1e-3
    y = np.clip(y, -clip * np.abs(y).max(), clip * np.abs(y).max())
    return sig, fs, y + np.random.default_rng(seed).normal(0.0, sigma, y.size)


def test_a_clipped_multisine_reads_its_noise_from_the_difference_of_its_periods():
    """A sensor clipped at 75 % of the stroke spreads harmonics over the whole spectrum, so the
    spectrum's white level reads far above the noise; the harmonics repeat every period, the noise
    does not, and the difference of successive periods reads the noise."""
    from physics.analysis.frf_estimation import periodic_noise_level
    from physics.io.timeseries import TimeSeries
    sigma = 3e-6
    sig, fs, y = _clipped_multisine(0.75, sigma)
    assert math.sqrt(noise_level(y, fs)[0] * fs / 2) > 1.3 * sigma       # the harmonics fill the spectrum
    assert math.sqrt(periodic_noise_level(y, fs, int(20.0 * fs))[0] * fs / 2) == pytest.approx(sigma, rel=0.1)
    ts = TimeSeries(sig.t, sig.v, y, rh=np.full(y.size, 60.0))
    rec, = prepare_records([ts])
    assert rec.noise_floor == pytest.approx(sigma, rel=0.1)
    assert "successive periods" in rec.noise_source


def test_an_unclipped_multisine_keeps_the_spectrum_noise_level():
    """Without a static nonlinearity on the sensor the two estimates agree, and the spectrum's
    level (the one every other record uses) stays."""
    sigma = 3e-6
    sig, fs, y = _clipped_multisine(2.0, sigma)
    from physics.io.timeseries import TimeSeries
    rec, = prepare_records([TimeSeries(sig.t, sig.v, y, rh=np.full(y.size, 60.0))])
    assert rec.noise_floor == pytest.approx(math.sqrt(noise_level(y, fs)[0] * fs / 2), rel=1e-12)
    assert "successive periods" not in rec.noise_source and rec.noise_floor == pytest.approx(sigma, rel=0.1)


def test_a_clipped_sweep_reads_its_noise_in_its_quietest_segments():
    """A sweep's harmonics from a clipped sensor pass each band of the spectrum only while the
    sweep's frequency is in the right range: the record's quietest segments read the noise."""
    from physics.analysis.frf_estimation import quiet_noise_level
    from physics.io.timeseries import TimeSeries
    from scipy.signal import butter, lfilter
    fs, sigma = 200.0, 3e-6
    sig = signals.sweep(1.0, 0.1, 50.0, 60.0, fs)
    y = lfilter(*butter(2, 20.0, fs=fs), sig.v) * 1e-3
    y = np.clip(y, -0.75 * np.abs(y).max(), 0.75 * np.abs(y).max()) + np.random.default_rng(2).normal(0.0, sigma, y.size)
    assert math.sqrt(noise_level(y, fs)[0] * fs / 2) > 2.0 * sigma
    assert math.sqrt(quiet_noise_level(y, fs)[0] * fs / 2) == pytest.approx(sigma, rel=0.15)
    rec, = prepare_records([TimeSeries(sig.t, sig.v, y, rh=np.full(y.size, 60.0))])
    assert rec.noise_floor == pytest.approx(sigma, rel=0.15) and "quietest" in rec.noise_source


def test_the_quiet_noise_reading_is_calibrated_on_white_noise():
    """On stationary white noise the quiet-segment reading agrees with the Welch level on average
    (its low quantile is scaled back by the same reading on other draws of white noise)."""
    from physics.analysis.frf_estimation import quiet_noise_level
    fs = 200.0
    draws = [np.random.default_rng(100 + seed).normal(0.0, 1.0, 12000) for seed in range(6)]
    ratios = [quiet_noise_level(w, fs)[0] / noise_level(w, fs)[0] for w in draws]
    assert np.mean(ratios) == pytest.approx(1.0, abs=0.08) and max(abs(np.log(ratios))) < 0.2
