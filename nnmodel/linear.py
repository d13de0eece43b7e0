"""The linear yardstick: the best ARX model on the same split as the networks.

    y[k] = a_1 y[k-1] + ... + a_na y[k-na] + b_0 u[k-d] + ... + b_{nb-1} u[k-d-nb+1] + c (+ e rh[k])

(``d = 0``: direct feedthrough; RH enters linearly when the records carry it.)  The orders
are chosen on the validation data: every (na, nb) of a grid is fitted by least squares on
the training records (one set of normal equations, the candidates are its sub-blocks) and
scored by its free-run NRMSE on the validation records; of the orders within 1 % of the best
score the one with the fewest coefficients is kept.  It and the next best orders
(:data:`OE_STARTS` in all: the equation error ranks orders poorly on noisy or finely sampled
data) are then refined for the output error (the simulation error on the training records,
Levenberg-Marquardt with the sensitivities filtered by 1/A; Ljung, *System Identification*,
2nd ed., §4.2 and §10.2), and the same rule picks among the ARX model and the refinements
on the validation data.  A free run starts from the
first ``n_init`` measured samples of a record, as the networks' does.

All arithmetic is numpy/scipy on normalised signals (``lfilter`` for simulation), so the
whole search costs seconds on records of 10^5 samples.  The fitted :class:`LinearModel` is
plain numbers (:meth:`LinearModel.card`), the row ``linear`` of ``eap train-compare`` and
the start of the networks (:mod:`nnmodel.models.features`, ``linear_start``).
"""
from __future__ import annotations

import collections
import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from physics.errors import InputError

__all__ = ["LinearModel", "fit_linear", "NA_GRID", "NB_GRID"]

#: output-lag orders tried (0 = FIR)
NA_GRID = (0, 1, 2, 3, 4, 6, 8, 10)
#: input-lag orders tried
NB_GRID = (1, 2, 3, 4, 6, 8, 10, 15, 20, 30)
#: orders whose validation score is within this fraction of the best count as equally good
PARSIMONY = 0.01
#: clip of a simulated normalised output (a diverging candidate scores large, not inf/NaN)
CLIP = 1e6
#: output-error refinement only when samples x parameters stays below this (cheap)
OE_BUDGET = 5e8
#: ARX orders the output-error refinement starts from: the chosen one and the next best by
#: validation score
OE_STARTS = 4


