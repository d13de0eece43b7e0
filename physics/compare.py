"""Model against measurement: time overlays, frequency responses, metrics and a report.

**One contract for every model.**  A *predictor* answers "what tip deflection [m] does
this voltage record [V], sampled at ``fs`` [Hz] at relative humidity ``rh`` [%] (a
constant or one value per sample), produce?"::

    y = predictor(voltage, rh, fs)

:class:`PhysicsPredictor` wraps an :class:`~physics.model.ActuatorModel` (and also offers
its closed-form small-signal frequency response); :class:`CallablePredictor` wraps any
function with that signature — the command line uses it for trained neural-model bundles
(``nnmodel.load(path).predict``), so that :mod:`physics` never imports :mod:`nnmodel`.
A predictor without a closed-form response is compared in frequency through the same
H1 estimate applied to its simulated output.

**What :func:`compare` computes** for each time-series record (``DATA_FORMAT.md``):

* the model's output for the measured voltage and RH; time metrics of
  :mod:`physics.metrics` — RMSE [m], NRMSE, fit % = 100 (1 − ‖y − ŷ‖/‖y − ȳ‖) (MATLAB
  ``compare``), Pearson correlation (the thesis reports 98 % for the IP2C at 0.2 Hz) —
  after removing the best constant offset (a laser sensor's zero is arbitrary;
  ``offset="none"`` keeps it) and an optional start-up interval ``skip_s``;
* the H1 frequency-response estimate of the measurement and, with the same estimator,
  of the model output (:func:`physics.frf_estimation.estimate_frf`; settings chosen from
  the record's excitation, see :class:`FRFOptions`), plus the model's closed form;
* the thesis identification cost J_err of eq. 13 (De Luca 2014),
  sqrt(Σ_i (|δ_exp(f_i)| − |δ_sim(f_i)|)²/N) [m/V], on the excited frequencies whose
  coherence reaches ``min_coherence``, with |δ_sim| the closed form when the model has
  one (as in the thesis, where COMSOL solved each frequency) and otherwise the estimate
  from the simulated output; the log-magnitude [dB] and phase [deg] RMS errors;
* errors by frequency band: the residual's RMS and its NRMSE within the band (from the
  spectrum of the residual, Parseval) and the FRF errors within the band;
* errors by RH: records grouped by their mean RH (within ``rh_tolerance`` %).

Frequency-response files (``freq_Hz, mag_m_per_V, phase_deg``…) are compared with the
closed form of a physics predictor at the file's RH.

RH given to the model: a record's RH channel is noisy; when it spans at most
``rh_tolerance`` % the model gets its median (robust to a sensor clipped at 100 %),
otherwise a 10-s moving mean rounded to 0.5 % (:func:`model_rh`).

Known sensor dynamics are part of the measurement, not of the actuator: with
``sensor_bandwidth="auto"`` a first-order sensor low-pass recorded in a record's
metadata (``meta["sensor"]["bandwidth"]``, written by :class:`physics.sensor.SensorModel`)
is applied to the model output before comparing; give a number [Hz] or ``None``.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np
from scipy import signal as sps

from . import metrics
from .errors import InputError
from .frf_estimation import FRFEstimate, estimate_frf
from .frfdata import FRFData, read_frf
from .model import ActuatorModel
from .timeseries import TimeSeries, read_timeseries

# ============================================================================ predictors


class Predictor:
    """Interface shared by physics and neural models (see the module doc).

    Subclasses implement :meth:`__call__`; those with a closed-form small-signal response
    also implement :meth:`frequency_response`.  ``name`` labels plots and reports,
    :meth:`describe` returns JSON-ready information (device, effects, card...)."""

    name: str = "model"

    def __call__(self, voltage: np.ndarray, rh, fs: float) -> np.ndarray:
        """Tip deflection [m] for ``voltage`` [V] sampled at ``fs`` [Hz] from t = 0, at
        ``rh`` [%] (constant or per sample)."""
        raise NotImplementedError

    def frequency_response(self, freq: np.ndarray, rh: float) -> np.ndarray | None:
        """Closed-form deflection per volt [m/V] at ``freq`` [Hz], or ``None``."""
        return None

    @property
    def has_closed_form(self) -> bool:
        return type(self).frequency_response is not Predictor.frequency_response

    def describe(self) -> dict:
        return {"name": self.name, "kind": type(self).__name__}


class PhysicsPredictor(Predictor):
    """A physics model (device + effects): :func:`physics.timedomain.simulate` in time
    (``hold``: input interpolation, ``cubic`` for smooth records, ``linear`` for steps),
    :func:`physics.frequency.frequency_response` in frequency."""

    def __init__(self, model: ActuatorModel, hold: str = "cubic"):
        if not isinstance(model, ActuatorModel):
            raise InputError(f"PhysicsPredictor needs an ActuatorModel, got {type(model).__name__}")
        if hold not in ("cubic", "linear"):
            raise InputError(f"hold must be 'cubic' or 'linear', got {hold!r}")
        self.model = model
        self.hold = hold
        self.name = f"{model.device.name} [{', '.join(model.effect_ids)}]"

    @classmethod
    def from_device(cls, device, effects=None, *, n_modes: int = 4, hold: str = "cubic") -> "PhysicsPredictor":
        return cls(ActuatorModel(device, effects, n_modes=n_modes), hold=hold)

    def __call__(self, voltage, rh, fs):
        from .timedomain import simulate
        v = np.asarray(voltage, dtype=float)
        t = np.arange(v.size) / float(fs)
        return simulate(self.model, None, t, v, rh=rh, hold=self.hold).deflection

    def frequency_response(self, freq, rh):
        from .frequency import frequency_response
        return frequency_response(self.model, None, np.asarray(freq, dtype=float), rh=rh).deflection

    def describe(self) -> dict:
        d = self.model.device
        return {"name": self.name, "kind": "physics", "device": d.name, "device_file": d.path,
                "effects": list(self.model.effect_ids), "n_modes": self.model.n_modes, "hold": self.hold}


class CallablePredictor(Predictor):
    """Any function ``fn(voltage [V], rh [%], fs [Hz]) -> deflection [m]`` (e.g. a neural
    model bundle's ``predict``); ``info`` is reported as is."""

    def __init__(self, fn: Callable[[np.ndarray, Any, float], np.ndarray], name: str = "model",
                 info: dict | None = None):
        if not callable(fn):
            raise InputError(f"CallablePredictor needs a callable, got {type(fn).__name__}")
        self.fn, self.name, self.info = fn, str(name), dict(info or {})

    def __call__(self, voltage, rh, fs):
        return self.fn(voltage, rh, fs)

    def describe(self) -> dict:
        return {"name": self.name, "kind": "callable", **self.info}


def _check_output(y, n: int, who: str) -> np.ndarray:
    arr = np.asarray(y, dtype=float).reshape(-1) if y is not None else None
    if arr is None or arr.size != n:
        raise InputError(f"model {who} returned {None if arr is None else arr.size} samples for an "
                         f"input of {n}; a predictor must return one deflection [m] per voltage sample")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"model {who} returned NaN or infinite deflections")
    return arr


