"""Bending unequal in the two directions: the strip (or what reads it) answers one sign of the
deflection more than the other.

Form: e ≈ a · |ŷ|^p / P^(p−1), P the largest predicted |deflection| and p = 1 or 2, an even
function of the model's output that no linear model and no odd nonlinearity (a saturation, a
play, a charge law that is the same for both signs) can produce.  p = 1 is a gain that
differs by direction, y = ŷ (1 + a sign ŷ): electrodes of unequal thickness or stiffness, a
strip pre-curved or clamped off its neutral plane; p = 2 a curved calibration, y = ŷ + a ŷ²/P:
a triangulation or eddy-current sensor read off its linear range, a lever arm that changes
with the bend.  At the largest deflection the two directions differ by 2a (both p).
The effect it drafts maps the simulated deflection y ↦ y + a|y|^p/P^(p−1) (P and p as found,
constants of the file), off at a = 0; an even map adds no line at a sinusoidal drive's own
frequency (its describing function is 1), so the frequency response is unchanged and a is
fitted on the time records.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import Param
from .base import Form, FormFit, Residual, best_on_grid, time_path_draft

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

    def draft(self, ff: FormFit, res: Residual) -> list:
        a, p, peak = ff.params["gain"], ff.params["exponent"], ff.params["peak_m"]
        law = "|y|" if p == 1.0 else f"y²/P, P = {peak:.4g} m"
        return time_path_draft(
            ff, "output_asymmetry", f"bending unequal in the two directions: y + a·{law}",
            f"The simulated deflection y is read as y + a·{law} (a gain that differs by direction for |y|, a curved "
            "calibration for y²): an even map, which adds no line at a sinusoidal drive's own frequency.",
            [Param("asymmetry_gain", "1", -0.9, 0.9, "a: relative excess of the deflection one way at P", a, "signed")],
            f'y + self.value(p, "asymmetry_gain") * np.abs(y) ** {p!r} / {peak ** (p - 1.0)!r}',
            "records that bend the strip both ways (any input)", "harmonics")