@dataclass
class LinearModel:
    """A fitted ARX model in normalised units (``u_mean``, ``u_std`` ... give the scales)."""

    na: int
    nb: int
    delay: int
    a: np.ndarray
    b: np.ndarray
    c: float
    e: float | None
    scale: dict
    report: dict = field(default_factory=dict)

    @property
    def n_init(self) -> int:
        return max(self.na, self.nb - 1 + self.delay, 1)

    @property
    def uses_rh(self) -> bool:
        return self.e is not None

    def label(self) -> str:
        kind = "output-error" if self.report.get("output_error_kept") else "ARX"
        return f"linear {kind} (na={self.na}, nb={self.nb})"

    # ---------------------------------------------------------------- simulation
    def _norm(self, name, x):
        return (np.asarray(x, float) - self.scale[f"{name}_mean"]) / self.scale[f"{name}_std"]

    def _forcing(self, un, rhn, before=None):
        """w[k] = sum_j b_j u[k-d-j] + c + e rh[k] (normalised), for every k; inputs before
        the record are ``before`` (a value held, or the last ``nb - 1 + delay`` inputs of the
        previous piece; default: held at the first sample)."""
        pad = self.nb - 1 + self.delay
        head = np.full(pad, un[0] if before is None else before) if np.ndim(before) == 0 else before
        up = np.concatenate([head, un])
        w = np.convolve(up, np.r_[np.zeros(self.delay), self.b])[pad:pad + un.size] + self.c
        if self.e is not None:
            w = w + self.e * rhn
        return w

    def _tail(self, before, un) -> np.ndarray:
        """The last ``nb - 1 + delay`` inputs up to the end of ``un`` (the next piece's past)."""
        pad = self.nb - 1 + self.delay
        return np.concatenate([before, un])[len(before) + un.size - pad:]

    def free_run_norm(self, un, rhn, yn_init=None, state=None):
        """Free run in normalised units, as ``(y, state)``; ``state``: where the previous
        piece of the record ended (None: the record's start), the returned one continues
        the run on the next piece (same output as one run over the whole record).  At the
        start, ``yn_init`` (measured outputs) start it: the first ``len(yn_init)`` outputs
        are returned as given, inputs before the record held at the first sample; else the
        run starts from rest: 0 V before the record and the output at its 0 V steady state
        (the convention of the networks' free run)."""
        den = np.r_[1.0, -self.a]
        pad = self.nb - 1 + self.delay
        m = 0 if state is not None or yn_init is None else len(yn_init)
        if state is not None:
            before, zi = state
        elif m:
            before = np.full(pad, un[0])
            past = np.asarray(yn_init, float)[::-1][:self.na]
            past = np.r_[past, np.full(self.na - past.size, past[-1])] if past.size else past
            zi = signal.lfiltic([1.0], den, past) if self.na else np.zeros(0)
        else:
            rest = -self.scale["u_mean"] / self.scale["u_std"]           # 0 V, normalised
            before = np.full(pad, rest)
            w0 = rest * float(np.sum(self.b)) + self.c + (0.0 if self.e is None else self.e * rhn[0])
            y0 = w0 / max(1e-12, 1.0 - float(np.sum(self.a)))
            zi = signal.lfiltic([1.0], den, np.full(self.na, y0)) if self.na else np.zeros(0)
        w = self._forcing(un, rhn, before)
        with np.errstate(all="ignore"):
            if self.na:
                y, zf = signal.lfilter([1.0], den, w[m:], zi=zi)
            else:
                y, zf = w[m:].copy(), zi
        y = np.clip(np.nan_to_num(y, nan=CLIP, posinf=CLIP, neginf=-CLIP), -CLIP, CLIP)
        y = np.concatenate([np.asarray(yn_init, float), y]) if m else y
        return y, (self._tail(before, un), zf)

    def simulate_norm(self, un, rhn, yn_init=None) -> np.ndarray:
        """Free run in normalised units over a whole record (see :meth:`free_run_norm`)."""
        return self.free_run_norm(un, rhn, yn_init)[0]

    def free_run(self, u, rh=None, y_init=None, state=None):
        """Free run in physical units, as ``(y, state)`` (``y_init``: first measured outputs,
        returned as given; ``state``: see :meth:`free_run_norm`)."""
        un = self._norm("u", u)
        rhn = self._norm("rh", rh) if self.uses_rh else None
        if rhn is not None and rhn.ndim == 0:
            rhn = np.full(un.size, float(rhn))
        yi = None if y_init is None or len(y_init) == 0 else self._norm("y", y_init)
        y, state = self.free_run_norm(un, rhn, yi, state)
        return y * self.scale["y_std"] + self.scale["y_mean"], state

    def simulate(self, u, rh=None, y_init=None) -> np.ndarray:
        """Free run in physical units (``y_init``: first measured outputs, returned as given)."""
        return self.free_run(u, rh, y_init)[0]

    def one_step(self, u, rh, y) -> np.ndarray:
        """One-step-ahead prediction from the measured past (physical units)."""
        un, yn = self._norm("u", u), self._norm("y", y)
        rhn = self._norm("rh", rh) if self.uses_rh else None
        w = self._forcing(un, rhn)
        ypad = np.concatenate([np.full(self.na, yn[0]), yn])
        ar = np.zeros(yn.size)
        for i, ai in enumerate(self.a, start=1):
            ar += ai * ypad[self.na - i:self.na - i + yn.size]
        return (w + ar) * self.scale["y_std"] + self.scale["y_mean"]

    # ---------------------------------------------------------------- persistence
    def card(self) -> dict:
        """Plain-number description (JSON) from which :meth:`from_card` rebuilds the model."""
        return {"na": self.na, "nb": self.nb, "delay": self.delay, "a": [float(v) for v in self.a],
                "b": [float(v) for v in self.b], "c": float(self.c), "e": None if self.e is None else float(self.e),
                "scale": {k: float(v) for k, v in self.scale.items()}, "report": self.report}

    @classmethod
    def from_card(cls, card: dict, where: str = "card") -> "LinearModel":
        try:
            m = cls(int(card["na"]), int(card["nb"]), int(card["delay"]), np.asarray(card["a"], float),
                    np.asarray(card["b"], float), float(card["c"]), None if card["e"] is None else float(card["e"]),
                    {k: float(v) for k, v in card["scale"].items()}, dict(card.get("report") or {}))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: linear start is malformed ({exc})") from None
        if m.a.size != m.na or m.b.size != m.nb or m.delay not in (0, 1) or not (
                np.all(np.isfinite(m.a)) and np.all(np.isfinite(m.b))):
            raise InputError(f"{where}: linear start has inconsistent orders or non-finite coefficients")
        return m


