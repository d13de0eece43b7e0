"""Model-comparison statistics for autocorrelated residuals.

The residuals of a deflection record are not independent: the sensor drifts, the
excitation is smooth, and a model error is itself a smooth signal.  Counting every
sample as an independent observation would make any extra parameter look significant.
Everything here therefore works with an **effective sample size**

    n_eff = n / τ_int,     τ_int = 1 + 2 Σ_{k=1}^{M} ρ_k,

ρ_k the sample autocorrelation of the residual and M the smallest lag with M ≥ c·τ_int(M)
(Sokal's automatic window, c = 5; A. Sokal, *Monte Carlo methods in statistical
mechanics*, 1997, §3; the same quantity that scales a mean's variance for a correlated
series).  With n_eff the Gaussian log-likelihood of record r with its own variance
profiled out is −(n_eff,r / 2) ln(RSS_r / n_r) + const, and for a model with k free
parameters (Schwarz, Ann. Stat. 6:461, 1978; Akaike, IEEE TAC 19:716, 1974)

    BIC = Σ_r n_eff,r ln(RSS_r / n_r) + k ln(Σ_r n_eff,r),
    AIC = Σ_r n_eff,r ln(RSS_r / n_r) + 2k.

ΔBIC = BIC_candidate − BIC_base < 0 favours the candidate; Kass & Raftery (JASA 90:773,
1995) call |ΔBIC| > 10 very strong evidence.  exp(−BIC/2), normalised over the models
compared, approximates their posterior probabilities under equal priors (Wagenmakers &
Farrell, Psychon. Bull. Rev. 11:192, 2004) — the verdict's confidence.

**p-values.**  Nested models (the base is the candidate with the effect at its "off"
limit, e.g. Rs → 0): Wilks' likelihood-ratio statistic Λ = Σ_r n_eff,r ln(RSS_base,r /
RSS_cand,r), referred to χ²(Δk).  The "off" value lies on the boundary of the
parameter space, where the null distribution is a χ² mixture with less mass in the tail
(Self & Liang, JASA 82:605, 1987): the χ²(Δk) p-value is conservative.  Non-nested
models (same number of parameters, or a nonlinear law that does not contain the linear
one): Vuong's test (Econometrica 57:307, 1989) on the pointwise log-likelihood
differences, with their variance inflated by τ_int.  Each p-value answers one question
("is this effect's improvement larger than chance?"); the verdict compares the smallest
with 0.01/m for m candidates (Bonferroni).

Residual whiteness: the Ljung–Box portmanteau statistic Q = n(n+2) Σ_{k=1}^{m} ρ_k²/(n−k)
~ χ²(m) (Ljung & Box, Biometrika 65:297, 1978).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy import stats

#: Sokal's window constant.
SOKAL_C = 5.0


def autocorrelation(e: np.ndarray, max_lag: int | None = None) -> np.ndarray:
    """Normalised sample autocorrelation ρ_0..ρ_max_lag of ``e`` (mean removed; biased
    estimator, divided by n, as in MATLAB ``resid``)."""
    e = np.asarray(e, dtype=float)
    n = e.size
    m = n - 1 if max_lag is None else min(int(max_lag), n - 1)
    if _direct(n, m):
        me = np.mean(e)
        if np.any(e != me):
            ac = _lag_products(e, me, e, me, m)
            return ac / ac[0]
    e = e - np.mean(e)
    if n < 2 or not np.any(e):
        out = np.zeros(m + 1)
        out[0] = 1.0
        return out
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    f = np.fft.rfft(e, nfft)
    ac = np.fft.irfft(f * np.conj(f), nfft)[:m + 1]
    return ac / ac[0]


def _direct(n: int, max_lag: int) -> bool:
    """Sum lag by lag (no FFT buffers of 2n complex values) when few lags of a long record
    are wanted: it costs fewer operations and memory stays at the record itself."""
    return n > 4096 and max_lag + 1 <= 8 * math.log2(n)


#: Samples of the centred signals formed at a time by :func:`_lag_products`.
LAG_BLOCK = 1 << 20


def _lag_products(a: np.ndarray, ma: float, b: np.ndarray, mb: float, max_lag: int) -> np.ndarray:
    """Σ_t (a_t − ma)(b_{t+k} − mb) for k = 0..max_lag, the centred signals formed a block of
    :data:`LAG_BLOCK` samples at a time (a long record gets no centred copies; a shorter
    one is one block: the products of the whole centred signals)."""
    n = a.size
    out = np.zeros(max_lag + 1)
    for s in range(0, n, LAG_BLOCK):
        t = min(n, s + LAG_BLOCK)
        bb = b[s:min(n, t + max_lag)] - mb
        ab = bb[:t - s] if a is b and ma == mb else a[s:t] - ma
        for k in range(max_lag + 1):
            m = min(t, n - k) - s
            if m > 0:
                out[k] += np.dot(ab[:m], bb[k:k + m])
    return out


def cross_correlation(u: np.ndarray, e: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """(lags, ρ_ue(lag)) for lag = −max_lag..max_lag: ρ_ue(k) = Σ_t u(t) e(t+k) / (n σ_u σ_e)
    (positive lags: the residual after the input, as in MATLAB ``resid``)."""
    u, e = np.asarray(u, float), np.asarray(e, float)
    n = u.size
    lags = np.arange(-max_lag, max_lag + 1)
    if _direct(n, 2 * max_lag):
        mu, me = np.mean(u), np.mean(e)
        ahead = _lag_products(u, mu, e, me, max_lag)             # k ≥ 0: Σ u(t) e(t+k)
        behind = _lag_products(e, me, u, mu, max_lag)            # k ≤ 0: Σ u(t+|k|) e(t)
        vals = np.concatenate([behind[:0:-1], ahead])
        den = math.sqrt(float(_lag_products(u, mu, u, mu, 0)[0]) * float(_lag_products(e, me, e, me, 0)[0]))
    else:
        u = u - np.mean(u)
        e = e - np.mean(e)
        nfft = 1 << int(math.ceil(math.log2(2 * n)))
        c = np.fft.irfft(np.conj(np.fft.rfft(u, nfft)) * np.fft.rfft(e, nfft), nfft)
        vals = c[lags % nfft]
        den = math.sqrt(float(np.dot(u, u)) * float(np.dot(e, e)))   # n σ_u σ_e, both already centred
    return lags, (vals / den if den > 0 else np.zeros(lags.size))


def integrated_time(e: np.ndarray, max_lag: int | None = None) -> float:
    """Integrated autocorrelation time τ_int ≥ 1 with Sokal's automatic window (module doc)."""
    e = np.asarray(e, dtype=float)
    n = e.size
    if n < 8 or not np.any(e - e.mean()):
        return 1.0
    rho = autocorrelation(e, max_lag if max_lag is not None else n // 4)
    tau = np.cumsum(2.0 * rho) - 1.0          # τ(M) = 1 + 2 Σ_{1..M} ρ_k
    m = np.arange(tau.size)
    ok = np.flatnonzero(m >= SOKAL_C * tau)
    t = tau[ok[0]] if ok.size else tau[-1]
    return float(min(max(t, 1.0), n / 2.0))


def loglik_term(rss: float, n: int, n_eff: float) -> float:
    """n_eff ln(RSS/n) — minus twice the profiled Gaussian log-likelihood up to a constant."""
    return n_eff * math.log(max(rss, 1e-300) / n)


def bic(rss: Sequence[float], n: Sequence[int], n_eff: Sequence[float], k: int) -> float:
    """Schwarz's criterion with effective sample sizes, summed over records (module doc)."""
    return float(sum(loglik_term(r, m, ne) for r, m, ne in zip(rss, n, n_eff)) + k * math.log(max(sum(n_eff), 1.0)))


def aic(rss: Sequence[float], n: Sequence[int], n_eff: Sequence[float], k: int) -> float:
    return float(sum(loglik_term(r, m, ne) for r, m, ne in zip(rss, n, n_eff)) + 2 * k)


def lr_pvalue(rss_base: Sequence[float], rss_cand: Sequence[float], n_eff: Sequence[float], dk: int) -> float:
    """Wilks' likelihood-ratio p-value (nested; conservative at a boundary, see module doc)."""
    lam = sum(ne * math.log(max(rb, 1e-300) / max(rc, 1e-300)) for rb, rc, ne in zip(rss_base, rss_cand, n_eff))
    if dk <= 0:
        return float("nan")
    return float(stats.chi2.sf(max(lam, 0.0), dk))


def vuong_pvalue(e_base: Sequence[np.ndarray], e_cand: Sequence[np.ndarray], taus: Sequence[float],
                 dk: int = 0, pooled: bool = False) -> float:
    """One-sided p-value of Vuong's test that the candidate is not closer to the data than
    the base.  Pointwise Gaussian log-likelihood differences d_i (each record with its
    own variance, or with ``pooled`` one variance over all records — the likelihood whose
    maximum is the pooled RMS error), on the effective scale: LR = Σ_r Σ_i d_ri / τ_r with
    variance Σ_r n_eff,r var(d_r); Schwarz's correction ½ Δk ln N_eff for extra parameters."""
    lr, var, n_eff = 0.0, 0.0, 0.0
    if pooled:
        n_all = max(sum(np.asarray(e).size for e in e_base), 1)
        pb = max(sum(float(np.sum(np.asarray(e, float) ** 2)) for e in e_base) / n_all, 1e-300)
        pc = max(sum(float(np.sum(np.asarray(e, float) ** 2)) for e in e_cand) / n_all, 1e-300)
    for eb, ec, tau in zip(e_base, e_cand, taus):
        eb, ec = np.asarray(eb, float), np.asarray(ec, float)
        tau = max(float(tau), 1.0)
        sb, sc = (pb, pc) if pooled else (max(np.mean(eb ** 2), 1e-300), max(np.mean(ec ** 2), 1e-300))
        d = -0.5 * (np.log(sc) + ec ** 2 / sc) + 0.5 * (np.log(sb) + eb ** 2 / sb)
        lr += float(np.sum(d)) / tau
        var += eb.size / tau * float(np.var(d))
        n_eff += eb.size / tau
    lr -= 0.5 * dk * math.log(max(n_eff, 1.0))
    if var <= 0 or not math.isfinite(var):
        return 0.5
    return float(stats.norm.sf(lr / math.sqrt(var)))


def bic_weights(bics: Sequence[float]) -> np.ndarray:
    """exp(−BIC/2) normalised (approximate posterior model probabilities, equal priors)."""
    b = np.asarray(bics, dtype=float)
    w = np.exp(-0.5 * (b - np.min(b)))
    return w / w.sum()


def evidence_label(delta_bic: float) -> str:
    """Kass & Raftery (1995) grades for ΔBIC = BIC_candidate − BIC_base."""
    d = -delta_bic
    if d > 10:
        return "very strong"
    if d > 6:
        return "strong"
    if d > 2:
        return "positive"
    if d > -2:
        return "none (not worth more than a bare mention)"
    return "against (the base model is preferred)"


def ljung_box(e: np.ndarray, lags: int = 20, tau_thin: bool = False) -> dict:
    """Ljung–Box statistic and p-value on ``lags`` autocorrelations of ``e``."""
    e = np.asarray(e, float)
    n = e.size
    m = min(lags, n - 2)
    rho = autocorrelation(e, m)[1:]
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, m + 1))))
    return {"lags": int(m), "Q": q, "p_value": float(stats.chi2.sf(q, m))}


def coherence_threshold(n_avg: np.ndarray | float, alpha: float = 0.01) -> np.ndarray:
    """Coherence γ² exceeded with probability ``alpha`` by two independent signals with
    n_avg independent averages: 1 − alpha^(1/(n_avg − 1)) (Carter, Proc. IEEE 75:236, 1987)."""
    n = np.maximum(np.asarray(n_avg, dtype=float), 1.0 + 1e-9)
    return 1.0 - alpha ** (1.0 / (n - 1.0))
