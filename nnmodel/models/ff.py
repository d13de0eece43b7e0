"""``ff``: multilayer perceptron on tapped delays, trained one step ahead.

    y[k] = f(y[k-1..k-na], u[k-d..k-d-nb+1], m[k], rh[k])

With ``na = 0`` it is an NFIR model (input delays only; one-step training is then exactly
free-run training); with ``na > 0`` it is a NARX model trained series-parallel: one step
ahead, with the *measured* past outputs as regressors.  It is evaluated (and
early-stopped) in free run, where its own past outputs are fed back.  The linear bypass
starts at the least-squares ARX solution (``arx_init``).  The memory filters ``m`` and
the RH scheduling of the bypass are the shared input features
(:mod:`nnmodel.models.features`).

``structures`` (see :mod:`nnmodel.models.structure`) are scored by the free-run NRMSE of
their linear least-squares start on the validation data and the best one is trained, so
one recipe serves plants that need output feedback and plants where it drifts.
"""
from __future__ import annotations

from .base import NeuralModel
from .lag import ACTIVATIONS, LagSimulator, MLPMap, arx_init
from .params import MAX_LAGS, MAX_LAYERS, MAX_WIDTH, flag, pos_int, size

#: value checks of the tapped-delay parameters (shared by ff, narx, rbf, hybrid)
LAG_CHECKS = {
    "na": size(MAX_LAGS, zero=True),
    "nb": size(MAX_LAGS),
    "hidden": size(MAX_WIDTH),
    "layers": size(MAX_LAYERS, zero=True),
    "activation": lambda v: None if v in ACTIVATIONS else f"one of {sorted(ACTIVATIONS)}",
    "feedthrough": flag,
    "arx_init": flag,
    "poly_degree": size(9),
}


def lag_core(model, features, n_tap: int | None = None, n_extra: int = 0, core_cls=LagSimulator,
             **core_kw) -> LagSimulator:
    """The LagSimulator of a tapped-delay model with an MLP map and linear bypass:
    ``n_tap`` delayed input channels (default: the voltage, and the linear start's output
    when there is one, which the core then adds to the map: a residual core; the hybrid
    passes its physics output), ``n_extra`` undelayed channels besides the memory filters,
    RH channels and scheduling from the fitted ``features``."""
    if n_tap is None:
        n_tap = 1 + features.n_ref
        core_kw.setdefault("residual", features.n_ref > 0)
    n_mem = features.n_mem + n_extra
    fmap = MLPMap(model.na, n_tap * model.nb + n_mem + features.n_rh, model.hidden, model.layers,
                  model.activation, linear=True, poly_degree=model.poly_degree, n_sched=features.n_sched)
    return core_cls(model.na, model.nb, features.n_rh, fmap, model.feedthrough, n_mem=n_mem, n_tap=n_tap,
                    **core_kw)


class LagModel(NeuralModel):
    """Shared core of ``ff`` and ``narx``: the lag map (:func:`lag_core`) with its
    least-squares ARX start; the subclasses differ in how they are trained."""

    CHECKS = LAG_CHECKS

    def __init__(self, na: int = 2, nb: int = 20, hidden: int = 32, layers: int = 2,
                 activation: str = "tanh", poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True,
                 **settings):
        self._set_params_from(locals())

    def _build_core(self, features):
        return lag_core(self, features)

    def _initialise(self, core, train):
        if self.arx_init:   # with a linear start: fitted to its residual (kept if it validates better)
            self.init_report_ = arx_init(core, train)


class FFModel(LagModel):
    """MLP on tapped delays of voltage (and RH, and past outputs), trained one step ahead.

    ``layers = 0`` gives a purely linear ARX/FIR model (least squares when ``max_epochs=0``).
    """

    kind = "ff"
    IN_DEFAULT_SET = True
    SELECTION_PROXY = {"layers": 0, "max_epochs": 0}    # structures are scored as linear least squares
    CHECK_PARAMS = {"max_epochs": 1, "hidden": 8}


def as_network(lin, train, val_fraction: float = 0.2) -> "FFModel":
    """The linear model ``lin`` (:class:`nnmodel.linear.LinearModel`) as a network that a bundle can hold and ``eap predict`` can run: an
    ``ff`` network whose linear start is this model and whose correction is zero (no hidden
    layer, no memory filters), so that its free run is this model's, started as every
    network's linear start is: from the record's first ``n_init`` measured outputs.
    ``train``: the training records (their sampling rate and RH range)."""
    from ..data import check_records, rh_range

    train = check_records(train, "training")
    net = FFModel(na=0, nb=lin.n_init + 1, layers=0, arx_init=False, memory_filters=0, rh_knots=[],
                       linear_start=True, inputs="voltage+rh" if lin.uses_rh else "voltage", max_epochs=0,
                       structures=None, cv_folds=1, val_fraction=val_fraction, progress_bar=False)
    net.restore({"inputs": ["voltage", "rh"] if lin.uses_rh else ["voltage"], "fs": train[0].fs,
                 "rh_range": list(rh_range(train)) if lin.uses_rh else None, "n_init": lin.n_init,
                 "card_extra": {"linear_start": lin.card()}}, None)
    for name in ("u", "y") + (("rh",) if lin.uses_rh else ()):   # the linear model's scales: exact round trip
        getattr(net.net_, f"{name}_mean").fill_(lin.scale[f"{name}_mean"])
        getattr(net.net_, f"{name}_std").fill_(lin.scale[f"{name}_std"])
    net.net_.core.zero_correction()
    return net