# ---------------------------------------------------------------------- fitting
def _scale(train, use_rh: bool) -> dict:
    def ms(x):
        m, s = float(np.mean(x)), float(np.std(x))
        return m, (s if np.isfinite(s) and s > 1e-12 * max(1.0, abs(m)) else 1.0)
    out = {}
    for name, xs in (("u", [r.u for r in train]), ("y", [r.y for r in train])):
        out[f"{name}_mean"], out[f"{name}_std"] = ms(np.concatenate(xs))
    if use_rh:
        out["rh_mean"], out["rh_std"] = ms(np.concatenate([r.rh for r in train]))
    return out


def _normed(recs, sc, use_rh):
    return [((r.u - sc["u_mean"]) / sc["u_std"], (r.y - sc["y_mean"]) / sc["y_std"],
             (r.rh - sc["rh_mean"]) / sc["rh_std"] if use_rh else None) for r in recs]


def _regressors(seqs, na_max, nb_max, delay, use_rh):
    """Normal equations of the largest ARX: columns [y lags 1..na_max, u lags 0..nb_max-1,
    1, rh]; every candidate's are a sub-block (all rows start at the largest history)."""
    k0 = max(na_max, nb_max - 1 + delay)
    G = None
    for un, yn, rhn in seqs:
        n = un.size
        if n <= k0 + 1:
            continue
        idx = np.arange(k0, n)
        cols = [yn[idx - i] for i in range(1, na_max + 1)] + [un[idx - delay - j] for j in range(nb_max)]
        cols.append(np.ones(idx.size))
        if use_rh:
            cols.append(rhn[idx])
        X = np.stack(cols, 1)
        if G is None:
            G, g = np.zeros((X.shape[1],) * 2), np.zeros(X.shape[1])
        G += X.T @ X
        g += X.T @ yn[idx]
    if G is None:
        raise InputError(f"every training record is shorter than the longest ARX candidate ({k0 + 2} samples)")
    return G, g


def _solve(G, g, na, nb, na_max, nb_max, use_rh):
    cols = list(range(na)) + list(range(na_max, na_max + nb)) + [na_max + nb_max] \
        + ([na_max + nb_max + 1] if use_rh else [])
    Gs = G[np.ix_(cols, cols)]
    Gs = Gs + np.eye(len(cols)) * (1e-9 * np.trace(Gs) / len(cols))
    w = np.linalg.solve(Gs, g[cols])
    return w[:na], w[na:na + nb], float(w[na + nb]), (float(w[na + nb + 1]) if use_rh else None)


def _free_run_nrmse(model: LinearModel, seqs) -> float:
    e2 = v2 = 0.0
    k = model.n_init
    for un, yn, rhn in seqs:
        if un.size <= k + 1:
            continue
        yh = model.simulate_norm(un, rhn, yn[:k])
        e2 += float(np.sum((yh[k:] - yn[k:]) ** 2))
        v2 += float(np.sum((yn[k:] - yn[k:].mean()) ** 2))
    return math.sqrt(e2 / v2) if v2 > 0 else math.inf