# ============================================================================ measurement input


def is_frf_file(path) -> bool:
    """True when a CSV's header has a ``freq_Hz`` column (a frequency-response file)."""
    p = Path(path)
    if p.suffix.lower() != ".csv" or not p.is_file():
        return False
    with open(p, encoding="utf-8-sig") as fh:
        header = fh.readline()
    return "freq_hz" in [h.strip().lower() for h in header.split(",")]


def load_measurements(items: Iterable, *, rh: float | None = None, columns: dict | None = None,
                      fs: float | None = None, resample: bool = False) -> list[TimeSeries | FRFData]:
    """Measurements from paths (time-series ``.csv``/``.mat`` or FRF ``.csv``, told apart by
    the ``freq_Hz`` column) or ready :class:`TimeSeries`/:class:`FRFData` objects.

    ``rh`` [%] for records without RH; ``columns``/``fs`` as in
    :func:`physics.timeseries.read_timeseries` (time series only)."""
    out: list[TimeSeries | FRFData] = []
    for item in items:
        if isinstance(item, (TimeSeries, FRFData)):
            out.append(item)
            continue
        if not isinstance(item, (str, Path)):
            raise InputError(f"measurement {item!r}: expected a file path, a TimeSeries or an FRFData")
        if is_frf_file(item):
            frf = read_frf(item)
            if frf.rh is None and rh is not None:
                frf = replace(frf, rh=float(rh))
            out.append(frf)
        else:
            out.append(read_timeseries(item, columns=columns, fs=fs, rh=rh, resample=resample))
    if not out:
        raise InputError("no measurement given: pass at least one time-series or FRF file")
    return out


def source_name(m, k: int) -> str:
    """The file a measurement came from, or ``record k`` for one built in memory."""
    return str(m.source) if getattr(m, "source", None) else f"record {k}"


def mean_rh(m, where: str) -> float:
    """Mean RH [%] of a record (an FRF without RH is an error naming it)."""
    rh = m.rh
    if rh is None:
        raise InputError(f"{where}: no relative humidity; add an rh_pct column or give the RH explicitly")
    return float(np.mean(rh))


