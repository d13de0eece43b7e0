"""``ss``: neural state-space network with an encoder for the initial state.

    x[k+1] = A x[k] + B v[k] + b + f(x[k], v[k])
    y[k]   = C x[k] + D v[k] + d + h(x[k], v[k])
    x[k0]  = E z + e + g(z),   z = (y, v)[k0 - n_init .. k0 - 1]

``v`` are the input channels (normalised voltage, the memory filters when there are any,
then the RH channels: normalised RH and its hat weights); ``f``, ``h`` and the encoder's
``g`` are MLPs whose output layers start at zero, so that the model starts as its linear
part.  Training is the shared closed-loop loop (:mod:`nnmodel.training`): every window is
``n_init`` measured samples, from which the encoder estimates the state, followed by
``horizon`` simulated samples, the loss being their simulation error (truncated simulation
windows, i.e. multiple shooting with the window start states given by the encoder instead
of free parameters: the SUBNET method of G. I. Beintema, M. Schoukens and R. Tóth, "Deep
subspace encoders for nonlinear system identification", Automatica 156, 111210, 2023).

With the shared ``linear_start`` the linear part is the package's linear yardstick (an ARX
model, :mod:`nnmodel.linear`) *realised in state space* (:func:`realise`): A, B, C, D and the
encoder's E are set so that the network with f = h = g = 0 reproduces the linear model's
free run exactly (its state is a linear function of the last ``max(na, nb - 1 + delay)``
measured outputs and inputs, so E recovers it without error); ``nx`` further states start
unused.  The residual nets then learn only what the linear model misses, and the linear
part is refined with them.  Without ``linear_start`` all ``nx`` states and the linear
part start from torch's default initialisation.

The time loop holds only what depends on the state (one matrix product for A and f's first
layer, f's hidden layers); input terms are computed for the whole window beforehand and the
outputs for all times at once afterwards.  Everything is torch on the core's device.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy import linalg
from torch import nn

from physics.errors import InputError

from .base import NeuralModel
from .core import SequenceCore
from .lag import ACTIVATIONS, OUTPUT_CLIP
from .params import MAX_LAGS, MAX_LAYERS, MAX_STATES, MAX_WIDTH, flag, size

__all__ = ["SSModel", "StateSpaceCore", "realise"]

#: bound on every state (normalised units) in a simulation, so a diverging model returns
#: large finite numbers (and a large validation error) rather than inf/NaN
STATE_CLIP = OUTPUT_CLIP
#: Hankel singular values below this fraction of the largest are dropped from the balanced
#: realisation (states the input cannot move or the output cannot see, to rounding)
HANKEL_TOL = 1e-9


def _channels(x):
    return None if x is None else (x[..., None] if x.dim() == 2 else x)


class MLP(nn.Module):
    """``layers`` hidden layers of ``hidden`` units, then a linear output layer that starts at
    zero (so the net adds nothing until it is trained)."""

    def __init__(self, n_in: int, n_out: int, hidden: int, layers: int, activation: str):
        super().__init__()
        self.first = nn.Linear(n_in, hidden)
        self.hidden = nn.ModuleList(nn.Linear(hidden, hidden) for _ in range(layers - 1))
        self.out = nn.Linear(hidden, n_out)
        self.act = ACTIVATIONS[activation]()
        self.zero()

    def zero(self) -> None:
        with torch.no_grad():
            self.out.weight.zero_()
            self.out.bias.zero_()

    def tail(self, pre):
        """The net from the first layer's pre-activation on."""
        h = self.act(pre)
        for layer in self.hidden:
            h = self.act(layer(h))
        return self.out(h)

    def forward(self, z):
        return self.tail(self.first(z))


