"""Frequency-response estimation from measured input/output records.

* :func:`estimate_frf` — H1 estimator H = S_uy / S_uu from Welch-averaged spectra, for
  swept-sine, multisine and noise excitation, with the ordinary coherence γ² and
  random-error confidence bounds.
* :func:`stepped_sine` — one least-squares sine fit per record at its known tone.
* :func:`detect_excitation` — what kind of excitation a voltage record is (steps, tone,
  periodic multisine, sweep, noise), from the samples alone, for records whose metadata
  do not say (a lab's exports): it decides how the frequency response is estimated.

Random errors follow Bendat & Piersol, *Random Data* (4th ed., Wiley 2010), §9.2.4,
Table 9.6: with n_d independent averages, the normalized random error of |Ĥ| and the
standard deviation (rad) of the phase are both

    ε = sqrt(1 − γ²) / (|γ| sqrt(2 n_d)),

and the bounds at confidence c are |Ĥ|(1 ± z ε) and φ̂ ± z ε with z the two-sided normal
quantile (valid for ε ≲ 0.2).  Overlapping windowed segments are not independent: n_d is
Welch's equivalent number of averages (P. D. Welch, IEEE Trans. Audio Electroacoust. 15,
1967, eq. for the variance of the averaged periodogram).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sp_fft, signal, stats

from ..errors import InputError
from ..io.frfdata import FRFData


@dataclass
class FRFEstimate:
    """An estimated frequency response with its uncertainty.

    ``freq`` Hz; ``response`` complex (output unit per input unit; m/V for deflection
    over voltage), NaN where the input has no power; ``coherence`` γ² at every frequency
    (``None`` for stepped sine); ``rel_error`` ε, the standard deviation of |Ĥ|/|H| and
    of the phase in rad; ``n_averages`` equivalent independent averages (periods for
    stepped sine); ``excited`` marks the frequencies where the input has power — only
    these are valid.
    """
    freq: np.ndarray
    response: np.ndarray
    coherence: np.ndarray | None
    rel_error: np.ndarray
    n_averages: np.ndarray
    excited: np.ndarray
    confidence: float
    method: str
    meta: dict = field(default_factory=dict)

    @property
    def magnitude(self) -> np.ndarray:
        """|Ĥ|."""
        return np.abs(self.response)

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase (deg), unwrapped along the excited frequencies (NaN elsewhere)."""
        phase = np.full(self.freq.shape, np.nan)
        phase[self.excited] = np.degrees(np.unwrap(np.angle(self.response[self.excited])))
        return phase

    @property
    def z(self) -> float:
        """Two-sided standard-normal quantile of ``confidence``."""
        return float(stats.norm.ppf(0.5 + self.confidence / 2))

    @property
    def mag_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper confidence bounds of |H|: |Ĥ|(1 ∓ z ε), lower clipped at 0."""
        half = self.z * self.rel_error * self.magnitude
        return np.maximum(self.magnitude - half, 0.0), self.magnitude + half

    @property
    def phase_bounds_deg(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper confidence bounds of the phase (deg): φ̂ ∓ z ε."""
        half = np.degrees(self.z * self.rel_error)
        return self.phase_deg - half, self.phase_deg + half

    def to_frfdata(self, *, rh: float | np.ndarray | None = None,
                   meta: dict | None = None) -> FRFData:
        """The excited, positive frequencies as :class:`FRFData` (``rh`` in %)."""
        keep = self.excited & (self.freq > 0)
        if not keep.any():
            raise InputError("FRF estimate: no excited frequency to export")
        if isinstance(rh, np.ndarray) and rh.shape == self.freq.shape:
            rh = rh[keep]
        info = {"estimator": self.method, "confidence": self.confidence,
                "n_averages": np.unique(self.n_averages[keep]).tolist(), **self.meta,
                **(meta or {})}
        return FRFData(self.freq[keep], self.response[keep],
                       None if self.coherence is None else self.coherence[keep], rh, meta=info)


