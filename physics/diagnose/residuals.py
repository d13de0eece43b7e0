"""Where a model fails: residual analysis of a fitted model against time records.

All on the decimated records (:mod:`.records`), residual e = measured − model with the best
offset removed, u the voltage.

* **Whiteness and independence** (MATLAB ``resid``; Ljung, *System Identification*,
  2nd ed., Prentice Hall 1999, §16.6; Söderström & Stoica, *System Identification*,
  Prentice Hall 1989, §11.4): the normalised autocorrelation ρ_ee(k) with the 99 % band
  ±2.576/√N (white residual), the input–residual cross-correlation ρ_ue(k) for
  k = −M..M with the band ±2.576 sqrt(Σ_j ρ_ee(j) ρ_uu(j))/√N (residual independent of
  the input, Ljung eq. 16.70), pooled over records (weights n_r); the Ljung–Box statistic.
  A correlation outside its band at positive lags means the model misses dynamics from u
  to y; a coloured residual alone can also be sensor drift.
* **Residual frequency response** u → e, Ĥ_e = Σ E U* / Σ |U|² over log-spaced bands
  (Daniell smoothing of the whole-record DFT, :data:`BANDS_PER_DECADE` per decade), with
  the coherence γ²_ue and its 99 % significance level for the band's effective number of
  independent lines n_b = (Σ|U|²)²/Σ|U|⁴ (Carter 1987): **noise floor**
  |Ĥ_e|_floor = sqrt(γ²_99 S_ee/S_uu), the residual response that noise alone would reach
  1 % of the time.  Bands above the floor are where the model fails; there the measured
  and modelled responses, estimated the same way, give the relative gain and phase error.
* **Error by frequency band** (decades; :func:`physics.compare.residual_by_band`), **by
  amplitude level** (gain ratio measured/model and the harmonic-distortion share of the
  residual: power at frequencies where the input has none, beyond :data:`NOISE_MARGIN` times
  what the record's noise floor puts there), the **amplitude contrast** (the gain ratio at two
  amplitudes of one kind of excitation at one RH level, :func:`amplitude_contrast`: only there
  is a change a gain that depends on the amplitude), **by RH level**, the **RH contrast** (the
  residual beyond the noise of records of one design — kind, amplitude level and band — at two RH
  levels, :func:`rh_contrast`: the drive is the same, so only humidity can make them differ), and **over
  time after steps** (mean residual early vs. late in each hold: slow drifts such as
  back-relaxation).
* **Findings**: sentences for a person, e.g. "Between 0.10 and 0.30 Hz the model
  overestimates the gain by 15 % and the measurement leads it by 6°; the residual leads
  the input by ~95°."
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import stats as sstats

from ..compare import default_bands, residual_by_band
from ..analysis import stats
from .records import PreparedRecord

Z99 = float(sstats.norm.ppf(0.995))
BANDS_PER_DECADE = 10
ALPHA = 0.01
#: Power at the quiet frequencies counted as distortion only beyond this multiple of what white
#: noise at the record's floor puts there (3 dB: room for a floor estimated a little low).
NOISE_MARGIN = 2.0
#: A measured/model gain that changes by more than this share between two amplitudes of the
#: same excitation at one RH level depends on the amplitude.
AMPLITUDE_CHANGE = 0.03
#: A residual with more than this share of its power at harmonics (beyond the noise) is distorted.
HARMONIC_SHARE = 0.05
#: Records of one design at two RH levels whose residuals beyond the noise differ by more than this
#: factor (the larger above :data:`RH_CONTRAST_FLOORS` noise floors) show a misfit that depends on RH.
RH_CONTRAST = 2.0
RH_CONTRAST_FLOORS = 3.0
#: ... or whose measured/model gain differs by more than this share.
RH_GAIN_CHANGE = 0.05


@dataclass
class ResidualFRF:
    """Band-smoothed responses (centre frequencies ``freq`` Hz)."""

    freq: np.ndarray
    H_e: np.ndarray            # input → residual [m/V]
    H_meas: np.ndarray         # input → measurement [m/V]
    H_model: np.ndarray        # input → model [m/V]
    coherence: np.ndarray      # γ²_ue
    threshold: np.ndarray      # γ² at 1 % significance
    floor: np.ndarray          # |H_e| noise floor [m/V]
    n_lines: np.ndarray        # effective independent lines per band

    @property
    def significant(self) -> np.ndarray:
        return (self.coherence > self.threshold) & (np.abs(self.H_e) > self.floor)

    @property
    def ratio(self) -> np.ndarray:
        """Measured / modelled response."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.H_meas / self.H_model


