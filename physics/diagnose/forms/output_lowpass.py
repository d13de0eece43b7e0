"""Low-pass on the output: a sensor (or clamp) slower than the excitation, first or second order.

Form: e ≈ a · (LP(ŷ) − ŷ): the measured deflection is the model's through a low-pass LP (a = 1
for a pure low-pass; the base's re-tuned parameters take up part of it), either first order,
1/(1 + sτ) with cut-off f_c = 1/(2πτ) (a laser triangulation head's response time), or second
order, 1/(1 + 2ζ s/ω_c + (s/ω_c)²) with ω_c = 2π f_c and damping ratio ζ (a sensor's
anti-aliasing or averaging filter — Butterworth ζ = 0.71, Bessel ≈ 0.87 — or a resonant mount).
Both are scanned; the second order is reported when its ΔBIC, its extra parameter counted, is the
lower and it is a pure low-pass (a within :data:`.base.PURE`): its extra parameter must earn its
place as the form it names, else the first order stands.  When the residual cannot choose (the
order reported is not a pure low-pass, or the other fits it better) and the other order is
significant, both are drafted and the fit with the model decides, as it decides a draft's values.
The effect it drafts multiplies the deflection by that low-pass, off at τ = 0.
"""
from __future__ import annotations

import math

import numpy as np

from ..effect_draft import EffectDraft, Param
from ..records import spectral_filter
from .base import PURE, SIGNIFICANT_BIC, Form, FormFit, Residual, best_on_grid, lowpass, refined

#: Damping ratios the second-order scan tries (under-damped mounts to over-damped filters).
ZETAS = (0.3, 0.45, 0.6, 0.8, 1.0, 1.3)


def lowpass2(f, fc: float, zeta: float) -> np.ndarray:
    """Second-order low-pass 1/(1 + 2ζ jf/f_c + (jf/f_c)²) at frequencies ``f`` [Hz]."""
    x = 1j * np.asarray(f, dtype=float) / fc
    return 1.0 / (1.0 + 2.0 * zeta * x + x * x)


class OutputLowPass(Form):
    id = "output_lowpass"
    title = "low-pass on the output, first or second order (sensor bandwidth)"

    def fit(self, res: Residual) -> FormFit | None:
        f_lo, f_hi = res.band
        f_top = 0.45 * res.fs_min
        f_bot = max(f_lo, 0.3 * f_hi / 30.0)
        if f_top <= 1.2 * f_bot:
            return None
        fcs = np.geomspace(f_bot, f_top, 30)

        def first(x):
            return [[lowpass(p, 1.0 / (2 * math.pi * math.exp(x[0])), r.fs_d) - p] for r, p in zip(res.records, res.preds)]

        spectra = [spectral_filter(p, r.fs_d) for r, p in zip(res.records, res.preds)]

        def second(x):
            return [[through(lambda f: lowpass2(f, math.exp(x[0]), x[1])) - p] for through, p in zip(spectra, res.preds)]
        # each order's best grid point refined (the 30-point grid steps 20 % in f_c: its misfit must not
        # decide the order)
        bounds = [(math.log(f_bot), math.log(f_top))]
        fc, _ = best_on_grid(res, fcs, lambda f: first([math.log(f)]))
        (lfc,), reg = refined(res, [math.log(fc)], bounds, first, 1)
        grid = [(f, z) for f in fcs for z in ZETAS]
        i, _ = best_on_grid(res, range(len(grid)), lambda i: second([math.log(grid[int(i)][0]), grid[int(i)][1]]), 2)
        (lfc2, zeta), reg2 = refined(res, [math.log(grid[int(i)][0]), grid[int(i)][1]],
                                     bounds + [(ZETAS[0], ZETAS[-1])], second, 2)
        orders = {1: (math.exp(lfc), None, reg), 2: (math.exp(lfc2), zeta, reg2)}
        chosen = 2 if reg2.delta_bic < reg.delta_bic and _pure(reg2) else 1
        fc, zeta, reg = orders[chosen]
        other = orders[3 - chosen]
        undecided = (not _pure(reg) or other[2].delta_bic < reg.delta_bic) and other[2].delta_bic <= -SIGNIFICANT_BIC
        alt, also = _described(*other)[0], ""
        if undecided:
            also = (f"; the {'second' if chosen == 1 else 'first'} order fits too (ΔBIC {other[2].delta_bic:.3g}, "
                    f"a = {alt['gain']:+.3g}): both are drafted, the fit with the model decides")
        ff = self.scored(res, reg, *_described(fc, zeta, reg, also), f_excited_Hz=[f_lo, f_hi])
        if undecided:
            ff.info["other_order"] = {**alt, "order": 3 - chosen, "delta_bic": other[2].delta_bic}
        ff.admissible = _pure(reg)
        ff.significant = ff.significant and ff.admissible
        return ff

    def draft(self, ff: FormFit, res: Residual) -> list:
        """The low-pass of ``ff`` as an effect, and its other order too when the residual could not
        choose (``ff.info['other_order']``)."""
        out = [_draft(self.id, ff.params["cutoff_Hz"], ff.params.get("damping_ratio"), ff, res)]
        other = ff.info.get("other_order")
        if other:
            out.append(_draft(self.id, other["cutoff_Hz"], other.get("damping_ratio"), ff, res))
        return out


def _pure(reg) -> bool:
    """Whether the regression's gain a is that of a pure low-pass (within :data:`.base.PURE`)."""
    return PURE[0] <= reg.gains[0] <= PURE[1]


