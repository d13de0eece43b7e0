"""Saturation of the output: the stroke stops growing beyond a level (an end stop, a
sensor's range, a clamp that yields).

Form: e ≈ a · (sat_L(ŷ) − ŷ), sat_L the clip to ±L about the rest deflection, L scanned
from 30 % to 95 % of the largest predicted deflection.  A clip of the output is what a
sensor read past its range or a stop in the set-up writes; a double layer that saturates
softens the drive before the dynamics instead (the input-side forms, and the catalog's
large-signal charge law).  The effect it drafts maps the simulated deflection
y ↦ (1 − a)·y + a·sat_L(y), off at a = 0; a clip's describing function depends on the
amplitude, so the frequency response is left at 1 and a and L are fitted on the time records.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import Param
from .base import Form, FormFit, Residual, best_on_grid, time_path_draft


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

    def draft(self, ff: FormFit, res: Residual) -> list:
        return time_path_draft(
            ff, "output_clip", "a saturation of the tip deflection: (1 − a)·y + a·clip(y, ±L)",
            "The simulated deflection y is read as (1 − a)·y + a·clip(y, ±L): beyond ±L about the rest deflection "
            "what is read stops growing (a sensor past its range, an end stop); a = 1 is a hard clip.",
            [Param("clip_share", "1", 0.0, 1.5, "a: share of the deflection that stops at the level", ff.params["gain"],
                   (0.02, 1.5)),
             Param("clip_level", "m", 1e-9, 1e-2, "L: level beyond which the deflection stops growing",
                   ff.params["level_m"])],
            '(1.0 - self.value(p, "clip_share")) * y + self.value(p, "clip_share") * np.clip(y, -self.value(p, "clip_level"), '
            'self.value(p, "clip_level"))',
            "records whose deflection reaches the level (a drive large enough)", "harmonics")
