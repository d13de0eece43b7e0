"""Slow pole on the output: the tip keeps moving after the drive settles (creep).

Form: e ≈ g · LP_τ(ŷ) with τ ≥ :func:`slowest` (below the excited band), a first-order lag
1/(1 + sτ) of the model's own output; g > 0 the tip creeps forward by a fraction g of the
deflection, g < 0 it relaxes back.  The effect
it drafts multiplies the deflection by 1 + r/(1 + sτ) (a standard linear solid in series
with the beam; Findley, Lai & Onaran, *Creep and relaxation of nonlinear viscoelastic
materials*, 1976, ch. 5), r = g, off at r = 0, and r = −1 the deflection relaxes back
completely: sτ/(1 + sτ), a first-order high-pass, what a sensor's AC coupling does.  r may reach
−1 so that, beside a catalog pick that relaxes back, the draft can take the pick's whole part
(:func:`.draft._relabel_on_written`): the strip this was chosen on, seen through a 0.012 Hz
AC-coupled sensor, named ``solvent_diffusion`` "high" when r stopped at −0.9.
"""
from __future__ import annotations

import numpy as np

from ..effect_draft import EffectDraft, Param
from .base import Form, FormFit, Residual, best_on_grid, lowpass


def slowest(res: Residual) -> float:
    """The fastest pole called slow [s]: 1/3 of the time constant of the lowest excited
    frequency (a faster pole acts inside the band: a low-pass, not a creep)."""
    return max(3.0 / res.fs_min, 1.0 / (2 * np.pi * res.band[0]) / 3.0)


class SlowPole(Form):
    id = "slow_pole"
    title = "slow pole on the output (creep)"

    def fit(self, res: Residual) -> FormFit:
        lo = slowest(res)
        taus = np.geomspace(lo, max(0.5 * res.span_s, 2.0 * lo), 36)
        tau, reg = best_on_grid(res, taus, lambda t: [[lowpass(p, t, r.fs_d)] for r, p in zip(res.records, res.preds)])
        g = reg.gains[0]
        kind = "creeps forward" if g > 0 else "relaxes back"
        return self.scored(res, reg, {"tau_s": tau, "gain": g}, {"tau_s": "s", "gain": "1"},
                           f"a slow pole on the output: the tip {kind} by {100 * abs(g):.3g} % of the model's "
                           f"deflection with time constant τ ≈ {tau:.3g} s (residual ≈ g/(1 + sτ) · model output, "
                           f"g = {g:+.3g})")

    def draft(self, ff: FormFit, res: Residual):
        tau, g = ff.params["tau_s"], ff.params["gain"]
        r = float(np.clip(g, -0.85, 4.5))
        f_lo = 1.0 / (2 * np.pi * tau)
        # what reveals it, relaxed to what the records it was found in offer
        f_max, hold = max(2.0 * f_lo, 1.1 * res.band[0]), min(0.5 * tau, 0.5 * res.span_s)
        creeps = r > 0
        return [EffectDraft(
            form=self.id, effect_id="drafted_slow_pole", class_name="DraftedSlowPole",
            summary="a slow pole on the tip: deflection × (1 + r/(1 + sτ))",
            model=("The deflection is multiplied by ``1 + r / (1 + s τ)``: a fraction ``r`` of it builds up "
                   "(r > 0, creep) or relaxes back (r < 0; r = −1 completely, a high-pass as a sensor's AC coupling "
                   "makes) with time constant ``τ``; r = 0 is the model without it "
                   "(a standard linear solid in series with the beam; Findley, Lai & Onaran 1976, ch. 5)."),
            params=[Param("slow_pole_r", "1", -1.0, 5.0, "static fraction r of the extra deflection", r, "fixed"),
                    Param("slow_pole_tau", "s", float(f"{slowest(res):.3g}"), 1e5, "time constant τ", tau)],
            scan="slow_pole_tau",
            off={"slow_pole_r": 0.0},
            excitation=f"a step or pulse held ≥ {hold:.2g} s, or a sweep down to {f_max:.2g} Hz",
            reveal={"f_lo_max": f_max, "hold_s": hold},
            signature=[("step_creep", 1.0), ("lf_excess_lag", 0.5)] if creeps else
                      [("step_back_relaxation", 1.0), ("lf_droop_lead", 0.5)],
            body=('    def output_tf(self, p):\n'
                  '        r, tau = self.value(p, "slow_pole_r"), self.value(p, "slow_pole_tau")\n'
                  '        return [tau, 1.0 + r], [tau, 1.0]     # (τ s + 1 + r) / (τ s + 1)\n'))]
