"""``ff``: multilayer perceptron on tapped delays, trained one step ahead.

    y[k] = f(y[k-1..k-na], u[k-d..k-d-nb+1], rh[k])

With ``na = 0`` it is an NFIR model (input delays only; one-step training is then exactly
free-run training); with ``na > 0`` it is a NARX model trained series-parallel: one step
ahead, with the *measured* past outputs as regressors.  It is evaluated (and
early-stopped) in free run, where its own past outputs are fed back.  The linear bypass
starts at the least-squares ARX solution (``arx_init``).

Long input memory: ``memory_filters`` first-order low-pass filters of the voltage (time
constants ``memory_min_s``..``memory_max_s``, s) join the delayed inputs (see
:mod:`nnmodel.models.features`).  ``rh_knots`` (%) schedules the linear bypass on RH
(coefficients interpolated linearly between knots); the MLP sees RH and the knot weights.

``structures``: a list of hyper-parameter overrides (e.g. ``[{}, {na: 10, nb: 10}]``); each
is scored by the free-run NRMSE of its linear least-squares start on the validation data
and the best one is trained (:meth:`NeuralModel._select_structure`), so one recipe serves
plants that need output feedback and plants where it drifts.
"""
from __future__ import annotations

from .base import NeuralModel, _pos_int
from .features import check_knots
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
    "rh_knots": lambda v: None if v is None else check_knots(v),
}


def lag_core(model, n_rh: int, fmap_cls=None) -> LagSimulator:
    """The LagSimulator of an ``ff`` / ``narx`` model (MLP map with linear bypass; memory
    filters and RH scheduling as the hyper-parameters say)."""
    n_mem = model._n_mem()
    n_sched = len(model._rh_knots()) if n_rh else 0
    fmap = MLPMap(model.na, model.nb + n_mem + n_rh, model.hidden, model.layers, model.activation,
                  linear=True, poly_degree=model.poly_degree, n_sched=n_sched)
    return LagSimulator(model.na, model.nb, n_rh, fmap, model.feedthrough, n_mem=n_mem)


class LagModel(NeuralModel):
    """Shared core of ``ff`` and ``narx``: the lag map (:func:`lag_core`) with its
    least-squares ARX start; the subclasses differ in how they are trained."""

    _checks = _LAG_CHECKS

    def _build_core(self, n_rh):
        return lag_core(self, n_rh)

    def _initialise(self, core, train):
        if self.arx_init:
            self.init_report_ = arx_init(core, train)


class FFModel(LagModel):
    """MLP on tapped delays of voltage (and RH, and past outputs), trained one step ahead.

    ``layers = 0`` gives a purely linear ARX/FIR model (least squares when ``max_epochs=0``).
    """

    kind = "ff"
    _SELECTION_PROXY = {"layers": 0, "max_epochs": 0}    # structures are scored as linear least squares

    def __init__(self, na: int = 2, nb: int = 20, hidden: int = 32, layers: int = 2,
                 activation: str = "tanh", poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True,
                 memory_filters: int = 0, memory_min_s: float = 0.02, memory_max_s: float = 100.0,
                 memory_abs: bool = False,
                 rh_knots: list | None = None,
                 inputs: str = "auto", structures: list | None = None, **training):
        self._set_params_from(locals())

    def _training_settings(self):
        return dict(horizon=1, stride=1)
