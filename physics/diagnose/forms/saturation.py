"""Saturation of the output: the stroke stops growing beyond a level (an end stop, a
sensor's range, a clamp that yields).

Form: e ≈ a · (sat_L(ŷ) − ŷ), sat_L the clip to ±L about the rest deflection, L scanned
from 30 % to 95 % of the largest predicted deflection.  Described, not drafted (a clip is
not a linear factor; a large-signal catalog effect, ``nonlinear_charge``, softens the gain
at the input side instead).
"""
from __future__ import annotations

import numpy as np

from .base import Form, FormFit, Residual, best_on_grid


class OutputSaturation(Form):
    id = "output_saturation"
    title = "saturation of the output"

    def fit(self, res: Residual) -> FormFit:
        peak = max(float(np.max(np.abs(p))) for p in res.preds) or 1.0
        lv, reg = best_on_grid(res, np.linspace(0.3, 0.95, 14) * peak,
                               lambda lv: [[np.clip(p, -lv, lv) - p] for p in res.preds])
        a = reg.gains[0]
        return self.scored(res, reg, {"level_m": lv, "gain": a}, {"level_m": "m", "gain": "1"},
                           f"a saturation of the output at ±{1e6 * lv:.3g} µm ({100 * lv / peak:.0f} % of the "
                           f"largest predicted deflection; residual ≈ a·(clip(ŷ) − ŷ), a = {a:+.3g})")
