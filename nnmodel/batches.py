"""Normalised records as torch batches, and the free-run error (the validation metric).

Shared by the training loop (:mod:`nnmodel.training`) and the models (which compare a
trained network with its start without importing Lightning)."""
from __future__ import annotations

import math

import numpy as np
import torch

__all__ = ["pad_batch", "split_batch", "free_run_error", "free_run_errors", "paired_gain", "correlation_time"]


def pad_batch(seqs, n_init: int) -> dict:
    """Whole records as one padded batch: history = first ``n_init`` samples."""
    L = max(len(s) for s in seqs)
    B = len(seqs)
    u = np.zeros((B, L) + np.shape(seqs[0].u)[1:], np.float32)
    y = np.zeros((B, L), np.float32)
    rh = np.zeros((B, L) + np.shape(seqs[0].rh)[1:], np.float32) if seqs[0].rh is not None else None
    mask = np.zeros((B, L), np.float32)
    for i, s in enumerate(seqs):
        n = len(s)
        u[i, :n], y[i, :n] = s.u, s.y
        u[i, n:] = s.u[-1]  # padding: hold the last input (masked out of the error anyway)
        if rh is not None:
            rh[i, :n] = s.rh
            rh[i, n:] = s.rh[-1]
        mask[i, n_init:n] = 1.0
    t = lambda a: None if a is None else torch.as_tensor(a)  # noqa: E731
    return {"u": t(u), "y": t(y), "rh": t(rh), "mask": t(mask)}


def split_batch(batch, k: int):
    """(history, inputs, outputs, RH) of a batch: the first ``k`` samples are history."""
    u, y, rh = batch["u"], batch["y"], batch["rh"]
    hist = (u[:, :k], y[:, :k], None if rh is None else rh[:, :k])
    return hist, u[:, k:], y[:, k:], None if rh is None else rh[:, k:]


def free_run_errors(core, seqs) -> list[np.ndarray]:
    """Free-run squared errors (normalised units) of ``core`` over whole records, one array
    per record from sample ``n_init`` on, each initialised from its first ``n_init``
    samples (non-finite values count as 1e12)."""
    batch = pad_batch(seqs, core.n_init)
    k = core.n_init
    hist, u, y, rh = split_batch(batch, k)
    was_training = core.training
    core.eval()
    with torch.no_grad():
        y_hat = core.simulate(core.init_state(*hist), u, rh)
    core.train(was_training)
    err = torch.nan_to_num((y_hat - y) ** 2, nan=1e12, posinf=1e12).double().numpy()
    return [err[i, :max(0, len(s) - k)] for i, s in enumerate(seqs)]


def free_run_error(core, seqs) -> float:
    """Free-run NRMSE (normalised units) of ``core`` over whole records, each initialised
    from its first ``n_init`` samples (the validation metric, outside Lightning)."""
    err = free_run_errors(core, seqs)
    n = sum(e.size for e in err)
    return min(math.sqrt(sum(float(e.sum()) for e in err) / max(n, 1)), 1e6)


def correlation_time(x: np.ndarray) -> float:
    """Integrated autocorrelation time (samples) of a series: 1 + 2 Σ ρ_k over the lags
    before the autocorrelation first drops below zero (Geyer's initial positive sequence;
    Sokal, *Monte Carlo methods in statistical mechanics*, 1997, §3)."""
    x = np.asarray(x, float) - np.mean(x)
    n = x.size
    if n < 3 or not np.any(x):
        return 1.0
    f = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[:n]
    rho = acf / acf[0]
    neg = np.flatnonzero(rho[1:] < 0)
    stop = 1 + (neg[0] if neg.size else n - 1)
    return float(1.0 + 2.0 * rho[1:stop].sum())


def paired_gain(err_ref, err_new, blocks: int) -> tuple[float, float, int]:
    """(gain, standard error, number of blocks): the mean of ``err_ref - err_new`` (squared
    errors per record, as :func:`free_run_errors` gives) and its standard error by batch
    means — each record cut into contiguous blocks, about ``blocks`` in all but none shorter
    than the difference's correlation time (:func:`correlation_time`), so that block means
    vary nearly as independent draws (Law & Kelton, *Simulation Modeling and Analysis*,
    §9.5.3).  The standard error is inf with fewer than 2 blocks.  Two models that start their
    free runs after different numbers of samples (``n_init``) are paired on the samples both
    score: each record's errors end at the record's end, so they are aligned there."""
    d = []
    for a, b in zip(err_ref, err_new):
        a, b = np.asarray(a, float), np.asarray(b, float)
        m = min(a.size, b.size)
        d.append(a[a.size - m:] - b[b.size - m:])
    d = [x for x in d if x.size]
    n = sum(x.size for x in d)
    if n == 0:
        return 0.0, math.inf, 0
    tau = max(correlation_time(x) for x in d)
    size = max(1, math.ceil(n / blocks), math.ceil(tau))
    parts = [p for x in d for p in np.array_split(x, max(1, x.size // size))]
    sums = np.array([p.sum() for p in parts])
    lens = np.array([p.size for p in parts], float)
    gain = float(sums.sum() / n)
    if len(parts) < 2:
        return gain, math.inf, len(parts)
    var = float(np.sum((sums - gain * lens) ** 2)) / n ** 2 * len(parts) / (len(parts) - 1)
    return gain, math.sqrt(var), len(parts)


#: blocks the validation data are cut into to judge a correction's gain
#: (:func:`nnmodel.models.base.keep_if_better`, :mod:`nnmodel.models.crossval`)
GAIN_BLOCKS = 10
#: standard errors by which a correction's validation gain must exceed zero: the gain must exceed
#: its own uncertainty (a stricter test dropped networks 35 % better than linear on 500
#: validation samples, bench/slow_plant.py)
GAIN_SE = 1.0


def gain_is_real(r_net: float, r_ref: float, gain: float, se: float) -> bool:
    """The single-split rule of :func:`nnmodel.models.base.keep_if_better`: a lower error, by more than
    :data:`GAIN_SE` standard errors of the gain when that is known."""
    return r_net < r_ref and (not math.isfinite(se) or gain > GAIN_SE * se)
