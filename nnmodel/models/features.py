"""Fixed (not learned) input front-ends shared by the neural models.

* **Memory filters** (long input memory): a bank of first-order low-pass filters of the
  normalised voltage, with time constants spaced logarithmically between
  ``memory_min_s`` and ``memory_max_s`` (s).  A sum of such terms approximates the slow
  fractional / diffusive dynamics of the actuator (f^-0.6 coupling down to 0.01 Hz,
  solvent back-diffusion over tens of seconds), as in Oustaloup's approximation of
  fractional operators, which no tapped delay line of reasonable length can cover
  (40 s = 10 000 samples at 250 Hz).  They are the generalised, orthonormal-basis-like
  form of an NFIR model's delay line: the networks stay static maps of (filtered)
  past inputs.  Each filter is discretised exactly for a zero-order hold,
  x[k] = a x[k-1] + (1 - a) u[k] with a = exp(-1/(fs tau)), and starts in equilibrium
  with the first input sample (the record starts from steady state, the convention of
  the physics simulator and of ``eap generate``).  With ``memory_abs`` the same filters
  of the voltage's magnitude |V| are added: slow measures of the drive level, for
  behaviour that depends on how hard the actuator is driven (a saturating double layer).
* **RH hat channels**: a piecewise-linear ("hat") encoding of the relative humidity on
  knots ``rh_knots`` (%): channel k is 1 at knot k and falls linearly to 0 at the
  neighbouring knots; outside the knots the end channels stay at 1.  The lag models use
  them to *schedule* their linear bypass (a linear-parameter-varying ARX/FIR part whose
  coefficients interpolate linearly in RH between knots) and the MLP sees them as inputs.

Everything here is numpy, deterministic and computed from whole records, so training
windows cut from the middle of a record see exactly the filter states of the record.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal

__all__ = ["memory_taus", "memory_filters", "rh_hats", "check_knots", "auto_knots"]


def memory_taus(n: int, min_s: float, max_s: float) -> np.ndarray:
    """``n`` time constants (s) spaced logarithmically from ``min_s`` to ``max_s``."""
    if n <= 0:
        return np.zeros(0)
    if n == 1:
        return np.array([float(min_s)])
    return np.logspace(math.log10(min_s), math.log10(max_s), int(n))


def memory_filters(u: np.ndarray, taus: np.ndarray, fs: float) -> np.ndarray:
    """Low-pass filter bank of ``u`` (one column per time constant ``taus`` in s) at the
    sampling rate ``fs`` (Hz); shape (len(u), len(taus)), each filter in equilibrium with
    ``u[0]`` before the first sample."""
    u = np.asarray(u, dtype=float)
    out = np.empty((u.size, len(taus)))
    for j, tau in enumerate(taus):
        a = math.exp(-1.0 / (fs * float(tau)))
        out[:, j], _ = signal.lfilter([1.0 - a], [1.0, -a], u, zi=np.array([a * u[0]]))
    return out


def check_knots(knots) -> str | None:
    """Validation message for ``rh_knots`` (None when valid): ``"auto"`` or a list of
    increasing RH values (%) in 0-100, empty or at least two of them."""
    if knots == "auto":
        return None
    if not isinstance(knots, (list, tuple)):
        return "a list of increasing relative humidities in % (e.g. [40, 60, 80, 100]) or []"
    try:
        k = [float(v) for v in knots]
    except (TypeError, ValueError):
        return "a list of numbers (relative humidity in %)"
    if len(k) == 1:
        return "at least two knots (or [] for an RH-independent bypass)"
    if any(not (0 <= v <= 100) for v in k) or any(b <= a for a, b in zip(k, k[1:])):
        return "strictly increasing relative humidities within 0-100 %"
    return None


def rh_hats(rh: np.ndarray, knots) -> np.ndarray:
    """Hat (piecewise-linear interpolation) weights of ``rh`` (%) on ``knots`` (%):
    shape (len(rh), len(knots)); every row sums to 1."""
    rh = np.asarray(rh, dtype=float)
    k = np.asarray(knots, dtype=float)
    r = np.clip(rh, k[0], k[-1])
    i = np.clip(np.searchsorted(k, r, side="right") - 1, 0, k.size - 2)
    w = (r - k[i]) / (k[i + 1] - k[i])
    out = np.zeros((rh.size, k.size))
    rows = np.arange(rh.size)
    out[rows, i] = 1.0 - w
    out[rows, i + 1] += w
    return out


def auto_knots(rh_series, tol: float = 2.5) -> list[float]:
    """Knots for ``rh_knots: auto`` from the training records' RH (one array per record,
    %): the distinct levels of the records whose RH stays within ``tol`` % (rounded to
    1 %; levels closer than ``tol`` merged), widened to the RH range of all records.
    Fewer than two levels: four knots spread over the range (none if the range is
    narrower than ``tol``)."""
    levels: list[float] = []
    lo, hi = np.inf, -np.inf
    for rh in rh_series:
        rh = np.asarray(rh, dtype=float)
        lo, hi = min(lo, float(rh.min())), max(hi, float(rh.max()))
        if np.ptp(rh) <= tol:
            lev = float(np.round(np.median(rh)))
            if all(abs(lev - v) > tol for v in levels):
                levels.append(lev)
    levels.sort()
    if len(levels) < 2:
        if not np.isfinite(lo) or hi - lo <= tol:
            return []
        return [float(v) for v in np.round(np.linspace(lo, hi, 4), 1)]
    if lo < levels[0] - tol:
        levels.insert(0, float(np.floor(lo)))
    if hi > levels[-1] + tol:
        levels.append(float(np.ceil(hi)))
    return levels

