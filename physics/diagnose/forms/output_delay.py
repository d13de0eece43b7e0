"""Delay on the output: the deflection is logged later than the voltage (sensor or logger latency), or earlier.

Form: e ≈ a · (ŷ(t − d) − ŷ): the measured deflection is the model's shifted by a dead time d
(a laser head's processing time, a controller's output stage, two channels of a logger sampled
one after the other), a = 1 for a pure delay.  Its phase lag grows in proportion to frequency,
360° · f · d, while the gain stays put; a low-pass's lag levels off at 90° or 180° and its
gain falls (:mod:`.output_lowpass`), an electrode line's lag grows as √f.  The delay is scanned
from a tenth of a sample to the larger of 1/(2 f_top) and eight samples, f_top the top of the
excited band, then refined; the same on the other side of zero, an advance: records that *lead*
the model (a sensor bandwidth or latency given larger than the setup's, a derivative term in the
sensor's conditioning, y + τ dy/dt ≈ y(t + τ); a first-order lead τ·dŷ/dt is tried beside it).
The effect it drafts for a delay multiplies the deflection by e^(−s d), exact in the frequency
domain (not a rational factor: it gives ``output_response`` and ``filter_output``), off at d = 0;
for a significant lead it adds τ·dy/dt, × (1 + sτ) (what a derivative term writes, and an advance
to first order), off at τ = 0: the base, fitted to the records before the lead was seen, has taken
part of it into its own parameters, and the fit with the model reads τ whole.
"""
from __future__ import annotations

import math

import numpy as np

from ..effect_draft import EffectDraft, Param
from ..records import spectral_filter
from .base import PURE, Form, FormFit, Residual, best_on_grid, refined


def delayed(f, d: float) -> np.ndarray:
    """The pure delay e^(−j2πf d) at frequencies ``f`` [Hz] for a delay ``d`` [s]."""
    return np.exp(-2j * math.pi * np.asarray(f, dtype=float) * d)


