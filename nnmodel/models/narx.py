"""``narx``: recurrent NARX network trained in closed loop.

Same map as ``ff`` (linear bypass + MLP on past outputs, voltage delays and RH), but trained
on its own simulated outputs: every training window starts from ``n_init`` measured samples
and is simulated ``horizon`` steps in free run; the loss is the simulation error,
back-propagated through the whole window (truncated back-propagation through time over
many short windows = multiple shooting).  So the free-run error is what is optimised.
Memory filters and RH scheduling of the bypass as for ``ff``.
"""
from __future__ import annotations

from .ff import LagModel


class NARXModel(LagModel):
    """Closed-loop-trained NARX network (simulation-error / multiple-shooting training)."""

    kind = "narx"
    IN_DEFAULT_SET = True
    DEFAULTS = {"lr": 2e-3, "batch_size": 64, "max_epochs": 200, "max_time": 600.0, "patience": 20,
                "grad_clip": 1.0, "horizon": 100, "stride": 20}
    CHECK_PARAMS = {"max_epochs": 1, "hidden": 8, "horizon": 20, "stride": 20}

    def __init__(self, na: int = 4, nb: int = 8, hidden: int = 32, layers: int = 2,
                 activation: str = "tanh", poly_degree: int = 1, feedthrough: bool = True, arx_init: bool = True,
                 **settings):
        self._set_params_from(locals())
