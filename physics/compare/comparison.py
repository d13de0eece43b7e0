"""Model against measurement: per-record metrics, by band, by RH, overall."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..analysis import metrics
from ..errors import InputError, arg
from ..io.frfdata import FRFData
from ..execution.memory import release_free_memory
from ..io.timeseries import TimeSeries
from .frf import FRFOptions, default_bands, estimate_record_frf, frf_errors, residual_by_band, sensor_bandwidth_of, sensor_lowpass, sensor_response, thin_log, valid_points
from .measurements import check_measurements, cluster_rh, model_rh, source_name
from .predictors import Predictor, _check_output



@dataclass
class RecordComparison:
    """Result for one measurement (see :func:`compare`); arrays in SI units."""

    source: str
    kind: str                          # "timeseries" or "frf"
    rh: float
    time: np.ndarray | None = None
    measured: np.ndarray | None = None     # the measurement as read [m] (no copy of a long record)
    predicted: np.ndarray | None = None    # model output [m]
    offset: float = 0.0                    # removed from measured before the time metrics [m]
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
            bands: Sequence[tuple[float, float]] | None = None, rh_tolerance: float = 1.0,
            sensor_bandwidth="auto", log=None) -> ComparisonResult:
    """Compare ``predictor`` with measurements (loaded :class:`TimeSeries` /
    :class:`FRFData`, see :func:`load_measurements`); see the module doc for the metrics.

    ``offset``: ``"mean"`` removes the best constant offset between measurement and model
    (default), ``"start"`` the mean difference over the model's start-up window (the
    predictor's ``start_samples``, which the time metrics then skip), ``"none"`` keeps it; ``skip_s`` [s] excludes a start-up interval from the
    time metrics; ``min_coherence`` (γ²) excludes poorly measured frequencies from the FRF
    errors; ``bands`` [(f_lo, f_hi), ...] Hz (default: decades over the compared range);
    ``log(message)`` is told each stage of each record."""
    if not isinstance(predictor, Predictor):
        raise InputError(f"compare needs a Predictor (PhysicsPredictor or CallablePredictor), "
                         f"got {type(predictor).__name__}")
    if offset not in ("mean", "start", "none"):
        raise InputError(f"offset {offset!r}: expected 'mean', 'start' or 'none'")
    if not (skip_s >= 0 and math.isfinite(skip_s)):
        raise InputError(f"skip_s={skip_s!r} must be a non-negative number of seconds")
    if not 0 <= min_coherence <= 1:
        raise InputError(f"min_coherence={min_coherence!r} must lie within 0–1")
    opts = frf_options or FRFOptions()
    ms = list(measurements)
    if not ms:
        raise InputError("no measurement to compare with")
    check_measurements(ms)
    warnings_: list[str] = []
    recs: list[RecordComparison] = []
    log = log or (lambda message: None)
    for k, m in enumerate(ms):
        where = source_name(m, k)
        if isinstance(m, TimeSeries):
            recs.append(_compare_record(m, where, predictor, opts, offset, skip_s, min_coherence,
                                        sensor_bandwidth, rh_tolerance, log))
            warnings_ += _sensor_notes(recs[-1], sensor_bandwidth)
        elif isinstance(m, FRFData):
            if not predictor.has_closed_form:
                warnings_.append(f"{where}: a frequency-response file needs a model with a closed-form "
                                 f"response; {predictor.name} has none, so this file was skipped")
                continue
            recs.append(_compare_frf(m, where, predictor, min_coherence, sensor_bandwidth))
            warnings_ += _sensor_notes(recs[-1], sensor_bandwidth)
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


#: Lags (samples) of the residual tests, at most.
RESIDUAL_LAGS = 50


def residual_tests(e: np.ndarray, u: np.ndarray, lags: int = RESIDUAL_LAGS) -> dict:
    """Whiteness and independence of the residual ``e`` (as MATLAB ``resid``): the share of
    autocorrelations ρ_ee(1..lags) and of input–residual cross-correlations ρ_ue(−lags..lags)
    outside the 99 % band ±2.576/√n of white noise; a model passes when at most 1 % + one
    lag falls outside (what chance alone gives)."""
    from ..analysis.stats import autocorrelation, cross_correlation
    n = e.size
    m = int(min(lags, max(1, n // 4)))
    band = 2.576 / math.sqrt(n)
    acf = autocorrelation(e, m)[1:]
    _, ccf = cross_correlation(u, e, m)
    out_a, out_c = int(np.sum(np.abs(acf) > band)), int(np.sum(np.abs(ccf) > band))
    return {"lags": m, "band_99pct": band, "autocorrelation_outside": out_a, "autocorrelation_lags": int(acf.size),
            "cross_correlation_outside": out_c, "cross_correlation_lags": int(ccf.size),
            "max_abs_autocorrelation": float(np.max(np.abs(acf))) if acf.size else 0.0,
            "max_abs_cross_correlation": float(np.max(np.abs(ccf))) if ccf.size else 0.0,
            "white": bool(out_a <= 0.01 * acf.size + 1), "independent_of_input": bool(out_c <= 0.01 * ccf.size + 1)}


def _compare_record(ts: TimeSeries, where, predictor, opts, offset, skip_s, min_coh, sb_setting,
                    rh_tolerance, log):
    if ts.deflection is None:
        raise InputError(f"{where}: has no deflection column; a measurement needs deflection_m")
    rh = ts.rh if ts.rh is not None else None
    if rh is None:
        raise InputError(f"{where}: no relative humidity (rh_pct); give the RH with {arg('rh')}")
    rh_arg = model_rh(rh, ts.fs, rh_tolerance)
    log(f"{Path(where).name}: {predictor.name} on {ts.n:,} samples")
    yhat = _check_output(predictor.run_record(ts, rh_arg), ts.n, predictor.name)
    release_free_memory()         # the heap a piecewise run leaves behind (8 B per sample, physics.execution.memory)
    bw = None if predictor.measured_output and sb_setting == "auto" else sensor_bandwidth_of(ts, sb_setting)
    yhat = sensor_lowpass(yhat, ts.fs, bw)
    y = ts.deflection
    w = predictor.start_samples if offset == "start" else 0
    i0 = max(int(math.ceil(skip_s * ts.fs)), w)
    if ts.n - i0 < 3:
        raise InputError(f"{where}: {arg('skip_s')} {skip_s:g} s and the start-up window ({w} samples) leave "
                         "fewer than 3 samples")
    c = float(np.mean(y[i0:]) - np.mean(yhat[i0:])) if offset == "mean" else \
        float(np.mean(y[:w]) - np.mean(yhat[:w])) if w else 0.0   # no residual copy
    after = (f" after {arg('skip_s')} {skip_s:g} s" if skip_s * ts.fs >= w and skip_s > 0 else
             f" after sample {i0} (the model's start-up window)" if i0 else "")
    names = (f"{where}: the measured {ts.output.name}" + after,
             f"{where}: the prediction of {predictor.name}")
    tm = metrics.summary(y[i0:], yhat[i0:], offset=c, names=names)   # the record keeps y and the offset
    tm["offset_removed_m"] = c
    tm["skip_s"] = skip_s
    e = y[i0:] - yhat[i0:]
    e -= c
    tm["residual_tests"] = residual_tests(e, ts.voltage[i0:])
    del e
    # frequency domain
    log(f"{Path(where).name}: residual tests done; frequency-response estimates")
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
        Hc = np.full(f.shape, np.nan, dtype=complex)     # only where compared and plotted
        pos = sel & (f > 0)
        Hc[pos] = predictor.frequency_response(f[pos], mean) * sensor_response(f[pos], bw)
    t = ts.time - ts.time[0] if ts.time[0] else ts.time     # no copy for a record that starts at 0 s
    rec = RecordComparison(where, "timeseries", mean, time=t, measured=y,
                           predicted=yhat, offset=c, freq=f, H_meas=est_m.response, H_model_est=est_p.response,
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


def _sensor_notes(rec: "RecordComparison", setting) -> list[str]:
    """Warn when a record's own sensor bandwidth (sidecar ``sensor.bandwidth``), applied to
    the model as a low-pass, lies inside the compared band: it then shapes every figure, and
    a wrong value would change them silently."""
    bw = rec.summary.get("sensor_bandwidth_Hz")
    f = rec.freq[rec.valid] if rec.valid is not None and rec.valid.any() else np.zeros(0)
    if bw is None or setting != "auto" or not f.size or bw >= f.max():
        return []
    return [f"{Path(rec.source).name}: the sidecar's sensor.bandwidth {bw:g} Hz low-passes the model output inside "
            f"the compared band (up to {f.max():.3g} Hz), so it shapes every figure: check that it is the sensor's "
            "real cut-off (--sensor-bandwidth-Hz none ignores it)"]


def _compare_frf(frf: FRFData, where, predictor, min_coh, sb_setting):
    if frf.rh is None:
        raise InputError(f"{where}: the FRF file has no rh_pct column; give the RH with {arg('rh')}")
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
        i0 = int(math.ceil(r.summary["time_metrics"]["skip_s"] * fs))
        y, yhat, c = r.measured[i0:], r.predicted[i0:], r.offset

        def e(k, m):                  # the residual's samples k, k + m, …: never the whole residual
            part = y[k::m] - yhat[k::m]
            part -= c
            return part
        tb = residual_by_band(e, y, fs, bands)
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