class OutputDelay(Form):
    id = "output_delay"
    title = "delay (or lead) of the output against the model (a sensor's or logger's latency)"

    def fit(self, res: Residual) -> FormFit | None:
        fs = res.fs_min
        lo = 0.1 / fs
        hi = max(0.5 / res.band[1], 8.0 / fs)
        spectra = [spectral_filter(p, r.fs_d) for r, p in zip(res.records, res.preds)]

        def branch(sign):
            def cols(x):
                return [[through(lambda f: delayed(f, sign * math.exp(x[0]))) - p]
                        for through, p in zip(spectra, res.preds)]
            d, _ = best_on_grid(res, np.geomspace(lo, hi, 30), lambda d: cols([math.log(d)]))
            (ld,), reg = refined(res, [math.log(d)], [(math.log(lo), math.log(hi))], cols, 1)
            return sign * math.exp(ld), reg
        lag, advance = branch(1.0), branch(-1.0)
        # a lead is reported only when it is one (an advance with a near 1, or a derivative term with
        # τ > 0) and fits better than the lag, whose fit (pure or not) is what a draft is written from
        leads = [self._derivative(res)] + ([advance] if PURE[0] <= advance[1].gains[0] <= PURE[1] else [])
        lead = min((b for b in leads if b is not None), key=lambda b: b[1].delta_bic, default=None)
        d, reg = lead if lead is not None and lead[1].delta_bic < lag[1].delta_bic else lag
        a = reg.gains[0] if reg.k > 1 else 1.0        # a derivative term is a lead of τ at unit gain
        pure = d < 0 or PURE[0] <= a <= PURE[1]
        why = ("the model lags the setup — a sensor bandwidth or latency given larger than the setup's, a derivative "
               "term in the sensor's conditioning, or a model too slow at the top of the band")
        if d > 0:
            far = "" if pure else "; a is far from 1: a band of error, not a delay"
            text = (f"a delay on the output of d ≈ {1e3 * d:.3g} ms ({d * fs:.2g} samples; residual ≈ "
                    f"a·(model output at t − d − model output), a = {a:+.3g}{far})")
        elif reg.k == 1:
            text = (f"the records lead the model as y ≈ ŷ + τ·dŷ/dt, τ ≈ {1e3 * -d:.3g} ms ({-d * fs:.2g} samples): "
                    + why)
        else:
            text = (f"the records lead the model by {1e3 * -d:.3g} ms ({-d * fs:.2g} samples; residual ≈ "
                    f"a·(model output at t + {1e3 * -d:.3g} ms − model output), a = {a:+.3g}): " + why)
        ff = self.scored(res, reg, {"delay_s": d, "gain": a}, {"delay_s": "s", "gain": "1"}, text,
                         f_excited_Hz=[res.band[0], res.band[1]])
        ff.admissible = pure
        ff.significant = ff.significant and pure
        return ff

    @staticmethod
    def _derivative(res: Residual):
        """(−τ, regression) of e ≈ τ·dŷ/dt when τ > 0 (a first-order lead), else None."""
        reg = res.regress([[np.gradient(p, 1.0 / r.fs_d)] for r, p in zip(res.records, res.preds)], k_grid=0)
        return (-reg.gains[0], reg) if reg.gains[0] > 0 else None

    def draft(self, ff: FormFit, res: Residual) -> list:
        """The delay as an effect, offered when the residual shows any evidence of it (ΔBIC < 0: it
        fits better than its parameters cost), significant or not: a pick that stands in for a delay
        takes up most of its lag and leaves a band of error that is not significantly a delay (a
        9.3 ms dead time behind the electrode's resistance: ΔBIC −589, a = 1.5 at 0.4 ms); on a
        residual that is noise (ΔBIC ≥ 0) it is not offered, and the model is not refitted with it."""
        d = ff.params["delay_s"]
        fs = res.fs_min
        if d < 0:
            return self._lead_draft(ff, res) if ff.significant else []
        if not ff.delta_bic < 0 or d == 0:
            return []
        # its phase lag reaches 17° at f = 17/(360 d); the records it was found in reach that far
        reach = float(f"{min(17.0 / (360.0 * d), ff.info['f_excited_Hz'][1]):.2g}")
        return [EffectDraft(
            form=self.id, effect_id="drafted_output_delay", class_name="DraftedOutputDelay",
            summary="a delay on the tip deflection: × e^(−s d)",
            model=("The measured deflection is the tip's a dead time ``d`` later (a sensor's or a logger's "
                   "latency): × ``e^(−s d)``, exact in the frequency domain; d = 0 is the model without it."),
            params=[Param("output_delay_s", "s", 0.0, 1.0, "dead time d of the deflection channel", d,
                          (0.05 / fs, max(1.0 / res.band[1], 16.0 / fs)))],
            scan="output_delay_s", off={"output_delay_s": 0.0},
            excitation=f"a broadband record reaching ≥ {reach:.2g} Hz", reveal={"f_hi_min": reach},
            signature=[("hf_phase_lag", 1.0)],
            body=('    def output_response(self, s, p):\n'
                  '        return np.exp(-np.asarray(s) * self.value(p, "output_delay_s"))     # e^(−s d)\n'
                  '\n'
                  '    def filter_output(self, y, fs, p):\n'
                  '        d = self.value(p, "output_delay_s")\n'
                  '        if d <= 0:\n'
                  '            return np.asarray(y, float)\n'
                  '        return response_filter(y, fs, lambda f: delayed(f, d))\n'),
            imports=("import numpy as np", "", "from physics.diagnose.forms.output_delay import delayed",
                     "from physics.diagnose.records import response_filter"))]

    @staticmethod
    def _lead_draft(ff: FormFit, res: Residual) -> list:
        """Records that lead the model as a first-order lead of the deflection, y + τ·dy/dt."""
        tau, fs = -ff.params["delay_s"], res.fs_min
        return [EffectDraft(
            form=OutputDelay.id, effect_id="drafted_output_lead", class_name="DraftedOutputLead",
            summary="records that lead the model: y + τ·dy/dt, × (1 + sτ)",
            model=("The measured deflection leads the tip's by a first-order lead: y + τ·dy/dt, × (1 + sτ) (a "
                   "derivative term in the sensor's conditioning; to first order an advance of τ, a latency or "
                   "bandwidth given larger than the setup's); τ = 0 is the model without it."),
            params=[Param("output_lead_s", "s", 0.0, 1.0, "time constant τ of the lead", tau,
                          (0.05 / fs, max(1.0 / res.band[1], 16.0 / fs)))],
            scan="output_lead_s", off={"output_lead_s": 0.0},
            excitation=f"a broadband record reaching ≥ {res.band[1]:.2g} Hz", reveal={},
            signature=[("hf_phase_lead", 1.0)],
            body=('    def output_response(self, s, p):\n'
                  '        return 1.0 + np.asarray(s) * self.value(p, "output_lead_s")     # 1 + sτ\n'
                  '\n'
                  '    def filter_output(self, y, fs, p):\n'
                  '        tau = self.value(p, "output_lead_s")\n'
                  '        if tau <= 0:\n'
                  '            return np.asarray(y, float)\n'
                  '        return response_filter(y, fs, lambda f: 1.0 + 2j * np.pi * np.asarray(f) * tau)\n'),
            imports=("import numpy as np", "", "from physics.diagnose.records import response_filter"))]