@dataclass
class ResidualAnalysis:
    """Everything :func:`analyse` finds for one fitted model (JSON via :meth:`to_dict`)."""

    label: str
    lag_s: np.ndarray
    acf: np.ndarray
    acf_band: float
    ccf_lag_s: np.ndarray
    ccf: np.ndarray
    ccf_band: float
    ljung_box: dict
    frf: ResidualFRF | None
    by_band: list[dict]
    by_amplitude: list[dict]
    by_rh: list[dict]
    after_steps: list[dict]
    findings: list[str] = field(default_factory=list)
    trend: list[dict] = field(default_factory=list)
    amplitude_contrast: list[dict] = field(default_factory=list)   # :func:`amplitude_contrast`
    rh_contrast: list[dict] = field(default_factory=list)          # :func:`rh_contrast`

    @property
    def acf_outside(self) -> float:
        """Fraction of lags ≥ 1 with |ρ_ee| outside the 99 % band."""
        return float(np.mean(np.abs(self.acf[1:]) > self.acf_band)) if self.acf.size > 1 else 0.0

    @property
    def ccf_outside(self) -> float:
        return float(np.mean(np.abs(self.ccf) > self.ccf_band)) if self.ccf.size else 0.0

    def to_dict(self) -> dict:
        frf = None
        if self.frf is not None:
            r = self.frf
            frf = {"freq_Hz": r.freq.tolist(), "residual_mag_m_per_V": np.abs(r.H_e).tolist(),
                   "residual_phase_deg": np.degrees(np.angle(r.H_e)).tolist(),
                   "noise_floor_m_per_V": r.floor.tolist(), "coherence": r.coherence.tolist(),
                   "coherence_99": r.threshold.tolist(), "significant": r.significant.tolist(),
                   "gain_ratio_meas_over_model": np.abs(r.ratio).tolist(),
                   "phase_meas_minus_model_deg": np.degrees(np.angle(r.ratio)).tolist()}
        return {"model": self.label, "autocorrelation": {"lag_s": self.lag_s.tolist(), "rho": self.acf.tolist(),
                                                         "band_99": self.acf_band,
                                                         "fraction_outside": self.acf_outside},
                "cross_correlation": {"lag_s": self.ccf_lag_s.tolist(), "rho": self.ccf.tolist(),
                                      "band_99": self.ccf_band, "fraction_outside": self.ccf_outside},
                "ljung_box": self.ljung_box, "residual_frf": frf, "by_band": self.by_band,
                "by_amplitude": self.by_amplitude, "amplitude_contrast": self.amplitude_contrast, "by_rh": self.by_rh,
                "rh_contrast": self.rh_contrast,
                "after_steps": self.after_steps, "trend": self.trend,
                "findings": self.findings}


# ============================================================================ pieces


