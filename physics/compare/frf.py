"""Frequency-response estimation settings, sensor dynamics, bands and FRF error measures."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from ..analysis import metrics
from ..errors import InputError
from ..analysis.frf_estimation import (FRFEstimate, detect_excitation, estimate_frf, leading_transient, noise_level,
                                       power_blocks)
from ..io.timeseries import TimeSeries


#: Excitation kinds of a record's metadata that :meth:`FRFOptions.settings_for` understands.
_KNOWN_KINDS = ("sweep", "multisine", "noise", "tone", "square", "steps")
#: Transient excitations (one event from rest): the whole record is one average.
_TRANSIENT_KINDS = ("sweep", "multisine", "square", "steps")


@dataclass
class FRFOptions:
    """How a time record's frequency response is estimated.

    ``method="auto"`` chooses from the record's excitation (``meta["signal"]``, written by
    ``eap simulate``): a multisine of ≥ 2 periods → one period per segment, boxcar window,
    no overlap (leakage-free H1 over the periods); a single sweep or a single multisine
    period → the whole record, boxcar (one average: the coherence is then 1 by
    construction and carries no information); square pulses and steps → the whole record
    too (a transient from rest); noise and tones → Welch with Hann windows of ``nperseg``
    samples (default n/8), 50 % overlap.  Without metadata (a lab's export) the excitation
    is read from the voltage (:func:`physics.analysis.frf_estimation.detect_excitation`).  ``nperseg``,
    ``window``, ``overlap`` override the choice.  ``band`` [Hz] keeps (f_lo, f_hi); by
    default the excitation's band from the metadata, if any.  ``max_points`` thins the
    estimate to about that many log-spaced frequencies (nearest lines; 0 keeps all): a
    balanced weight per decade and a bounded cost."""

    method: str = "auto"
    nperseg: int | None = None
    window: str | None = None
    overlap: float | None = None
    band: tuple[float, float] | None = None
    max_points: int = 400
    min_input_power: float = 1e-3

    def settings_for(self, ts: TimeSeries) -> dict:
        """Keyword arguments for :func:`estimate_frf` for record ``ts``.  With ``method="auto"``
        and no excitation in the record's metadata (a lab's export) the excitation is read
        from the voltage itself (:func:`physics.analysis.frf_estimation.detect_excitation`) and the
        choice says so (key ``_how``)."""
        n = ts.n
        sig = ts.meta.get("signal") if isinstance(ts.meta.get("signal"), dict) else {}
        if self.method not in ("auto", "welch", "periodic", "whole"):
            raise InputError(f"FRF method {self.method!r}: expected auto, welch, periodic or whole")
        kind = str(sig.get("kind", "")) if self.method == "auto" else ""
        periods = int(sig.get("periods", 1)) if kind == "multisine" else 1
        period = sig.get("period_s")
        how = f"{self.method} (as asked)" if self.method != "auto" else f"auto: the metadata say {kind}"
        if self.method == "auto" and kind not in _KNOWN_KINDS:
            ex = detect_excitation(ts.voltage, ts.fs, ts.source)
            kind = {"periodic": "multisine", "steps": "square"}.get(ex.kind, ex.kind)
            if ex.kind == "periodic":
                period, periods = ex.period_s, int(round(n / ts.fs / ex.period_s))
            how = f"auto: no excitation in the metadata; from the voltage: {ex.how}"
        kw: dict = {}
        chosen = self.method
        if self.method == "periodic" or (kind == "multisine" and periods >= 2):
            if period is None and self.nperseg is None:
                raise InputError(f"{ts.source or 'record'}: periodic FRF estimation needs the period "
                                 "(meta signal.period_s) or an explicit nperseg")
            nper = self.nperseg or int(round(float(period) * ts.fs))
            kw = dict(nperseg=nper, window="boxcar", overlap=0.0)
            chosen = "periodic"
            skip = leading_transient(ts.voltage, ts.deflection, ts.fs, nper / ts.fs)
            if skip:
                kw["_skip"] = skip
                how += (f"; the first {skip / ts.fs:.3g} s are not yet periodic (a lead-in or the response settling "
                        "from rest): estimated from the periods after them")
        elif self.method == "whole" or kind in _TRANSIENT_KINDS:
            kw = dict(nperseg=n, window="boxcar", overlap=0.0)
            chosen = "whole"
        else:
            kw = dict(nperseg=self.nperseg or max(n // 8, 16), window="hann", overlap=0.5)
            chosen = "welch"
        if self.nperseg is not None:
            kw["nperseg"] = int(self.nperseg)
        if self.window is not None:
            kw["window"] = self.window
        if self.overlap is not None:
            kw["overlap"] = float(self.overlap)
        kw["nperseg"] = min(int(kw["nperseg"]), n)
        band = self.band
        if band is None and "f_start_Hz" in sig and "f_stop_Hz" in sig:
            band = (float(sig["f_start_Hz"]), float(sig["f_stop_Hz"]))
        if band is not None:
            kw["band"] = (float(band[0]), float(band[1]))
        kw["min_input_power"] = self.min_input_power
        kw["_method"] = chosen
        kw["_how"] = how
        return kw


def estimate_record_frf(ts: TimeSeries, y: np.ndarray, options: FRFOptions, *,
                        settings: dict | None = None) -> tuple[FRFEstimate, dict]:
    """H1 estimate from the record's voltage to ``y`` (its deflection or a model output)."""
    kw = dict(settings or options.settings_for(ts))
    method = kw.pop("_method", "custom")
    how = kw.pop("_how", "")
    skip = int(kw.pop("_skip", 0))
    u, y = ts.voltage[skip:], np.asarray(y)[skip:]
    kw["nperseg"] = min(int(kw["nperseg"]), u.size)
    if kw["nperseg"] >= u.size:     # one average: the coherence from the output's noise level
        level = noise_level(y, ts.fs)[0]
        if np.isfinite(level):
            kw["noise_psd"] = level
    try:
        est = estimate_frf(u, y, ts.fs, **kw)
    except InputError as exc:
        raise InputError(f"{ts.source or 'record'}: FRF estimation failed: {exc}") from None
    return est, {"method": method, "chosen": how, "coherence": est.meta.get("coherence"),
                 **({"skipped_s": skip / ts.fs} if skip else {}),
                 **{k: v for k, v in kw.items() if k not in ("min_input_power", "noise_psd")}}


