"""``ff``: multilayer perceptron on tapped delays, trained one step ahead.

    y[k] = f(y[k-1..k-na], u[k-d..k-d-nb+1], rh[k])

With ``na = 0`` it is an NFIR model (input delays only); with ``na > 0`` it is a NARX model
trained series-parallel: one step ahead, with the *measured* past outputs as regressors.
It is evaluated (and early-stopped) in free run, where its own past outputs are fed back.
The linear bypass starts at the least-squares ARX solution (``arx_init``).
"""
from __future__ import annotations

from .base import NeuralModel, _pos_int
from .lag import ACTIVATIONS, LagSimulator, MLPMap, arx_init

_LAG_CHECKS = {
    "na": lambda v: _pos_int(v, zero=True),
    "nb": _pos_int,
    "hidden": _pos_int,
    "layers": lambda v: _pos_int(v, zero=True),
    "activation": lambda v: None if v in ACTIVATIONS else f"one of {sorted(ACTIVATIONS)}",
    "feedthrough": lambda v: None if isinstance(v, bool) else "true or false",
    "arx_init": lambda v: None if isinstance(v, bool) else "true or false",
    "horizon": _pos_int,
    "poly_degree": _pos_int,
    "stride": _pos_int,
}


class FFModel(NeuralModel):
    """MLP on tapped delays of voltage (and RH, and past outputs), trained one step ahead.

    ``layers = 0`` gives a purely linear ARX/FIR model (least squares when ``max_epochs=0``).
    """

    kind = "ff"
    _checks = _LAG_CHECKS

    def __init__(self, na: int = 2, nb: int = 20, hidden: int = 32, layers: int = 2,
                 activation: str = "tanh", poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True,
                 inputs: str = "auto", seed: int = 0, lr: float = 1e-3, weight_decay: float = 0.0,
                 batch_size: int = 256, max_epochs: int = 100, max_time: float | None = None,
                 patience: int = 10, val_fraction: float = 0.2, grad_clip: float | None = None,
                 accelerator: str = "cpu", progress_bar: bool = True,
                 num_threads: int | None = 1, checkpoint_dir: str | None = None):
        self._set_params_from(locals())

    def _build_core(self, n_rh):
        fmap = MLPMap(self.na, self.nb + n_rh, self.hidden, self.layers, self.activation, linear=True,
                      poly_degree=self.poly_degree)
        return LagSimulator(self.na, self.nb, n_rh, fmap, self.feedthrough)

    def _initialise(self, core, train):
        if self.arx_init:
            self.init_report_ = arx_init(core, train)

    def _training_settings(self):
        return dict(horizon=1, stride=1)