class StateSpaceCore(SequenceCore):
    """Encoder + state-space simulator (see the module docstring).

    ``n_lin`` states of the linear start's realisation plus ``nx`` free ones; input channels:
    voltage (then ``n_ref`` reference channels, not used here: the linear start enters
    through the realisation), ``n_mem`` memory filters, ``n_rh`` RH channels."""

    def __init__(self, n_lin: int, nx: int, hidden: int, layers: int, activation: str, n_init: int,
                 encoder_hidden: int, feedthrough: bool = True, n_mem: int = 0, n_rh: int = 0, n_ref: int = 0):
        super().__init__()
        self.n_lin, self.n_free = int(n_lin), int(nx)
        self.n_state = n = self.n_lin + self.n_free
        if n < 1:
            raise InputError("model 'ss': no state (nx=0 without a linear start that has dynamics); set nx >= 1")
        self.n_mem, self.n_rh, self.n_ref = int(n_mem), int(n_rh), int(n_ref)
        self.n_v = nv = 1 + self.n_mem + self.n_rh
        self.n_init = int(n_init)
        self.feedthrough = bool(feedthrough)
        self.state_lin = nn.Linear(n + nv, n)            # [A | B], b
        self.output_lin = nn.Linear(n + nv, 1)           # [C | D], d
        self.f = MLP(n + nv, n, hidden, layers, activation)
        self.h = MLP(n + (nv if feedthrough else 0), 1, hidden, layers, activation)
        n_z = self.n_init * (1 + nv)
        self.encoder_lin = nn.Linear(n_z, n)             # E, e
        self.encoder = MLP(n_z, n, encoder_hidden, 1, activation)
        # the linear start, for zero_correction (zeros without one)
        for name, layer in (("state", self.state_lin), ("output", self.output_lin), ("encoder", self.encoder_lin)):
            self.register_buffer(f"start_{name}_weight", torch.zeros_like(layer.weight))
            self.register_buffer(f"start_{name}_bias", torch.zeros_like(layer.bias))
        if not self.n_lin:   # no linear start: zero output path (h at zero too: y = 0 until trained)
            with torch.no_grad():
                self.output_lin.weight.zero_()
                self.output_lin.bias.zero_()

    # ------------------------------------------------------------------ pieces
    def _inputs(self, u, rh):
        u = _channels(u)
        parts = [u[..., :1]]
        if self.n_mem:
            parts.append(u[..., 1 + self.n_ref:1 + self.n_ref + self.n_mem])
        if self.n_rh:
            parts.append(_channels(rh)[..., :self.n_rh])
        return torch.cat(parts, -1) if len(parts) > 1 else parts[0]

    def init_state(self, u_hist, y_hist, rh_hist):
        k = self.n_init
        v = self._inputs(u_hist[:, -k:], None if rh_hist is None else rh_hist[:, -k:])
        z = torch.cat([y_hist[:, -k:], v.reshape(v.shape[0], -1)], 1)
        return self.encoder_lin(z) + self.encoder(z)

    def simulate(self, state, u, rh):
        return self.advance(state, u, rh)[0]

    def advance(self, state, u, rh):
        """Outputs (B, T) and the state after the last sample (B, n_state)."""
        n = self.n_state
        v = self._inputs(u, rh)
        w_lin, w_f = self.state_lin.weight, self.f.first.weight
        drive = v @ w_lin[:, n:].T + self.state_lin.bias             # input terms for every time
        pre_v = v @ w_f[:, n:].T + self.f.first.bias
        w_x = torch.cat([w_lin[:, :n], w_f[:, :n]], 0).T              # state terms: one product a step
        x, xs = state, []
        # unbound once: indexing a time step of the whole tensor would, in the backward pass,
        # write a full-size gradient per step
        for d_t, p_t in zip(drive.unbind(1), pre_v.unbind(1)):
            xs.append(x)
            z = x @ w_x
            x = (z[:, :n] + d_t + self.f.tail(z[:, n:] + p_t)).clamp(-STATE_CLIP, STATE_CLIP)
        X = torch.stack(xs, 1)
        xv = torch.cat([X, v], -1)
        y = self.output_lin(xv) + self.h(xv if self.feedthrough else X)
        return y[..., 0].clamp(-OUTPUT_CLIP, OUTPUT_CLIP), x

    # ------------------------------------------------------------------ the linear start
    def set_start(self, a, b, c, d, e_w, e_b) -> None:
        """Write a linear realisation (normalised units, float64 arrays) into the first
        ``n_lin`` states: x+ = a x + b v + ..., y = c x + d v + ..., x0 = e_w z + e_b, the
        last column of ``b`` and of ``d`` being the constant (bias); the free states and every
        net start at zero.  It is also the reference :meth:`zero_correction` returns to."""
        m, n, nv = self.n_lin, self.n_state, self.n_v
        W = np.zeros((n, n + nv))
        W[:m, :m], W[:m, n:] = a, b[:, :-1]
        bias = np.zeros(n)
        bias[:m] = b[:, -1]
        O = np.zeros((1, n + nv))
        O[0, :m], O[0, n:] = c, d[:-1]
        E = np.zeros(tuple(self.encoder_lin.weight.shape))
        E[:m] = e_w
        eb = np.zeros(n)
        eb[:m] = e_b
        t = lambda x: torch.as_tensor(x, dtype=torch.float32)  # noqa: E731
        with torch.no_grad():
            for name, w, bb in (("state", W, bias), ("output", O, [d[-1]]), ("encoder", E, eb)):
                getattr(self, f"start_{name}_weight").copy_(t(w))
                getattr(self, f"start_{name}_bias").copy_(t(np.asarray(bb, float)))
        self.zero_correction()

    def zero_correction(self) -> None:
        """Back to the linear start: linear parts at their realisation, f, h, g at zero."""
        with torch.no_grad():
            for name in ("state", "output", "encoder"):
                layer = getattr(self, f"{name}_lin")
                layer.weight.copy_(getattr(self, f"start_{name}_weight"))
                layer.bias.copy_(getattr(self, f"start_{name}_bias"))
            for net in (self.f, self.h, self.encoder):
                net.zero()


