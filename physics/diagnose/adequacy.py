"""Is what remains noise?  The adequacy check after the best model, and a description of
missing dynamics that no catalog effect explains.

**Adequacy.**  The final model (the base plus the missing effect, or the base) is adequate
when its RMS error is within :data:`ADEQUATE_RATIO` × the records' noise floor (the
sensor's white noise, quantisation and drift, :mod:`.records`).  Otherwise the catalog
explains at most part of the failure and the verdict says so (its confidence is then never
"high").  Whiteness (Ljung–Box) and input–residual correlation are reported beside it.

**What remains** is described by the residual forms of :mod:`.forms` (each in its own
module: a slow pole, a low-pass or a saturation on the output, an additive drift, a play,
amplitude and RH dependence), fitted to the residual of the final model on the decimated
records and forward-selected by BIC; :mod:`.draft` writes the selected ones as effect files.

The template for adding what is found is ``examples/effects/creep.py`` (README, "Adding
an effect").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..analysis import stats
from . import forms

#: The final model explains the data when its RMS error is within this × the noise floor.
ADEQUATE_RATIO = 1.3


@dataclass
class Adequacy:
    """The adequacy of the final model and, when it fails, what the residual looks like."""

    model: str
    rmse: float
    noise_floor: float
    adequate: bool | None
    ljung_box_p: float
    descriptors: list[dict] = field(default_factory=list)
    #: the residual forms (:class:`.forms.FormFit`) behind ``descriptors``
    forms: list = field(default_factory=list, repr=False)
    #: significant structure left within the ratio (a drift the records share), "" when none
    structure: str = ""
    #: the records' own slow wander [m] that does not repeat from record to record (a sensor's),
    #: allowed beside the noise floor (:func:`assess`)
    wander: float = 0.0

    @property
    def ratio(self) -> float:
        return self.rmse / self.noise_floor if self.noise_floor > 0 else math.nan

    def summary(self) -> str:
        """One sentence: the level against the noise and the significant descriptors."""
        if self.adequate is None:
            return f"{self.model}: noise floor unknown, adequacy not assessed"
        txt = (f"{self.model}: RMS error {1e6 * self.rmse:.3g} µm = {self.ratio:.2f}× the noise floor "
               f"({'within' if self.ratio <= ADEQUATE_RATIO else 'above'} {ADEQUATE_RATIO}×"
               + (f"; {'within' if self.adequate else 'above'} {ADEQUATE_RATIO}× the floor with the records' own "
                  f"slow wander of {1e6 * self.wander:.3g} µm" if self.wander > 0 else "") + ")")
        if self.structure:
            txt += f", but {self.structure}"
        found = self.remaining()
        if found:
            txt += "; remaining: " + "; ".join(d["text"] for d in found)
        return txt

    def remaining(self) -> list[dict]:
        """What remains, described: the forward-selected forms in order, then any significant
        level dependence (:mod:`.forms`)."""
        chosen = sorted((d for d in self.descriptors if d.get("selected_step")), key=lambda d: d["selected_step"])
        levels = [d for d in self.descriptors if d.get("significant") and "delta_bic" not in d]
        return chosen + levels

    def to_dict(self) -> dict:
        return {"model": self.model, "rmse_m": self.rmse, "noise_floor_m": self.noise_floor,
                "ratio": self.ratio, "adequate": self.adequate, "threshold_ratio": ADEQUATE_RATIO,
                "ljung_box_p": self.ljung_box_p, "descriptors": self.descriptors, "structure": self.structure,
                "wander_allowed_m": self.wander,
                "summary": self.summary()}


def assess(label: str, fit, records: Sequence, noise: float, describe: bool = True, structure: str = "",
           wander: float = 0.0) -> Adequacy:
    """Adequacy of ``fit`` (a scored :class:`.candidates.ModelFit`) on ``records``; with
    ``describe`` the residual of an inadequate model is described (:func:`.forms.describe`).
    ``structure``: a sentence naming significant deterministic structure the residual holds
    whatever its size (a drift the records share, :func:`.wander.shared_wander`): the model
    is then not adequate even within the ratio, and what remains is described.  ``wander`` [m]:
    a slow wander of the records that does not repeat from record to record (a sensor's drift,
    not physics) allowed beside the floor: adequate within the ratio × sqrt(noise² + wander²);
    the ratio reported stays against the floor."""
    tol = math.hypot(noise, wander) if wander > 0 else noise
    adequate = None if not (math.isfinite(noise) and noise > 0) else \
        bool(fit.rmse <= ADEQUATE_RATIO * tol and not structure)
    excused = bool(adequate and fit.rmse > ADEQUATE_RATIO * noise)      # adequate only with the wander
    found = forms.describe(fit, records) if (adequate is not True and describe) or excused else []
    if excused and forms.input_driven(found):
        # what the wander would excuse follows the input: the model's error, not a sensor's drift
        adequate, wander = False, 0.0
        structure = structure or ("what remains follows the input (" + "; ".join(
            f.text for f in forms.input_driven(found)) + "): the model's error, not the records' wander")
    lb = stats.ljung_box(np.concatenate(list(fit.resid_d)), lags=20)
    out = Adequacy(label, float(fit.rmse), float(noise), adequate, float(lb.get("p_value", math.nan)),
                   structure=structure if adequate is not None else "", wander=float(wander))
    if adequate is not True and (describe or excused):
        out.forms = found
        out.descriptors = [ff.to_dict() for ff in out.forms]
    return out
