"""``lstm`` and ``gru``: recurrent sequence models with RH as an input channel.

The core keeps the two parts apart (as in SUBNET / torchid): an *encoder* (MLP) maps the
last ``n_init`` measured inputs and outputs to the initial hidden state, and the recurrent
network then runs on the inputs alone (voltage, and RH when the model uses humidity), with
a linear read-out plus a direct linear input-to-output path.  Training is closed loop on
windows of ``n_init`` + ``horizon`` samples, so the free-run error is what is optimised.
Without measured history the encoder sees the system at rest (0 V, 0 output).
With ``memory_filters`` the voltage's low-pass filter bank (long input memory, see
:mod:`nnmodel.models.features`) joins the input channels, and its state at the end of the
history joins the encoder's input.  ``rh_knots`` schedules the direct linear path on RH
(coefficients interpolated between knots) and ``skip_init`` starts that path at its
least-squares fit with the recurrent read-out at zero, so that training refines a
linear-parameter-varying model instead of starting from scratch.
"""
from __future__ import annotations

import torch
from torch import nn

import numpy as np

from .base import NeuralModel
from .core import SequenceCore
from .lag import _normal_equations
from .params import MAX_LAGS, MAX_LAYERS, MAX_WIDTH, flag, size


def _channels(x):
    return None if x is None else (x[..., None] if x.dim() == 2 else x)


class RNNSimulator(SequenceCore):
    """Recurrent core; inputs: voltage (+ ``n_ref`` reference channel: the linear start's
    output, which is then added to the output; + ``n_mem`` memory-filter channels) and
    ``n_rh`` RH channels, tensors (batch, time) or (batch, time, channels)."""

    def __init__(self, cell: str, n_rh: int, hidden: int, layers: int, n_init: int,
                 encoder_hidden: int, n_mem: int = 0, n_sched: int = 0, n_ref: int = 0):
        super().__init__()
        self.cell, self.n_rh, self.n_mem, self.n_ref = cell, int(n_rh), int(n_mem), int(n_ref)
        self.n_sched = int(n_sched)
        self.hidden_size, self.layers, self.n_init = int(hidden), int(layers), int(n_init)
        n_in = 1 + self.n_ref + self.n_mem + self.n_rh
        rnn_cls = nn.LSTM if cell == "lstm" else nn.GRU
        self.rnn = rnn_cls(n_in, hidden, layers, batch_first=True)
        self.n_parts = 2 if cell == "lstm" else 1
        self.encoder = nn.Sequential(nn.Linear((2 + self.n_ref) * n_init + self.n_rh + self.n_mem, encoder_hidden),
                                     nn.Tanh(),
                                     nn.Linear(encoder_hidden, self.n_parts * layers * hidden))
        self.readout = nn.Linear(hidden, 1)
        # direct linear path; scheduled: one set of weights per RH knot (last n_sched inputs)
        self.skip = nn.Linear(n_in - self.n_sched, max(1, self.n_sched))

    def direct(self, x):
        """The direct linear input-to-output path (scheduled on the RH hats if any)."""
        if not self.n_sched:
            return self.skip(x)[..., 0]
        K = self.n_sched
        return (self.skip(x[..., :-K]) * x[..., -K:]).sum(-1)

    def _inputs(self, u, rh):
        u = _channels(u)[..., :1 + self.n_ref + self.n_mem]
        return u if not self.n_rh else torch.cat([u, _channels(rh)[..., :self.n_rh]], -1)

    def init_state(self, u_hist, y_hist, rh_hist):
        k = self.n_init
        u_hist = _channels(u_hist)
        parts = [u_hist[:, -k:, 0], y_hist[:, -k:]]
        if self.n_ref:
            parts.append(u_hist[:, -k:, 1])
        if self.n_rh:
            parts.append(_channels(rh_hist)[:, -1, :self.n_rh])
        if self.n_mem:
            parts.append(u_hist[:, -1, 1 + self.n_ref:1 + self.n_ref + self.n_mem])
        s = self.encoder(torch.cat(parts, 1))
        B = s.shape[0]
        s = s.view(B, self.n_parts, self.layers, self.hidden_size).permute(1, 2, 0, 3)
        if self.cell == "lstm":
            return (torch.tanh(s[0]).contiguous(), s[1].contiguous())
        return torch.tanh(s[0]).contiguous()

    def simulate(self, state, u, rh):
        return self.advance(state, u, rh)[0]

    def advance(self, state, u, rh):
        x = self._inputs(u, rh)
        out, state = self.rnn(x, state)
        y = self.readout(out)[..., 0] + self.direct(x)
        return (y + x[..., 1] if self.n_ref else y), state

    def zero_correction(self) -> None:
        """Reduce the core to its reference (read-out and direct path at zero)."""
        with torch.no_grad():
            for p in (self.readout.weight, self.readout.bias, self.skip.weight, self.skip.bias):
                p.zero_()