def cluster_rh(values: Sequence[float], tolerance: float = 2.5) -> list[float]:
    """Group RH values [%] into levels: sorted values closer than ``tolerance`` [%] to the
    previous one join its group; each level is its group's mean (rounded to 0.1 %).
    Returns the level of each input value."""
    vals = np.asarray(values, dtype=float)
    order = np.argsort(vals)
    groups: list[list[int]] = []
    for i in order:
        if groups and vals[i] - vals[groups[-1][-1]] <= tolerance:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    level = np.empty(vals.size)
    for g in groups:
        level[g] = round(float(np.mean(vals[g])), 1)
    return level.tolist()


# ============================================================================ FRF estimation settings


@dataclass
class FRFOptions:
    """How a time record's frequency response is estimated.

    ``method="auto"`` chooses from the record's excitation (``meta["signal"]``, written by
    ``eap simulate``): a multisine of ≥ 2 periods → one period per segment, boxcar window,
    no overlap (leakage-free H1 over the periods); a single sweep or a single multisine
    period → the whole record, boxcar (one average: the coherence is then 1 by
    construction and carries no information); anything else (noise, lab records) → Welch
    with Hann windows of ``nperseg`` samples (default n/8), 50 % overlap.  ``nperseg``,
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
        """Keyword arguments for :func:`estimate_frf` for record ``ts``."""
        n = ts.n
        sig = ts.meta.get("signal") if isinstance(ts.meta.get("signal"), dict) else {}
        kind = str(sig.get("kind", "")) if self.method == "auto" else ""
        if self.method not in ("auto", "welch", "periodic", "whole"):
            raise InputError(f"FRF method {self.method!r}: expected auto, welch, periodic or whole")
        kw: dict = {}
        chosen = self.method
        if self.method == "periodic" or (kind == "multisine" and int(sig.get("periods", 1)) >= 2):
            period = sig.get("period_s")
            if period is None and self.nperseg is None:
                raise InputError(f"{ts.source or 'record'}: periodic FRF estimation needs the period "
                                 "(meta signal.period_s) or an explicit nperseg")
            nper = self.nperseg or int(round(float(period) * ts.fs))
            kw = dict(nperseg=nper, window="boxcar", overlap=0.0)
            chosen = "periodic"
        elif self.method == "whole" or kind in ("sweep", "multisine"):
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
        return kw


def estimate_record_frf(ts: TimeSeries, y: np.ndarray, options: FRFOptions, *,
                        settings: dict | None = None) -> tuple[FRFEstimate, dict]:
    """H1 estimate from the record's voltage to ``y`` (its deflection or a model output)."""
    kw = dict(settings or options.settings_for(ts))
    method = kw.pop("_method", "custom")
    try:
        est = estimate_frf(ts.voltage, y, ts.fs, **kw)
    except InputError as exc:
        raise InputError(f"{ts.source or 'record'}: FRF estimation failed: {exc}") from None
    return est, {"method": method, **{k: v for k, v in kw.items() if k != "min_input_power"}}


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
    :class:`physics.sensor.SensorModel` applies it."""
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


def residual_by_band(e: np.ndarray, y: np.ndarray, fs: float, bands) -> list[dict]:
    """RMS of the residual ``e`` [m] within each band and its ratio to the RMS of the
    (offset-free) measurement ``y`` in that band (one-sided spectra, Parseval)."""
    n = e.size
    f = np.fft.rfftfreq(n, 1.0 / fs)
    E, Y = np.fft.rfft(e), np.fft.rfft(y - y.mean())
    w = np.full(f.size, 2.0)
    w[0] = 1.0
    if n % 2 == 0:
        w[-1] = 1.0
    out = []
    for lo, hi in bands:
        m = (f >= lo) & (f < hi) if hi != bands[-1][1] else (f >= lo) & (f <= hi)
        pe = float(np.sum(w[m] * np.abs(E[m]) ** 2)) / n ** 2
        py = float(np.sum(w[m] * np.abs(Y[m]) ** 2)) / n ** 2
        out.append({"band_Hz": [lo, hi], "residual_rms_m": math.sqrt(pe),
                    "nrmse_in_band": math.sqrt(pe / py) if py > 0 else None})
    return out


@dataclass
class RecordComparison:
    """Result for one measurement (see :func:`compare`); arrays in SI units."""

    source: str
    kind: str                          # "timeseries" or "frf"
    rh: float
    time: np.ndarray | None = None
    measured: np.ndarray | None = None     # offset-aligned measurement [m]
    predicted: np.ndarray | None = None    # model output [m]
    freq: np.ndarray | None = None
    H_meas: np.ndarray | None = None
    H_model_est: np.ndarray | None = None
    H_model_closed: np.ndarray | None = None
    coherence: np.ndarray | None = None
    mag_bounds: tuple[np.ndarray, np.ndarray] | None = None
    valid: np.ndarray | None = None
    summary: dict = field(default_factory=dict)

    @property
    def H_model(self) -> np.ndarray | None:
        """The model response used for the FRF errors (closed form when available)."""
        return self.H_model_closed if self.H_model_closed is not None else self.H_model_est


@dataclass
class ComparisonResult:
    predictor: dict
    records: list[RecordComparison]
    by_rh: list[dict]
    overall: dict
    settings: dict
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"model": self.predictor, "settings": self.settings, "overall": self.overall,
                "records": [dict(source=r.source, kind=r.kind, rh_pct=r.rh, **r.summary) for r in self.records],
                "by_rh": self.by_rh, "warnings": self.warnings}


def compare(measurements: Sequence, predictor: Predictor, *, frf_options: FRFOptions | None = None,
            offset: str = "mean", skip_s: float = 0.0, min_coherence: float = 0.0,
            bands: Sequence[tuple[float, float]] | None = None, rh_tolerance: float = 2.5,
            sensor_bandwidth="auto") -> ComparisonResult:
    """Compare ``predictor`` with measurements (loaded :class:`TimeSeries` /
    :class:`FRFData`, see :func:`load_measurements`); see the module doc for the metrics.

    ``offset``: ``"mean"`` removes the best constant offset between measurement and model
    (default), ``"none"`` keeps it; ``skip_s`` [s] excludes a start-up interval from the
    time metrics; ``min_coherence`` (γ²) excludes poorly measured frequencies from the FRF
    errors; ``bands`` [(f_lo, f_hi), ...] Hz (default: decades over the compared range)."""
    if not isinstance(predictor, Predictor):
        raise InputError(f"compare needs a Predictor (PhysicsPredictor or CallablePredictor), "
                         f"got {type(predictor).__name__}")
    if offset not in ("mean", "none"):
        raise InputError(f"offset {offset!r}: expected 'mean' or 'none'")
    if not (skip_s >= 0 and math.isfinite(skip_s)):
        raise InputError(f"skip_s={skip_s!r} must be a non-negative number of seconds")
    if not 0 <= min_coherence <= 1:
        raise InputError(f"min_coherence={min_coherence!r} must lie within 0–1")
    opts = frf_options or FRFOptions()
    ms = list(measurements)
    if not ms:
        raise InputError("no measurement to compare with")
    warnings_: list[str] = []
    recs: list[RecordComparison] = []
    for k, m in enumerate(ms):
        where = source_name(m, k)
        if isinstance(m, TimeSeries):
            recs.append(_compare_record(m, where, predictor, opts, offset, skip_s, min_coherence,
                                        sensor_bandwidth, rh_tolerance))
        elif isinstance(m, FRFData):
            if not predictor.has_closed_form:
                warnings_.append(f"{where}: a frequency-response file needs a model with a closed-form "
                                 f"response; {predictor.name} has none, so this file was skipped")
                continue
            recs.append(_compare_frf(m, where, predictor, min_coherence, sensor_bandwidth))
        else:
            raise InputError(f"{where}: expected a TimeSeries or FRFData, got {type(m).__name__}")
    if not recs:
        raise InputError("nothing could be compared (see the warnings: " + "; ".join(warnings_) + ")")
    # bands
    if bands is None:
        fmin = min(float(r.freq[r.valid].min()) for r in recs if r.valid is not None and r.valid.any()) \
            if any(r.valid is not None and r.valid.any() for r in recs) else None
        fmax = max(float(r.freq[r.valid].max()) for r in recs if r.valid is not None and r.valid.any()) \
            if fmin is not None else None
        bands = default_bands(fmin, fmax) if fmin is not None and fmax > fmin else []
    bands = [(float(a), float(b)) for a, b in bands]
    for r in recs:
        _band_errors(r, bands)
    levels = cluster_rh([r.rh for r in recs], rh_tolerance)
    by_rh = _by_rh(recs, levels)
    overall = _overall(recs)
    settings = {"offset": offset, "skip_s": skip_s, "min_coherence": min_coherence,
                "bands_Hz": [list(b) for b in bands], "rh_tolerance_pct": rh_tolerance,
                "sensor_bandwidth": sensor_bandwidth, "frf": vars(opts).copy()}
    return ComparisonResult(predictor.describe(), recs, by_rh, overall, settings, warnings_)


def model_rh(rh: np.ndarray, fs: float, tolerance: float = 2.5, window_s: float = 10.0,
             step: float = 0.5):
    """The RH [%] given to a model for a record's RH channel.

    A humidity sensor's noise is not a humidity change, and a time solver would restart
    its mechanics at every new RH value: when the record's RH spans no more than
    ``tolerance`` [%] its median is used (robust to a sensor clipped at 100 %); otherwise a moving mean over ``window_s`` [s],
    rounded to ``step`` [%] (RH changes slowly compared with the mechanics)."""
    rh = np.asarray(rh, dtype=float)
    if np.ptp(rh) <= tolerance:
        return float(np.median(rh))
    k = max(1, int(round(window_s * fs)))
    kernel = np.ones(min(k, rh.size)) / min(k, rh.size)
    pad = kernel.size // 2
    smooth = np.convolve(np.pad(rh, (pad, kernel.size - 1 - pad), mode="edge"), kernel, mode="valid")
    return np.clip(np.round(smooth / step) * step, 0.0, 100.0)


def _compare_record(ts: TimeSeries, where, predictor, opts, offset, skip_s, min_coh, sb_setting,
                    rh_tolerance):
    if ts.deflection is None:
        raise InputError(f"{where}: has no deflection column; a measurement needs deflection_m")
    rh = ts.rh if ts.rh is not None else None
    if rh is None:
        raise InputError(f"{where}: no relative humidity (rh_pct); give the RH explicitly")
    rh_arg = model_rh(rh, ts.fs, rh_tolerance)
    yhat = _check_output(predictor(ts.voltage, rh_arg, ts.fs), ts.n, predictor.name)
    bw = sensor_bandwidth_of(ts, sb_setting)
    yhat = sensor_lowpass(yhat, ts.fs, bw)
    y = ts.deflection
    i0 = int(math.ceil(skip_s * ts.fs))
    if ts.n - i0 < 3:
        raise InputError(f"{where}: skip_s={skip_s:g} s leaves fewer than 3 samples")
    e_raw = y - yhat
    c = float(np.mean(e_raw[i0:])) if offset == "mean" else 0.0
    y_al = y - c
    tm = metrics.summary(y_al[i0:], yhat[i0:])
    tm["offset_removed_m"] = c
    tm["skip_s"] = skip_s
    # frequency domain
    settings = opts.settings_for(ts)
    est_m, info = estimate_record_frf(ts, y, opts, settings=settings)
    est_p, _ = estimate_record_frf(ts, yhat, opts, settings=settings)
    valid = valid_points(est_m, min_coh)
    sel = np.zeros_like(valid)
    idx = np.flatnonzero(valid)
    if idx.size:
        sel[idx[thin_log(est_m.freq[idx], opts.max_points)]] = True
    f = est_m.freq
    Hc = None
    mean = float(np.median(rh))
    if predictor.has_closed_form:
        Hc = np.full(f.shape, np.nan, dtype=complex)
        pos = f > 0
        Hc[pos] = predictor.frequency_response(f[pos], mean) * sensor_response(f[pos], bw)
    rec = RecordComparison(where, "timeseries", mean, time=ts.time - ts.time[0], measured=y_al,
                           predicted=yhat, freq=f, H_meas=est_m.response, H_model_est=est_p.response,
                           H_model_closed=Hc, coherence=est_m.coherence, mag_bounds=est_m.mag_bounds,
                           valid=sel)
    fe = frf_errors(f, est_m.response, rec.H_model, sel)
    fe_est = frf_errors(f, est_m.response, est_p.response, sel)
    fe["j_err_estimated_m_per_V"] = fe_est["j_err_m_per_V"]
    fe["j_err_reference"] = "closed form" if Hc is not None else "H1 estimate of the simulated output"
    fe["mean_coherence"] = float(np.mean(est_m.coherence[sel])) if sel.any() else None
    fe["estimator"] = info
    rec.summary = {"n_samples": ts.n, "fs_Hz": ts.fs, "duration_s": ts.duration,
                   "sensor_bandwidth_Hz": bw, "time_metrics": tm, "frf_metrics": fe}
    return rec


def _compare_frf(frf: FRFData, where, predictor, min_coh, sb_setting):
    if frf.rh is None:
        raise InputError(f"{where}: the FRF file has no rh_pct column; give the RH explicitly")
    rh = float(np.mean(frf.rh))
    bw = sensor_bandwidth_of(frf, sb_setting)
    Hc = predictor.frequency_response(frf.freq, rh) * sensor_response(frf.freq, bw)
    valid = np.ones(frf.freq.shape, bool)
    if frf.coherence is not None and min_coh > 0:
        valid &= frf.coherence >= min_coh
    rec = RecordComparison(where, "frf", rh, freq=frf.freq, H_meas=frf.response, H_model_closed=Hc,
                           coherence=frf.coherence, valid=valid)
    fe = frf_errors(frf.freq, frf.response, Hc, valid)
    fe["j_err_reference"] = "closed form"
    fe["mean_coherence"] = float(np.mean(frf.coherence[valid])) if frf.coherence is not None and valid.any() else None
    rec.summary = {"n_frequencies": int(frf.freq.size), "sensor_bandwidth_Hz": bw, "frf_metrics": fe}
    return rec


def _band_errors(r: RecordComparison, bands):
    rows = []
    if r.kind == "timeseries":
        fs = r.summary["fs_Hz"]
        e = r.measured - r.predicted
        i0 = int(math.ceil(r.summary["time_metrics"]["skip_s"] * fs))
        tb = residual_by_band(e[i0:], r.measured[i0:], fs, bands)
    else:
        tb = [{} for _ in bands]
    for k, ((lo, hi), t) in enumerate(zip(bands, tb)):
        upper = (r.freq <= hi) if k == len(bands) - 1 else (r.freq < hi)   # each point in one band
        m = r.valid & (r.freq >= lo) & upper
        row = {"band_Hz": [lo, hi], **{k: v for k, v in t.items() if k != "band_Hz"}}
        row.update(frf_errors(r.freq, r.H_meas, r.H_model, m))
        rows.append(row)
    r.summary["bands"] = rows


def _by_rh(recs, levels) -> list[dict]:
    out = []
    for lv in sorted(set(levels)):
        group = [r for r, l in zip(recs, levels) if l == lv]
        ts = [r for r in group if r.kind == "timeseries"]
        jes = [r.summary["frf_metrics"]["j_err_m_per_V"] for r in group
               if r.summary["frf_metrics"]["j_err_m_per_V"] is not None]
        lm = [r.summary["frf_metrics"]["log_mag_rms_dB"] for r in group
              if r.summary["frf_metrics"]["log_mag_rms_dB"] is not None]
        row = {"rh_pct": lv, "records": len(group),
               "fit_percent": float(np.mean([r.summary["time_metrics"]["fit_percent"] for r in ts])) if ts else None,
               "nrmse": float(np.mean([r.summary["time_metrics"]["nrmse"] for r in ts])) if ts else None,
               "correlation": float(np.mean([r.summary["time_metrics"]["correlation"] for r in ts])) if ts else None,
               "j_err_m_per_V": float(np.sqrt(np.mean(np.square(jes)))) if jes else None,
               "log_mag_rms_dB": float(np.sqrt(np.mean(np.square(lm)))) if lm else None}
        out.append(row)
    return out


def _overall(recs) -> dict:
    ts = [r for r in recs if r.kind == "timeseries"]
    out: dict = {"records": len(recs)}
    if ts:
        tms = [r.summary["time_metrics"] for r in ts]
        out.update({"fit_percent_mean": float(np.mean([t["fit_percent"] for t in tms])),
                    "fit_percent_min": float(np.min([t["fit_percent"] for t in tms])),
                    "nrmse_mean": float(np.mean([t["nrmse"] for t in tms])),
                    "correlation_mean": float(np.mean([t["correlation"] for t in tms])),
                    "rmse_m_rms": float(np.sqrt(np.mean([t["rmse"] ** 2 for t in tms])))})
    # J_err over all compared frequency points of all records (eq. 13 on the union)
    a, b = [], []
    for r in recs:
        if r.valid is not None and r.valid.any() and r.H_model is not None:
            a.append(np.abs(r.H_meas[r.valid]))
            b.append(np.abs(r.H_model[r.valid]))
    if a:
        out["j_err_m_per_V"] = metrics.j_err(np.concatenate(a), np.concatenate(b))
    return out


# ============================================================================ report


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(text).stem)[:60] or "record"


def plot_time_overlay(r: RecordComparison, path, title: str = "", zoom_s: float | None = None) -> None:
    """Measured and model deflection [mm], the residual below, and a zoom on the last
    ``zoom_s`` seconds (default: 2 s or a tenth of the record, the shorter)."""
    import matplotlib.pyplot as plt
    from .plotting import save
    fig, ax = plt.subplots(3, 1, figsize=(8, 6.4), gridspec_kw={"height_ratios": [2, 1, 1.6]})
    ax[0].plot(r.time, 1e3 * r.measured, lw=0.7, label="measured")
    ax[0].plot(r.time, 1e3 * r.predicted, lw=0.7, label="model")
    ax[0].set_ylabel("deflection [mm]")
    ax[0].legend(fontsize=8, loc="upper right")
    ax[1].plot(r.time, 1e3 * (r.measured - r.predicted), lw=0.6, color="k")
    ax[1].set_ylabel("residual [mm]")
    ax[1].sharex(ax[0])
    span = float(r.time[-1] - r.time[0])
    zoom = min(2.0, 0.1 * span) if zoom_s is None else float(zoom_s)
    z = r.time >= r.time[-1] - zoom
    ax[2].plot(r.time[z], 1e3 * r.measured[z], lw=0.9, label="measured")
    ax[2].plot(r.time[z], 1e3 * r.predicted[z], lw=0.9, ls="--", label="model")
    ax[2].set_ylabel("zoom [mm]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.grid(alpha=0.3)
    tm = r.summary["time_metrics"]
    ax[0].set_title(title or f"{Path(r.source).name}: fit {tm['fit_percent']:.1f} %, "
                    f"corr {100 * tm['correlation']:.1f} %, RH {r.rh:.3g} %", fontsize=10)
    fig.tight_layout()
    save(fig, path)


def _plot_bode_record(r: RecordComparison, path):
    from .plotting import plot_bode_curves
    v = r.valid
    curves = {"measured (H1)" if r.kind == "timeseries" else "measured": (r.freq[v], r.H_meas[v], {"lw": 1.2})}
    if r.H_model_est is not None:
        curves["model (H1 of simulated output)"] = (r.freq[v], r.H_model_est[v], {"lw": 0.9, "ls": "--"})
    if r.H_model_closed is not None:
        f = r.freq[v]
        curves["model (closed form)"] = (f, r.H_model_closed[v], {"lw": 1.0})
    coh = (r.freq[v], r.coherence[v]) if r.coherence is not None else None
    bounds = (r.freq[v], r.mag_bounds[0][v], r.mag_bounds[1][v]) if r.mag_bounds is not None else None
    fe = r.summary["frf_metrics"]
    je = fe.get("j_err_m_per_V")
    title = f"{Path(r.source).name}, RH {r.rh:.3g} %" + (f": J_err {1e3 * je:.3g} mm/V" if je is not None else "")
    plot_bode_curves(curves, path, coherence=coh, bounds=bounds, title=title)


def _plot_bands(res: ComparisonResult, path):
    import matplotlib.pyplot as plt
    from .plotting import save
    bands = res.settings["bands_Hz"]
    if not bands:
        return False
    labels = [f"{a:g}–{b:g} Hz" for a, b in bands]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.4))
    width = 0.8 / max(len(res.records), 1)
    x = np.arange(len(bands))
    for i, r in enumerate(res.records):
        rows = r.summary["bands"]
        nr = [row.get("nrmse_in_band") or 0.0 for row in rows]
        lm = [row.get("log_mag_rms_dB") or 0.0 for row in rows]
        name = Path(r.source).name[:25]
        if r.kind == "timeseries":
            ax[0].bar(x + i * width, nr, width, label=name)
        ax[1].bar(x + i * width, lm, width, label=name)
    ax[0].set_ylabel("residual NRMSE in band")
    ax[1].set_ylabel("FRF log-magnitude RMS error [dB]")
    for a in ax:
        a.set_xticks(x + 0.4 - width / 2)
        a.set_xticklabels(labels, fontsize=8)
        a.grid(alpha=0.3, axis="y")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
    return True


def _plot_rh(res: ComparisonResult, path):
    import matplotlib.pyplot as plt
    from .plotting import save
    rows = res.by_rh
    rh = [r["rh_pct"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    fit = [r["fit_percent"] for r in rows]
    if any(v is not None for v in fit):
        ax[0].plot(rh, [np.nan if v is None else v for v in fit], "o-")
    ax[0].set_ylabel("fit [%]")
    je = [r["j_err_m_per_V"] for r in rows]
    ax[1].plot(rh, [np.nan if v is None else 1e3 * v for v in je], "s-", color="C1")
    ax[1].set_ylabel("J_err (eq. 13) [mm/V]")
    for a in ax:
        a.set_xlabel("RH [%]")
        a.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)


def write_comparison_report(res: ComparisonResult, out_dir, *, provenance: dict | None = None,
                            title: str = "Model vs measurement") -> dict:
    """Write ``report.json``, ``metrics.csv``, ``bands.csv``, PNGs and ``report.html`` into
    ``out_dir`` (all atomically); returns the JSON dict."""
    from .fileio import write_json
    from .report import Report, jsonable, write_csv
    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    plots: dict[str, list[str]] = {}
    for k, r in enumerate(res.records):
        slug = f"{k:02d}_{_slug(r.source)}"
        files = []
        if r.kind == "timeseries":
            plot_time_overlay(r, d / f"time_{slug}.png")
            files.append(f"time_{slug}.png")
        if r.valid is not None and r.valid.any():
            _plot_bode_record(r, d / f"bode_{slug}.png")
            files.append(f"bode_{slug}.png")
        r.summary["plots"] = files
        plots[r.source] = files
    extra = []
    if _plot_bands(res, d / "bands.png"):
        extra.append("bands.png")
    if len(res.by_rh) >= 2:
        _plot_rh(res, d / "rh.png")
        extra.append("rh.png")
    out = jsonable(res.to_dict())
    out["plots"] = extra
    if provenance:
        out["provenance"] = provenance
    write_json(d / "report.json", out)
    # tables
    rows = []
    for r in res.records:
        tm = r.summary.get("time_metrics", {})
        fe = r.summary["frf_metrics"]
        rows.append({"source": r.source, "kind": r.kind, "rh_pct": r.rh, "fit_percent": tm.get("fit_percent"),
                     "nrmse": tm.get("nrmse"), "rmse_m": tm.get("rmse"), "correlation": tm.get("correlation"),
                     "j_err_m_per_V": fe.get("j_err_m_per_V"), "log_mag_rms_dB": fe.get("log_mag_rms_dB"),
                     "phase_rms_deg": fe.get("phase_rms_deg"), "frf_points": fe.get("n_points")})
    write_csv(rows, d / "metrics.csv")
    brows = []
    for r in res.records:
        for b in r.summary["bands"]:
            brows.append({"source": r.source, "rh_pct": r.rh, "f_lo_Hz": b["band_Hz"][0], "f_hi_Hz": b["band_Hz"][1],
                          "residual_rms_m": b.get("residual_rms_m"), "nrmse_in_band": b.get("nrmse_in_band"),
                          "j_err_m_per_V": b.get("j_err_m_per_V"), "log_mag_rms_dB": b.get("log_mag_rms_dB"),
                          "phase_rms_deg": b.get("phase_rms_deg"), "frf_points": b.get("n_points")})
    if brows:
        write_csv(brows, d / "bands.csv")
    write_csv(res.by_rh, d / "by_rh.csv")
    # HTML
    rep = Report(title, subtitle=f"model: {res.predictor.get('name')}; {len(res.records)} measurement(s)")
    for w in res.warnings:
        rep.warning(w)
    rep.heading("Summary")
    rep.table(jsonable(res.overall), caption="overall (fit %, NRMSE, correlation: time records; "
                                             "J_err: eq. 13 over all compared frequencies, m/V)")
    rep.table([{k: v for k, v in row.items() if k != "source"} | {"record": Path(row["source"]).name}
               for row in rows], columns=["record", "kind", "rh_pct", "fit_percent", "nrmse", "rmse_m",
                                          "correlation", "j_err_m_per_V", "log_mag_rms_dB", "phase_rms_deg",
                                          "frf_points"], caption="metrics per measurement")
    if len(res.by_rh) >= 2:
        rep.heading("Error by relative humidity")
        rep.table(res.by_rh)
        rep.image(d / "rh.png", caption="fit and J_err by RH")
    if brows:
        rep.heading("Error by frequency band")
        rep.table([{k: v for k, v in b.items() if k != "source"} | {"record": Path(b["source"]).name}
                   for b in brows], columns=["record", "f_lo_Hz", "f_hi_Hz", "residual_rms_m", "nrmse_in_band",
                                             "j_err_m_per_V", "log_mag_rms_dB", "phase_rms_deg", "frf_points"])
        if "bands.png" in extra:
            rep.image(d / "bands.png", caption="errors by frequency band")
    for r in res.records:
        rep.heading(f"{Path(r.source).name} (RH {r.rh:.3g} %)", level=3)
        est = r.summary["frf_metrics"].get("estimator")
        if est:
            rep.paragraph(f"FRF estimate: {est}", note=True)
        for f in r.summary["plots"]:
            rep.image(d / f, caption=f)
    rep.heading("Model and settings")
    rep.json_block(jsonable(res.predictor), "model")
    rep.json_block(jsonable(res.settings), "settings")
    if provenance:
        rep.json_block(provenance, "provenance")
    rep.write(d / "report.html")
    return out
