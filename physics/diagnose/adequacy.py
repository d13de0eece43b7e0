"""Is what remains noise?  The adequacy check after the best model, and a description of
missing dynamics that no catalog effect explains.

**Adequacy.**  The final model (the base plus the missing effect, or the base) is adequate
when its RMS error is within :data:`ADEQUATE_RATIO` × the records' noise floor (the
sensor's white noise, quantisation and drift, :mod:`.records`).  Otherwise the catalog
explains at most part of the failure and the verdict says so (its confidence is then never
"high").  Whiteness (Ljung–Box) and input–residual correlation are reported beside it.

**Descriptors of the missing dynamics** (each fitted to the residual of the final model on
the decimated records; significant when ΔBIC ≤ −:data:`DESCRIPTOR_BIC` with the effective
sample size of :mod:`.stats` and the RMS error falls by ≥ 10 %):

* *slow pole*: residual ≈ g · LP_τ(ŷ), a first-order lag 1/(1 + sτ) of the model's own
  output — a creep (g > 0: the tip keeps moving forward; g < 0: it relaxes back) with time
  constant τ and static fraction g;
* *hysteresis*: residual ≈ a · (P_w(ŷ) − ŷ) with P_w the play (backlash) operator of width
  w — a rate-independent loop on the output side (clamp play, sensor backlash);
* *amplitude / RH dependence*: the relative residual (RMS residual / RMS output) of the
  largest against the smallest amplitude (RH) level.

The template for adding what is found is ``examples/effects/creep.py`` (README, "Adding
an effect").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.signal import lfilter

from .. import stats
from ..metrics import remove_nuisance

#: The final model explains the data when its RMS error is within this × the noise floor.
ADEQUATE_RATIO = 1.3
#: A descriptor is significant at ΔBIC ≤ −this (very strong, Kass & Raftery) ...
DESCRIPTOR_BIC = 10.0
#: ... and when it lowers the RMS error by at least this fraction.
DESCRIPTOR_MIN_GAIN = 0.10
#: Relative-residual ratio between extreme amplitude (RH) levels called a dependence.
DEPENDENCE_RATIO = 1.5


@dataclass
class Adequacy:
    """The adequacy of the final model and, when it fails, what the residual looks like."""

    model: str
    rmse: float
    noise_floor: float
    adequate: bool | None
    ljung_box_p: float
    descriptors: list[dict] = field(default_factory=list)

    @property
    def ratio(self) -> float:
        return self.rmse / self.noise_floor if self.noise_floor > 0 else math.nan

    def summary(self) -> str:
        """One sentence: the level against the noise and the significant descriptors."""
        if self.adequate is None:
            return f"{self.model}: noise floor unknown, adequacy not assessed"
        txt = (f"{self.model}: RMS error {1e6 * self.rmse:.3g} µm = {self.ratio:.2f}× the noise floor "
               f"({'within' if self.adequate else 'above'} {ADEQUATE_RATIO}×)")
        found = [d["text"] for d in self.descriptors if d.get("significant")]
        if found:
            txt += "; remaining: " + "; ".join(found)
        return txt

    def to_dict(self) -> dict:
        return {"model": self.model, "rmse_m": self.rmse, "noise_floor_m": self.noise_floor,
                "ratio": self.ratio, "adequate": self.adequate, "threshold_ratio": ADEQUATE_RATIO,
                "ljung_box_p": self.ljung_box_p, "descriptors": self.descriptors, "summary": self.summary()}


def assess(label: str, fit, records: Sequence, noise: float, describe: bool = True) -> Adequacy:
    """Adequacy of ``fit`` (a scored :class:`.candidates.ModelFit`) on ``records``; with
    ``describe`` the residual of an inadequate model is described (:func:`describe_missing`)."""
    adequate = None if not (math.isfinite(noise) and noise > 0) else bool(fit.rmse <= ADEQUATE_RATIO * noise)
    lb = stats.ljung_box(np.concatenate(list(fit.resid_d)), lags=20)
    out = Adequacy(label, float(fit.rmse), float(noise), adequate, float(lb.get("p_value", math.nan)))
    if adequate is not True and describe:
        out.descriptors = describe_missing(fit, records)
    return out


def _lowpass(x: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """First-order lag 1/(1 + sτ) (exact for a zero-order hold), started at rest."""
    a = math.exp(-1.0 / (tau * fs))
    return lfilter([1.0 - a], [1.0, -a], x)


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Play (backlash) operator of total width ``width``, started centred on x[0]."""
    out = np.empty_like(x)
    y = float(x[0])
    h = 0.5 * width
    for i, v in enumerate(x.tolist()):
        if v - h > y:
            y = v - h
        elif v + h < y:
            y = v + h
        out[i] = y
    return out


