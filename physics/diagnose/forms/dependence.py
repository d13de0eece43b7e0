"""Amplitude and RH dependence of what remains: does the model's error follow its own output
with a gain (and lag) that changes from level to level?

Within the records of one kind (a pulse and a sweep differ whatever their levels) at one RH
(amplitude) level, the residual is regressed on the model's prediction ŷ and its rate dŷ/dt
(a gain and a lag of the model, :meth:`.base.Residual.regress`) twice: with one pair of gains
shared by every level, and with a pair per level.  A misfit that changes with humidity is so
not read as an amplitude dependence, nor one that changes with the amplitude as an RH
dependence.  The dependence is significant when the per-level gains beat the shared ones by
ΔBIC ≤ −:data:`.base.SIGNIFICANT_BIC` and lower the group's RMS error by ≥ :data:`.base.MIN_GAIN`
— the two tests of every form, against the nested form a level cannot change (one gain error
is a wrong parameter, not a dependence).  An error that does not follow the output at all (a
sensor's drift, noise) has the same size at every level: its share of a larger output is
smaller, yet it is no dependence, and it leaves both regressions where they started.
Described, not drafted: the catalog's ``nonlinear_charge`` and ``humidity`` are the effects
for them.

The RH comparison holds the amplitude fixed, but the model's own parameters at an RH level
were fitted on every record at that level.  Where one level holds a second amplitude and the
error changes with the amplitude (the amplitude form's ΔBIC ≤ −:data:`.base.SIGNIFICANT_BIC`),
those parameters are a compromise between the amplitudes at that level only: a gain that
differs between RH levels is then the amplitude's doing as much as the humidity's, and the RH
dependence is described as not separable, not as significant.
"""
from __future__ import annotations

import math

import numpy as np

from .base import MIN_GAIN, SIGNIFICANT_BIC, Form, FormFit, Residual


class _Dependence(Form):
    attr: str
    within: str             # the other level, held fixed
    unit: str
    key: str

    def fit(self, res: Residual) -> FormFit | None:
        by_kind: dict = {}
        for i, r in enumerate(res.records):
            by_kind.setdefault((r.kind, round(float(getattr(r, self.within)), 6)), {}).setdefault(
                round(float(getattr(r, self.attr)), 6), []).append(i)
        groups = max(by_kind.values(), key=len)
        if len(groups) < 2:
            return None
        levels = sorted(groups)
        level_of = {i: j for j, lv in enumerate(levels) for i in groups[lv]}
        zero = [np.zeros_like(p) for p in res.preds]
        rate = [np.gradient(p) * r.fs_d / (2 * math.pi * math.sqrt(max(r.band[0], 1e-6) * max(r.band[1], 1e-6)))
                for r, p in zip(res.records, res.preds)]

        def columns(per_level: bool) -> list[list[np.ndarray]]:
            """ŷ and dŷ/dt of each record in the group, in its level's pair of columns (or the one pair)."""
            out = []
            for i, (p, d) in enumerate(zip(res.preds, rate)):
                cols = [zero[i]] * (2 * len(levels) if per_level else 2)
                if i in level_of:
                    at = 2 * level_of[i] if per_level else 0
                    cols[at:at + 2] = [p, d]
                out.append(cols)
            return out
        shared, each = res.regress(columns(False)), res.regress(columns(True))
        inside = sorted(level_of)
        rss0 = sum(res.rss[i] for i in inside)
        rss_shared, rss_each = (sum(reg.rss[i] for i in inside) for reg in (shared, each))
        reduction = 1.0 - math.sqrt(rss_each / rss_shared) if rss_shared > 0 else 0.0
        # ΔBIC of the per-level gains against the shared ones, on the residual's n_eff
        penalty = math.log(max(sum(res.n_eff), 2.0))
        d_bic = sum(res.n_eff[i] * math.log(max(each.rss[i], 1e-300) / max(shared.rss[i], 1e-300)) for i in inside) \
            + (each.k - shared.k) * penalty
        gains = {lv: each.gains[2 * j] for j, lv in enumerate(levels)}
        rel = {lv: math.sqrt(sum(res.rss[i] for i in groups[lv])
                             / max(sum(float(res.preds[i] @ res.preds[i]) for i in groups[lv]), 1e-300))
               for lv in levels}
        sig = bool(d_bic <= -SIGNIFICANT_BIC and reduction >= MIN_GAIN)
        lo, hi = levels[0], levels[-1]
        text = (f"the measured response differs from the model's by {100 * gains[lo]:+.0f} % at {self.key} "
                f"{lo:.3g} {self.unit} and by {100 * gains[hi]:+.0f} % at {hi:.3g} {self.unit} (a gain per {self.key} "
                f"level lowers the error {100 * reduction:.0f} % beyond one shared gain, ΔBIC {d_bic:.3g})")
        return FormFit(self.id, {"levels": levels, "gain_error": gains, "relative_residual": rel,
                                 "rms_reduction_beyond_shared_gain": reduction, "delta_bic_beyond_shared_gain": d_bic,
                                 "share_of_error_following_output": 1.0 - math.sqrt(rss_shared / rss0) if rss0 > 0
                                 else 0.0},
                       {"levels": self.unit, "gain_error": "1", "relative_residual": "1",
                        "rms_reduction_beyond_shared_gain": "1", "delta_bic_beyond_shared_gain": "1",
                        "share_of_error_following_output": "1"},
                       text, significant=sig)


class AmplitudeDependence(_Dependence):
    id, title, attr, within, unit, key = ("amplitude_dependence", "amplitude dependence", "amplitude_level", "rh", "V",
                                          "amplitude")


class RHDependence(_Dependence):
    id, title, attr, within, unit, key = "rh_dependence", "RH dependence", "rh", "amplitude_level", "%", "RH"

    def fit(self, res: Residual) -> FormFit | None:
        own = super().fit(res)
        if own is None or not own.significant:
            return own
        amplitudes: dict = {}
        for r in res.records:
            amplitudes.setdefault(round(float(r.rh), 6), set()).add(round(float(r.amplitude_level), 6))
        held = {lv: sorted(amplitudes.get(lv, ())) for lv in own.params["levels"]}
        if len({tuple(a) for a in held.values()}) < 2:
            return own
        amp = AmplitudeDependence().fit(res)
        if amp is None or amp.params["delta_bic_beyond_shared_gain"] > -SIGNIFICANT_BIC:
            return own
        mixed = max(held, key=lambda lv: len(held[lv]))
        own.significant = False
        own.info["confounded_with_amplitude"] = True
        own.text += (f"; not told apart from the amplitude dependence: the records at RH {mixed:.3g} % hold amplitudes "
                     + ", ".join(f"{a:.3g}" for a in held[mixed]) + " V, the model's parameters there are a compromise "
                     f"between them, and the error changes with the amplitude (ΔBIC "
                     f"{amp.params['delta_bic_beyond_shared_gain']:.3g})")
        return own
