"""Residual forms: what remains after the best model, fitted and selected by BIC.

When the best model still leaves more than noise, the diagnosis describes the residual
e_r(t) (measured minus model, per record r, offsets removed) with a small library of
*forms*, each in its own module of this package and named nowhere else:

* forms with a **regressor** explain e ≈ Σ_j c_j x_j(θ) with x_j built from the model's
  own prediction ŷ (or time, or the input through the fitted linear model,
  :attr:`Residual.respond`) and a few nonlinear parameters θ scanned on a grid; the gains
  c_j are shared by every record and solved by linear least squares;
* **dependence** forms ask whether the error follows the model's output with a gain that changes
  between amplitude or RH levels (a gain per level against one shared gain).

Each regressor form is scored by ΔBIC on the effective sample size of :mod:`..stats`
(ΔBIC = Σ_r n_eff,r ln(RSS₁,r/RSS₀,r) + k ln Σ n_eff,r, k = its gains and grid
parameters) and called *significant* at ΔBIC ≤ −:data:`SIGNIFICANT_BIC` (very strong,
Kass & Raftery 1995) with the RMS error lowered by ≥ :data:`MIN_GAIN`.  As in the
diagnosis, one n_eff serves every form compared: that of the residual closest to noise,
the one the best-fitting form leaves (a residual that *is* a slow creep has a handful of
effective samples; the noise left once the creep is removed has thousands).  Selection is
forward: the best significant form is taken, its fitted part removed from the residual,
and the others are fitted again on what is left, while one stays significant (at most
:data:`MAX_SELECTED`).  A selected form that can be written as an effect gives a draft
(:meth:`Form.draft`, a list of :class:`..effect_draft.EffectDraft`: one, or each version of the
form the residual cannot choose between; selected by :mod:`..draft`).

The pieces every form builds on (:class:`Residual`, :class:`Form`, :class:`FormFit`, the
regression) live in :mod:`.base`.  A form is a subclass of :class:`Form` with an ``id``,
``title`` and :meth:`Form.fit` (and :meth:`Form.draft` when it can be written as an effect);
:data:`FORMS` lists them.
"""
from __future__ import annotations

import math
from typing import Sequence

from .base import (MAX_SELECTED, MIN_GAIN, PURE, SIGNIFICANT_BIC, Form, FormFit, Regression, Residual,  # noqa: F401
                   best_on_grid, lowpass)
from .dependence import AmplitudeDependence, RHDependence
from .drift import Drift
from .gain_drift import GainDrift
from .input_side import InputDeadZone, InputSaturation
from .output_asymmetry import OutputAsymmetry
from .output_delay import OutputDelay
from .output_lowpass import OutputLowPass
from .play import Play
from .saturation import OutputSaturation
from .slow_pole import SlowPole

#: Every form, in the order they are reported when their evidence ties.
FORMS: tuple[type[Form], ...] = (SlowPole, OutputLowPass, OutputDelay, Drift, Play, OutputSaturation, InputDeadZone,
                                 InputSaturation, OutputAsymmetry, GainDrift, AmplitudeDependence, RHDependence)


def titles() -> str:
    """The forms' titles, for a sentence."""
    return ", ".join(f.title for f in FORMS)


def form_of(form_id: str) -> type[Form]:
    return next(f for f in FORMS if f.id == form_id)


def rescore(fits: dict, res: Residual) -> None:
    """Score the regressor forms of ``fits`` (fitted to ``res``) again on one n_eff, that of
    the residual the best-fitting form leaves (package doc); in place."""
    regs = [ff for ff in fits.values() if ff.rss is not None]
    if not regs:
        return
    best = min(regs, key=lambda ff: sum(ff.rss))
    n_eff = res.minus(best.parts).n_eff
    penalty = math.log(max(sum(n_eff), 2.0))
    for ff in regs:
        ff.delta_bic = sum(ne * math.log(max(b1, 1e-300) / max(b0, 1e-300))
                           for ne, b0, b1 in zip(n_eff, res.rss, ff.rss)) + ff.k * penalty
        ff.significant = bool(ff.admissible and ff.delta_bic <= -SIGNIFICANT_BIC and ff.rms_reduction >= MIN_GAIN)


def describe(fit, records: Sequence) -> list[FormFit]:
    """Every form fitted to the residual of ``fit`` on ``records``, forward-selected (package
    doc): the selected forms first, in order, then the rest by ΔBIC."""
    res = Residual.of(fit, records)
    fits = {f.id: ff for f in FORMS if (ff := f().fit(res)) is not None}
    rescore(fits, res)
    chain: list[FormFit] = []
    remaining = res
    while len(chain) < MAX_SELECTED:
        pool = [ff for k, ff in fits.items() if ff.parts is not None and ff.significant
                and k not in {c.form for c in chain}]
        if not pool:
            break
        best = min(pool, key=lambda ff: ff.delta_bic)
        best.selected_step = len(chain) + 1
        chain.append(best)
        remaining = remaining.minus(best.parts)
        rest = {}
        for k in list(fits):
            if fits[k].parts is not None and k not in {c.form for c in chain}:
                refit = form_of(k)().fit(remaining)
                if refit is not None:
                    fits[k] = rest[k] = refit
        rescore(rest, remaining)
    rest = sorted((ff for ff in fits.values() if ff.selected_step is None),
                  key=lambda ff: (ff.delta_bic if math.isfinite(ff.delta_bic) else math.inf))
    return chain + rest


def input_driven(forms: Sequence[FormFit]) -> list[FormFit]:
    """The forward-selected forms that follow the input (structure a sensor's wander cannot make)."""
    return [f for f in selected(forms) if form_of(f.form).input_driven]


def selected(forms: Sequence[FormFit]) -> list[FormFit]:
    """The forward-selected forms (in order)."""
    return [f for f in forms if f.selected_step is not None]


def residual_of(fit, records: Sequence) -> Residual:
    return Residual.of(fit, records)


__all__ = ["FORMS", "Form", "FormFit", "Residual", "Regression", "describe", "rescore", "selected", "input_driven",
           "form_of", "lowpass",
           "best_on_grid", "titles", "SIGNIFICANT_BIC", "MIN_GAIN", "PURE"]