def power_spectrum(x: np.ndarray, zero_dc: bool = False) -> np.ndarray:
    """|X_k|² of the real FFT of ``x`` (k = 0..n/2); ``zero_dc``: the line of the mean set
    to 0 (the spectrum of x − mean(x)).  A long record's spectrum is assembled from
    interleaved parts (:func:`power_blocks`): beside the result it costs the parts' half
    spectra (n/2 complex values), not the whole FFT's output, work buffers and plan (~24 B
    per sample) and a squared copy."""
    n = x.size
    out = np.empty(n // 2 + 1)
    for k0, p in power_blocks(lambda r, m: x[r::m], n, zero_dc):
        out[k0:k0 + p.size] = p
    return out


#: Records of at least this many samples have their spectrum taken in interleaved parts.
SPLIT_SPECTRUM = 1 << 20
#: Lines of the spectrum assembled at a time from the parts.
_LINES = 1 << 16


def _split_factor(n: int) -> int:
    """Parts of a length-``n`` spectrum: the largest divisor of n up to 8, else the
    smallest up to 16 (1: none, the whole FFT)."""
    if n < SPLIT_SPECTRUM:
        return 1
    small = [m for m in range(2, 9) if n % m == 0]
    return small[-1] if small else next((m for m in range(9, 17) if n % m == 0), 1)


def power_blocks(part, n: int, zero_dc: bool = False):
    """Yield ``(k0, P)``: P = |X_k|² of the real DFT X of a signal of ``n`` samples for the
    lines k = k0, k0 + 1, … (all of k = 0..n/2, in order, in blocks); ``zero_dc`` sets X_0 = 0.

    ``part(r, m)`` returns the samples r, r + m, r + 2m, … of the signal (``x[r::m]``), so a
    signal computed on the fly (a residual) never exists whole.  A record shorter than
    :data:`SPLIT_SPECTRUM` (or whose length has no factor up to 16) is one real FFT, one
    block.  A longer one is split into m interleaved parts of L = n/m samples (one
    decimation-in-time step): X_k = Σ_r W^{rk} S_r(k mod L), W = e^{−2πi/n}, with S_r the
    length-L DFT of part r (only its half is stored: S_r(L − j) = conj S_r(j) for real
    parts), evaluated by Horner's rule in blocks of lines.  Memory: the m half spectra
    (n/2 complex values, as the whole FFT's output) and one part; the same |X_k|² to
    rounding (~1e-14 of the largest line at 10^7 samples)."""
    m = _split_factor(n)
    if m == 1:
        X = np.fft.rfft(part(0, 1))
        if zero_dc:
            X[0] = 0.0
        parts = X.view(np.float64).reshape(-1, 2)        # (re, im) per line, squared in place
        np.square(parts, out=parts)
        yield 0, parts.sum(axis=1)
        return
    L = n // m
    half = L // 2
    S = np.empty((m, half + 1), dtype=complex)
    for r in range(m):
        np.fft.rfft(part(r, m), out=S[r])
    lines = n // 2 + 1
    for k0 in range(0, lines, _LINES):
        k = np.arange(k0, min(lines, k0 + _LINES))
        j = k % L
        flip = j > half
        j[flip] = L - j[flip]
        w = np.exp((-2j * np.pi / n) * k)
        acc = S[m - 1, j]
        np.conjugate(acc, out=acc, where=flip)
        for r in range(m - 2, -1, -1):
            s = S[r, j]
            np.conjugate(s, out=s, where=flip)
            acc *= w
            acc += s
        if zero_dc and k0 == 0:
            acc[0] = 0.0
        yield k0, acc.real ** 2 + acc.imag ** 2


def _as_signal(x, name: str) -> np.ndarray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1 or arr.size < 2:
        raise InputError(f"{name} must be a 1-D signal of at least 2 samples, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise InputError(f"{name}: sample {bad[0]} is {arr[bad[0]]}; expected finite values")
    return arr


def _check_pair(u, y, fs, confidence) -> tuple[np.ndarray, np.ndarray]:
    u, y = _as_signal(u, "input u"), _as_signal(y, "output y")
    if u.size != y.size:
        raise InputError(f"input u has {u.size} samples but output y has {y.size}")
    if not (np.isfinite(fs) and fs > 0):
        raise InputError(f"sampling frequency fs={fs!r} Hz must be positive")
    if not 0 < confidence < 1:
        raise InputError(f"confidence={confidence!r} must lie strictly between 0 and 1")
    return u, y


def welch_averages(window: np.ndarray, step: int, n_segments: int) -> float:
    """Equivalent number of independent averages of Welch's method (Welch 1967):
    K / (1 + 2 Σ_j (1 − j/K) ρ(j)²), ρ(j) the window overlap correlation at shift j·step."""
    nperseg = window.size
    shifts = np.arange(1, min(n_segments, -(-nperseg // step)))
    rho = np.array([np.dot(window[: nperseg - j * step], window[j * step:]) for j in shifts])
    rho /= np.dot(window, window)
    return n_segments / (1 + 2 * np.sum((1 - shifts / n_segments) * rho**2))


#: Samples of the segments whose spectra are taken at once: on a long record the Welch
#: averages are accumulated block by block (memory bounded, the same mean).
WELCH_BLOCK = 1 << 21


def _welch(u: np.ndarray, y: np.ndarray, kw: dict):
    """(freq, S_uy, S_uu, S_yy): Welch averages (scipy's csd/welch with ``kw``) over the
    segments of ``u``, ``y``, taken a block of whole segments at a time, so a long record
    never has all its windowed segments in memory at once."""
    nperseg, step = kw["nperseg"], kw["nperseg"] - kw["noverlap"]
    n_seg = 1 + (u.size - nperseg) // step
    per = max(1, WELCH_BLOCK // nperseg)
    sums = None
    for s0 in range(0, n_seg, per):
        s1 = min(n_seg, s0 + per)
        a, b = s0 * step, (s1 - 1) * step + nperseg
        freq, s_uy = signal.csd(u[a:b], y[a:b], **kw)
        parts = (s_uy, signal.welch(u[a:b], **kw)[1], signal.welch(y[a:b], **kw)[1])
        w = s1 - s0
        sums = [w * p for p in parts] if sums is None else [acc + w * p for acc, p in zip(sums, parts)]
    return (freq, *(acc / n_seg for acc in sums)) if per < n_seg else (freq, *parts)


def estimate_frf(u, y, fs: float, *, nperseg: int | None = None, window="hann",
                 overlap: float = 0.5, detrend="constant",
                 band: tuple[float, float] | None = None, confidence: float = 0.95,
                 min_input_power: float = 1e-3, noise_psd: float | None = None) -> FRFEstimate:
    """H1 estimate of the frequency response from input ``u`` to output ``y`` (fs in Hz).

    Spectra are Welch averages (:func:`scipy.signal.csd`, :func:`scipy.signal.welch`) over
    segments of ``nperseg`` samples (default ``n // 8``: 15 half-overlapping segments)
    with the given ``window``, ``overlap`` fraction and ``detrend``.  For a periodic
    excitation use ``nperseg`` = one period with ``window="boxcar"``, ``overlap=0``
    (leakage-free); for a single transient sweep that starts and ends at rest use the
    whole record (``nperseg=len(u)``, boxcar).  ``band`` = (f_lo, f_hi) Hz keeps only
    those frequencies.  A frequency counts as excited when S_uu exceeds
    ``min_input_power`` times its largest value in the band; elsewhere ``response`` and
    ``rel_error`` are NaN.

    With one average (the whole record, one period) the ordinary coherence is 1 by
    construction and says nothing about the noise; given the output's noise level
    ``noise_psd`` [units²/Hz, one-sided] (:func:`noise_level`), the coherence is then
    γ² = 1 − S_nn/S_yy (the output power not explained by noise), so that the random
    error ε of each line — and the weights of a fit — follow its signal-to-noise ratio.
    """
    u, y = _check_pair(u, y, fs, confidence)
    n = u.size
    nperseg = n // 8 if nperseg is None else int(nperseg)
    if not 2 <= nperseg <= n:
        raise InputError(f"nperseg={nperseg} must lie within 2 and the record length {n}")
    if not 0 <= overlap < 1:
        raise InputError(f"overlap={overlap!r} must lie within [0, 1)")
    if not 0 <= min_input_power < 1:
        raise InputError(f"min_input_power={min_input_power!r} must lie within [0, 1)")
    noverlap = int(round(overlap * nperseg))
    if noverlap >= nperseg:
        raise InputError(f"overlap={overlap!r} leaves no step between segments of {nperseg}")
    kw = dict(fs=fs, window=window, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
    freq, s_uy, s_uu, s_yy = _welch(u, y, kw)
    if band is not None:
        f_lo, f_hi = band
        if not 0 <= f_lo < f_hi:
            raise InputError(f"band={band!r} must be (f_lo, f_hi) with 0 <= f_lo < f_hi (Hz)")
        keep = (freq >= f_lo) & (freq <= f_hi)
        if not keep.any():
            raise InputError(f"band={band!r} Hz contains no frequency of the estimate "
                             f"(resolution {fs / nperseg:g} Hz, Nyquist {fs / 2:g} Hz)")
        freq, s_uy, s_uu, s_yy = freq[keep], s_uy[keep], s_uu[keep], s_yy[keep]
    excited = s_uu > min_input_power * s_uu.max() if s_uu.max() > 0 else np.zeros(freq.shape, bool)
    step = nperseg - noverlap
    n_seg = 1 + (n - nperseg) // step
    n_d = welch_averages(signal.get_window(window, nperseg), step, n_seg)
    with np.errstate(divide="ignore", invalid="ignore"):
        if n_seg == 1 and noise_psd is not None:
            coherence = np.clip(1.0 - noise_psd / s_yy, 1e-12, 1.0)
        else:
            coherence = np.clip(np.abs(s_uy) ** 2 / (s_uu * s_yy), 0.0, 1.0)
        h = np.where(excited, s_uy / s_uu, np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        eps = np.sqrt(1 - coherence) / np.sqrt(coherence * 2 * n_d)
    eps = np.where(excited, eps, np.nan)
    return FRFEstimate(freq, h, coherence, eps, np.full(freq.shape, n_d), excited, confidence,
                       "H1 (Welch)", meta={"nperseg": nperseg, "window": str(window),
                                           "overlap": noverlap / nperseg, "segments": n_seg,
                                           "detrend": str(detrend),
                                           "coherence": "from the output noise level" if n_seg == 1
                                           and noise_psd is not None else "ordinary"})


def noise_level(y, fs: float) -> tuple[float, float, tuple[float, float]]:
    """(white noise level of the output [units²/Hz, one-sided], highest frequency where the
    response stands ≥ :data:`RESPONSE_SNR` × above it [Hz], the band the level came from [Hz]).

    Welch spectrum of the linearly detrended record (segments of ~4 s); the level is the
    lowest median power of eight log-spaced bands above 1 Hz: where the response has fallen
    away (beyond the excitation or the resonance) only the sensor's white noise and
    quantisation remain, while a drift lives below 1 Hz.  When the response fills the whole
    spectrum the level is an upper bound.  NaN when the record is too short."""
    y = signal.detrend(_as_signal(y, "output y"))
    nper = _noise_segment(y.size, fs)
    f, P = signal.welch(y, fs=fs, nperseg=nper)
    meds = [(float(np.median(P[m])), a, b) for a, b, m in _noise_bands(f, fs, nper, 3)]
    if not meds:
        return float("nan"), fs / 2, (float("nan"), float("nan"))
    level, a, b = min(meds)
    smooth = np.convolve(P, np.ones(5) / 5, mode="same")
    above = np.flatnonzero(smooth > RESPONSE_SNR * level)
    return level, float(f[above[-1]]) if above.size else float(f[1]), (a, b)


#: The response band ends where the output spectrum falls below this × its noise level.
RESPONSE_SNR = 30.0


def _noise_segment(n: int, fs: float) -> int:
    """Welch segment [samples] of the noise estimates: ~4 s, at least 256, at most the record."""
    return int(min(n, max(256, 4.0 * fs)))


def _noise_bands(f: np.ndarray, fs: float, nper: int, min_lines: int) -> list[tuple[float, float, np.ndarray]]:
    """(low edge, high edge [Hz], mask of ``f``) of the eight log-spaced bands above 1 Hz (and
    above 8 lines of the segment) that the noise estimates read, each of ``min_lines`` lines or more."""
    lo = max(1.0, 8.0 * fs / nper)
    edges = np.geomspace(lo, 0.98 * fs / 2, 9) if 0.98 * fs / 2 > 2 * lo else np.array([lo, fs / 2])
    bands = [(float(a), float(b), (f >= a) & (f < b)) for a, b in zip(edges[:-1], edges[1:])]
    return [x for x in bands if x[2].sum() >= min_lines]


def _quiet_bands(y: np.ndarray, fs: float) -> list[tuple[float, float, float, float]]:
    """Per band of :func:`_noise_bands` (16 lines or more): (the :data:`QUIET_SHARE` quantile over
    the ~4 s segments of the segment's median power, the Welch median power, low and high edge).
    Welch's spectrum is the mean of these segments (same window, overlap and detrending)."""
    nper = _noise_segment(y.size, fs)
    f, _, S = signal.spectrogram(y, fs=fs, nperseg=nper, noverlap=nper // 2, window="hann", detrend="constant",
                                 scaling="density")
    if S.shape[1] < 4:
        return []
    P = S.mean(axis=1)
    return [(float(np.quantile(np.median(S[m], axis=0), QUIET_SHARE)), float(np.median(P[m])), a, b)
            for a, b, m in _noise_bands(f, fs, nper, 16)]


@functools.lru_cache(maxsize=32)
def _quiet_calibration(n: int, fs: float) -> tuple[float, ...]:
    """Per band, Welch median ÷ quiet quantile on white noise of ``n`` samples (eight draws of a
    fixed seed; at most 64 segments, beyond which the factor no longer changes): the factor that
    puts :func:`quiet_noise_level` on :func:`noise_level`'s scale."""
    rng = np.random.default_rng(0)
    n = min(n, 32 * _noise_segment(n, fs))
    draws = [_quiet_bands(rng.standard_normal(n), fs) for _ in range(8)]
    return tuple(float(np.mean([d[k][1] / d[k][0] for d in draws])) for k in range(len(draws[0])))


def quiet_noise_level(y, fs: float) -> tuple[float, tuple[float, float]]:
    """(white noise level of the output [units²/Hz, one-sided], the band it came from [Hz]) read
    in the record's quietest segments: the :data:`QUIET_SHARE` quantile over its ~4 s segments of
    each band's median power, scaled by what the same reading gives on white noise of the record's
    length (:func:`_quiet_calibration`), lowest over the bands of :func:`noise_level`.  A sweep
    through a play or a clipped sensor puts its harmonics in each band only while its frequency
    is in the right range; stationary noise is in every segment.  NaN when the record holds fewer
    than four segments or no band of 16 lines."""
    y = signal.detrend(_as_signal(y, "output y"))
    rec = _quiet_bands(y, fs)
    if not rec:
        return float("nan"), (float("nan"), float("nan"))
    level, a, b = min((q * c, a, b) for (q, _, a, b), c in zip(rec, _quiet_calibration(y.size, float(fs))))
    return level, (a, b)


#: The share of a record's segments whose power the quiet noise reading takes (its lower quartile).
QUIET_SHARE = 0.25


def periodic_noise_level(y, fs: float, period: int) -> tuple[float, tuple[float, float]]:
    """(white noise level of a periodic record's output [units²/Hz, one-sided], the band it came
    from [Hz]) from the difference of successive periods, y[k + P] − y[k] (``period`` P in
    samples): everything that repeats — the response and the harmonics a clipped sensor or a
    static nonlinearity adds across the whole spectrum — cancels, while independent noise
    doubles its power.  The level is that of :func:`noise_level` on the difference, halved.
    NaN when fewer than two periods are recorded."""
    y = _as_signal(y, "output y")
    if not 0 < period <= y.size // 2:
        return float("nan"), (float("nan"), float("nan"))
    level, _, band = noise_level(y[period:] - y[:-period], fs)
    return level / 2.0, band


def _tone(x: np.ndarray, fs: float, f0: float, i0: int, n: int) -> tuple[complex, float]:
    """Least-squares fit of x[i0:i0+n] ≈ Re(X e^{j2πf0 t}) + c0 + c1 t; returns the phasor
    X and the standard error of each of its real and imaginary parts (numpy float, so
    that dividing by a zero amplitude gives inf rather than an exception)."""
    t = np.arange(n) / fs
    w = 2 * np.pi * f0 * t
    basis = np.column_stack([np.cos(w), np.sin(w), np.ones(n), t - t.mean()])
    coef, *_ = np.linalg.lstsq(basis, x[i0:i0 + n], rcond=None)
    resid = x[i0:i0 + n] - basis @ coef
    sigma2 = resid @ resid / (n - basis.shape[1])
    cov = sigma2 * np.linalg.inv(basis.T @ basis)
    return complex(coef[0], -coef[1]), np.sqrt((cov[0, 0] + cov[1, 1]) / 2)


def stepped_sine(records, *, settle: float = 0.0, confidence: float = 0.95,
                 min_snr: float = 5.0) -> FRFEstimate:
    """Stepped-sine (lock-in) estimate: one record per tone.

    ``records`` is an iterable of ``(u, y, fs, f0)`` (signals, Hz, Hz).  In each record
    the first ``settle`` s (transient) are discarded, then the largest integer number of
    periods of f0 is fitted by least squares with a sine, an offset and a linear trend
    (harmonics of a nonlinear response are orthogonal to the fundamental over whole
    periods).  H(f0) = Y/U; its error ε = sqrt((σ_Y/|Y|)² + (σ_U/|U|)²) from the
    residuals (white-noise assumption).  A tone whose input amplitude is below
    ``min_snr`` standard errors is flagged as not excited.
    """
    rows = []
    for k, (u, y, fs, f0) in enumerate(records):
        u, y = _check_pair(u, y, fs, confidence)
        if not 0 < f0 < fs / 2:
            raise InputError(f"record {k}: tone f0={f0!r} Hz must lie within 0 and fs/2 = {fs / 2:g} Hz")
        i0 = int(np.ceil(settle * fs))
        periods = int(np.floor((u.size - i0) * f0 / fs))
        n = int(round(periods * fs / f0))
        if periods < 1 or n < 5:
            raise InputError(f"record {k}: after discarding settle={settle!r} s, "
                             f"{(u.size - i0) / fs:.4g} s remain, less than one period of "
                             f"f0={f0:g} Hz (or fewer than 5 samples)")
        (U, su), (Y, sy) = (_tone(x, fs, f0, i0, n) for x in (u, y))
        excited = bool(abs(U) > min_snr * su)
        with np.errstate(divide="ignore"):
            h, eps = (Y / U, np.hypot(sy / abs(Y), su / abs(U))) if excited else (np.nan, np.nan)
        rows.append((float(f0), h, eps, periods, excited))
    if not rows:
        raise InputError("stepped sine: no records given")
    rows.sort(key=lambda r: r[0])
    freq = np.array([r[0] for r in rows])
    dup = np.flatnonzero(np.diff(freq) == 0)
    if dup.size:
        raise InputError(f"stepped sine: two records share the tone f0={freq[dup[0]]:g} Hz")
    return FRFEstimate(freq, np.array([r[1] for r in rows]), None,
                       np.array([r[2] for r in rows]), np.array([r[3] for r in rows], float),
                       np.array([r[4] for r in rows]), confidence, "stepped sine",
                       meta={"settle_s": settle})


# ============================================================================ excitation from the data


@dataclass
class Excitation:
    """What a voltage record excites, read from its samples (:func:`detect_excitation`).

    ``kind``: ``steps`` (piecewise constant), ``tone`` (one line), ``periodic`` (a signal
    repeating with ``period_s``, e.g. a multisine of several periods), ``sweep`` (a single
    transient chirp: its dominant frequency moves monotonically), ``noise`` (stationary
    broadband), ``other``; ``band`` [Hz] holds 99 % of the input power; ``how`` says why."""

    kind: str
    band: tuple[float, float]
    tone_hz: float | None = None
    period_s: float | None = None
    how: str = ""


#: Steps: at least this fraction of the samples lies in the 8 most populated bins of 2 % of the span.
STEP_LEVEL_FRACTION = 0.9
#: Periodic: normalised autocorrelation at the period at least this.
PERIODIC_CORRELATION = 0.98
#: Sweep: the dominant log-frequency of successive segments rises (or falls) with a rank
#: correlation of at least this over at least SWEEP_DECADES decades.
SWEEP_RANK = 0.9
SWEEP_DECADES = 0.6
#: Samples per block when scanning a long record for jumps (bounds the temporaries).
_BLOCK = 1 << 18


#: A period whose voltage differs from the next one by more than this share of the drive's RMS
#: does not repeat: a lead-in (a fade-in, the start of the drive).
REPEAT_TOLERANCE = 0.02
#: A period whose deflection changes to the next one by more than this factor times the change
#: between the two periods that follow is still settling (the response of a start from rest).
SETTLING_RATIO = 2.0


def _rms_change(x: np.ndarray, a: int, p: int) -> float:
    """RMS of x over period ``a + 1`` less x over period ``a`` (``p`` samples each)."""
    d = np.asarray(x[(a + 1) * p:(a + 2) * p], dtype=float) - np.asarray(x[a * p:(a + 1) * p], dtype=float)
    return float(np.sqrt(np.mean(d * d)))


def leading_transient(v, y, fs: float, period_s: float) -> int:
    """Samples at the start of a periodic record that are not yet its periodic steady state.

    A lab often starts the drive inside the record (from rest, perhaps faded in) instead of
    recording once the response has settled; that first period is a transient, and an
    estimate that treats it as one period of the steady state (or a model started in its
    steady state) is biased near lightly damped lines.  Counted here, in whole periods: those
    whose voltage differs from the next period's by more than :data:`REPEAT_TOLERANCE` of the
    drive's RMS, then — when two more periods follow — one whose deflection ``y`` changes to
    the next by more than :data:`SETTLING_RATIO` × the change between the two after it (noise
    and a steady drift change every period alike).  At least one period is always kept; 0 for
    a record of fewer than two periods or one recorded once settled (Pintelon & Schoukens,
    *System Identification*, 2012, §2.4: discard the transient periods)."""
    v = np.asarray(v)
    p = int(round(float(period_s) * fs))
    k = v.size // p if p > 0 else 0
    if k < 2:
        return 0
    ref = float(np.std(v[:k * p]))
    if ref <= 0:
        return 0
    j = 0
    while j + 1 < k and _rms_change(v, j, p) > REPEAT_TOLERANCE * ref:
        j += 1
    if y is not None and j + 2 < k and _rms_change(y, j, p) > SETTLING_RATIO * _rms_change(y, j + 1, p):
        j += 1
    return min(j, k - 1) * p


def detect_excitation(v, fs: float, source: str | None = None) -> Excitation:
    """Classify the voltage record ``v`` sampled at ``fs`` [Hz] (see :class:`Excitation`).

    Steps: the samples sit on a few levels (histogram of 2 %-of-span bins) and jump between
    them.  Tone: one spectral line holds 90 % of the power.  Periodic: the autocorrelation
    reaches :data:`PERIODIC_CORRELATION` at a lag L ≤ n/2 (two periods or more), over the whole
    record or after its first :data:`LEAD_IN_SHARE` (a drive faded in).  Sweep: the
    power-weighted mean log-frequency of 24 successive segments is monotone in time (Spearman
    rank correlation ≥ :data:`SWEEP_RANK`) over ≥ :data:`SWEEP_DECADES` decades.  Noise: the rest
    of the broadband records.  ``source`` names the record in errors."""
    v = _as_signal(v, "voltage")
    med = np.median(v)
    x = v - med
    n = x.size
    lo, hi = np.percentile(x, [0.5, 99.5])
    span = float(hi - lo)
    if span <= 0 or x.max() == x.min():
        raise InputError(f"{source + ': ' if source else ''}the voltage is constant; nothing is excited")
    del x                       # the spectrum first, from parts of x: never beside a copy of the record
    X = np.empty(n // 2 + 1)    # |X_k|² of x − mean(x); line k is at k·fs/n Hz
    for k0, p in power_blocks(lambda r, m: v[r::m] - med, n, zero_dc=True):
        X[k0:k0 + p.size] = p
    x = v - med
    df = fs / n
    cum = np.cumsum(X[1:])
    cum /= cum[-1]
    band = (float(max((np.searchsorted(cum, 0.005) + 1) * df, df)),
            float(min((min(np.searchsorted(cum, 0.995), cum.size - 1) + 1) * df, fs / 2)))
    del cum
    # steps: a few levels and jumps between them
    counts, _ = np.histogram(x, bins=np.arange(lo - 0.01 * span, hi + 0.03 * span, 0.02 * span))
    top = np.sort(counts)[::-1][:8].sum() / n
    k = max(1, int(round(0.02 * fs)))
    jumps = _jumps(x, k, 0.3 * span)
    if top >= STEP_LEVEL_FRACTION and jumps:
        return Excitation("steps", (1.0 / (n / fs), min(fs / 2, 50.0)),
                          how=f"piecewise constant: {100 * top:.0f} % of the samples on a few levels")
    kmax = int(np.argmax(X[1:])) + 1
    near = X[max(kmax - 2, 0):kmax + 3].sum()       # the lines within 2.5 fs/n of the peak
    if near > 0.9 * X[1:].sum():
        f_tone = kmax * df
        return Excitation("tone", (f_tone, f_tone), tone_hz=f_tone,
                          how=f"one line at {f_tone:.4g} Hz holds {100 * near / X[1:].sum():.0f} % of the power")
    del X
    offset = med + x.mean()
    del x                       # _period forms v less its mean in pieces, beside no copy of the record
    period = _period(v, fs, offset)
    if period is not None:
        return Excitation("periodic", band, period_s=period,
                          how=f"repeats every {period:.6g} s ({n / fs / period:.3g} periods)")
    x = v - med
    rank, decades = _sweep_trend(x, fs)
    if abs(rank) >= SWEEP_RANK and decades >= SWEEP_DECADES:
        return Excitation("sweep", band, how=f"a single sweep: the dominant frequency moves monotonically over "
                                             f"{decades:.2g} decades (rank correlation {rank:+.2f})")
    if band[1] > 2 * band[0]:
        return Excitation("noise", band, how="stationary broadband (no period, no monotone sweep)")
    return Excitation("other", band, how="narrow band, neither a tone nor a sweep")


def _jumps(x: np.ndarray, k: int, size: float) -> bool:
    """Whether |x[j + k] − x[j]| > size anywhere, scanned in blocks (no record-long temporaries)."""
    n = x.size
    for i in range(0, max(n - k, 0), _BLOCK):
        j = min(i + _BLOCK, n - k)
        if np.any(np.abs(x[i + k:j + k] - x[i:j]) > size):
            return True
    return False


def _period(x: np.ndarray, fs: float, mean: float = 0.0) -> float | None:
    """The period [s] of x − ``mean`` (:func:`_repeat_lag`), or — when the whole record does not
    repeat — that of the record after its first :data:`LEAD_IN_SHARE`: a lab often fades the
    drive in or starts it inside the record, and that lead-in lowers the correlation at the
    period although every period after it repeats (:func:`leading_transient` then counts the
    periods it spoils).  None when neither repeats."""
    lag = _repeat_lag(x, fs, mean)
    if lag is None:
        lag = _repeat_lag(x[int(x.size * LEAD_IN_SHARE):], fs, mean)
    return lag


#: A record that does not repeat as a whole is tried again without this share of its start
#: (a lead-in of up to a quarter; the rest must still hold two periods).
LEAD_IN_SHARE = 0.25


def _repeat_lag(x: np.ndarray, fs: float, mean: float = 0.0) -> float | None:
    """The shortest lag (≤ n/2, ≥ 8 samples) at which x − ``mean`` repeats (normalised
    correlation over the overlap ≥ :data:`PERIODIC_CORRELATION`), in s; None when it does not.

    The autocorrelation is one FFT in single precision (its rounding, ~1e-6 of the energy,
    is far below the 2 % the test allows), zero-padded to 1.5 n (lags up to n/2 do not wrap
    around), squared in place; x − mean is formed in pieces (no float64 copy of the record)
    and the normalisation works on views of one cumulative energy: at 10^7 samples the
    FFT's buffers are the peak, ~20 B per sample (was ~68, then ~32)."""
    n = x.size
    if n // 2 < 8:
        return None
    size = sp_fft.next_fast_len(n + n // 2 + 1, real=True)
    xf = np.empty(n, np.float32)
    for a in range(0, n, _BLOCK):
        np.subtract(x[a:a + _BLOCK], mean, out=xf[a:a + _BLOCK], casting="same_kind")
    F = sp_fft.rfft(xf, size, overwrite_x=True)
    del xf
    parts = F.view(np.float32).reshape(-1, 2)       # |F|² in F itself: (re² + im², 0)
    np.square(parts, out=parts)
    parts[:, 0] += parts[:, 1]
    parts[:, 1] = 0.0
    ac = sp_fft.irfft(F, size, overwrite_x=True)[: n // 2 + 1].astype(np.float64)
    del F, parts
    head = np.empty(n)                              # energy of x[:L+1], cumulated in place
    for a in range(0, n, _BLOCK):
        np.subtract(x[a:a + _BLOCK], mean, out=head[a:a + _BLOCK])
    np.square(head, out=head)
    np.cumsum(head, out=head)
    h = n // 2
    rho = head[-1] - head[7:h]                      # energy of x[L:], L = 8..n/2
    rho *= head[n - 1 - h:n - 8][::-1]              # energy of x[:n − L]
    np.maximum(rho, 1e-300, out=rho)
    np.sqrt(rho, out=rho)
    np.divide(ac[8:], rho, out=rho)
    del head, ac
    ok = np.flatnonzero(rho >= PERIODIC_CORRELATION)
    if ok.size == 0:
        return None
    i = ok[0]
    while i + 1 < rho.size and rho[i + 1] > rho[i]:        # the top of that peak
        i += 1
    return float((i + 8) / fs)


def _sweep_trend(x: np.ndarray, fs: float, segments: int = 24) -> tuple[float, float]:
    """(Spearman rank correlation of the segments' dominant log-frequency with time, decades spanned)."""
    n = x.size
    m = n // segments
    if m < 16:
        return 0.0, 0.0
    w = np.hanning(m)
    f = np.fft.rfftfreq(m, 1.0 / fs)[1:]
    cents = []
    for k in range(segments):
        seg = x[k * m:(k + 1) * m]
        P = np.abs(np.fft.rfft((seg - seg.mean()) * w))[1:] ** 2
        if P.sum() <= 0:
            continue
        cents.append(float(np.sum(P * np.log10(f)) / P.sum()))
    if len(cents) < 6:
        return 0.0, 0.0
    c = np.asarray(cents)
    r = stats.spearmanr(np.arange(c.size), c)[0]
    return (float(r) if np.isfinite(r) else 0.0), float(np.ptp(c))
