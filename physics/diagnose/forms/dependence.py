"""Amplitude and RH dependence of what remains: the relative residual (RMS residual / RMS
output) of the largest against the smallest amplitude (RH) level, within records of one
kind (a pulse and a sweep differ in relative residual whatever their levels) at one RH
(amplitude) level: a misfit that changes with humidity is not an amplitude dependence, nor
one that changes with the amplitude a humidity dependence.  A ratio
≥ :data:`DEPENDENCE_RATIO` (or ≤ its inverse) is called a dependence.  Described, not
drafted: the catalog's ``nonlinear_charge`` and ``humidity`` are the effects for them.
"""
from __future__ import annotations

import math

from .base import Form, FormFit, Residual

#: Relative-residual ratio between extreme levels called a dependence.
DEPENDENCE_RATIO = 1.5


class _Dependence(Form):
    attr: str
    within: str             # the other level, held fixed
    unit: str
    key: str

    def fit(self, res: Residual) -> FormFit | None:
        by_kind: dict = {}
        for r, e, p in zip(res.records, res.resid, res.preds):
            by_kind.setdefault((r.kind, round(float(getattr(r, self.within)), 6)), {}).setdefault(
                round(float(getattr(r, self.attr)), 6), []).append((e, p))
        groups = max(by_kind.values(), key=len)
        if len(groups) < 2:
            return None
        rel = {k: math.sqrt(sum(float(e @ e) for e, _ in v) / max(sum(float(p @ p) for _, p in v), 1e-300))
               for k, v in groups.items()}
        lo, hi = min(groups), max(groups)
        ratio = rel[hi] / rel[lo] if rel[lo] > 0 else math.inf
        sig = bool(ratio >= DEPENDENCE_RATIO or ratio <= 1 / DEPENDENCE_RATIO)
        return FormFit(self.id, {"levels": sorted(groups), "relative_residual": rel, "ratio_high_to_low": ratio},
                       {"levels": self.unit, "relative_residual": "1", "ratio_high_to_low": "1"},
                       f"the relative residual at {self.key} {hi:.3g} {self.unit} is {ratio:.2g}× that at "
                       f"{lo:.3g} {self.unit}", significant=sig)


class AmplitudeDependence(_Dependence):
    id, title, attr, within, unit, key = ("amplitude_dependence", "amplitude dependence", "amplitude_level", "rh", "V",
                                          "amplitude")


class RHDependence(_Dependence):
    id, title, attr, within, unit, key = "rh_dependence", "RH dependence", "rh", "amplitude_level", "%", "rh"