def _described(fc: float, zeta: float | None, reg, also: str = "") -> tuple[dict, dict, str]:
    """(params, units, sentence) of a low-pass of cut-off ``fc`` [Hz], damping ratio ``zeta``
    (None: first order) and gain ``reg.gains[0]``; ``also`` ends the sentence's parenthesis."""
    a = reg.gains[0]
    params, units = {"cutoff_Hz": fc, "gain": a}, {"cutoff_Hz": "Hz", "gain": "1"}
    if zeta is None:
        what = (f"a first-order low-pass on the output with cut-off f_c ≈ {fc:.3g} Hz (τ = "
                f"{1e3 / (2 * math.pi * fc):.3g} ms; residual ≈ a·(1/(1 + sτ) − 1) · model output")
    else:
        params["damping_ratio"], units["damping_ratio"] = zeta, "1"
        what = (f"a second-order low-pass on the output with cut-off f_c ≈ {fc:.3g} Hz and damping ratio "
                f"ζ ≈ {zeta:.2g} (residual ≈ a·(1/(1 + 2ζ s/ω_c + (s/ω_c)²) − 1) · model output")
    return params, units, what + f", a = {a:+.3g}" + (
        "" if _pure(reg) else "; a is far from 1: a band of error, not a sensor's low-pass") + also + ")"


def _draft(form: str, fc: float, zeta: float | None, ff: FormFit, res: Residual) -> EffectDraft:
    """The effect multiplying the deflection by the low-pass of cut-off ``fc`` [Hz] and damping
    ratio ``zeta`` (None: first order), found as ``ff`` in ``res``."""
    tau = 1.0 / (2 * math.pi * fc)
    # its phase lag reaches 17° at 0.3 f_c; the records it was found in reach that far
    reach = float(f"{0.3 * min(fc, ff.info['f_excited_Hz'][1]):.2g}")
    # searched from a cut-off 20× the sampling rate (practically off: the base model, nested) down to the
    # lowest excited frequency
    tau_param = Param("lowpass_tau", "s", 0.0, 10.0, "time constant τ = 1/(2π f_c) of the low-pass", tau,
                      (1.0 / (2 * math.pi * 20.0 * res.fs_min), 1.0 / (2 * math.pi * res.band[0])))
    # exact in continuous time, in the frequency domain (as the diagnosis applies a stated sensor bandwidth):
    # a discrete filter errs by % near fs/10, where a sensor's cut-off lies
    common = dict(form=form, scan="lowpass_tau", off={"lowpass_tau": 0.0},
                  excitation=f"a broadband record reaching ≥ {reach:.2g} Hz", reveal={"f_hi_min": reach},
                  signature=[("hf_phase_lag", 1.0)])
    if zeta is None:
        return EffectDraft(
            effect_id="drafted_output_lowpass", class_name="DraftedOutputLowPass",
            summary="a first-order low-pass on the tip deflection: × 1/(1 + sτ)",
            model=("The measured deflection is the tip's through a first-order low-pass ``1 / (1 + s τ)`` "
                   "(a sensor or a mount slower than the excitation); τ = 0 is the model without it."),
            params=[tau_param],
            body=('    def output_tf(self, p):\n'
                  '        tau = self.value(p, "lowpass_tau")\n'
                  '        return ([1.0], [tau, 1.0]) if tau > 0 else ([1.0], [1.0])     # 1 / (τ s + 1)\n'
                  '\n'
                  '    def filter_output(self, y, fs, p):\n'
                  '        tau = self.value(p, "lowpass_tau")\n'
                  '        return sensor_filter(y, fs, 1.0 / (2 * math.pi * tau)) if tau > 0 else np.asarray(y, float)\n'),
            imports=("import math", "", "import numpy as np", "", "from physics.diagnose.records import sensor_filter"),
            **common)
    return EffectDraft(
        effect_id="drafted_output_lowpass2", class_name="DraftedOutputLowPass2",
        summary="a second-order low-pass on the tip deflection: × 1/(1 + 2ζτs + (τs)²)",
        model=("The measured deflection is the tip's through a second-order low-pass "
               "``1 / (1 + 2 ζ τ s + (τ s)²)``, τ = 1/(2π f_c) (a sensor's filter or a mount slower than the "
               "excitation); τ = 0 is the model without it."),
        params=[tau_param, Param("lowpass_zeta", "1", 0.05, 5.0, "damping ratio ζ of the low-pass",
                                 zeta, (0.2, 2.0))],
        body=('    def output_tf(self, p):\n'
              '        tau, zeta = self.value(p, "lowpass_tau"), self.value(p, "lowpass_zeta")\n'
              '        return ([1.0], [tau * tau, 2.0 * zeta * tau, 1.0]) if tau > 0 else ([1.0], [1.0])\n'
              '\n'
              '    def filter_output(self, y, fs, p):\n'
              '        tau, zeta = self.value(p, "lowpass_tau"), self.value(p, "lowpass_zeta")\n'
              '        if tau <= 0:\n'
              '            return np.asarray(y, float)\n'
              '        return response_filter(y, fs, lambda f: lowpass2(f, 1.0 / (2 * math.pi * tau), zeta))\n'),
        imports=("import math", "", "import numpy as np", "", "from physics.diagnose.forms.output_lowpass import lowpass2",
                 "from physics.diagnose.records import response_filter"),
        **common)
