"""FRF estimators against an LTI system whose FRF is known exactly: a 2nd-order resonance
(20 Hz, ζ = 0.05) in series with a 1st-order low-pass (5 Hz), discretised with the bilinear
transform at fs = 1 kHz and simulated with scipy.signal.lfilter; the truth is the FRF of
that discrete system (scipy.signal.freqz)."""
import numpy as np
import pytest
from scipy import signal

from physics.errors import InputError
from physics.analysis.frf_estimation import estimate_frf, leading_transient, stepped_sine, welch_averages
from physics.io.frfdata import read_frf, write_frf

FS = 1000.0
_WN, _WC = 2 * np.pi * 20.0, 2 * np.pi * 5.0
_B, _A, _ = signal.cont2discrete(([_WN**2], np.polymul([1, 2 * 0.05 * _WN, _WN**2], [1 / _WC, 1])),
                                 1 / FS, method="bilinear")
_B = np.ravel(_B)


def simulate(u):
    return signal.lfilter(_B, _A, u)


def truth(f):
    return signal.freqz(_B, _A, worN=np.atleast_1d(f), fs=FS)[1]


def errors(est, f_lo, f_hi):
    """Largest relative magnitude error and phase error (deg) over excited f_lo..f_hi."""
    sel = est.excited & (est.freq >= f_lo) & (est.freq <= f_hi)
    assert sel.sum() > 20
    h = truth(est.freq[sel])
    return (np.max(np.abs(np.abs(est.response[sel]) / np.abs(h) - 1)),
            np.max(np.abs(np.degrees(np.angle(est.response[sel] / h)))))


def noise_input(n, seed):
    b, a = signal.butter(8, 50.0, fs=FS)
    return signal.lfilter(b, a, np.random.default_rng(seed).normal(size=n + 5000))[5000:]


