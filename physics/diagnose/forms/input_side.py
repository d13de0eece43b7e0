"""Static nonlinearities on the input side: a dead-zone or a saturation of the drive
voltage before the (linear) electrochemistry — an amplifier that clips, a contact that
conducts only beyond a threshold.

Form: e ≈ a · H(N(v) − v) + c · H(v), H the fitted linear model (:attr:`.Residual.respond`), v
each record's voltage and N the nonlinearity: the dead-zone N(v) = v − clip(v, −d, d) with d
scanned from 0.5 % to 40 % of the largest |v|, or the saturation N(v) = clip(v, −L, L) with L
from 30 % to 95 % of it, then finer between the grid neighbours of the best.

The second term is there because the base was fitted to the distorted records: if they are
κ·H(N(v)), the fitted gain has taken up part of the distortion and the residual is
(κ − 1)·H(v) + κ·H(N(v) − v), so c = κ − 1 and a = κ.  Without it, a leans on the part of
H(N(v) − v) that looks like H(v) and the threshold comes out wrong (on a test-bed strip with a
0.17 V dead-zone: 0.05 V with a = 1.6 alone, 0.18 V with a/(1 + c) = 0.88 beside H(v)).  The
form is significant only with a/(1 + c) in :data:`.PURE` and 1 + c > 0 (the pure nonlinearity
gives 1; far from it, H of a part of the voltage only happens to fit a band of error).
Skipped for a large-signal model, or one that maps the voltage already (no H).

Each form drafts an input effect (:class:`physics.effects.InputEffect`) that maps the voltage
before the chain: the diagnosis fits its threshold on the time records; the frequency solver
sees the map as 1, and the coupling gain takes what passes.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import EffectDraft, Param
from .base import PURE, Form, FormFit, Residual, best_on_grid


class _InputNonlinearity(Form):
    needs_response = True
    grid: tuple[float, float, int]
    what: str                                       # what the strip does, with {level} [V]
    #: the drafted effect ``drafted_<id>``: param (its threshold [V]), off (the threshold that leaves the
    #: voltage as it is), description, summary, model, body (the map)
    effect: dict

    def distort(self, v: np.ndarray, level: float) -> np.ndarray:
        """N(v) − v for the threshold ``level`` [V]."""
        raise NotImplementedError

    def fit(self, res: Residual) -> FormFit | None:
        if res.respond is None:
            return None
        volts = [r.v_d for r in res.records]
        vmax = max(float(np.max(np.abs(v))) for v in volts) or 1.0
        levels = np.geomspace(*self.grid[:2], self.grid[2]) * vmax
        linear = [res.respond(k, v) for k, v in enumerate(volts)]

        def columns(x):
            return [[res.respond(k, self.distort(v, x)), lin] for k, (v, lin) in enumerate(zip(volts, linear))]
        level, reg = best_on_grid(res, levels, columns)
        i = int(np.argmin(np.abs(levels - level)))      # then finer between the neighbours of the best
        fine = np.geomspace(levels[max(i - 1, 0)], levels[min(i + 1, levels.size - 1)], 9)
        level, reg = best_on_grid(res, fine, columns)
        kappa = 1.0 + reg.gains[1]                  # the records' linear gain over the fitted model's
        a = reg.gains[0] / kappa if kappa > 0 else float("nan")
        ff = self.scored(res, reg, {"level_V": level, "gain": a, "linear_gain": kappa},
                         {"level_V": "V", "gain": "1", "linear_gain": "1"}, self.sentence(level, vmax, a, kappa))
        ff.admissible = kappa > 0 and PURE[0] <= a <= PURE[1]
        ff.significant = ff.significant and ff.admissible
        return ff

    def sentence(self, level: float, vmax: float, a: float, kappa: float) -> str:
        what = self.what.format(level=f"{level:.3g}")
        return (f"a {self.title}: {what} ({100 * level / vmax:.0f} % of the largest |v|; "
                f"residual ≈ κ·a·H(N(v) − v) + (κ − 1)·H(v), a = {a:+.3g}, κ = {kappa:.3g}: the records' "
                "linear gain over the model's)")

    def draft(self, ff: FormFit, res: Residual):
        e, name = self.effect, self.effect["param"]
        return [EffectDraft(
            form=self.id, effect_id=f"drafted_{self.id}", class_name="Drafted" + self.id.title().replace("_", ""),
            summary=e["summary"], model=e["model"],
            params=[Param(name, "V", 0.0, 1e3, e["description"], ff.params["level_V"])],
            scan=name, off={name: e["off"]},
            excitation="records at two or more drive amplitudes (the share of the voltage the map changes "
                       "depends on the amplitude)",
            reveal={}, signature=[("amplitude_dependence", 1.0), ("harmonics", 0.5)],
            body=("    def filter_input(self, v, fs, p):\n"
                  f"        level = self.value(p, {name!r})\n"
                  f"        return {e['body']}\n"),
            imports=("import numpy as np", ""), base="InputEffect")]


class InputDeadZone(_InputNonlinearity):
    id = "input_deadzone"
    title = "dead-zone of the input"
    what = "the strip does not follow the voltage within ±{level} V"
    grid = (0.005, 0.4, 14)
    effect = {"param": "deadzone_level", "off": 0.0, "description": "half width d of the dead-zone",
              "summary": "a dead-zone of the drive: the strip sees v − clip(v, −d, d)",
              "model": "The strip is driven by ``v − clip(v, −d, d)``: nothing passes within ±d (a driver or a "
                       "contact that conducts only beyond a threshold); d = 0 is the model without it.",
              "body": "np.asarray(v, float) - np.clip(v, -level, level)"}

    def distort(self, v, level):
        return -np.clip(v, -level, level)


class InputSaturation(_InputNonlinearity):
    id = "input_saturation"
    title = "saturation of the input"
    what = "the drive acts as if clipped at ±{level} V"
    grid = (0.3, 0.95, 10)
    effect = {"param": "saturation_level", "off": 1e3, "description": "level L at which the drive clips",
              "summary": "a saturation of the drive: the strip sees clip(v, −L, L)",
              "model": "The strip is driven by ``clip(v, −L, L)`` (an amplifier that clips); a level above every "
                       "drive, e.g. 1000 V, is the model without it.",
              "body": "np.clip(v, -level, level)"}

    def distort(self, v, level):
        return np.clip(v, -level, level) - v
