"""Rate-independent hysteresis on the output: play (backlash) in the clamp or the sensor.

Form: e ≈ a · (P_w(ŷ) − ŷ), P_w the play operator of total width w (Krasnosel'skii &
Pokrovskii, *Systems with hysteresis*, 1989), started centred on the first sample; the
loop's width is a·w.  Described, not drafted: a play is not a linear factor, and an
effect for it needs the large-signal time path (``filter_output``) and a describing
function for the frequency fit.
"""
from __future__ import annotations

import numpy as np

from .base import Form, FormFit, Residual, best_on_grid


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Play (backlash) operator of total width ``width``, started centred on x[0]."""
    out = np.empty_like(x)
    y = float(x[0])
    h = 0.5 * width
    for i, v in enumerate(x.tolist()):
        if v - h > y:
            y = v - h
        elif v + h < y:
            y = v + h
        out[i] = y
    return out


class Play(Form):
    id = "hysteresis"
    title = "play (backlash) on the output"

    def fit(self, res: Residual) -> FormFit:
        ptp = max(float(np.ptp(p)) for p in res.preds) or 1.0
        w, reg = best_on_grid(res, np.geomspace(0.01, 0.6, 14) * ptp,
                              lambda w: [[play(p, w) - p] for p in res.preds])
        a = reg.gains[0]
        return self.scored(res, reg, {"width_m": w * a, "play_width_m": w, "gain": a},
                           {"width_m": "m", "play_width_m": "m", "gain": "1"},
                           f"a rate-independent loop (backlash/play) on the output of width ≈ {1e6 * abs(w * a):.3g} µm")