def thin_log(freq: np.ndarray, max_points: int) -> np.ndarray:
    """Indices of about ``max_points`` frequencies spread evenly in log-frequency (the
    nearest line to each of ``max_points`` log-spaced targets, duplicates removed)."""
    n = freq.size
    if max_points <= 0 or n <= max_points:
        return np.arange(n)
    lf = np.log(freq)
    targets = np.linspace(lf[0], lf[-1], max_points)
    right = np.clip(np.searchsorted(lf, targets), 0, n - 1)
    left = np.clip(right - 1, 0, n - 1)
    nearer = np.where(np.abs(lf[left] - targets) <= np.abs(lf[right] - targets), left, right)
    return np.unique(nearer)


def valid_points(est: FRFEstimate, min_coherence: float) -> np.ndarray:
    """Mask of excited, positive frequencies whose coherence reaches ``min_coherence``."""
    ok = est.excited & (est.freq > 0) & np.isfinite(est.response)
    if est.coherence is not None and min_coherence > 0:
        ok &= est.coherence >= min_coherence
    return ok


# ============================================================================ sensor


def sensor_bandwidth_of(m, setting) -> float | None:
    """The sensor low-pass cut-off [Hz] to apply for measurement ``m``: ``setting`` if a
    number, the record's ``meta["sensor"]["bandwidth"]`` if ``"auto"``, else ``None``."""
    if setting is None or setting == "none":
        return None
    if setting == "auto":
        sensor = m.meta.get("sensor") if isinstance(getattr(m, "meta", None), dict) else None
        bw = sensor.get("bandwidth") if isinstance(sensor, dict) else None
        return float(bw) if isinstance(bw, (int, float)) and bw > 0 else None
    try:
        bw = float(setting)
    except (TypeError, ValueError):
        raise InputError(f"sensor bandwidth {setting!r}: expected a frequency in Hz, 'auto' or 'none'") from None
    if not (math.isfinite(bw) and bw > 0):
        raise InputError(f"sensor bandwidth {setting!r} Hz must be positive")
    return bw


def sensor_response(freq, bandwidth: float | None) -> np.ndarray:
    """First-order sensor response 1/(1 + j f/f_c) (1 when ``bandwidth`` is None)."""
    f = np.asarray(freq, dtype=float)
    if bandwidth is None:
        return np.ones(f.shape, dtype=complex)
    return 1.0 / (1.0 + 1j * f / bandwidth)


def sensor_lowpass(y: np.ndarray, fs: float, bandwidth: float | None) -> np.ndarray:
    """The same first-order low-pass in time (bilinear, started in steady state), as
    :class:`physics.io.sensor.SensorModel` applies it."""
    if bandwidth is None:
        return y
    b, a = sps.bilinear([1.0], [1.0 / (2 * np.pi * bandwidth), 1.0], fs)
    out, _ = sps.lfilter(b, a, y, zi=sps.lfilter_zi(b, a) * y[0])
    return out