def multisine_period(p, lines, seed):
    spec = np.zeros(p // 2 + 1, complex)
    spec[lines] = np.exp(2j * np.pi * np.random.default_rng(seed).uniform(size=lines.size))
    x = np.fft.irfft(spec, p)
    return x / x.std()


def coverage(est, f_lo, f_hi):
    """Fraction of excited frequencies whose true |H| and phase lie inside the bounds."""
    sel = est.excited & (est.freq >= f_lo) & (est.freq <= f_hi)
    h = truth(est.freq[sel])
    lo, hi = (b[sel] for b in est.mag_bounds)
    half_phase = (est.phase_bounds_deg[1] - est.phase_bounds_deg[0])[sel] / 2
    in_mag = (np.abs(h) >= lo) & (np.abs(h) <= hi)
    in_phase = np.abs(np.degrees(np.angle(h / est.response[sel]))) <= half_phase
    return in_mag.mean(), in_phase.mean()


# ------------------------------------------------------------------ noise-free accuracy

def test_swept_sine_noise_free():
    t = np.arange(int(100 * FS)) / FS
    sweep = 2.0 * signal.chirp(t, 0.1, t[-1], 50.0, method="logarithmic") * signal.windows.tukey(t.size, 0.01)
    u = np.r_[sweep, np.zeros(int(5 * FS))]  # starts and ends at rest: one whole-record segment
    est = estimate_frf(u, simulate(u), FS, nperseg=u.size, window="boxcar")
    mag_err, phase_err = errors(est, 0.1, 50.0)
    assert mag_err < 0.01 and phase_err < 1.0
    in_sweep = (est.freq >= 0.2) & (est.freq <= 45)
    assert est.excited[in_sweep].all()
    far = est.freq > 100  # the sweep never went there
    assert not est.excited[far].any() and np.isnan(est.response[far]).all()


def test_multisine_noise_free_and_unexcited_lines_flagged():
    p = 4096
    lines = np.arange(1, int(50 * p / FS), 2)  # odd lines only, up to 50 Hz
    u = np.tile(multisine_period(p, lines, seed=1), 5)
    y = simulate(u)[p:]  # first period discarded: transient
    est = estimate_frf(u[p:], y, FS, nperseg=p, window="boxcar", overlap=0.0)
    np.testing.assert_array_equal(np.flatnonzero(est.excited), lines)
    assert np.isnan(est.response[lines + 1]).all() and np.isnan(est.rel_error[lines + 1]).all()
    mag_err, phase_err = errors(est, 0, 50.0)
    assert mag_err < 1e-6 and phase_err < 1e-4  # periodic steady state: leakage-free
    assert est.coherence[lines].min() > 1 - 1e-9
    assert est.n_averages[0] == 4


@pytest.mark.parametrize("fade", [True, False])
def test_a_multisine_started_inside_the_record_skips_its_transient_period(fade):
    """A lab starts the drive inside the record (from rest, perhaps faded in): the first period
    is a transient, found from the voltage (a fade-in does not repeat) or the deflection (its
    first period changes more than the later ones), and the estimate from the periods after it
    is leakage-free again; a record begun in its steady state loses nothing."""
    p = 4096
    lines = np.arange(1, int(50 * p / FS), 2)
    u = np.tile(multisine_period(p, lines, seed=1), 4)
    if fade:
        u[:p // 4] *= 0.5 * (1 - np.cos(np.pi * np.arange(p // 4) / (p // 4)))
    y = simulate(u) + 1e-3 * np.random.default_rng(0).normal(size=u.size)
    skip = leading_transient(u, y, FS, p / FS)
    assert skip == p
    whole = estimate_frf(u, y, FS, nperseg=p, window="boxcar", overlap=0.0)
    settled = estimate_frf(u[skip:], y[skip:], FS, nperseg=p, window="boxcar", overlap=0.0)
    assert errors(whole, 1.0, 50.0)[0] > 0.02 > errors(settled, 1.0, 50.0)[0]
    steady = np.tile(multisine_period(p, lines, seed=1), 5)
    ys = simulate(steady)[p:] + 1e-3 * np.random.default_rng(1).normal(size=4 * p)
    assert leading_transient(steady[p:], ys, FS, p / FS) == 0


def test_band_limited_noise_noise_free():
    u = noise_input(2**19, seed=2)
    est = estimate_frf(u, simulate(u), FS, nperseg=2**16)
    mag_err, phase_err = errors(est, 0.5, 45.0)
    assert mag_err < 0.01 and phase_err < 1.0
    band = (est.freq >= 0.5) & (est.freq <= 45.0)
    assert est.coherence[band].min() > 0.99
    assert not est.excited[est.freq > 150].any()  # 8th-order low-pass input: no power there


# ------------------------------------------------------------------ noisy records

@pytest.mark.parametrize("confidence", [0.95, 0.68])
def test_noise_confidence_bounds_cover_the_truth(confidence):
    u = noise_input(2**18, seed=3)
    y0 = simulate(u)
    y = y0 + np.random.default_rng(4).normal(scale=0.2 * y0.std(), size=y0.size)
    est = estimate_frf(u, y, FS, nperseg=2**13, confidence=confidence)
    for fraction in coverage(est, 0.5, 45.0):
        assert confidence - 0.07 < fraction < min(confidence + 0.07, 0.99)
    clean = estimate_frf(u, y0, FS, nperseg=2**13)
    band = (est.freq >= 0.5) & (est.freq <= 45.0)
    assert np.mean(est.coherence[band]) < np.mean(clean.coherence[band]) - 0.1
    assert np.min(clean.coherence[band]) > 0.99


def test_noisy_multisine_bounds_with_independent_periods():
    p = 2048
    lines = np.arange(1, int(50 * p / FS))
    u = np.tile(multisine_period(p, lines, seed=5), 41)
    y = simulate(u)[p:]
    y = y + np.random.default_rng(6).normal(scale=0.3 * y.std(), size=y.size)
    est = estimate_frf(u[p:], y, FS, nperseg=p, window="boxcar", overlap=0.0)
    assert est.n_averages[0] == 40  # non-overlapping rectangular segments are independent
    for fraction in coverage(est, 0.5, 50.0):
        assert 0.88 < fraction < 0.99


def test_equivalent_number_of_averages():
    # rectangular, no overlap: K; Hann at 50 %: overlap correlation 1/6 (Welch 1967)
    assert welch_averages(np.ones(64), 64, 10) == 10
    k = 15
    expected = k / (1 + 2 * (1 - 1 / k) * (1 / 6) ** 2)
    assert welch_averages(signal.get_window("hann", 1024), 512, k) == pytest.approx(expected, rel=1e-9)
    u = noise_input(2**14, seed=0)
    assert estimate_frf(u, u, FS).n_averages[0] == pytest.approx(expected, rel=1e-9)  # n//8, 50 %


def test_band_limits_the_frequencies():
    u = noise_input(2**14, seed=7)
    est = estimate_frf(u, simulate(u), FS, nperseg=2**11, band=(2.0, 40.0))
    assert est.freq.min() >= 2.0 and est.freq.max() <= 40.0
    assert est.excited.all()


# ------------------------------------------------------------------ stepped sine

def tone_record(f0, duration=6.0, amp=2.0, phase=0.3):
    t = np.arange(int(duration * FS)) / FS
    u = amp * np.sin(2 * np.pi * f0 * t + phase)
    return u, simulate(u), FS, f0


def test_stepped_sine_matches_true_frf_at_each_tone():
    tones = [35.0, 0.5, 19.3, 20.0, 2.0, 21.7, 7.3]  # unsorted; most not a whole number of samples per period
    est = stepped_sine([tone_record(f) for f in tones], settle=3.0)
    np.testing.assert_array_equal(est.freq, sorted(tones))
    assert np.max(np.abs(est.response / truth(est.freq) - 1)) < 1e-3
    np.testing.assert_array_equal(est.n_averages, np.floor(3.0 * est.freq))
    assert est.excited.all() and est.coherence is None


def test_stepped_sine_ignores_harmonics_offset_and_trend():
    u, y, fs, f0 = tone_record(7.3)
    t = np.arange(u.size) / FS
    distorted = y + 0.5 * np.abs(y).max() * np.sin(2 * np.pi * 2 * f0 * t) + 1e-3 + 2e-4 * t
    est = stepped_sine([(u, distorted, fs, f0)], settle=3.0)
    assert abs(est.response[0] / truth(f0)[0] - 1) < 1e-3


def test_stepped_sine_error_estimate_is_calibrated():
    rng = np.random.default_rng(8)
    t = np.arange(int(2 * FS)) / FS
    inside = []
    for _ in range(300):
        f0 = rng.uniform(1, 45)
        u = np.sin(2 * np.pi * f0 * t)
        y = simulate(u) + rng.normal(scale=0.05 * abs(truth(f0)[0]), size=t.size)
        est = stepped_sine([(u + rng.normal(scale=0.01, size=t.size), y, FS, f0)], settle=1.0)
        h = truth(f0)[0]
        lo, hi = est.mag_bounds
        plo, phi = est.phase_bounds_deg
        inside.append((lo[0] <= abs(h) <= hi[0],
                       abs(np.degrees(np.angle(h / est.response[0]))) <= (phi[0] - plo[0]) / 2))
    for fraction in np.mean(inside, axis=0):
        assert 0.91 < fraction < 0.99


def test_stepped_sine_flags_a_tone_missing_from_the_input():
    _, y, fs, f0 = tone_record(10.0)
    est = stepped_sine([(np.zeros_like(y), y, fs, f0), tone_record(12.0)], settle=1.0)
    np.testing.assert_array_equal(est.excited, [False, True])
    assert np.isnan(est.response[0])
    assert est.to_frfdata().freq.tolist() == [12.0]


@pytest.mark.parametrize("records, settle, msg", [
    ([tone_record(5.0), tone_record(5.0)], 1.0, "share the tone f0=5"),
    ([tone_record(0.5, duration=3.0)], 2.0, "less than one period"),
    ([tone_record(5.0)[:3] + (600.0,)], 0.0, "fs/2"),
    ([], 0.0, "no records"),
])
def test_stepped_sine_rejects_bad_records(records, settle, msg):
    with pytest.raises(InputError, match=msg):
        stepped_sine(records, settle=settle)


# ------------------------------------------------------------------ export and validation

def test_to_frfdata_exports_only_excited_frequencies(tmp_path):
    p = 1024
    lines = np.arange(2, 40, 3)
    u = np.tile(multisine_period(p, lines, seed=9), 4)
    est = estimate_frf(u[2 * p:], simulate(u)[2 * p:], FS, nperseg=p, window="boxcar", overlap=0)
    frf = est.to_frfdata(rh=60.0, meta={"device": "IPMC"})
    np.testing.assert_allclose(frf.freq, lines * FS / p)
    np.testing.assert_allclose(frf.response, truth(frf.freq), rtol=1e-6)
    assert frf.meta["device"] == "IPMC" and frf.meta["estimator"] == "H1 (Welch)"
    back = read_frf(write_frf(frf, tmp_path / "frf.csv"))
    np.testing.assert_allclose(back.response, frf.response, rtol=1e-12)
    np.testing.assert_allclose(back.coherence, 1.0)


@pytest.mark.parametrize("call, msg", [
    (lambda u: estimate_frf(u, u[:-1], FS), "has 4096 samples but output y has 4095"),
    (lambda u: estimate_frf(np.r_[u[:-1], np.nan], u, FS), "input u: sample 4095 is nan"),
    (lambda u: estimate_frf(u, u, FS, nperseg=5000), "nperseg=5000"),
    (lambda u: estimate_frf(u, u, FS, overlap=1.0), "overlap=1.0"),
    (lambda u: estimate_frf(u, u, FS, band=(40.0, 10.0)), "band="),
    (lambda u: estimate_frf(u, u, FS, band=(600.0, 700.0)), "contains no frequency"),
    (lambda u: estimate_frf(u, u, -1.0), "fs=-1.0"),
    (lambda u: estimate_frf(u, u, FS, confidence=1.0), "confidence=1.0"),
])
def test_estimate_frf_rejects_bad_input(call, msg):
    with pytest.raises(InputError, match=msg):
        call(noise_input(4096, seed=0))


def test_period_matches_a_direct_correlation():
    """_period (one single-precision FFT) finds the lag a direct float64 correlation finds:
    the first lag whose normalised correlation over the overlap reaches the threshold."""
    from physics.analysis.frf_estimation import PERIODIC_CORRELATION, _period
    rng = np.random.default_rng(3)
    n = 3000
    for L, noise in [(137, 0.05), (611, 0.1), (900, 0.2), (None, 1.0)]:
        base = rng.standard_normal(L or n)
        x = np.resize(base, n) + noise * rng.standard_normal(n)
        x -= x.mean()
        rho = np.array([x[k:] @ x[:n - k] / np.sqrt((x[k:] @ x[k:]) * (x[:n - k] @ x[:n - k]))
                        for k in range(8, n // 2 + 1)])
        hits = np.flatnonzero(rho >= PERIODIC_CORRELATION)
        expected = None if hits.size == 0 else 8 + hits[0]
        got = _period(x, 1.0)
        assert (got is None) == (expected is None), (L, noise, got, expected)
        if expected is not None:
            assert got == expected == L


def test_a_faded_in_multisine_is_periodic_after_its_lead_in():
    """A multisine faded in over part of its first period (as a lab starts its drive) repeats
    too little as a whole record to pass the correlation test, yet every later period repeats:
    it is read as periodic at its period, and leading_transient counts the faded period.
    Broadband noise stays non-periodic with the second look."""
    from physics.analysis.frf_estimation import PERIODIC_CORRELATION, detect_excitation
    p = 2000
    one = multisine_period(p, np.arange(1, 200), seed=4)
    u = np.tile(one, 3)
    t = np.arange(u.size) / FS
    fade = t < 0.6
    u[fade] *= 0.5 * (1 - np.cos(np.pi * t[fade] / 0.6))
    rho = u[p:] @ u[:-p] / np.sqrt((u[p:] @ u[p:]) * (u[:-p] @ u[:-p]))
    assert rho < PERIODIC_CORRELATION                      # the whole record alone fails the test
    ex = detect_excitation(u, FS)
    assert ex.kind == "periodic" and ex.period_s == pytest.approx(p / FS)
    assert leading_transient(u, None, FS, ex.period_s) == p
    assert detect_excitation(noise_input(3 * p, seed=2), FS).kind == "noise"


def test_jump_scan_in_blocks_matches_the_whole_record(monkeypatch):
    """The blockwise jump scan of detect_excitation sees a jump wherever it lies, block edges included."""
    import physics.analysis.frf_estimation as fe
    monkeypatch.setattr(fe, "_BLOCK", 7)
    x = np.zeros(100)
    for at in (3, 6, 7, 13, 14, 60, 99):
        y = x.copy()
        y[at:] = 1.0
        for k in (1, 3, 5):
            direct = bool(np.any(np.abs(y[k:] - y[:-k]) > 0.5))
            assert fe._jumps(y, k, 0.5) == direct
    assert not fe._jumps(x, 3, 0.5)


def test_spectrum_in_parts_matches_the_whole_fft(monkeypatch):
    """A long record's |X_k|² is assembled from m interleaved parts (one decimation-in-time
    step, lines in blocks): the whole real FFT's values to rounding, for every split a length
    allows (8, 7, 5, 3, a factor above 8, and none: the whole FFT), with and without the DC
    line, and the same classification of the excitation (tone, noise, steps, periodic)."""
    import physics.analysis.frf_estimation as fe
    monkeypatch.setattr(fe, "SPLIT_SPECTRUM", 64)
    monkeypatch.setattr(fe, "_LINES", 37)                  # lines in many uneven blocks
    rng = np.random.default_rng(4)
    for n, m in [(4000, 8), (3003, 7), (2005, 5), (2001, 3), (2431, 11), (2477, 1), (64, 8)]:
        assert fe._split_factor(n) == m
        x = np.cumsum(rng.standard_normal(n)) + 3.0
        for zero_dc in (False, True):
            X = np.fft.rfft(x)
            if zero_dc:
                X[0] = 0.0
            want = X.real ** 2 + X.imag ** 2
            got = fe.power_spectrum(x, zero_dc=zero_dc)
            assert got.shape == want.shape
            assert np.max(np.abs(got - want)) <= 1e-12 * want.max(), (n, zero_dc)
    t = np.arange(4000) / 100.0
    for v in (np.sin(2 * np.pi * 1.3 * t), rng.standard_normal(4000), np.sign(np.sin(2 * np.pi * 0.2 * t)),
              np.tile(rng.standard_normal(400), 10) + 0.05 * rng.standard_normal(4000) + 2.0):
        parts = fe.detect_excitation(v, 100.0)
        monkeypatch.setattr(fe, "SPLIT_SPECTRUM", 1 << 30)
        whole = fe.detect_excitation(v, 100.0)
        monkeypatch.setattr(fe, "SPLIT_SPECTRUM", 64)
        assert (parts.kind, parts.how, parts.period_s) == (whole.kind, whole.how, whole.period_s)
        assert np.allclose(parts.band, whole.band, rtol=1e-12)
    assert [parts.kind, parts.period_s] == ["periodic", 4.0]
