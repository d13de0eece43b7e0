import numpy as np
import pytest

from physics import signals
from physics.errors import InputError


def test_log_sweep_covers_the_band_with_the_thesis_amplitude():
    s = signals.sweep(2.0, 0.1, 50.0, 100.0, 1000.0)
    assert np.max(np.abs(s.v)) == pytest.approx(2.0, rel=1e-3)          # 4 Vpp
    inst = np.diff(np.unwrap(np.angle(__import__("scipy").signal.hilbert(s.v)))) * s.fs / (2 * np.pi)
    assert inst[2000] == pytest.approx(0.1 * (500.0) ** (2.0 / 100.0), rel=0.05)   # log: f0 (f1/f0)^(t/T)
    assert np.median(inst[-2000:-500]) == pytest.approx(50.0 * 500 ** (-1.25 / 100), rel=0.05)


def test_multisine_lines_and_rms():
    s = signals.multisine(rms=0.5, f_start=0.1, f_stop=50.0, period=20.0, fs=1000.0, seed=1)
    assert np.std(s.v) == pytest.approx(0.5, rel=1e-6)
    X = np.abs(np.fft.rfft(s.v))
    f = np.fft.rfftfreq(s.v.size, 1 / s.fs)
    on = (f >= 0.1) & (f <= 50.0)
    assert np.all(X[on] > 1e-3 * X.max()) and np.all(X[~on] < 1e-9 * X.max())
    s2 = signals.multisine(rms=0.5, f_start=0.1, f_stop=50.0, period=20.0, fs=1000.0, seed=1)
    np.testing.assert_array_equal(s.v, s2.v)


def test_schroeder_phases_lower_the_crest_factor():
    crest = lambda v: np.max(np.abs(v)) / np.std(v)  # noqa: E731
    sch = signals.multisine(phases="schroeder", period=20.0)
    rnd = [crest(signals.multisine(phases="random", period=20.0, seed=k).v) for k in range(5)]
    assert crest(sch.v) < min(rnd)


def test_square_wave_duty_and_levels():
    s = signals.square(2.0, t_on=20.0, t_off=80.0, cycles=2, fs=10.0)
    assert s.t[-1] == pytest.approx(199.9)
    assert np.mean(s.v > 1.0) == pytest.approx(0.2, abs=0.01)
    assert set(np.round(s.v[[50, 500, 1050]], 6)) == {2.0, 0.0}


def test_noise_is_band_limited_and_seeded():
    s = signals.noise(rms=0.3, f_start=1.0, f_stop=20.0, duration=50.0, fs=200.0, seed=7)
    P = np.abs(np.fft.rfft(s.v)) ** 2
    f = np.fft.rfftfreq(s.v.size, 1 / s.fs)
    assert P[(f < 1.0) | (f > 20.0)].sum() < 1e-20 * P.sum()
    assert np.std(s.v) == pytest.approx(0.3)
    assert not np.array_equal(s.v, signals.noise(rms=0.3, f_start=1.0, f_stop=20.0, duration=50.0, fs=200.0,
                                                  seed=8).v)


def test_fade_in_starts_at_zero_and_leaves_the_rest_untouched():
    s = signals.multisine(rms=0.5, f_start=0.5, f_stop=20.0, period=10.0, fs=100.0, seed=3)
    f = signals.fade_in(s, 1.0)
    assert f.v[0] == 0.0 and abs(s.v[0]) > 1e-3
    np.testing.assert_array_equal(f.v[100:], s.v[100:])           # unchanged after 1 s
    w = f.v[1:100] / s.v[1:100]
    assert np.all((w > 0) & (w < 1)) and np.all(np.diff(w) > 0)  # a monotone ramp
    assert signals.fade_in(s, 0.0) is s and f.params["fade_in_s"] == 1.0
    with pytest.raises(InputError, match="fade-in"):
        signals.fade_in(s, 20.0)


def test_steps():
    s = signals.steps([1.0, 2.0], [0.5, -0.5], duration=3.0, fs=100.0)
    assert s.v[50] == 0.0 and s.v[150] == 0.5 and s.v[250] == -0.5


@pytest.mark.parametrize("call", [
    lambda: signals.sweep(f_start=10, f_stop=5),
    lambda: signals.sweep(f_stop=600, fs=1000),
    lambda: signals.tone(duration=-1),
    lambda: signals.multisine(f_start=0.01, f_stop=0.02, period=1.0),
    lambda: signals.square(t_on=0),
    lambda: signals.steps([2, 1], [0, 1], 3.0),
])
def test_bad_arguments_raise_input_error(call):
    with pytest.raises(InputError):
        call()