def _stable(a) -> bool:
    return a.size == 0 or bool(np.all(np.abs(np.roots(np.r_[1.0, -a])) < 1.0 - 1e-9))


def _sse_and_jacobian(m: LinearModel, seqs, want_jac: bool = True):
    """Free-run error (sum of squares) of ``m`` on ``seqs`` and, with ``want_jac``, the
    Gauss-Newton system (J'J, J'r) for (a, b, c, e): the output sensitivities are the
    regressors [y_hat lags, u lags, 1, rh] filtered by 1/A (one ``lfilter`` per record)."""
    k, den = m.n_init, np.r_[1.0, -m.a]
    sse, H, grad = 0.0, None, None
    for un, yn, rhn in seqs:
        if un.size <= k + 1:
            continue
        yh = m.simulate_norm(un, rhn, yn[:k])
        r = yn[k:] - yh[k:]
        sse += float(r @ r)
        if not want_jac:
            continue
        idx = np.arange(k, un.size)
        pad = m.nb - 1 + m.delay
        up = np.concatenate([np.full(pad, un[0]), un])
        cols = [yh[idx - i] for i in range(1, m.na + 1)] + [up[idx + pad - m.delay - j] for j in range(m.nb)]
        cols.append(np.ones(idx.size))
        if m.e is not None:
            cols.append(rhn[idx])
        J = signal.lfilter([1.0], den, np.stack(cols, 1), axis=0) if m.na else np.stack(cols, 1)
        H = J.T @ J if H is None else H + J.T @ J
        grad = J.T @ r if grad is None else grad + J.T @ r
    return sse, H, grad


def _output_error(model: LinearModel, seqs, iterations: int = 40) -> LinearModel:
    """Refine (a, b, c, e) for the free-run error on ``seqs`` by Levenberg-Marquardt with
    analytic sensitivities; steps that would make the model unstable are refused."""
    na, nb = model.na, model.nb

    def unpack(x):
        return LinearModel(na, nb, model.delay, x[:na], x[na:na + nb], float(x[na + nb]),
                           float(x[na + nb + 1]) if model.e is not None else None, model.scale)
    x = np.r_[model.a, model.b, model.c, [] if model.e is None else [model.e]]
    cur = unpack(x)
    sse, H, grad = _sse_and_jacobian(cur, seqs)
    lam = 1e-3
    for _ in range(iterations):
        D = np.diag(np.diag(H)) + 1e-12 * np.trace(H) / len(H) * np.eye(len(H))
        try:
            step = np.linalg.solve(H + lam * D, grad)
        except np.linalg.LinAlgError:
            break
        cand = unpack(x + step)
        new = _sse_and_jacobian(cand, seqs, want_jac=False)[0] if _stable(cand.a) else math.inf
        if new < sse:
            done = sse - new < 1e-10 * sse
            x, cur = x + step, cand
            sse, H, grad = _sse_and_jacobian(cur, seqs)
            lam = max(lam / 3.0, 1e-9)
            if done:
                break
        else:
            lam *= 4.0
            if lam > 1e8:
                break
    return cur


def _finite(x: float) -> float | None:
    """A score for the card (None for a candidate whose free run diverged)."""
    return float(x) if math.isfinite(x) else None


#: fitted models of this process, by a hash of their data and options (the same data give the
#: same model); the oldest is dropped beyond :data:`_CACHE_SIZE`
_CACHE: "collections.OrderedDict[str, LinearModel]" = collections.OrderedDict()
_CACHE_SIZE = 16


def _key(train, val, *options) -> str:
    h = hashlib.sha1()
    for part in (train, val or []):
        h.update(b"|")
        for r in part:
            for a in (r.u, r.y, r.rh):
                h.update(b"-" if a is None else np.ascontiguousarray(a).tobytes())
            h.update(repr(float(r.fs)).encode())
    h.update(repr(options).encode())
    return h.hexdigest()