# ============================================================================ comparison


def default_bands(f_lo: float, f_hi: float) -> list[tuple[float, float]]:
    """Decade bands covering [f_lo, f_hi] Hz (edges at powers of ten)."""
    if not (0 < f_lo < f_hi):
        raise InputError(f"frequency bands need 0 < f_lo < f_hi, got {f_lo:g}, {f_hi:g} Hz")
    edges = [f_lo] + [10.0 ** k for k in range(int(math.floor(math.log10(f_lo))) + 1,
                                               int(math.ceil(math.log10(f_hi))))
                      if f_lo < 10.0 ** k < f_hi] + [f_hi]
    return list(zip(edges[:-1], edges[1:]))


def parse_bands(text: str) -> list[tuple[float, float]]:
    """``"0.1,1,10,50"`` (band edges in Hz) → [(0.1, 1), (1, 10), (10, 50)]."""
    try:
        edges = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"bands {text!r}: expected comma-separated band edges in Hz, e.g. 0.1,1,10,50") from None
    if len(edges) < 2 or any(e <= 0 for e in edges) or np.any(np.diff(edges) <= 0):
        raise InputError(f"bands {text!r}: need at least two positive, increasing edges in Hz")
    return list(zip(edges[:-1], edges[1:]))


def frf_errors(freq, H_meas, H_model, mask=None) -> dict:
    """FRF error measures on the points ``mask``: J_err (eq. 13) [m/V], RMS log-magnitude
    error [dB], RMS phase error [deg] (wrapped difference), number of points."""
    m = np.ones(np.shape(freq), bool) if mask is None else np.asarray(mask, bool)
    if not m.any():
        return {"n_points": 0, "j_err_m_per_V": None, "log_mag_rms_dB": None, "phase_rms_deg": None}
    ratio = H_model[m] / H_meas[m]
    return {"n_points": int(m.sum()),
            "j_err_m_per_V": metrics.j_err(np.abs(H_meas[m]), np.abs(H_model[m])),
            "log_mag_rms_dB": float(np.sqrt(np.mean((20 * np.log10(np.abs(ratio))) ** 2))),
            "phase_rms_deg": float(np.sqrt(np.mean(np.degrees(np.angle(ratio)) ** 2)))}


def residual_by_band(e, y: np.ndarray, fs: float, bands) -> list[dict]:
    """RMS of the residual ``e`` [m] within each band and its ratio to the RMS of the
    (offset-free) measurement ``y`` in that band (one-sided spectra, Parseval).

    ``e`` is an array like ``y``, or a function ``e(r, m)`` giving its samples r, r + m, …
    (``e[r::m]``), so that a long residual is never formed whole.  Each spectrum is
    reduced to its band sums as it is assembled (:func:`~physics.analysis.frf_estimation.power_blocks`):
    a long record costs half a spectrum, not the spectrum and its squares."""
    n = y.size
    part = e if callable(e) else (lambda r, m: e[r::m])
    if not callable(e) and e.size != n:
        raise InputError(f"residual has {e.size} samples but the measurement {n}")
    f = np.fft.rfftfreq(n, 1.0 / fs)
    ranges = [(int(np.searchsorted(f, lo, "left")),
               int(np.searchsorted(f, hi, "right" if hi == bands[-1][1] else "left"))) for lo, hi in bands]
    del f
    last = n // 2 if n % 2 == 0 else -1             # the Nyquist line, counted once like DC

    def band_power(x_part, offset_free: bool = False):   # Σ w |X|² per band (w = 2 but DC, Nyquist)
        sums = [0.0] * len(ranges)
        for k0, p in power_blocks(x_part, n, zero_dc=offset_free):   # the mean removed: only DC changes
            k1 = k0 + p.size
            p *= 2.0
            if k0 == 0:
                p[0] /= 2.0
            if k0 <= last < k1:
                p[last - k0] /= 2.0
            for i, (a, b) in enumerate(ranges):
                if a < k1 and b > k0:
                    sums[i] += float(np.sum(p[max(a, k0) - k0:min(b, k1) - k0]))
        return sums

    ce, cy = band_power(part), band_power(lambda r, m: y[r::m], offset_free=True)
    out = []
    for (lo, hi), se, sy in zip(bands, ce, cy):
        pe, py = se / n ** 2, sy / n ** 2
        out.append({"band_Hz": [lo, hi], "residual_rms_m": math.sqrt(max(pe, 0.0)),
                    "nrmse_in_band": math.sqrt(pe / py) if py > 0 else None})
    return out