class _RNNModel(NeuralModel):
    cell = "lstm"
    DEFAULTS = {"lr": 3e-3, "batch_size": 32, "max_epochs": 300, "max_time": 600.0, "patience": 20,
                "grad_clip": 1.0, "horizon": 200, "stride": 50}
    CHECKS = {"hidden": size(MAX_WIDTH), "layers": size(MAX_LAYERS), "n_init": size(MAX_LAGS),
              "encoder_hidden": size(MAX_WIDTH), "skip_init": flag}
    CHECK_PARAMS = {"max_epochs": 1, "hidden": 8, "horizon": 20, "stride": 20, "n_init": 5}

    def __init__(self, hidden: int = 32, layers: int = 1, n_init: int = 20, encoder_hidden: int = 64,
                 skip_init: bool = False, **settings):
        self._set_params_from(locals())

    def _build_core(self, features):
        return RNNSimulator(self.cell, features.n_rh, self.hidden, self.layers, self.n_init, self.encoder_hidden,
                            n_mem=features.n_mem, n_sched=features.n_sched, n_ref=features.n_ref)

    def _initialise(self, core, train):
        """``skip_init``: least-squares fit of the direct path on the training records
        (normalised; with a linear start on its residual, kept if it validates better),
        recurrent read-out set to zero.  A linear start without ``skip_init`` starts as that
        linear model (read-out and direct path at zero)."""
        if core.n_ref:
            core.zero_correction()
        if not self.skip_init:
            return
        xs = [np.concatenate([s.u if s.u.ndim == 2 else s.u[:, None]]
                             + ([s.rh if s.rh.ndim == 2 else s.rh[:, None]] if core.n_rh else []), 1)
              for s in train]
        X = np.concatenate(xs)
        t = np.concatenate([s.y - (s.u[:, 1] if core.n_ref else 0.0) for s in train])
        K = core.n_sched
        if K:
            S, Xl = X[:, -K:], X[:, :-K]
            m = Xl.shape[1]

            def blocks(sl):
                return np.concatenate([(Xl[sl, :, None] * S[sl, None, :]).reshape(-1, m * K), S[sl]], 1)
        else:
            m = X.shape[1]

            def blocks(sl):
                return np.concatenate([X[sl], np.ones((X[sl].shape[0], 1))], 1)
        G, rhs = _normal_equations(blocks, t)
        G[np.diag_indices_from(G)] += 1e-8 * len(t) + 1e-10 * np.trace(G) / len(G)
        w = np.linalg.solve(G, rhs)
        with torch.no_grad():
            if K:
                core.skip.weight.copy_(torch.as_tensor(w[:m * K].reshape(m, K).T, dtype=torch.float32))
                core.skip.bias.copy_(torch.as_tensor(w[m * K:], dtype=torch.float32))
            else:
                core.skip.weight.copy_(torch.as_tensor(w[None, :m], dtype=torch.float32))
                core.skip.bias.fill_(float(w[m]))
            core.readout.weight.zero_()
            core.readout.bias.zero_()
        resid = t - np.concatenate([blocks(slice(a, a + 20000)) for a in range(0, len(t), 20000)]) @ w
        self.init_report_ = {"skip_one_step_rmse": float(np.sqrt(np.mean(resid ** 2)))}


class LSTMModel(_RNNModel):
    """LSTM sequence model (encoder-initialised state, closed-loop training)."""

    kind = "lstm"
    cell = "lstm"
    IN_DEFAULT_SET = True


class GRUModel(_RNNModel):
    """GRU sequence model (encoder-initialised state, closed-loop training)."""

    kind = "gru"
    cell = "gru"