def fit_linear(train, val=None, val_fraction: float = 0.2, feedthrough: bool = True,
               use_rh: bool | None = None, na_grid=NA_GRID, nb_grid=NB_GRID,
               output_error: bool = True) -> LinearModel:
    """The best linear ARX model for these records (see the module docstring).  Without
    validation records the last ``val_fraction`` of every training record validates (as the
    networks do); ``use_rh``: RH as a linear input (None: when the records carry it);
    ``na_grid``, ``nb_grid``: the orders tried; ``output_error``: try the refinement.
    Results are cached per process (the same data give the same model; the last 16 kept)."""
    from .data import check_records
    train = check_records(train, "training")
    val = check_records(val, "validation") if val else None
    options = (val_fraction, feedthrough, use_rh, tuple(na_grid), tuple(nb_grid), output_error)
    key = _key(train, val, *options)
    if key not in _CACHE:
        from threadpoolctl import threadpool_limits
        with threadpool_limits(limits=1, user_api="blas"):   # small matrices: one thread is fastest
            _CACHE[key] = _fit(train, val, *options)
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    _CACHE.move_to_end(key)
    return _CACHE[key]


def _fit(train, val, val_fraction, feedthrough, use_rh, na_grid, nb_grid, output_error) -> LinearModel:
    from .data import split_records
    if not val:
        k = max(max(na_grid), max(nb_grid))
        train, val = split_records(train, val_fraction, min_len=k + 2)
        if not val:
            val = train
    use_rh = train[0].rh is not None if use_rh is None else bool(use_rh and train[0].rh is not None)
    sc = _scale(train, use_rh)
    tr, va = _normed(train, sc, use_rh), _normed(val, sc, use_rh)
    delay = 0 if feedthrough else 1
    # orders whose history fits in half the shortest training record
    room = max(1, min(len(r) for r in train) // 2 - 1)
    grid_na = [n for n in na_grid if n <= room] or [0]
    grid_nb = [n for n in nb_grid if n <= room] or [1]
    na_max, nb_max = max(grid_na), max(grid_nb)
    G, g = _regressors(tr, na_max, nb_max, delay, use_rh)
    scores, fits = {}, []
    for na in grid_na:
        for nb in grid_nb:
            a, b, c, e = _solve(G, g, na, nb, na_max, nb_max, use_rh)
            m = LinearModel(na, nb, delay, a, b, c, e, sc)
            scores[f"{na},{nb}"] = s = _free_run_nrmse(m, va)
            fits.append((s, na + nb, m))
    # parsimony: the fewest coefficients among the orders within PARSIMONY of the best score
    top = min(f[0] for f in fits)
    score, _, model = min((f for f in fits if f[0] <= top * (1 + PARSIMONY) + 1e-6), key=lambda f: (f[1], f[0]))
    report = {"orders_scored_on": "validation free-run NRMSE", "grid_na": grid_na, "grid_nb": grid_nb,
              "validation_nrmse_arx": _finite(score), "output_error_kept": False}
    n_train = sum(u.size for u, _, _ in tr)
    # the equation error ranks orders poorly (it weights high frequencies, and is biased by
    # output noise): the refinement starts from the chosen order and the next best ones
    starts = [model] + [f[2] for f in sorted(fits, key=lambda f: f[0]) if f[2] is not model][:OE_STARTS - 1]
    refined = []
    for start in starts:
        if output_error and np.isfinite(score) and n_train * (start.na + start.nb + 2) <= OE_BUDGET:
            oe = _output_error(start, tr)
            refined.append((_free_run_nrmse(oe, va), start.na + start.nb, oe))
    if refined:
        report["validation_nrmse_output_error"] = _finite(min(f[0] for f in refined))
        report["output_error_starts"] = [f"{m.na},{m.nb}" for _, _, m in refined]
        pool = [(score, model.na + model.nb, model)] + refined    # the same parsimony over both
        best = min(f[0] for f in pool)
        score, _, kept = min((f for f in pool if f[0] <= best * (1 + PARSIMONY) + 1e-6), key=lambda f: (f[1], f[0]))
        report["output_error_kept"] = kept is not model
        model = kept
    report["validation_nrmse"] = _finite(score)
    report["scores"] = {k: _finite(v) for k, v in scores.items()}
    model.report = report
    return model
