"""Bending unequal in the two directions: the strip (or what reads it) answers one sign of the
deflection more than the other.

Form: e ≈ a · |ŷ|^p / P^(p−1), P the largest predicted |deflection| and p = 1 or 2, an even
function of the model's output that no linear model and no odd nonlinearity (a saturation, a
play, a charge law that is the same for both signs) can produce.  p = 1 is a gain that
differs by direction, y = ŷ (1 + a sign ŷ): electrodes of unequal thickness or stiffness, a
strip pre-curved or clamped off its neutral plane; p = 2 a curved calibration, y = ŷ + a ŷ²/P:
a triangulation or eddy-current sensor read off its linear range, a lever arm that changes
with the bend.  At the largest deflection the two directions differ by 2a (both p).
Described, not drafted: a static even map of the output is no linear factor, and writing it as
an effect needs the large-signal time path and a describing function for the frequency fit.
"""
from __future__ import annotations

import numpy as np

from .base import Form, FormFit, Residual, best_on_grid

#: The exponents p tried: a gain that differs by direction (1) and a curved calibration (2).
EXPONENTS = (1.0, 2.0)


class OutputAsymmetry(Form):
    id = "output_asymmetry"
    title = "bending unequal in the two directions (or a curved sensor calibration)"

    def fit(self, res: Residual) -> FormFit:
        peak = max(float(np.max(np.abs(p))) for p in res.preds) or 1.0
        p, reg = best_on_grid(res, EXPONENTS, lambda p: [[np.abs(y) ** p / peak ** (p - 1.0)] for y in res.preds])
        a = reg.gains[0]
        law = ("a gain that differs by direction, y ≈ ŷ·(1 + a·sign ŷ)" if p == 1.0
               else "a curved calibration, y ≈ ŷ + a·ŷ²/P")
        return self.scored(res, reg, {"gain": a, "exponent": p, "peak_m": peak},
                           {"gain": "1", "exponent": "1", "peak_m": "m"},
                           f"the deflection is {100 * abs(a):.2g} % larger {'upward' if a > 0 else 'downward'} and as "
                           f"much smaller the other way at the largest predicted deflection ({1e6 * peak:.3g} µm; "
                           f"{law}, a = {a:+.3g}): unequal electrodes, a pre-curved or off-centre clamped strip, or a "
                           "sensor read off its linear range")
