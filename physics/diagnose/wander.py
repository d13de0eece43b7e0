"""The slow wander of the records: how much of it is noise, and how much the records share.

A model's residual keeps, below the excited band, what the per-record nuisance terms (offset
and linear drift, :func:`physics.metrics.remove_nuisance`) leave of a slow drift.  When the
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

from .records import WALK_AFTER_TREND

#: Mean square of a random walk left after its linear trend, per mean square of the fitted
#: trend's rise over the record: (σ²T/15) / (6σ²T/5) = 1/18 (Brownian motion of variance σ²t on
#: [0, T]: its least-squares slope has variance 6σ²/(5T)).
WANDER_PER_TREND = WALK_AFTER_TREND / (6.0 / 5.0)


def slow_wander(records: Sequence, resid_d: Sequence[np.ndarray], nuisance) -> float:
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
    would pass for drift.  NaN when no record can show it."""
    num = dof = 0.0
    for r, e, (_, b) in zip(records, resid_d, nuisance):
        if r.kind != "broadband":      # a step's slow physics (creep, back-relaxation) would pass for drift
            continue
        T = r.ts.duration
        num += WANDER_PER_TREND * (b * T) ** 2
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


#: Significance of the test that the records share part of their slow wander (the F-test of
#: :func:`shared_wander`; one-sided, the false alarms when they wander independently).
SHARED_ALPHA = 0.01
#: Below this p-value (the conventional "suggestive" level) but not below SHARED_ALPHA, the
#: test is inconclusive: the records hint at a shared part they cannot confirm.
HINT_P = 0.10
#: At most this many cosine lines per record enter the test.
MAX_LINES = 24


@dataclass
class WanderSplit:
    """What the records' slow residuals share (:func:`shared_wander`)."""

    fraction: float          # share of the slow power common to the records (0 when not significant); NaN: not testable
    p_value: float           # of the F-test (independent wanders)
    records: int             # records compared
    dims: int                # slow components per record (the trend and the cosine lines)
    why: str = ""            # why it could not be tested

    @property
    def testable(self) -> bool:
        return math.isfinite(self.fraction)

    @property
    def inconclusive(self) -> bool:
        """The records hint at a shared part (p < :data:`HINT_P`) without confirming it."""
        return self.testable and self.fraction == 0 and self.p_value < HINT_P

    def text(self) -> str:
        if not self.testable:
            return self.why
        if self.fraction > 0:
            return (f"{100 * self.fraction:.0f} % of it is common to the {self.records} records (F-test on "
                    f"{self.dims} slow components each, p = {self.p_value:.2g}): a drift they share, described, "
                    "not noise")
        if self.inconclusive:
            return (f"the {self.records} records hint that they share part of it but cannot confirm it (F-test on "
                    f"{self.dims} slow components each, p = {self.p_value:.2g}, not below {SHARED_ALPHA:g}): counted "
                    "as noise")
        return (f"it does not repeat from record to record (F-test on {self.dims} slow components of the "
                f"{self.records} records, p = {self.p_value:.2g}): the sensor's own wander, counted as noise")


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


def slow_components(records: Sequence, resid_d: Sequence[np.ndarray], nuisance, wander: float):
    """(R × d array of whitened slow components, d) of the records' residuals on their common
    span T from each record's start, or a string saying why they cannot show it.

    Each record's components (:func:`_operator`: trend and k = ⌊2T·f⌋ cosine lines below the
    broadband records' lowest excited frequency f, at most :data:`MAX_LINES`) are whitened by
    their covariance when the record wanders independently: a random walk detrended over its
    record whose RMS is ``wander`` [m] (:func:`slow_wander`) plus the record's white noise —
    so that, wandering independently, every record's components are independent N(0, σ²)."""
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
    rows = []
    for r, e, (_, b) in zip(records, resid_d, nuisance):
        n = int(round(span * r.fs_d))
        M = _operator(n, r.fs_d, span, k)
        raw = np.asarray(e[:n], float) + b * np.arange(n) / r.fs_d    # the record's own trend back in
        ML = np.cumsum(M[:, ::-1], axis=1)[:, ::-1]                    # M · (cumulative sum): a random walk
        walk = (ML @ ML.T) / n * (wander ** 2 / WALK_AFTER_TREND)
        white = (M @ M.T) * (r.noise_floor_d ** 2 if math.isfinite(r.noise_floor_d) else 0.0)
        L = np.linalg.cholesky(walk + white + 1e-12 * np.trace(walk + white) / (k + 1) * np.eye(k + 1))
        rows.append(np.linalg.solve(L, M @ raw))
    return np.array(rows), k + 1


def shared_wander(records: Sequence, resid_d: Sequence[np.ndarray], nuisance, wander: float) -> WanderSplit:
    """Do the records share part of their slow residual?  A one-way random-effects analysis on
    the whitened slow components u_r (:func:`slow_components`; R records, d components): with
    ū their mean, F = (R|ū|²/d) / (Σ_r|u_r − ū|²/(d(R − 1))) follows F(d, d(R − 1)) when the
    records wander independently; at p < :data:`SHARED_ALPHA` the records share a part, and its
    fraction of the slow power is |s|²/(|s|² + σ²) with |s|² = |ū|² − Σ|u_r − ū|²/(R(R − 1)) and
    σ² = Σ|u_r − ū|²/(R − 1) (unbiased; the intraclass correlation)."""
    from scipy.stats import f as fdist
    got = slow_components(records, resid_d, nuisance, wander) if math.isfinite(wander) and wander > 0 else \
        "no slow wander to split"
    if isinstance(got, str):
        return WanderSplit(math.nan, math.nan, len(records), 0, got)
    u, d = got
    R = len(u)
    mean = u.mean(axis=0)
    within = float(((u - mean) ** 2).sum())
    F = (R * float(mean @ mean) / d) / (within / (d * (R - 1))) if within > 0 else math.inf
    p = float(fdist.sf(F, d, d * (R - 1)))
    shared = max(float(mean @ mean) - within / (R * (R - 1)), 0.0)
    ind = within / (R - 1)
    frac = shared / (shared + ind) if p < SHARED_ALPHA and shared + ind > 0 else 0.0
    return WanderSplit(frac, p, R, d)


__all__ = ["slow_wander", "shared_wander", "slow_components", "WanderSplit", "WANDER_PER_TREND", "SHARED_ALPHA",
           "HINT_P"]
