"""Additive drift on the output, independent of the input (sensor warm-up, a clamp that
settles thermally).

Form: e_r(t) ≈ A · (1 − exp(−t/τ)), t from each record's start, the same A and τ in every
record (τ ≫ the record: a linear drift at rate A/τ).  Nothing in it depends on the
voltage.  The effect it drafts adds A·(1 − e^(−t/τ)) to the simulated deflection (no
change to the frequency response), off at A = 0.  A drift that differs from record to
record is not physics and no effect can model it; the draft then explains only the part
the records share.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import EffectDraft, Param
from .base import Form, FormFit, Residual, best_on_grid


def tau_grid(span: float) -> np.ndarray:
    """Time constants [s] scanned for a drift seen over ``span`` [s]: a step at the start
    (span/30) to a straight line (30 span), 25 log-spaced."""
    return np.geomspace(span / 30.0, span * 30.0, 25)


def shape(t: np.ndarray, taus) -> np.ndarray:
    """1 − exp(−t/τ) for t [s] from the record's start: len(t) × len(taus)."""
    return -np.expm1(-np.outer(np.asarray(t, float), 1.0 / np.atleast_1d(np.asarray(taus, float))))


class Drift(Form):
    id = "drift"
    title = "additive drift independent of the input"
    input_driven = False

    def fit(self, res: Residual) -> FormFit:
        t = [np.arange(e.size) / r.fs_d for r, e in zip(res.records, res.resid)]
        tau, reg = best_on_grid(res, tau_grid(res.span_s), lambda tt: [[shape(x, tt)[:, 0]] for x in t])
        amp = reg.gains[0]
        rate = amp / tau
        return self.scored(res, reg, {"amplitude_m": amp, "tau_s": tau}, {"amplitude_m": "m", "tau_s": "s"},
                           f"an additive drift independent of the input: {1e6 * amp:+.3g} µm × (1 − e^(−t/τ)), "
                           f"τ ≈ {tau:.3g} s from each record's start (initial rate {1e6 * rate:+.3g} µm/s)")

    def draft(self, ff: FormFit, res: Residual):
        amp, tau = ff.params["amplitude_m"], ff.params["tau_s"]
        return [EffectDraft(
            form=self.id, effect_id="drafted_drift", class_name="DraftedDrift",
            summary="an additive drift of the tip reading: + A (1 − e^(−t/τ)) from the record's start",
            model=("The simulated deflection gets ``A (1 − exp(−t/τ))`` added, t from the start of the record, "
                   "whatever the voltage (no change to the frequency response); A = 0 is the model without it. "
                   "This is a property of the measurement (sensor warm-up, thermal settling of the clamp), not of "
                   "the polymer: keep it out of a model used for control."),
            params=[Param("drift_amplitude", "m", -1e-2, 1e-2, "drift amplitude A (final offset)", amp, "signed"),
                    Param("drift_tau", "s", 1e-3, 1e6, "drift time constant τ", tau)],
            scan="drift_tau",
            off={"drift_amplitude": 0.0},
            excitation=f"records of ≥ {min(tau, res.span_s):.2g} s (any input)",
            reveal={},
            signature=[("slow_trend", 1.0)],
            body=('    def filter_output(self, y, fs, p):\n'
                  '        amp, tau = self.value(p, "drift_amplitude"), self.value(p, "drift_tau")\n'
                  '        t = np.arange(np.size(y)) / fs\n'
                  '        return np.asarray(y, float) + amp * -np.expm1(-t / tau)\n'
                  '\n'
                  '    def output_response(self, s, p):\n'
                  '        return np.ones_like(np.asarray(s), dtype=complex)     # independent of the input\n'),
            imports=("import numpy as np",))]
