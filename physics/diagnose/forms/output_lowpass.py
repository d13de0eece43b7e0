"""First-order low-pass on the output: a sensor (or clamp) slower than the excitation.

Form: e ≈ a · (LP_τ(ŷ) − ŷ): the measured deflection is the model's through 1/(1 + sτ)
(a = 1 for a pure low-pass; the base's re-tuned parameters take up part of it).  Cut-off
f_c = 1/(2πτ).  The effect it drafts multiplies the deflection by 1/(1 + sτ), off at τ = 0
(a first-order sensor; e.g. a laser triangulation head's response time).
"""
from __future__ import annotations

import math

import numpy as np

from ..effect_draft import EffectDraft, Param
from .base import PURE, Form, FormFit, Residual, best_on_grid, lowpass


class OutputLowPass(Form):
    id = "output_lowpass"
    title = "first-order low-pass on the output (sensor bandwidth)"

    def fit(self, res: Residual) -> FormFit | None:
        f_lo, f_hi = res.band
        f_top = 0.45 * res.fs_min
        f_bot = max(f_lo, 0.3 * f_hi / 30.0)
        if f_top <= 1.2 * f_bot:
            return None
        fcs = np.geomspace(f_bot, f_top, 30)
        fc, reg = best_on_grid(res, fcs, lambda f: [[lowpass(p, 1.0 / (2 * math.pi * f), r.fs_d) - p]
                                                    for r, p in zip(res.records, res.preds)])
        a = reg.gains[0]
        ff = self.scored(res, reg, {"cutoff_Hz": fc, "gain": a}, {"cutoff_Hz": "Hz", "gain": "1"},
                           f"a first-order low-pass on the output with cut-off f_c ≈ {fc:.3g} Hz (τ = "
                           f"{1e3 / (2 * math.pi * fc):.3g} ms; residual ≈ a·(1/(1 + sτ) − 1) · model output, "
                           f"a = {a:+.3g}" + ("" if PURE[0] <= a <= PURE[1] else "; a is far from 1: a band of error, not "
                           "a sensor's low-pass") + ")", f_excited_Hz=[f_lo, f_hi])
        ff.admissible = PURE[0] <= a <= PURE[1]
        ff.significant = ff.significant and ff.admissible
        return ff

    def draft(self, ff: FormFit, res: Residual):
        fc = ff.params["cutoff_Hz"]
        tau = 1.0 / (2 * math.pi * fc)
        # its phase lag reaches 17° at 0.3 f_c; the records it was found in reach that far
        reach = float(f"{0.3 * min(fc, ff.info['f_excited_Hz'][1]):.2g}")
        return EffectDraft(
            form=self.id, effect_id="drafted_output_lowpass", class_name="DraftedOutputLowPass",
            summary="a first-order low-pass on the tip deflection: × 1/(1 + sτ)",
            model=("The measured deflection is the tip's through a first-order low-pass ``1 / (1 + s τ)`` "
                   "(a sensor or a mount slower than the excitation); τ = 0 is the model without it."),
            # searched from a cut-off 20× the sampling rate (practically off: the base model, nested) down to the
            # lowest excited frequency
            params=[Param("lowpass_tau", "s", 0.0, 10.0, "time constant τ = 1/(2π f_c) of the low-pass", tau,
                          (1.0 / (2 * math.pi * 20.0 * res.fs_min), 1.0 / (2 * math.pi * res.band[0])))],
            scan="lowpass_tau",
            off={"lowpass_tau": 0.0},
            excitation=f"a broadband record reaching ≥ {reach:.2g} Hz",
            reveal={"f_hi_min": reach},
            signature=[("hf_phase_lag", 1.0)],
            body=('    def output_tf(self, p):\n'
                  '        tau = self.value(p, "lowpass_tau")\n'
                  '        return ([1.0], [tau, 1.0]) if tau > 0 else ([1.0], [1.0])     # 1 / (τ s + 1)\n'
                  '\n'
                  '    def filter_output(self, y, fs, p):\n'
                  '        # exact in continuous time, in the frequency domain (as the diagnosis applies a stated\n'
                  '        # sensor bandwidth): a discrete filter errs by % near fs/10, where a sensor\'s cut-off lies\n'
                  '        tau = self.value(p, "lowpass_tau")\n'
                  '        return sensor_filter(y, fs, 1.0 / (2 * math.pi * tau)) if tau > 0 else np.asarray(y, float)\n'),
            imports=("import math", "", "import numpy as np", "", "from physics.diagnose.records import sensor_filter"))
