"""Tapped-delay (NARX / NFIR) simulator shared by the ``ff``, ``rbf`` and ``narx`` models.

    y[k] = f(y[k-1], ..., y[k-na], u[k-d], ..., u[k-d-nb+1], m[k], rh[k]),   d = 0 or 1

``f`` is a *map* (MLP or Gaussian RBF network, each with a linear bypass).  The state is
the vector of past outputs; the input part of ``f``'s first layer does not depend on the
state, so it is computed for the whole sequence at once and only the output-lag part runs
in the time loop.  With ``na = 0`` (NFIR) there is no loop at all.

Input channels (all normalised; tensors (batch, time) for a single channel or
(batch, time, channels)): the first ``n_tap`` input channels get ``nb`` delays each
(voltage; for the grey-box hybrid also the physics output), the next ``n_mem`` are used
at time k only (memory filters, physics states: see :mod:`nnmodel.models.features`),
and the RH channels (normalised RH, then ``n_sched`` hat channels) at time k.  With
``n_sched > 0`` the MLP map's linear bypass is *scheduled*: its coefficients interpolate
linearly in RH between the hat knots (a linear-parameter-varying ARX/FIR part).  With
``residual`` the output is input channel 1 (the physics output) plus the map.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .core import SequenceCore

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "gelu": nn.GELU, "silu": nn.SiLU,
               "elu": nn.ELU, "sigmoid": nn.Sigmoid}

#: bound on the normalised output during simulation, so a diverging model returns large
#: finite numbers (and a large validation error) rather than inf/NaN
OUTPUT_CLIP = 1e3


class MLPMap(nn.Module):
    """Linear bypass + MLP: f(yl, x) = a.yl + b.x + c + W_out act(... act(W_y yl + W_x x + b1)).

    With ``n_sched = K > 0`` the last K columns of x are RH hat weights s_k (summing to 1)
    and the bypass is sum_k s_k (a_k.yl + b_k.x' + c_k), x' = x without the hat columns.
    """

    def __init__(self, n_y: int, n_x: int, hidden: int, layers: int, activation: str = "tanh",
                 linear: bool = True, poly_degree: int = 1, n_sched: int = 0):
        super().__init__()
        self.n_y, self.n_x = n_y, n_x
        self.n_sched = int(n_sched)
        self.poly_degree = int(poly_degree)
        self.hidden_size = hidden if layers > 0 else 0
        self.linear = linear or self.hidden_size == 0
        H = self.hidden_size
        if H:
            self.in_y = nn.Linear(n_y, H, bias=False) if n_y else None
            self.in_x = nn.Linear(n_x, H)
            self.hidden = nn.ModuleList(nn.Linear(H, H) for _ in range(layers - 1))
            self.out = nn.Linear(H, 1)
            self.act = ACTIVATIONS[activation]()
            with torch.no_grad():  # start as the (linear / polynomial) bypass alone
                self.out.weight.zero_()
                self.out.bias.zero_()
        if self.linear:
            P = self.poly_degree
            K = max(1, self.n_sched)
            self.lin_y = nn.Linear(n_y * P, K, bias=False) if n_y else None
            self.lin_x = nn.Linear((n_x - self.n_sched) * P, K)
            with torch.no_grad():
                if self.lin_y is not None:
                    self.lin_y.weight.zero_()
                self.lin_x.weight.zero_()
                self.lin_x.bias.zero_()

    def powers(self, z):
        """z and its elementwise powers 2..poly_degree (the polynomial bypass terms)."""
        if self.poly_degree == 1:
            return z
        return torch.cat([z ** p for p in range(1, self.poly_degree + 1)], -1)

    def precompute(self, x):
        """(first-layer input part, bypass input part, hat weights or None) for all times."""
        pre = self.in_x(x) if self.hidden_size else None
        lin = sched = None
        if self.linear:
            if self.n_sched:
                sched = x[..., -self.n_sched:]
                lin = self.lin_x(self.powers(x[..., :-self.n_sched]))
            else:
                lin = self.lin_x(self.powers(x))[..., 0]
        return pre, lin, sched

    def step(self, yl, cache):
        pre, lin, sched = cache
        out = 0.0
        if self.hidden_size:
            if self.in_y is not None:
                pre = pre + self.in_y(yl)
            h = self.act(pre)
            for layer in self.hidden:
                h = self.act(layer(h))
            out = self.out(h)[..., 0]
        if self.linear:
            if sched is not None:
                z = lin if self.lin_y is None else lin + self.lin_y(self.powers(yl))
                out = out + (z * sched).sum(-1)
            else:
                out = out + lin
                if self.lin_y is not None:
                    out = out + self.lin_y(self.powers(yl))[..., 0]
        return out

    def zero(self) -> None:
        """f = 0: every output weight and the bypass set to zero."""
        with torch.no_grad():
            for p in (self.out.weight, self.out.bias) if self.hidden_size else ():
                p.zero_()
            if self.linear:
                for layer in (self.lin_y, self.lin_x):
                    if layer is not None:
                        layer.weight.zero_()
                self.lin_x.bias.zero_()

    def set_linear(self, a: np.ndarray, b: np.ndarray, c) -> None:
        """Set the linear bypass: weights ``a`` of the output-lag terms and ``b`` of the input
        terms (each ordered as :meth:`powers`: all lags, then their squares, ...), bias ``c``;
        scheduled: one row of ``a``, ``b`` and one ``c`` per hat knot."""
        K = max(1, self.n_sched)
        with torch.no_grad():
            if self.lin_y is not None:
                self.lin_y.weight.copy_(torch.as_tensor(np.reshape(a, (K, -1)), dtype=torch.float32))
            self.lin_x.weight.copy_(torch.as_tensor(np.reshape(b, (K, -1)), dtype=torch.float32))
            self.lin_x.bias.copy_(torch.as_tensor(np.reshape(c, (K,)), dtype=torch.float32))


class RBFMap(nn.Module):
    """Linear bypass + Gaussian radial-basis layer:
    f(z) = a.z + c + sum_j w_j exp(-|z - c_j|^2 / (2 s_j^2)),   z = (yl, x).

    With ``n_sched = K > 0`` the last K columns of x are RH hat weights s_k and the bypass
    is scheduled: sum_k s_k (a_k.z' + c_k), z' = z without the hat columns (an RBF network
    with an RH-interpolated linear part, fitted in the same ridge regression)."""

    def __init__(self, n_y: int, n_x: int, n_centres: int, n_sched: int = 0):
        super().__init__()
        self.n_y, self.n_x = n_y, n_x
        self.n_sched = K = int(n_sched)
        d = n_y + n_x
        self.centres = nn.Parameter(torch.zeros(n_centres, d))
        self.log_width = nn.Parameter(torch.zeros(n_centres))
        self.weight = nn.Parameter(torch.zeros(n_centres))
        self.lin = nn.Parameter(torch.zeros((K, d - K) if K else (d,)))
        self.bias = nn.Parameter(torch.zeros((K,) if K else ()))

    def zero(self) -> None:
        """f = 0: output weights, bypass and bias set to zero."""
        with torch.no_grad():
            for p in (self.weight, self.lin, self.bias):
                p.zero_()

    def features(self, z):
        """Gaussian activations (..., M) of full regressors z (..., n_y + n_x)."""
        d2 = (z * z).sum(-1, keepdim=True) - 2 * z @ self.centres.T + (self.centres ** 2).sum(-1)
        return torch.exp(-0.5 * d2.clamp_min(0) * torch.exp(-2 * self.log_width))

    def precompute(self, x):
        cx = self.centres[:, self.n_y:]
        d2x = (x * x).sum(-1, keepdim=True) - 2 * x @ cx.T + (cx ** 2).sum(-1)
        if self.n_sched:
            K = self.n_sched
            sched = x[..., -K:]
            lin = x[..., :-K] @ self.lin[:, self.n_y:].T + self.bias     # (..., K)
            return d2x, lin, sched
        lin = x @ self.lin[self.n_y:] + self.bias
        return d2x, lin, None

    def step(self, yl, cache):
        d2x, lin, sched = cache
        d2 = d2x
        if self.n_y:
            cy = self.centres[:, :self.n_y]
            d2 = d2 + (yl * yl).sum(-1, keepdim=True) - 2 * yl @ cy.T + (cy ** 2).sum(-1)
        if sched is not None:
            z = lin if not self.n_y else lin + yl @ self.lin[:, :self.n_y].T
            out = (z * sched).sum(-1)
        else:
            out = lin if not self.n_y else lin + yl @ self.lin[:self.n_y]
        phi = torch.exp(-0.5 * d2.clamp_min(0) * torch.exp(-2 * self.log_width))
        return out + phi @ self.weight


def _channels(x):
    """(batch, time) -> (batch, time, 1); (batch, time, channels) unchanged."""
    return None if x is None else (x[..., None] if x.dim() == 2 else x)


class LagSimulator(SequenceCore):
    """NARX/NFIR core: state = the last ``na`` outputs (normalised).

    Channels: see the module docstring (``n_tap`` delayed input channels, ``n_mem``
    undelayed ones, ``n_rh`` RH channels, ``residual``: output = input channel 1 + map).
    """

    #: free-run one sequence (batch 1, no gradient) with a float64 numpy loop: ~5x fewer
    #: per-step overheads than small torch ops; same maths (tested against the torch loop)
    fast_inference = True

    def __init__(self, na: int, nb: int, n_rh: int, fmap: nn.Module, feedthrough: bool = True,
                 n_mem: int = 0, n_tap: int = 1, residual: bool = False):
        super().__init__()
        self.na, self.nb, self.n_rh = int(na), int(nb), int(n_rh)
        self.n_mem, self.n_tap, self.residual = int(n_mem), int(n_tap), bool(residual)
        if self.residual and self.n_tap < 2:
            raise ValueError("a residual core needs the reference output as input channel 1")
        self.delay = 0 if feedthrough else 1
        self.fmap = fmap
        self.n_init = max(self.na, self.nb - 1 + self.delay, 1)

    @property
    def n_x(self) -> int:
        return self.n_tap * self.nb + self.n_mem + self.n_rh

    def exo(self, u_all, rh_all, n_hist: int):
        """Input regressors (B, T, n_x) for the samples after ``n_hist`` history."""
        u_all = _channels(u_all)
        L = u_all.shape[1]
        cols = [u_all[:, n_hist - self.delay - j: L - self.delay - j, c]
                for c in range(self.n_tap) for j in range(self.nb)]
        parts = [torch.stack(cols, -1)] if cols else []
        if self.n_mem:
            parts.append(u_all[:, n_hist:, self.n_tap:self.n_tap + self.n_mem])
        if self.n_rh:
            parts.append(_channels(rh_all)[:, n_hist:, :self.n_rh])
        return torch.cat(parts, -1)

    def init_state(self, u_hist, y_hist, rh_hist):
        k = self.n_init
        return (u_hist[:, -k:], y_hist[:, -k:], None if rh_hist is None else rh_hist[:, -k:])

    def zero_correction(self) -> None:
        """Reduce a residual core to its reference (the map outputs zero)."""
        self.fmap.zero()

    def reference(self, u_all, x, k: int):
        """The output the map is added to: input channel 1 for a residual core, else None."""
        return u_all[:, k:, 1] if self.residual else None

    def advance(self, state, u, rh):
        out = self.simulate(state, u, rh)
        k = self.n_init
        u_hist, y_hist, rh_hist = state
        return out, (torch.cat([u_hist, u], 1)[:, -k:], torch.cat([y_hist, out.to(y_hist.dtype)], 1)[:, -k:],
                     None if rh_hist is None or rh is None else torch.cat([rh_hist, rh], 1)[:, -k:])

    def simulate(self, state, u, rh):
        u_hist, y_hist, rh_hist = state
        k = self.n_init
        u_all = torch.cat([_channels(u_hist), _channels(u)], 1)
        rh_all = None if rh is None or not self.n_rh else torch.cat([_channels(rh_hist), _channels(rh)], 1)
        x = self.exo(u_all, rh_all, k)
        base = self.reference(u_all, x, k)
        cache = self.fmap.precompute(x)
        B, T = u.shape[:2]
        if self.na == 0:
            out = self.fmap.step(x.new_zeros(B, T, 0), cache)
            return out if base is None else out + base
        yl = y_hist[:, k - self.na:].flip(1)  # most recent first
        if B == 1 and self.fast_inference and not torch.is_grad_enabled():
            b0 = None if base is None else base[0].detach().double().numpy()
            if isinstance(self.fmap, MLPMap):
                return _mlp_free_run_numpy(self.fmap, yl, cache, b0).to(u.dtype)
            if isinstance(self.fmap, RBFMap):
                return _rbf_free_run_numpy(self.fmap, yl, cache, b0).to(u.dtype)
        outs = []
        # the input terms unbound along time once: indexing one step of the whole tensor would,
        # in the backward pass, write a full-size gradient at every step (cost ~ T^2)
        steps = zip(*(c.unbind(1) if c is not None else (None,) * T for c in cache))
        bases = base.unbind(1) if base is not None else (None,) * T
        for cache_t, base_t in zip(steps, bases):
            y = self.fmap.step(yl, cache_t)
            if base_t is not None:
                y = y + base_t
            y = y.clamp(-OUTPUT_CLIP, OUTPUT_CLIP)
            outs.append(y)
            yl = torch.cat([y[:, None], yl[:, :-1]], 1)
        return torch.stack(outs, 1)

    # ---------------------------------------------------------------- one-step regression data
    def regressors(self, seqs) -> tuple[np.ndarray, np.ndarray]:
        """One-step regression data from normalised records: Z = [y lags, input regressors]
        (n, na + n_x) in the order of :meth:`exo`, and targets (n,) (minus the reference
        channel for a residual core)."""
        Zs, ts = [], []
        k = self.n_init
        for s in seqs:
            n = len(s)
            if n <= k:
                continue
            u = s.u if s.u.ndim == 2 else s.u[:, None]
            idx = np.arange(k, n)
            cols = [s.y[idx - i] for i in range(1, self.na + 1)]
            cols += [u[idx - self.delay - j, c] for c in range(self.n_tap) for j in range(self.nb)]
            cols += [u[idx, self.n_tap + m] for m in range(self.n_mem)]
            if self.n_rh:
                rh = s.rh if s.rh.ndim == 2 else s.rh[:, None]
                cols += [rh[idx, m] for m in range(self.n_rh)]
            Zs.append(np.stack(cols, 1))
            ts.append(s.y[idx] - (u[idx, 1] if self.residual else 0.0))
        return np.concatenate(Zs), np.concatenate(ts)

    def is_stable_ar(self, a: np.ndarray, margin: float = 1.0) -> bool:
        """True when the AR polynomial 1 - a1 z^-1 - ... - a_na z^-na has all roots inside
        the unit circle (radius < margin)."""
        if self.na == 0:
            return True
        roots = np.roots(np.concatenate([[1.0], -np.asarray(a, float)]))
        return bool(np.all(np.abs(roots) < margin))


def ridge(Z: np.ndarray, t: np.ndarray, alpha: float, penalise_from: int = 0) -> np.ndarray:
    """Ridge regression with an unpenalised intercept: returns (weights..., intercept).
    Columns before ``penalise_from`` are not penalised."""
    X = np.concatenate([Z, np.ones((Z.shape[0], 1))], 1)
    G = X.T @ X
    reg = np.zeros(X.shape[1])
    reg[penalise_from:-1] = alpha * Z.shape[0]
    G[np.diag_indices_from(G)] += reg + 1e-10 * np.trace(G) / len(G)
    return np.linalg.solve(G, X.T @ t)


def _normal_equations(blocks, t: np.ndarray, chunk: int = 20000):
    """(X'X, X't) of X = blocks(rows) without holding all of X (row chunks)."""
    n = t.size
    G = c = None
    for a in range(0, n, chunk):
        X = blocks(slice(a, min(n, a + chunk)))
        if G is None:
            G, c = np.zeros((X.shape[1], X.shape[1])), np.zeros(X.shape[1])
        G += X.T @ X
        c += X.T @ t[a:a + chunk]
    return G, c


def arx_init(core: LagSimulator, seqs, alpha: float = 1e-6) -> dict:
    """Least-squares (polynomial, possibly RH-scheduled) ARX fit of the map's bypass on
    normalised one-step data, written into the bypass when its linear AR part is stable
    (at every RH knot).  Returns a small report."""
    Z, t = core.regressors(seqs)
    P = getattr(core.fmap, "poly_degree", 1)
    K = getattr(core.fmap, "n_sched", 0)
    na = core.na
    Zy, Zx = Z[:, :na], Z[:, na:]
    S = Zx[:, -K:] if K else None
    if K:
        Zx = Zx[:, :-K]
    feats = [Zy ** p for p in range(1, P + 1)] + [Zx ** p for p in range(1, P + 1)]
    X = np.concatenate(feats, 1)
    m = X.shape[1]
    if not K:
        w = ridge(X, t, alpha)
        a, b, c = w[:na * P], w[na * P:-1], w[-1]
        resid = t - np.concatenate([X, np.ones((len(X), 1))], 1) @ w
        stable = core.is_stable_ar(a[:na])
    else:
        def blocks(sl):
            return np.concatenate([(X[sl, :, None] * S[sl, None, :]).reshape(-1, m * K), S[sl]], 1)
        G, rhs = _normal_equations(blocks, t)
        reg = np.full(len(G), alpha * len(t))
        reg[-K:] = 0.0  # intercepts unpenalised
        G[np.diag_indices_from(G)] += reg + 1e-10 * np.trace(G) / len(G)
        w = np.linalg.solve(G, rhs)
        W = w[:m * K].reshape(m, K).T         # (K, m): one bypass per knot
        a, b, c = W[:, :na * P], W[:, na * P:], w[m * K:]
        resid = t - np.einsum("nm,nk,km->n", X, S, W) - S @ c
        stable = all(core.is_stable_ar(a[k, :na]) for k in range(K))
    if stable:
        core.fmap.set_linear(a, b, c)
    return {"arx_stable": stable, "arx_one_step_rmse": float(np.sqrt(np.mean(resid ** 2)))}


def _np_activation(act: nn.Module):
    from scipy.special import erf

    table = {nn.Tanh: np.tanh, nn.ReLU: lambda x: np.maximum(x, 0.0),
             nn.Sigmoid: lambda x: 1.0 / (1.0 + np.exp(-x)),
             nn.SiLU: lambda x: x / (1.0 + np.exp(-x)),
             nn.ELU: lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
             nn.GELU: lambda x: 0.5 * x * (1.0 + erf(x / np.sqrt(2.0)))}
    return table[type(act)]


def _mlp_free_run_numpy(fmap: MLPMap, yl, cache, base=None):
    """Free run of one sequence through an :class:`MLPMap` (see LagSimulator.simulate);
    ``base``: reference output added at every step (residual cores)."""
    def arr(t):
        return t.detach().double().numpy()
    pre, lin, sched = cache
    T = (pre if pre is not None else lin).shape[1]
    pre = None if pre is None else arr(pre[0])
    lin = None if lin is None else arr(lin[0])
    sched = None if sched is None else arr(sched[0])
    H = fmap.hidden_size
    if H:
        Wy = arr(fmap.in_y.weight) if fmap.in_y is not None else None
        hidden = [(arr(layer.weight), arr(layer.bias)) for layer in fmap.hidden]
        wo, bo = arr(fmap.out.weight)[0], float(fmap.out.bias)
        act = _np_activation(fmap.act)
    A = arr(fmap.lin_y.weight) if fmap.linear and fmap.lin_y is not None else None
    a = None if A is None else A[0]
    P = fmap.poly_degree
    z = arr(yl[0]).copy()
    out = np.empty(T)
    for t in range(T):
        y = 0.0
        if H:
            p = pre[t] + Wy @ z if Wy is not None else pre[t]
            h = act(p)
            for W, b in hidden:
                h = act(W @ h + b)
            y = wo @ h + bo
        if lin is not None:
            zp = z if P == 1 else np.concatenate([z ** q for q in range(1, P + 1)])
            if sched is not None:
                v = lin[t] if A is None else lin[t] + A @ zp
                y += v @ sched[t]
            else:
                y += lin[t]
                if a is not None:
                    y += a @ zp
        _emit(out, z, t, y, base)
    return torch.from_numpy(out)[None]


def _emit(out: np.ndarray, z: np.ndarray, t: int, y: float, base) -> None:
    """Finish free-run step ``t``: add the reference output (residual cores), clip, store,
    and push ``y`` into the output-lag buffer ``z`` (newest first)."""
    if base is not None:
        y += base[t]
    y = min(max(y, -OUTPUT_CLIP), OUTPUT_CLIP)
    out[t] = y
    z[1:] = z[:-1]
    z[0] = y


def _rbf_free_run_numpy(fmap: RBFMap, yl, cache, base=None):
    """Free run of one sequence through an :class:`RBFMap` (see LagSimulator.simulate)."""
    def arr(t):
        return t.detach().double().numpy()
    d2x, lin = arr(cache[0][0]), arr(cache[1][0])
    sched = None if cache[2] is None else arr(cache[2][0])
    n_y = fmap.n_y
    cy = arr(fmap.centres)[:, :n_y]
    a = arr(fmap.lin)[..., :n_y]
    w = arr(fmap.weight)
    g = 0.5 * np.exp(-2.0 * arr(fmap.log_width))
    z = arr(yl[0]).copy()
    out = np.empty(lin.shape[0])
    for t in range(out.size):
        d2 = d2x[t] + ((cy - z) ** 2).sum(1)
        lt = lin[t] + a @ z
        y = (lt @ sched[t] if sched is not None else lt) + np.exp(-np.maximum(d2, 0.0) * g) @ w
        _emit(out, z, t, y, base)
    return torch.from_numpy(out)[None]
