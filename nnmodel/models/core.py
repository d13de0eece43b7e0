"""The torch *core* of a network: what a model module builds (:meth:`NeuralModel._build_core`).

All tensors are normalised, shapes (batch, time) for one channel or (batch, time, channels).
As in torchid/dynoNet, the two jobs are kept apart: ``init_state`` (the initial-state
estimator: measured history -> state) and ``simulate`` (state + inputs -> outputs).  Every
core is trained by the same Lightning loop (:mod:`nnmodel.training`).
"""
from __future__ import annotations

from torch import nn

__all__ = ["SequenceCore"]


class SequenceCore(nn.Module):
    """Interface of a torch core.  ``n_init`` is the number of past samples ``init_state``
    needs."""

    n_init: int = 1

    def init_state(self, u_hist, y_hist, rh_hist):  # pragma: no cover - interface
        raise NotImplementedError

    def simulate(self, state, u, rh):  # pragma: no cover - interface
        raise NotImplementedError

    def advance(self, state, u, rh):
        """(outputs, state after the last sample) of :meth:`simulate`, so that a long record
        can be simulated in chunks with the same result; ``None`` as the state means the
        core cannot continue (the caller then simulates in one piece)."""
        return self.simulate(state, u, rh), None