# ---------------------------------------------------------------------- realisation
def arx_order(lin) -> int:
    """States of the observer-form realisation of an ARX model: max(na, nb - 1 + delay)."""
    return max(lin.na, lin.nb - 1 + lin.delay)


def _arx_in_net_units(lin, stat):
    """The ARX model's coefficients for signals normalised with ``stat(name) -> (mean, std)``
    (the network's scales): (a, beta) with y[k] = sum_i a_i y[k-i] + sum_{i>=0} beta_i . w[k-i],
    w = (u, rh, 1); ``a``: (n,), ``beta``: (n + 1, 3)."""
    s = lin.scale
    my, sy = stat("y")
    mu, su = stat("u")
    al, be = sy / s["y_std"], (my - s["y_mean"]) / s["y_std"]     # y_lin = al y_net + be
    ga, de = su / s["u_std"], (mu - s["u_mean"]) / s["u_std"]
    n = arx_order(lin)
    a = np.zeros(n)
    a[:lin.na] = lin.a
    beta = np.zeros((n + 1, 3))
    beta[lin.delay:lin.delay + lin.nb, 0] = lin.b * ga / al
    const = lin.c + be * (np.sum(lin.a) - 1.0) + de * np.sum(lin.b)
    if lin.e is not None:       # the linear start takes RH exactly when the network does
        mr, sr = stat("rh")
        beta[0, 1] = lin.e * sr / s["rh_std"] / al
        const += lin.e * (mr - s["rh_mean"]) / s["rh_std"]
    beta[0, 2] = const / al
    return a, beta