def correlations(records: Sequence[PreparedRecord], resid: Sequence[np.ndarray], max_lag_s: float = 2.0):
    """Pooled ρ_ee and ρ_ue with their 99 % bands (module doc)."""
    fs = min(r.fs_d for r in records)
    m = max(5, int(round(max_lag_s * fs)))
    m = min(m, min(e.size for e in resid) // 4)
    acf = np.zeros(m + 1)
    ccf = np.zeros(2 * m + 1)
    var_ccf = 0.0
    n_tot = 0
    for r, e in zip(records, resid):
        n = e.size
        a = stats.autocorrelation(e, m)
        lags, c = stats.cross_correlation(r.v_d, e, m)
        au = stats.autocorrelation(r.v_d, n - 1)
        ae = stats.autocorrelation(e, n - 1)
        kk = min(n - 1, 50 * m)
        p = 1.0 + 2.0 * float(np.sum(ae[1:kk + 1] * au[1:kk + 1]))
        acf += n * a
        ccf += n * c
        var_ccf += n * max(p, 0.0)
        n_tot += n
    acf /= n_tot
    ccf /= n_tot
    lag_s = np.arange(m + 1) / fs
    ccf_lag = np.arange(-m, m + 1) / fs
    return lag_s, acf, Z99 / math.sqrt(n_tot), ccf_lag, ccf, Z99 * math.sqrt(var_ccf / n_tot) / math.sqrt(n_tot)


def _band_edges(f_lo: float, f_hi: float) -> np.ndarray:
    n = max(2, int(math.ceil(math.log10(f_hi / f_lo) * BANDS_PER_DECADE)))
    return np.geomspace(f_lo, f_hi, n + 1)


def residual_frf(records: Sequence[PreparedRecord], resid: Sequence[np.ndarray], preds: Sequence[np.ndarray],
                 band: tuple[float, float] | None = None) -> ResidualFRF | None:
    """Band-smoothed residual FRF with its coherence-based noise floor (module doc),
    pooled over the broadband and step records."""
    use = [i for i, r in enumerate(records) if r.kind in ("broadband", "steps", "other")]
    if not use:
        return None
    f_lo = band[0] if band else min(records[i].band[0] for i in use)
    f_hi = band[1] if band else max(records[i].band[1] for i in use)
    if not f_hi > f_lo > 0:
        return None
    edges = _band_edges(f_lo, f_hi)
    nb = edges.size - 1
    Suu, Sue, See, Suy, Sum, U4 = (np.zeros(nb) for _ in range(6))
    Sue, Suy, Sum = (np.zeros(nb, complex) for _ in range(3))
    for i in use:
        r = records[i]
        u = r.v_d - r.v_d.mean()
        f = np.fft.rfftfreq(u.size, 1.0 / r.fs_d)
        U = np.fft.rfft(u)
        E = np.fft.rfft(resid[i])
        Y = np.fft.rfft(r.y_d - r.y_d.mean())
        M = np.fft.rfft(preds[i] - preds[i].mean())
        idx = np.searchsorted(edges, f, side="right") - 1
        ok = (idx >= 0) & (idx < nb) & (f > 0)
        k = idx[ok]
        P = np.abs(U[ok]) ** 2
        np.add.at(Suu, k, P)
        np.add.at(U4, k, P ** 2)
        np.add.at(See, k, np.abs(E[ok]) ** 2)
        np.add.at(Sue, k, E[ok] * np.conj(U[ok]))
        np.add.at(Suy, k, Y[ok] * np.conj(U[ok]))
        np.add.at(Sum, k, M[ok] * np.conj(U[ok]))
    # keep bands where the input has power
    keep = Suu > 1e-6 * Suu.max()
    if not keep.any():
        return None
    fc = np.sqrt(edges[:-1] * edges[1:])[keep]
    Suu, U4, See, Sue, Suy, Sum = Suu[keep], U4[keep], See[keep], Sue[keep], Suy[keep], Sum[keep]
    n_lines = Suu ** 2 / np.maximum(U4, 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        coh = np.clip(np.abs(Sue) ** 2 / (Suu * See), 0.0, 1.0)
        thr = stats.coherence_threshold(n_lines, ALPHA)
        floor = np.sqrt(thr * See / Suu)
    return ResidualFRF(fc, Sue / Suu, Suy / Suu, Sum / Suu, coh, thr, floor, n_lines)


def by_band(records: Sequence[PreparedRecord], resid: Sequence[np.ndarray], f_lo: float, f_hi: float) -> list[dict]:
    """RMS residual within decade bands, pooled over records (power-weighted)."""
    bands = default_bands(f_lo, f_hi)
    acc = [{"band_Hz": list(b), "pe": 0.0, "py": 0.0, "n": 0} for b in bands]
    for r, e in zip(records, resid):
        rows = residual_by_band(e, r.y_d - r.y_d.mean(), r.fs_d, bands)
        for a, row in zip(acc, rows):
            a["pe"] += row["residual_rms_m"] ** 2 * e.size
            if row["nrmse_in_band"]:
                a["py"] += (row["residual_rms_m"] / row["nrmse_in_band"]) ** 2 * e.size
            a["n"] += e.size
    out = []
    for a in acc:
        n = max(a["n"], 1)
        out.append({"band_Hz": a["band_Hz"], "residual_rms_m": math.sqrt(a["pe"] / n),
                    "nrmse_in_band": math.sqrt(a["pe"] / a["py"]) if a["py"] > 0 else None})
    return out


def _gain_phase(records, resid, preds, idx) -> tuple[float | None, float | None]:
    """Median gain ratio (measured/model) and phase difference [deg] over significant-or-not
    bands of the records ``idx`` (Daniell estimate of each)."""
    sub = [records[i] for i in idx]
    frf = residual_frf(sub, [resid[i] for i in idx], [preds[i] for i in idx])
    if frf is None:
        return None, None
    w = np.abs(frf.H_meas)
    ok = np.isfinite(frf.ratio) & (w > 0.05 * w.max())
    if not ok.any():
        return None, None
    return float(np.median(np.abs(frf.ratio[ok]))), float(np.median(np.degrees(np.angle(frf.ratio[ok]))))


def _distortion_share(r: PreparedRecord, e: np.ndarray) -> float | None:
    """Share of the residual power at frequencies where the input has (almost) no power
    and which are not the excitation band: harmonics and other nonlinear products."""
    if r.kind not in ("tone", "broadband"):
        return None
    U = np.abs(np.fft.rfft(r.v_d - r.v_d.mean())) ** 2
    E = np.abs(np.fft.rfft(e)) ** 2
    f = np.fft.rfftfreq(r.v_d.size, 1.0 / r.fs_d)
    quiet = (U < 1e-4 * U.max()) & (f > r.band[1] * 1.05) & (f < min(3.5 * r.band[1], 0.45 * r.fs_d))
    if r.kind == "tone":
        quiet = (U < 1e-4 * U.max()) & (f > 1.5 * r.band[0])
    tot = E[1:].sum()
    if tot <= 0 or not quiet.any():
        return None
    # white noise of RMS σ puts N σ² into each bin (E|X_k|² for 0 < k < N/2): only the power beyond
    # NOISE_MARGIN times that is distortion — a residual near the noise would otherwise show half its
    # power "at harmonics"
    sigma = r.noise_floor_d
    noise = NOISE_MARGIN * int(quiet.sum()) * e.size * sigma ** 2 if math.isfinite(sigma) else 0.0
    return float(max(E[quiet].sum() - noise, 0.0) / tot)


def amplitude_contrast(records, resid, preds) -> list[dict]:
    """The measured/model gain at the lowest and the highest amplitude level of the same kind of
    excitation at one RH level, for each such pair: a misfit that differs with humidity or with
    the excitation is not read as a gain that depends on the amplitude."""
    groups: dict[tuple, dict[float, list[int]]] = {}
    for i, r in enumerate(records):
        if r.kind in ("broadband", "tone", "steps"):
            groups.setdefault((r.rh, r.kind), {}).setdefault(r.amplitude_level, []).append(i)
    out = []
    for (rh, kind), levels in sorted(groups.items()):
        if len(levels) < 2:
            continue
        lo, hi = min(levels), max(levels)
        g_lo, g_hi = _gain_phase(records, resid, preds, levels[lo])[0], _gain_phase(records, resid, preds, levels[hi])[0]
        if g_lo and g_hi:
            out.append({"rh_pct": rh, "kind": kind, "amplitude_low_V": lo, "amplitude_high_V": hi,
                        "gain_ratio_low": g_lo, "gain_ratio_high": g_hi, "change": g_hi / g_lo - 1.0})
    return out


def rh_contrast(records, resid, preds) -> list[dict]:
    """For each design (excitation kind, amplitude level, band to a tenth of a decade) recorded at
    two RH levels or more, between its lowest and highest RH level: the residual RMS beyond the
    noise floor [m] at each and ``contrast``, the larger over the smaller (the smaller taken at
    least the noise floor), and the change of the measured/model gain.  The drive is the same, so
    only humidity can make them differ: ``depends_on_rh`` when the gain changes by more than
    :data:`RH_GAIN_CHANGE`, or the residual by more than
    :data:`RH_CONTRAST` (a misfit in dynamics a gain ratio does not see, such as a resonance that
    moves with humidity).  Records of different designs are never compared: a sweep at half the
    amplitude differs from a multisine on any strip whose gain depends on the amplitude."""
    groups: dict[tuple, dict[float, list[int]]] = {}
    for i, r in enumerate(records):
        if r.kind in ("broadband", "tone", "steps") and min(r.band) > 0:
            key = (r.kind, r.amplitude_level, *(round(10 * math.log10(b)) for b in r.band))
            groups.setdefault(key, {}).setdefault(r.rh, []).append(i)

    def excess(idx) -> tuple[float, float]:
        sq = sum(float(resid[i] @ resid[i]) for i in idx) / sum(resid[i].size for i in idx)
        floor = float(np.sqrt(np.mean([records[i].noise_floor_d ** 2 for i in idx])))
        return math.sqrt(max(sq - floor ** 2, 0.0)), floor

    out = []
    for (kind, amp, *_), levels in sorted(groups.items()):
        if len(levels) < 2:
            continue
        lo, hi = min(levels), max(levels)
        (e_lo, n_lo), (e_hi, n_hi) = excess(levels[lo]), excess(levels[hi])
        floor = max(n_lo, n_hi)
        if not math.isfinite(floor):
            continue
        g_lo, g_hi = _gain_phase(records, resid, preds, levels[lo])[0], _gain_phase(records, resid, preds, levels[hi])[0]
        change = g_hi / g_lo - 1.0 if g_lo and g_hi else 0.0
        big, small = max(e_lo, e_hi), max(min(e_lo, e_hi), floor)
        moves = big > RH_CONTRAST_FLOORS * floor and big > RH_CONTRAST * small
        out.append({"kind": kind, "amplitude_V": amp, "rh_low_pct": lo, "rh_high_pct": hi,
                    "excess_low_m": e_lo, "excess_high_m": e_hi, "noise_floor_m": floor,
                    "contrast": big / small if small > 0 else math.inf, "gain_change": change,
                    "depends_on_rh": bool(moves or abs(change) > RH_GAIN_CHANGE)})
    return out


def by_group(records, resid, preds, key: str) -> list[dict]:
    """Residual RMS and gain/phase ratio per amplitude level (``key="amplitude"``) or RH level."""
    groups: dict[float, list[int]] = {}
    for i, r in enumerate(records):
        groups.setdefault(r.amplitude_level if key == "amplitude" else r.rh, []).append(i)
    out = []
    for lv in sorted(groups):
        idx = groups[lv]
        sq = sum(float(resid[i] @ resid[i]) for i in idx)
        n = sum(resid[i].size for i in idx)
        spread = sum(float(np.sum((records[i].y_d - records[i].y_d.mean()) ** 2)) for i in idx)
        g, ph = _gain_phase(records, resid, preds, idx)
        row = {("amplitude_V" if key == "amplitude" else "rh_pct"): lv, "records": len(idx),
               "residual_rms_m": math.sqrt(sq / n), "nrmse": math.sqrt(sq / spread) if spread > 0 else None,
               "gain_ratio_meas_over_model": g, "phase_meas_minus_model_deg": ph}
        if key == "amplitude":
            shares = [s for s in (_distortion_share(records[i], resid[i]) for i in idx) if s is not None]
            row["distortion_share_of_residual"] = float(np.mean(shares)) if shares else None
        out.append(row)
    return out


def after_steps(records, resid, noise: float) -> list[dict]:
    """Mean residual early (0.5–2 s) and late (last 25 %) in each hold after a step, signed
    by the step's direction: a positive drift means the measurement moves back against the
    step relative to the model (back-relaxation), negative that it keeps creeping on."""
    out = []
    for r, e in zip(records, resid):
        if r.kind != "steps" or r.steps.size == 0:
            continue
        fs = r.fs_d
        bounds = list(r.steps) + [e.size]
        for k in range(len(bounds) - 1):
            i0, i1 = int(bounds[k]), int(bounds[k + 1])
            hold = (i1 - i0) / fs
            if hold < 4.0:
                continue
            jump = float(np.median(r.v_d[i0 + int(0.2 * (i1 - i0)):i1]) - np.median(r.v_d[max(0, i0 - int(0.5 * fs)):i0 + 1]))
            if jump == 0:
                continue
            early = e[i0 + int(0.5 * fs):i0 + int(2.0 * fs)]
            late = e[i1 - int(0.25 * (i1 - i0)):i1]
            drift = float((late.mean() - early.mean()) * (-np.sign(jump)))
            out.append({"record": r.source, "t_step_s": i0 / fs, "hold_s": hold, "step_V": jump,
                        "residual_early_m": float(early.mean()), "residual_late_m": float(late.mean()),
                        "back_drift_m": drift, "significant": bool(abs(drift) > 3 * noise)})
    return out


# ============================================================================ driver


def analyse(label: str, records: Sequence[PreparedRecord], resid: Sequence[np.ndarray], preds: Sequence[np.ndarray],
            *, resonance_hz: float | None = None, per_rh: bool = False) -> ResidualAnalysis:
    """The residual analysis of one fitted model (module doc).  ``per_rh``: the model has
    parameters fitted per RH level, so records at two levels are not fitted by one model and
    their contrast (:func:`rh_contrast`) is not read."""
    lag_s, acf, ab, ccf_lag, ccf, cb = correlations(records, resid)
    pooled = np.concatenate(list(resid))
    lb = stats.ljung_box(pooled, lags=20)
    frf = residual_frf(records, resid, preds)
    f_lo = min(r.band[0] for r in records)
    f_hi = max(r.band[1] for r in records)
    bands = by_band(records, resid, f_lo, f_hi) if f_hi > f_lo > 0 else []
    noise = float(np.nanmedian([r.noise_floor_d for r in records]))
    ra = ResidualAnalysis(label, lag_s, acf, ab, ccf_lag, ccf, cb, lb, frf, bands,
                          by_group(records, resid, preds, "amplitude"), by_group(records, resid, preds, "rh"),
                          after_steps(records, resid, noise if math.isfinite(noise) else 0.0))
    ra.trend = trend(records, resid)
    ra.amplitude_contrast = amplitude_contrast(records, resid, preds)
    ra.rh_contrast = [] if per_rh else rh_contrast(records, resid, preds)
    ra.findings = findings(ra, records, resonance_hz=resonance_hz)
    return ra


def trend(records, resid) -> list[dict]:
    """Net change of each record's residual from its first to its last tenth [m] (a slow
    trend whatever the input), significant beyond 3× the record's noise floor."""
    out = []
    for r, e in zip(records, resid):
        k = max(e.size // 10, 1)
        change = float(np.mean(e[-k:]) - np.mean(e[:k]))
        out.append({"record": r.source, "change_m": change,
                    "significant": bool(math.isfinite(r.noise_floor_d) and abs(change) > 3 * r.noise_floor_d)})
    return out


def _classified_runs(frf: ResidualFRF) -> list[tuple[int, int, tuple[str, str], float]]:
    """Runs of consecutive significant bands with the same kind of error: gain over/under
    (beyond 2 %) or right, phase lead/lag (beyond 1°) or right; (first, last, class, size)."""
    R = frf.ratio
    sig = frf.significant & np.isfinite(R)
    g, ph = np.abs(R), np.degrees(np.angle(R))
    cls = [("over" if gi < 0.98 else "under" if gi > 1.02 else "ok", "lead" if p > 1 else "lag" if p < -1 else "0")
           for gi, p in zip(g, ph)]
    out = []
    i = 0
    while i < R.size:
        if not sig[i]:
            i += 1
            continue
        j = i
        while j + 1 < R.size and sig[j + 1] and cls[j + 1] == cls[i]:
            j += 1
        if cls[i] != ("ok", "0"):
            size = float(np.max(np.abs(np.log(R[i:j + 1])))) * (j - i + 1)
            out.append((i, j, cls[i], size))
        i = j + 1
    return out


def _fmt_f(f: float) -> str:
    return f"{f:.2g}" if f < 10 else f"{f:.0f}"


def findings(ra: ResidualAnalysis, records: Sequence[PreparedRecord], *, resonance_hz: float | None = None) -> list[str]:
    """Sentences for a person (module doc)."""
    out: list[str] = []
    frf = ra.frf
    if frf is not None:
        out += _frf_findings(frf, resonance_hz)
    if ra.ccf_outside > 0.05:
        pos = ra.ccf[ra.ccf_lag_s > 0]
        out.append(f"The residual is correlated with the input ({100 * ra.ccf_outside:.0f} % of lags outside the "
                   f"99 % band, largest |ρ_ue| = {np.max(np.abs(ra.ccf)):.2f}"
                   + (", mostly at positive lags: the model misses dynamics from voltage to deflection)."
                      if pos.size and np.max(np.abs(pos)) >= np.max(np.abs(ra.ccf)) - 1e-12 else ")."))
    elif frf is not None and _classified_runs(frf):
        out.append(f"Within ±{ra.lag_s[-1]:.3g} s the input–residual cross-correlation stays mostly inside its 99 % "
                   "band, but the residual frequency response above shows input-related error: dynamics slower "
                   "(or narrower in frequency) than the correlation window.")
    elif ra.acf_outside > 0.2:
        out.append(f"The residual is not white ({100 * ra.acf_outside:.0f} % of autocorrelation lags outside the "
                   "99 % band) but is uncorrelated with the input: sensor drift or disturbances rather than "
                   "missing input dynamics.")
    else:
        out.append("The residual passes the whiteness and independence checks at 1 %.")
    for c in ra.amplitude_contrast:
        if abs(c["change"]) > AMPLITUDE_CHANGE:
            out.append(f"The gain depends on the amplitude: at RH {c['rh_pct']:g} % relative to the model it is "
                       f"{100 * c['change']:+.2g} % at {c['amplitude_high_V']:.3g} V compared with "
                       f"{c['amplitude_low_V']:.3g} V, the same kind of excitation (a linear model cannot do this).")
    if ra.by_amplitude:
        a1 = ra.by_amplitude[-1]
        d = a1.get("distortion_share_of_residual")
        if d is not None and d > HARMONIC_SHARE:
            out.append(f"At {a1['amplitude_V']:.3g} V, {100 * d:.2g} % of the residual lies at harmonics outside "
                       "the excited band (harmonic distortion).")
    for c in ra.rh_contrast:
        if c["depends_on_rh"]:
            out.append(f"The same {c['kind']} drive ({c['amplitude_V']:.3g} V) leaves {1e6 * c['excess_low_m']:.3g} µm "
                       f"beyond the noise at RH {c['rh_low_pct']:g} % and {1e6 * c['excess_high_m']:.3g} µm at RH "
                       f"{c['rh_high_pct']:g} %, its measured/model gain {100 * c['gain_change']:+.2g} % from the "
                       "one to the other: the misfit depends on humidity in a way the model does not follow.")
    sig_steps = [s for s in ra.after_steps if s["significant"]]
    if sig_steps:
        d = float(np.median([s["back_drift_m"] for s in sig_steps]))
        holds = float(np.median([s["hold_s"] for s in sig_steps]))
        if d > 0:
            out.append(f"After the voltage steps the measured deflection relaxes back by ~{1e6 * d:.3g} µm over "
                       f"the {holds:.3g}-s holds while the model stays put (slow back-relaxation).")
        else:
            out.append(f"After the voltage steps the measured deflection keeps creeping on by ~{1e6 * -d:.3g} µm "
                       f"over the {holds:.3g}-s holds beyond the model (slow drift).")
    worst = max(ra.by_band, key=lambda b: b["residual_rms_m"], default=None)
    if worst is not None and len(ra.by_band) > 1:
        out.append(f"The largest error is in the {worst['band_Hz'][0]:.3g}–{worst['band_Hz'][1]:.3g} Hz band "
                   f"({1e6 * worst['residual_rms_m']:.3g} µm RMS).")
    return out


def _frf_findings(frf, resonance_hz: float | None) -> list[str]:
    """Sentences on the residual's frequency response ``frf``: nothing above the noise floor,
    or the gain and phase error in each of the (at most four) largest classified runs of bands."""
    out: list[str] = []
    sig = frf.significant
    if not sig.any():
        out.append("The residual's frequency response stays below its 1 % noise floor in every band: "
                   "no systematic input-to-error dynamics are visible.")
    runs = _classified_runs(frf)
    if sig.any() and not runs:
        out.append(f"The residual frequency response exceeds its noise floor in {int(sig.sum())} band(s), but "
                   "there the model is within 2 % in gain and 1° in phase: small systematic differences, "
                   "nothing a physical effect needs to explain.")
    runs = sorted(sorted(runs, key=lambda r: -r[3])[:4], key=lambda r: r[0])
    for i, j, cls, _ in runs:
        sl = slice(i, j + 1)
        g = float(np.median(np.abs(frf.ratio[sl])))
        ph = float(np.median(np.degrees(np.angle(frf.ratio[sl]))))
        pe = float(np.degrees(np.angle(np.sum(frf.H_e[sl] * frf.n_lines[sl]))))
        lo, hi = frf.freq[i] / 10 ** (0.5 / BANDS_PER_DECADE), frf.freq[j] * 10 ** (0.5 / BANDS_PER_DECADE)
        if cls[0] == "ok":
            gtxt = "the model gets the gain right (within 2 %)"
        elif g < 1:
            gtxt = f"the model overestimates the gain by {100 * (1 / g - 1):.2g} %"
        else:
            gtxt = f"the model underestimates the gain by {100 * (1 - 1 / g):.2g} %"
        ptxt = ("" if cls[1] == "0" else
                f" and the measurement {'leads' if ph > 0 else 'lags'} the model by {abs(ph):.2g}°")
        near = ""
        if resonance_hz and lo <= resonance_hz <= hi:
            near = f" (around the first resonance, {resonance_hz:.3g} Hz)"
        rel = "leads" if pe > 0 else "lags"
        out.append(f"Between {_fmt_f(lo)} and {_fmt_f(hi)} Hz{near} {gtxt}{ptxt}; "
                   f"the residual {rel} the input by ~{abs(pe):.0f}°.")
    return out
