"""Fit metrics between a measured signal ``y`` and a model output ``yhat``.

All take 1-D arrays of equal length with finite values (otherwise
:class:`~physics.errors.InputError`) and return plain floats.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError


def _pair(y, yhat, *, allow_complex: bool = False) -> tuple[np.ndarray, np.ndarray]:
    arrays = []
    for name, value in (("y", y), ("yhat", yhat)):
        arr = np.asarray(value)
        if arr.dtype.kind not in ("biufc" if allow_complex else "biuf"):
            raise InputError(f"{name}: expected real numbers, got {arr.dtype} values")
        if arr.ndim != 1 or arr.size == 0:
            raise InputError(f"{name}: expected a non-empty 1-D array, got shape {arr.shape}")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise InputError(f"{name}: element {bad[0]} is {arr[bad[0]]}; expected finite values")
        arrays.append(arr if arr.dtype.kind == "c" else arr.astype(float, copy=False))   # no copy of a long record
    if arrays[0].shape != arrays[1].shape:
        raise InputError(f"y has {arrays[0].size} values but yhat has {arrays[1].size}")
    return arrays[0], arrays[1]


#: Samples of a long record's differences formed at a time: the metrics of a record of 10^7
#: samples cost no record-long temporary (a shorter one is one block, the whole record).
BLOCK = 1 << 20


def _blocks(n: int):
    return ((a, min(n, a + BLOCK)) for a in range(0, max(n, 1), BLOCK))


def _sum_sq_error(y: np.ndarray, yhat: np.ndarray, offset: float = 0.0) -> float:
    """Σ (y − offset − ŷ)², formed a block at a time."""
    total = 0.0
    for a, b in _blocks(y.size):
        if offset:                 # (y − offset) − ŷ, as from an aligned copy of y
            e = y[a:b] - offset
            e -= yhat[a:b]
        else:
            e = y[a:b] - yhat[a:b]
        total += float(np.dot(e, e))
    return total


def _centred_dot(y: np.ndarray, x: np.ndarray) -> float:
    """Σ (y − ȳ) x, formed a block at a time."""
    mean = y.mean()
    total = 0.0
    for a, b in _blocks(y.size):
        total += float(np.dot(y[a:b] - mean, x[a:b]))
    return total


def _spread(y: np.ndarray, name: str = "y") -> float:
    """‖y − ȳ‖, refusing a constant signal (for which relative metrics are undefined): one
    whose spread is below 10⁻¹² of its norm is constant up to the rounding of its mean."""
    mean = y.mean()
    sq = 0.0
    for a, b in _blocks(y.size):
        c = y[a:b] - mean
        sq += float(np.dot(c, c))
    spread = float(np.sqrt(sq))
    if spread <= 1e-12 * float(np.sqrt(y.size)) * abs(float(mean)):
        raise InputError(f"{name} is constant; a relative error (NRMSE, fit %) or a correlation is undefined")
    return spread


def rmse(y, yhat, offset: float = 0.0) -> float:
    """Root-mean-square error sqrt(mean((y − ŷ)²)), in the unit of y (of y − ``offset``)."""
    y, yhat = _pair(y, yhat)
    return float(np.sqrt(_sum_sq_error(y, yhat, offset) / y.size))


def nrmse(y, yhat, offset: float = 0.0, names: tuple[str, str] = ("y", "yhat")) -> float:
    """RMSE / std(y) (population std), a fraction: 0 is perfect, 1 is no better than the
    mean of y.  Equals ‖y − ŷ‖ / ‖y − ȳ‖ (with y − ``offset`` for y: the spread of y does
    not depend on it)."""
    y, yhat = _pair(y, yhat)
    return float(np.sqrt(_sum_sq_error(y, yhat, offset))) / _spread(y, names[0])


def fit_percent(y, yhat, offset: float = 0.0, names: tuple[str, str] = ("y", "yhat")) -> float:
    """Fit (%) = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), the NRMSE fit of MATLAB ``compare``/
    ``goodnessOfFit``: 100 is perfect, 0 is the mean of y, negative is worse."""
    return 100.0 * (1.0 - nrmse(y, yhat, offset, names))


def correlation(y, yhat, names: tuple[str, str] = ("y", "yhat")) -> float:
    """Pearson correlation coefficient of y and ŷ (−1…1); ``names``: how errors name y and ŷ."""
    y, yhat = _pair(y, yhat)
    # Σ (y − ȳ)(ŷ − mean ŷ) = Σ (y − ȳ) ŷ: no centred copy of ŷ, and y's a block at a time
    return _centred_dot(y, yhat) / (_spread(y, names[0]) * _spread(yhat, names[1]))


def j_err(mag_exp, mag_sim) -> float:
    """Identification cost of the thesis, eq. 13 (De Luca 2014):
    sqrt(Σ_i (|δ_exp(f_i)| − |δ_sim(f_i)|)² / N), in the unit of the magnitudes.

    Accepts magnitudes or complex responses (their absolute values are compared).
    """
    a, b = _pair(mag_exp, mag_sim, allow_complex=True)
    return rmse(np.abs(a), np.abs(b))


def summary(y, yhat, offset: float = 0.0, names: tuple[str, str] = ("y", "yhat")) -> dict:
    """All time-domain metrics as a JSON-ready dict: ``n``, ``rmse``, ``nrmse``,
    ``fit_percent``, ``correlation``, of y − ``offset`` against ŷ (a long record is not
    copied to remove it; ``names``: how an error names y and ŷ, e.g. the record and the
    model).  (:func:`j_err` compares FRF magnitudes, not signals, and is left out.)"""
    return {"n": int(np.size(y)), "rmse": rmse(y, yhat, offset), "nrmse": nrmse(y, yhat, offset, names),
            "fit_percent": fit_percent(y, yhat, offset, names), "correlation": correlation(y, yhat, names)}


#: Nuisance terms per record (offset and linear drift), counted as parameters in the BIC.
NUISANCE_TERMS = 2


def nuisance_terms(e: np.ndarray, t: np.ndarray | None = None) -> tuple[float, float]:
    """(offset [units of e] at the record's start, drift [units per s]) of the least-squares
    line through ``e`` (``t`` [s], default the sample index)."""
    e = np.asarray(e, dtype=float)
    t = np.arange(e.size, dtype=float) if t is None else np.asarray(t, dtype=float)
    tc = t - t.mean()
    den = float(tc @ tc)
    slope = float(tc @ e) / den if den > 0 else 0.0
    return float(e.mean() - slope * (t.mean() - t[0])), slope


def remove_nuisance(e: np.ndarray, t: np.ndarray | None = None) -> np.ndarray:
    """``e`` minus its least-squares offset and linear drift a + b·t (``t`` [s], default the
    sample index): the nuisance terms of every record (a laser's zero is arbitrary and
    drifts slowly; neither is physics)."""
    e = np.asarray(e, dtype=float)
    t = np.arange(e.size, dtype=float) if t is None else np.asarray(t, dtype=float)
    tc = t - t.mean()
    den = float(tc @ tc)
    slope = float(tc @ e) / den if den > 0 else 0.0
    return e - e.mean() - slope * tc