def _observer_form(a, beta, n_init: int):
    """Observer canonical form of y[k] = sum a_i y[k-i] + sum beta_i w[k-i] (Kailath,
    *Linear Systems*, 1980, §2.1): x_i[k+1] = a_i y[k] + x_{i+1}[k] + beta_i w[k], y = x_1 +
    beta_0 w; and the exact state at k from the ``n_init`` samples before it,
    x_i[k] = sum_{j>=i} a_j y[k-1-(j-i)] + beta_j w[k-1-(j-i)] (matrices over y and w history)."""
    n = a.size
    A = np.zeros((n, n))
    A[:, 0] = a
    A[np.arange(n - 1), np.arange(1, n)] = 1.0
    B = beta[1:] + a[:, None] * beta[0]
    C = np.zeros(n)
    C[0] = 1.0
    Ey = np.zeros((n, n_init))
    Ew = np.zeros((n, n_init, beta.shape[1]))
    for i in range(1, n + 1):
        for j in range(i, n + 1):
            pos = n_init - 1 - (j - i)
            Ey[i - 1, pos] = a[j - 1]
            Ew[i - 1, pos] = beta[j]
    return A, B, C, beta[0], Ey, Ew


def _balance(A, Bu, C):
    """Square-root balancing (Laub et al., IEEE TAC 32, 1987): T, T^-1 of the balanced
    realisation of a stable (A, Bu, C), states with Hankel singular values below
    :data:`HANKEL_TOL` of the largest dropped; None when the model is not stable or the
    Gramians are not positive definite."""
    if not np.all(np.abs(np.linalg.eigvals(A)) < 1.0 - 1e-9):
        return None
    try:
        Wc = linalg.solve_discrete_lyapunov(A, Bu @ Bu.T)
        Wo = linalg.solve_discrete_lyapunov(A.T, np.outer(C, C))
        Lc, Lo = linalg.cholesky(Wc + 1e-14 * np.trace(Wc) * np.eye(len(A)), lower=True), \
            linalg.cholesky(Wo + 1e-14 * np.trace(Wo) * np.eye(len(A)), lower=True)
        U, s, Vt = linalg.svd(Lo.T @ Lc)
    except (linalg.LinAlgError, ValueError):
        return None
    keep = s > HANKEL_TOL * s[0]
    r = np.sqrt(s[keep])
    T = (U[:, keep] / r).T @ Lo.T          # Σ^-1/2 U' Lo'
    Ti = Lc @ Vt[keep].T / r               # Lc V Σ^-1/2
    return (T, Ti) if np.all(np.isfinite(T)) and np.all(np.isfinite(Ti)) else None


def realise(lin, stat, n_init: int, n_mem: int, n_rh: int) -> dict:
    """State-space realisation of the ARX model ``lin`` (:class:`nnmodel.linear.LinearModel`)
    for a network whose signals are normalised with ``stat`` and whose input channels are
    (voltage, ``n_mem`` memory filters, ``n_rh`` RH channels): ``{"a", "b", "c", "d", "e_w",
    "e_b", "form", "n"}``, ``b`` and ``d`` with a last column for the constant, ``e_w`` over the
    encoder's input (``n_init`` outputs, then ``n_init`` x channels).  Balanced when the model
    is stable (each state as controllable as observable, ordered by importance; states that
    the input cannot move or the output cannot see, to rounding, dropped), else the observer
    form; both reproduce the ARX free run (to float32 rounding of the weights)."""
    a, beta = _arx_in_net_units(lin, stat)
    n = a.size
    if n > n_init:
        raise InputError(f"model 'ss': the linear start has {n} states but the encoder sees {n_init} samples")
    A, B3, C, D3, Ey, Ew3 = _observer_form(a, beta, n_init)
    form = "observer"
    bal = _balance(A, B3[:, :2], C) if n else None
    if bal is not None:
        T, Ti = bal
        A, B3, C, Ey, Ew3 = T @ A @ Ti, T @ B3, C @ Ti, T @ Ey, np.einsum("ij,jkc->ikc", T, Ew3)
        form = "balanced"
    m = A.shape[0]
    nv = 1 + n_mem + n_rh
    rh_col = 1 + n_mem                      # normalised RH among the input channels

    def spread(M3):                          # (.., 3) over (u, rh, 1) -> (.., nv + 1)
        out = np.zeros(M3.shape[:-1] + (nv + 1,))
        out[..., 0], out[..., -1] = M3[..., 0], M3[..., 2]
        if n_rh:
            out[..., rh_col] = M3[..., 1]
        return out
    Ew = spread(Ew3)[..., :nv]               # the constant never enters the history terms
    return {"a": A, "b": spread(B3), "c": C, "d": spread(D3),
            "e_w": np.concatenate([Ey, Ew.reshape(m, -1)], 1), "e_b": np.zeros(m), "form": form, "n": m}


