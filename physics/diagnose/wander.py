"""The slow wander of the records: how much of it is noise, and how much the records share.

A model's residual keeps, below the excited band, what the per-record nuisance terms (offset
and linear drift, :func:`physics.analysis.metrics.remove_nuisance`) leave of a slow drift.  When the
noise floor is estimated from the records (no sensor metadata), :func:`slow_wander` measures
it and the diagnosis counts it as noise — *unless the records share it*.  A sensor's drift
wanders independently from one record to the next; a drift of the setup the same in every
record (a clamp settling from each start, a warm-up) is deterministic, is described by the
residual forms and can be drafted as an effect.  :func:`shared_wander` tells the two apart
by comparing the records' slow residuals on their common span from each record's start.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..analysis.metrics import remove_nuisance
from .forms.drift import shape as drift_shape, tau_grid
from .records import WALK_AFTER_TREND

#: Mean square of a random walk left after its linear trend, per mean square of the fitted
#: trend's rise over the record: (σ²T/15) / (6σ²T/5) = 1/18 (Brownian motion of variance σ²t on
#: [0, T]: its least-squares slope has variance 6σ²/(5T)).
WANDER_PER_TREND = WALK_AFTER_TREND / (6.0 / 5.0)


def slow_wander(records: Sequence, resid_d: Sequence[np.ndarray], nuisance, trend: bool = True) -> float:
    """RMS [m] of a slow wander (a sensor's drift beyond the linear trend the nuisance terms
    remove) in a model's residuals, assuming a random-walk drift, from two independent
    signs of it, pooled by their degrees of freedom:

    * the fitted drift rates b of the broadband records (``nuisance``: (offset, drift) per
      record): a random walk leaves, after its trend, WANDER_PER_TREND × (b·T)² on average (T
      the record's duration; one degree of freedom per record);
    * the broadband records' residual below half their lowest excited frequency, where the
      input has no power (the white noise's share removed; two degrees of freedom per line),
      extrapolated with the share of a detrended random walk's variance those lines hold.

    Only broadband records count: their input has no power at the lowest lines, so a linear
    model's slow physics leaves nothing there, while a step record's creep or back-relaxation
    would pass for drift.  With ``trend=False`` the drift rates are left out: a rate fitted to a
    residual takes whatever slow error the model leaves, the lowest lines do not.  NaN when no
    record can show it."""
    num = dof = 0.0
    for r, e, (_, b) in zip(records, resid_d, nuisance):
        if r.kind != "broadband":      # a step's slow physics (creep, back-relaxation) would pass for drift
            continue
        if trend:
            num += WANDER_PER_TREND * (b * r.ts.duration) ** 2
            dof += 1.0
        n = e.size
        k_max = int(math.floor(0.5 * r.band[0] * n / r.fs_d))
        if k_max < 1 or not math.isfinite(r.noise_floor_d):
            continue
        E = np.fft.rfft(e)[1:k_max + 1]
        low = 2.0 * float(np.sum(np.abs(E) ** 2)) / n ** 2
        white = r.noise_floor_d ** 2 * 2.0 * k_max / n
        share = _WALK_SHARE[min(k_max, len(_WALK_SHARE)) - 1]
        num += 2.0 * k_max * max(low - white, 0.0) / share
        dof += 2.0 * k_max
    return math.sqrt(num / dof) if dof else math.nan


#: Share of a linearly detrended random walk's variance in its first k spectral lines (k = 1…10; computed).
_WALK_SHARE = (0.46, 0.66, 0.75, 0.80, 0.84, 0.86, 0.88, 0.89, 0.90, 0.91)


#: Significance of the test that the records share part of their slow wander (the likelihood-
#: ratio test of :func:`shared_wander`; one-sided, the false alarms when they wander independently).
SHARED_ALPHA = 0.01
#: Below this p-value (the conventional "suggestive" level) but not below SHARED_ALPHA, the
#: test is inconclusive: the records hint at a shared part they cannot confirm.
HINT_P = 0.10
#: At most this many cosine lines per record enter the test.
MAX_LINES = 24
#: Draws of the null distribution of the test statistic (its p-value resolves 1/NULL_DRAWS),
#: from a fixed seed: the same records give the same p-value.
NULL_DRAWS = 4000


@dataclass
class WanderSplit:
    """What the records' slow residuals share (:func:`shared_wander`)."""

    fraction: float          # share of the slow power common to the records (0 when not significant); NaN: not testable
    p_value: float           # of the likelihood-ratio test (independent wanders)
    records: int             # records compared
    dims: int                # slow components per record (the trend and the cosine lines)
    why: str = ""            # why it could not be tested
    tau: float = math.nan    # time constant [s] of the shared form that fits best
    amplitude: float = math.nan   # its amplitude A [m] (when significant)
    rms: float = math.nan    # RMS [m] of that shared form over the records, each record's offset and trend removed

    @property
    def testable(self) -> bool:
        return math.isfinite(self.fraction)

    @property
    def inconclusive(self) -> bool:
        """The records hint at a shared part (p < :data:`HINT_P`) without confirming it."""
        return self.testable and self.fraction == 0 and self.p_value < HINT_P

    def _test(self) -> str:
        return (f"likelihood-ratio test of a shared A(1 − e^(−t/τ)) from each record's start on {self.dims} slow "
                f"components of the {self.records} records, p = {self.p_value:.2g}")

    def text(self) -> str:
        if not self.testable:
            return self.why
        if self.fraction > 0:
            return (f"{100 * self.fraction:.0f} % of it is common to the {self.records} records ({self._test()}; "
                    f"A ≈ {1e6 * self.amplitude:+.3g} µm, τ ≈ {self.tau:.3g} s): a drift they share, not counted as noise")
        if self.inconclusive:
            return (f"the {self.records} records hint that they share part of it but cannot confirm it ({self._test()}, "
                    f"not below {SHARED_ALPHA:g}): counted as noise")
        return f"it does not repeat from record to record ({self._test()}): the sensor's own wander, counted as noise"


def _operator(n: int, fs: float, span: float, k: int) -> np.ndarray:
    """(1 + k) × n matrix taking a record's first n samples (at ``fs`` [Hz], span [s]) to its slow
    components: the rise of its linear trend over the span, scaled by sqrt(WANDER_PER_TREND)
    (its square: the wander power a random walk with that trend leaves), and the coefficients
    of cos(πj t/span), j = 1…k, of what the offset and trend leave, scaled by 1/sqrt(2) (their
    squares: their powers)."""
    t = np.arange(n) / fs
    tc = t - t.mean()
    rise = math.sqrt(WANDER_PER_TREND) * span * tc / float(tc @ tc)
    basis = np.cos(np.pi * np.outer(np.arange(1, k + 1), (np.arange(n) + 0.5) / n))
    A = np.column_stack([np.ones(n), tc])
    basis = basis - (basis @ A) @ np.linalg.pinv(A)            # the projector removing offset and trend
    return np.vstack([rise, basis * (2.0 / n / math.sqrt(2.0))])


def slow_components(records: Sequence, resid_d: Sequence[np.ndarray], nuisance, wander: float, taus=()):
    """(R × d whitened slow components, R × d × len(taus) whitened shared forms, d) of the
    records' residuals on their common span T from each record's start, or a string saying why
    they cannot show it.

    Each record's components (:func:`_operator`: trend and k = ⌊2T·f⌋ cosine lines below the
    broadband records' lowest excited frequency f, at most :data:`MAX_LINES`) are whitened by
    their covariance when the record wanders independently: a random walk detrended over its
    record whose RMS is ``wander`` [m] (:func:`slow_wander`) plus the record's white noise —
    so that, wandering independently, every record's components are independent N(0, σ²).
    The same operator and whitening take the forms 1 − e^(−t/τ) (:func:`.forms.drift.shape`,
    τ in ``taus`` [s]) to the components they would add."""
    broadband = [r for r in records if r.kind == "broadband"]
    if not broadband:
        return "no broadband record shows the wander below its excited band"
    if len(records) < 2:
        return "one record cannot tell a drift shared by the records from the sensor's own wander"
    span = min(e.size / r.fs_d for r, e in zip(records, resid_d))
    f_lo = min(r.band[0] for r in broadband)
    k = min(int(math.floor(2.0 * span * f_lo)), MAX_LINES)
    if k < 1:
        return f"their common span ({span:.3g} s) is too short to show a wander below {f_lo:.3g} Hz"
    rows, forms = [], []
    for r, e, (_, b) in zip(records, resid_d, nuisance):
        n = int(round(span * r.fs_d))
        t = np.arange(n) / r.fs_d
        M = _operator(n, r.fs_d, span, k)
        raw = np.asarray(e[:n], float) + b * t                         # the record's own trend back in
        ML = np.cumsum(M[:, ::-1], axis=1)[:, ::-1]                    # M · (cumulative sum): a random walk
        walk = (ML @ ML.T) / n * (wander ** 2 / WALK_AFTER_TREND)
        white = (M @ M.T) * (r.noise_floor_d ** 2 if math.isfinite(r.noise_floor_d) else 0.0)
        L = np.linalg.cholesky(walk + white + 1e-12 * np.trace(walk + white) / (k + 1) * np.eye(k + 1))
        rows.append(np.linalg.solve(L, M @ raw))
        forms.append(np.linalg.solve(L, M @ drift_shape(t, taus)) if len(taus) else np.zeros((k + 1, 0)))
    return np.array(rows), np.array(forms), k + 1


def _shared_statistic(u: np.ndarray, h: np.ndarray) -> np.ndarray:
    """max over τ of Λ(τ) = e(τ) / ((|u|² − e(τ)) / (Rd − 1)), e(τ) = (Σ_r h_r·u_r)² / Σ_r |h_r|²
    the whitened power a form A·h(τ) shared by the records explains (A fitted): the
    likelihood-ratio statistic of the shared form against independent wanders of unknown scale
    (F(1, Rd − 1) at one τ).  ``u``: (…, R, d), ``h``: R × d × τ."""
    R, d = h.shape[:2]
    e = np.einsum("...rd,rdt->...t", u, h) ** 2 / np.maximum(np.einsum("rdt,rdt->t", h, h), 1e-300)
    total = (u ** 2).sum(axis=(-1, -2))[..., None]
    return (e / np.maximum(total - e, 1e-300) * (R * d - 1)).max(axis=-1)


def shared_wander(records: Sequence, resid_d: Sequence[np.ndarray], nuisance, wander: float) -> WanderSplit:
    """Do the records share part of their slow residual?  A drift of the setup repeats from each
    record's start; a sensor's wander does not.  On the whitened slow components u_r
    (:func:`slow_components`; R records, d components, independent N(0, σ²) when the records
    wander independently), a likelihood-ratio test of a shared form A(1 − e^(−t/τ)) (A fitted, τ
    scanned over :func:`.forms.drift.tau_grid`, σ² unknown) against none: its statistic
    (:func:`_shared_statistic`) is referred to its exact null distribution, drawn
    (:data:`NULL_DRAWS`, fixed seed) with the same records, whitening and τ.  The records share a
    part at p < :data:`SHARED_ALPHA`; its fraction of the slow wander is 1 − σ̂², σ̂² = (|u|² −
    e)/(Rd − 1) the whitened power per component that the best-fitting shared form (A by
    generalised least squares, its τ) leaves: 1 when the records wander independently at the
    scale ``wander`` assumed by the whitening (the slow components are a random walk's, the white
    noise's share is small), so ``wander``·σ̂ is the wander the records do not share, estimated
    on all Rd components (:func:`slow_wander` sees the broadband records only).  A shared drift
    that is nearly a straight line over the records is told from a random walk's trend only as
    far as its size exceeds the walk's spread."""
    got, taus = "no slow wander to split", ()
    if math.isfinite(wander) and wander > 0:
        span = min(e.size / r.fs_d for r, e in zip(records, resid_d)) if records else 0.0
        taus = tau_grid(span) if span > 0 else ()
        got = slow_components(records, resid_d, nuisance, wander, taus)
    if isinstance(got, str):
        return WanderSplit(math.nan, math.nan, len(records), 0, got)
    u, h, d = got
    R = len(u)
    stat = float(_shared_statistic(u, h))
    null = _shared_statistic(np.random.default_rng(0).normal(size=(NULL_DRAWS, R, d)), h)
    p = float((1 + np.count_nonzero(null >= stat)) / (NULL_DRAWS + 1))
    hu, hh = np.einsum("rd,rdt->t", u, h), np.maximum(np.einsum("rdt,rdt->t", h, h), 1e-300)
    best = int(np.argmax(hu ** 2 / hh))
    amp, tau = float(hu[best] / hh[best]), float(taus[best])
    if p >= SHARED_ALPHA:
        return WanderSplit(0.0, p, R, d, tau=tau)
    left = (float(u.ravel() @ u.ravel()) - hu[best] ** 2 / hh[best]) / (R * d - 1)     # σ² of what it leaves
    parts = [remove_nuisance(amp * drift_shape(np.arange(e.size) / r.fs_d, [tau])[:, 0]) for r, e in
             zip(records, resid_d)]
    rms = math.sqrt(sum(float(x @ x) for x in parts) / sum(x.size for x in parts))
    return WanderSplit(min(max(1.0 - left, 0.0), 1.0), p, R, d, tau=tau, amplitude=amp, rms=rms)


__all__ = ["slow_wander", "shared_wander", "slow_components", "WanderSplit", "WANDER_PER_TREND", "SHARED_ALPHA",
           "HINT_P"]
