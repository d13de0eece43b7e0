"""Static nonlinearities on the input side: a dead-zone or a saturation of the drive
voltage before the (linear) electrochemistry — an amplifier that clips, a contact that
conducts only beyond a threshold.

Form: e ≈ a · H(N(v) − v), H the fitted linear model (:attr:`.Residual.respond`), v each
record's voltage and N the nonlinearity: the dead-zone N(v) = v − clip(v, −d, d) with d
scanned from 0.5 % to 40 % of the largest |v|, or the saturation N(v) = clip(v, −L, L) with L
from 30 % to 95 % of it; significant only with a in :data:`.PURE` (a = 1 for the pure
nonlinearity; far from it, H of a part of the voltage only happens to fit a band of error).
Skipped for a large-signal model (no H).  Described, not drafted: an effect
acts after the electrochemistry (stages, load and output factors) and has no hook on the
voltage; model it by pre-distorting the voltage, or as a stage of the chain.
"""
from __future__ import annotations

import numpy as np

from .base import PURE, Form, FormFit, Residual, best_on_grid


class _InputNonlinearity(Form):
    grid: tuple[float, float, int]

    def distort(self, v: np.ndarray, level: float) -> np.ndarray:
        """N(v) − v for the threshold ``level`` [V]."""
        raise NotImplementedError

    def fit(self, res: Residual) -> FormFit | None:
        if res.respond is None:
            return None
        volts = [r.v_d for r in res.records]
        vmax = max(float(np.max(np.abs(v))) for v in volts) or 1.0
        levels = np.geomspace(*self.grid[:2], self.grid[2]) * vmax
        level, reg = best_on_grid(res, levels, lambda x: [[res.respond(k, self.distort(v, x))]
                                                          for k, v in enumerate(volts)])
        a = reg.gains[0]
        ff = self.scored(res, reg, {"level_V": level, "gain": a}, {"level_V": "V", "gain": "1"},
                         self.sentence(level, vmax, a))
        ff.admissible = PURE[0] <= a <= PURE[1]
        ff.significant = ff.significant and ff.admissible
        return ff


class InputDeadZone(_InputNonlinearity):
    id = "input_deadzone"
    title = "dead-zone of the input"
    grid = (0.005, 0.4, 14)

    def distort(self, v, level):
        return -np.clip(v, -level, level)

    @staticmethod
    def sentence(level, vmax, a):
        return (f"a dead-zone of the input: the strip does not follow the voltage within ±{level:.3g} V "
                f"({100 * level / vmax:.0f} % of the largest |v|; residual ≈ a·H(N(v) − v), a = {a:+.3g}; "
                "no effect hook acts on the voltage: pre-distort it to model this)")


class InputSaturation(_InputNonlinearity):
    id = "input_saturation"
    title = "saturation of the input"
    grid = (0.3, 0.95, 10)

    def distort(self, v, level):
        return np.clip(v, -level, level) - v

    @staticmethod
    def sentence(level, vmax, a):
        return (f"a saturation of the input: the drive acts as if clipped at ±{level:.3g} V "
                f"({100 * level / vmax:.0f} % of the largest |v|; residual ≈ a·H(N(v) − v), a = {a:+.3g}; "
                "no effect hook acts on the voltage: pre-distort it to model this)")
