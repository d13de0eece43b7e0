"""The start-up rule: how a free run begins on a measured record, the same in every command.

``eap train-compare`` (every row, its scores and plots), ``eap predict`` and ``eap compare``
(a trained bundle) start a free run on a measured record in one way:

* the record's first ``W = max(START_SAMPLES, n_init)`` samples are its **start-up window**
  (``n_init``: the past outputs the model's state holds; 0 for the physics simulator);
* a model with a state is handed the measured outputs of the window, and over the window its
  output is the measurement itself: a network's state is set from the last ``n_init`` of
  them and its free run begins at sample ``W``; its input channels run from the record's
  first sample, as in training — the memory filters, and the free run of its linear start
  from the record's first measured outputs (the linear row runs the same way, so a network
  whose correction was dropped scores exactly the linear row);
* the output is then shifted by the mean error over the window (the **offset rule**): zero
  for a model handed the window, the sensor's zero for the physics simulator, which starts
  from rest and cannot know it;
* every score counts from sample ``W`` on.

So every row of a comparison starts at the same sample, from the same measured outputs, and
no row sees a measured output after the window.
"""
from __future__ import annotations

import numpy as np

from physics.errors import InputError

__all__ = ["START_SAMPLES", "start_samples", "free_run"]

#: samples at the start of a record that only start a free run (never scored)
START_SAMPLES = 50


def start_samples(n_init: int) -> int:
    """The start-up window (samples) of a model whose state holds ``n_init`` past outputs."""
    return max(START_SAMPLES, int(n_init))


def free_run(simulate, y: np.ndarray, n_init: int, where: str = "the record") -> tuple[np.ndarray, int]:
    """(free-run output, start-up window ``W``) under the start-up rule.  ``simulate(y_init)``
    runs the model over the whole record, given the measured outputs of the window (``None``
    for a model without a state, ``n_init = 0``); ``y``: the record's measured output."""
    y = np.asarray(y, dtype=float)
    w = start_samples(n_init)
    if y.size <= w + 1:
        raise InputError(f"{where}: {y.size} samples; a free run is scored after its start-up window of {w} "
                         f"samples, so the record needs at least {w + 2}")
    yhat = np.asarray(simulate(y[:w] if n_init else None), dtype=float)
    return yhat + float(np.mean(y[:w] - yhat[:w])), w
