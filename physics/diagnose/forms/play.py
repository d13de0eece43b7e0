"""Rate-independent hysteresis on the output: play (backlash) in the clamp or the sensor.

Form: e ≈ a · (P_w(ŷ) − ŷ), P_w the play operator of total width w (Krasnosel'skii &
Pokrovskii, *Systems with hysteresis*, 1989), started centred on the first sample; the
loop's width is a·w.  The effect it drafts (where the form is significant) maps the simulated
deflection y ↦ (1 − a)·y + a·P_w(y), off at a = 0; its frequency response is left unchanged
(a play's describing function depends on the amplitude), so a and w are fitted on the time
records.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import Param
from .base import Form, FormFit, Residual, best_on_grid, time_path_draft


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Play (backlash) operator of total width ``width`` ≥ 0, started centred on x[0].

    Each sample clamps the state, y_k = min(max(y_{k−1}, x_k − w/2), x_k + w/2), and clamps
    compose into clamps (the later one applied to the earlier one's bounds), so the state at
    every sample is one clamp of x[0] found by a prefix scan in log2(n) vectorised passes
    (Hillis & Steele, *Data parallel algorithms*, 1986).  Only min and max act on x ± w/2:
    the result equals the sample-by-sample loop exactly.
    """
    x = np.asarray(x, dtype=float)
    if not width >= 0.0:
        raise ValueError(f"play width must be >= 0, got {width!r}")
    h = 0.5 * width
    lo, hi = x - h, x + h
    step = 1
    while step < x.size:
        # the clamp up to sample k ← clamp k ∘ (the clamp up to k − step)
        lo[step:], hi[step:] = (np.minimum(np.maximum(lo[:-step], lo[step:]), hi[step:]),
                                np.minimum(np.maximum(hi[:-step], lo[step:]), hi[step:]))
        step *= 2
    return np.minimum(np.maximum(x[:1], lo), hi)


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

    def draft(self, ff: FormFit, res: Residual) -> list:
        return time_path_draft(
            ff, "play", "a play (backlash) on the tip deflection: (1 − a)·y + a·P_w(y)",
            "The simulated deflection y is read as (1 − a)·y + a·P_w(y), P_w the play operator of total width w (what "
            "the sensor sees follows the strip only after the slack w is taken up) started centred on the first "
            "sample: a loop of width a·w whatever the frequency (its describing function depends on the amplitude).",
            [Param("play_share", "1", 0.0, 1.5, "a: share of the deflection seen through the play", ff.params["gain"],
                   (0.02, 1.5)),
             Param("play_width", "m", 1e-9, 1e-2, "w: total width of the play", ff.params["play_width_m"])],
            '(1.0 - self.value(p, "play_share")) * y + self.value(p, "play_share") * play(y, self.value(p, "play_width"))',
            "records that reverse the bend (any periodic drive)", "harmonics",
            ("", "from physics.diagnose.forms.play import play"))