# ---------------------------------------------------------------------- the model
class SSModel(NeuralModel):
    """Neural state-space model with an encoder, trained on truncated simulation windows."""

    kind = "ss"
    IN_DEFAULT_SET = True
    CHECKS = {"nx": size(MAX_STATES, zero=True), "hidden": size(MAX_WIDTH), "layers": size(MAX_LAYERS),
              "activation": lambda v: None if v in ACTIVATIONS else f"one of {sorted(ACTIVATIONS)}",
              "n_init": size(MAX_LAGS), "encoder_hidden": size(MAX_WIDTH), "feedthrough": flag}
    DEFAULTS = {"lr": 2e-3, "batch_size": 64, "max_epochs": 60, "max_time": 600.0, "patience": 15,
                "grad_clip": 1.0, "horizon": 50, "stride": 5}
    CHECK_PARAMS = {"max_epochs": 1, "hidden": 8, "encoder_hidden": 8, "horizon": 20, "stride": 20, "n_init": 5}
    CARD_KEYS = ("state_space",)
    _LEARNED = NeuralModel._LEARNED + ("realisation_",)

    def __init__(self, nx: int = 4, hidden: int = 64, layers: int = 2, activation: str = "tanh",
                 n_init: int = 20, encoder_hidden: int = 64, feedthrough: bool = True, **settings):
        self._set_params_from(locals())

    def _n_lin(self, features) -> int:
        return 0 if features.linear is None else arx_order(features.linear)

    def _build_core(self, features):
        n_lin = self._n_lin(features)
        return StateSpaceCore(n_lin, self.nx, self.hidden, self.layers, self.activation, max(self.n_init, n_lin, 1),
                              self.encoder_hidden, self.feedthrough, n_mem=features.n_mem, n_rh=features.n_rh,
                              n_ref=features.n_ref)

    def _initialise(self, core, train):
        """With a linear start: its realisation in the linear part (:func:`realise`)."""
        lin = self.features_.linear
        if lin is None:
            self.realisation_ = None
            return
        r = realise(lin, self.net_.stat, core.n_init, core.n_mem, core.n_rh)
        if r["n"] < core.n_lin:             # balanced truncation dropped invisible states: keep them unused
            pad = core.n_lin - r["n"]
            r["a"] = np.pad(r["a"], ((0, pad), (0, pad)))
            r["b"] = np.pad(r["b"], ((0, pad), (0, 0)))
            r["c"] = np.pad(r["c"], (0, pad))
            r["e_w"] = np.pad(r["e_w"], ((0, pad), (0, 0)))
            r["e_b"] = np.pad(r["e_b"], (0, pad))
        core.set_start(r["a"], r["b"], r["c"], r["d"], r["e_w"], r["e_b"])
        self.realisation_ = {"form": r["form"], "states": int(r["n"])}

    def _card_extra(self) -> dict:
        core = self.net_.core
        out = {"states": core.n_state, "linear_states": core.n_lin, "free_states": core.n_free,
               "encoder_samples": core.n_init}
        if self.__dict__.get("realisation_"):
            out["linear_realisation"] = self.realisation_
        return {"state_space": out}

    def _restore_extra(self, card_extra: dict) -> None:
        self.realisation_ = (card_extra.get("state_space") or {}).get("linear_realisation")