def _fit_regressor(resid, regs, n_eff) -> tuple[float, list[float], float]:
    """Shared gain g of residual ≈ g·reg over the records: (g, RSS per record, ΔBIC for 2 extra params)."""
    num = sum(float(r @ e) for r, e in zip(regs, resid))
    den = sum(float(r @ r) for r in regs)
    g = num / den if den > 0 else 0.0
    rss0 = [float(e @ e) for e in resid]
    rss1 = [float((e - g * r) @ (e - g * r)) for r, e in zip(regs, resid)]
    d_bic = sum(ne * math.log(max(b, 1e-300) / max(a, 1e-300)) for ne, a, b in zip(n_eff, rss0, rss1)) \
        + 2 * math.log(max(sum(n_eff), 2.0))
    return g, rss1, d_bic


def describe_missing(fit, records: Sequence) -> list[dict]:
    """The descriptors of the module doc for the residual of ``fit``."""
    resid = [np.asarray(e, float) for e in fit.resid_d]
    preds = [np.asarray(p, float) for p in fit.pred_d]
    n_eff = [e.size / max(stats.integrated_time(e), 1.0) for e in resid]
    rss0 = sum(float(e @ e) for e in resid)
    n_tot = sum(e.size for e in resid)
    rms0 = math.sqrt(rss0 / n_tot) if n_tot else math.nan
    out = []

    def finish(kind, value, rss1, d_bic, text):
        rms1 = math.sqrt(sum(rss1) / n_tot)
        gain = 1.0 - rms1 / rms0 if rms0 > 0 else 0.0
        sig = bool(d_bic <= -DESCRIPTOR_BIC and gain >= DESCRIPTOR_MIN_GAIN)
        out.append({"kind": kind, **value, "delta_bic": d_bic, "rms_reduction": gain, "significant": sig,
                    "text": text + f" (RMS error −{100 * gain:.0f} %, ΔBIC {d_bic:.3g})"})

    # slow pole on the output side
    span = min(r.y_d.size / r.fs_d for r in records)
    fs_min = min(r.fs_d for r in records)
    taus = np.geomspace(3.0 / fs_min, max(0.5 * span, 6.0 / fs_min), 36)
    best = None
    for tau in taus:
        regs = []
        for r, p in zip(records, preds):
            x = _lowpass(p, tau, r.fs_d)
            regs.append(remove_nuisance(x))
        g, rss1, d_bic = _fit_regressor(resid, regs, n_eff)
        if best is None or d_bic < best[3]:
            best = (tau, g, rss1, d_bic)
    tau, g, rss1, d_bic = best
    kind = "creeps forward" if g > 0 else "relaxes back"
    finish("slow_pole", {"tau_s": float(tau), "gain": float(g)}, rss1, d_bic,
           f"a slow pole on the output: the tip {kind} by {100 * abs(g):.3g} % of the model's deflection with "
           f"time constant τ ≈ {tau:.3g} s (residual ≈ g/(1 + sτ) · model output, g = {g:+.3g})")

    # rate-independent hysteresis (play operator on the output)
    ptp = max(float(np.ptp(p)) for p in preds) or 1.0
    best = None
    for w in np.geomspace(0.01, 0.6, 14) * ptp:
        regs = []
        for p in preds:
            x = play(p, w) - p
            regs.append(remove_nuisance(x))
        a, rss1, d_bic = _fit_regressor(resid, regs, n_eff)
        if best is None or d_bic < best[3]:
            best = (w, a, rss1, d_bic)
    w, a, rss1, d_bic = best
    finish("hysteresis", {"width_m": float(w * a), "play_width_m": float(w), "gain": float(a)}, rss1, d_bic,
           f"a rate-independent loop (backlash/play) on the output of width ≈ {1e6 * abs(w * a):.3g} µm")

    # amplitude and RH dependence of the relative residual (records of one kind only:
    # a pulse and a sweep differ in relative residual whatever their amplitudes)
    for key, attr, unit in (("amplitude", "amplitude_level", "V"), ("rh", "rh", "%")):
        by_kind: dict = {}
        for r, e, p in zip(records, resid, preds):
            by_kind.setdefault(r.kind, {}).setdefault(round(float(getattr(r, attr)), 6), []).append((e, p))
        groups = max(by_kind.values(), key=len)
        if len(groups) < 2:
            continue
        rel = {k: math.sqrt(sum(float(e @ e) for e, _ in v) / max(sum(float(p @ p) for _, p in v), 1e-300))
               for k, v in groups.items()}
        lo, hi = min(groups), max(groups)
        ratio = rel[hi] / rel[lo] if rel[lo] > 0 else math.inf
        sig = bool(ratio >= DEPENDENCE_RATIO or ratio <= 1 / DEPENDENCE_RATIO)
        out.append({"kind": f"{key}_dependence", "levels": sorted(groups), "relative_residual": rel,
                    "ratio_high_to_low": ratio, "significant": sig,
                    "text": f"the relative residual at {key} {hi:.3g} {unit} is {ratio:.2g}× that at {lo:.3g} {unit}"})
    return out
