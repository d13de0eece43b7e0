"""Residual forms: what remains after the best model, fitted and selected by BIC.

When the best model still leaves more than noise, the diagnosis describes the residual
e_r(t) (measured minus model, per record r, offsets removed) with a small library of
*forms*, each in its own module of this package and named nowhere else:

* forms with a **regressor** explain e ≈ Σ_j c_j x_j(θ) with x_j built from the model's
  own prediction ŷ (or time, or the input) and a few nonlinear parameters θ scanned on a
  grid; the gains c_j are shared by every record and solved by linear least squares;
* **dependence** forms compare the relative residual between amplitude or RH levels.

Each regressor form is scored by ΔBIC on the effective sample size of :mod:`..stats`
(ΔBIC = Σ_r n_eff,r ln(RSS₁,r/RSS₀,r) + k ln Σ n_eff,r, k = its gains and grid
parameters) and called *significant* at ΔBIC ≤ −:data:`SIGNIFICANT_BIC` (very strong,
Kass & Raftery 1995) with the RMS error lowered by ≥ :data:`MIN_GAIN`.  Selection is
forward: the best significant form is taken, its fitted part removed from the residual,
and the others are fitted again on what is left, while one stays significant (at most
:data:`MAX_SELECTED`).  A selected form that can be written as an effect gives a draft
(:meth:`Form.draft`, rendered by :mod:`..draft`).

A form is a subclass of :class:`Form` with an ``id``, ``title`` and :meth:`Form.fit`
(and :meth:`Form.draft` when it can be written as an effect); :data:`FORMS` lists them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar, Sequence

import numpy as np
from scipy.signal import lfilter, lfilter_zi

from .. import stats

#: A form is significant at ΔBIC ≤ −this (very strong evidence, Kass & Raftery) ...
SIGNIFICANT_BIC = 10.0
#: ... and when it lowers the RMS error by at least this fraction.
MIN_GAIN = 0.10
#: Forward selection stops after this many forms.
MAX_SELECTED = 3


@dataclass
class Residual:
    """What a form is fitted to: the residual, the model's prediction, the records."""

    records: list
    resid: list                  # per record, decimated [m], mean removed
    preds: list                  # model prediction per record, decimated [m]
    n_eff: list                  # effective sample size per record

    @classmethod
    def of(cls, fit, records: Sequence) -> "Residual":
        resid = [np.asarray(e, float) - float(np.mean(e)) for e in fit.resid_d]
        preds = [np.asarray(p, float) for p in fit.pred_d]
        n_eff = [e.size / max(stats.integrated_time(e), 1.0) for e in resid]
        return cls(list(records), resid, preds, n_eff)

    def minus(self, parts: list) -> "Residual":
        """The residual with a fitted part removed (its own effective sample sizes)."""
        resid = [e - p for e, p in zip(self.resid, parts)]
        return Residual(self.records, resid, self.preds, [e.size / max(stats.integrated_time(e), 1.0) for e in resid])

    @property
    def rss(self) -> list[float]:
        return [float(e @ e) for e in self.resid]

    @property
    def n_total(self) -> int:
        return sum(e.size for e in self.resid)

    @property
    def span_s(self) -> float:
        """The shortest record [s]."""
        return min(r.y_d.size / r.fs_d for r in self.records)

    @property
    def fs_min(self) -> float:
        return min(r.fs_d for r in self.records)

    @property
    def band(self) -> tuple[float, float]:
        """Excited band over all records [Hz]."""
        return min(r.band[0] for r in self.records), max(r.band[1] for r in self.records)

    def regress(self, columns: list[list[np.ndarray]], k_grid: int = 1) -> "Regression":
        """Least squares e_r ≈ Σ_j c_j x_rj with gains shared by the records; ``columns[r]`` the
        regressors of record r (means removed here, as the fit removes each record's offset);
        ``k_grid`` nonlinear parameters scanned outside (counted in ΔBIC with the gains)."""
        X = [np.column_stack([x - x.mean() for x in cols]) for cols in columns]
        A = sum(x.T @ x for x in X)
        b = sum(x.T @ e for x, e in zip(X, self.resid))
        scale = np.sqrt(np.maximum(np.diag(A), 1e-300))
        try:
            c = np.linalg.lstsq(A / np.outer(scale, scale), b / scale, rcond=1e-12)[0] / scale
        except np.linalg.LinAlgError:
            c = np.zeros(A.shape[0])
        parts = [x @ c for x in X]
        rss1 = [float((e - p) @ (e - p)) for e, p in zip(self.resid, parts)]
        k = len(c) + k_grid
        d_bic = sum(ne * math.log(max(b1, 1e-300) / max(b0, 1e-300))
                    for ne, b0, b1 in zip(self.n_eff, self.rss, rss1)) + k * math.log(max(sum(self.n_eff), 2.0))
        return Regression([float(x) for x in c], parts, rss1, d_bic, k)


@dataclass
class Regression:
    gains: list[float]
    parts: list                  # fitted part per record
    rss: list[float]
    delta_bic: float
    k: int


@dataclass
class FormFit:
    """One form fitted to a residual: its parameters (SI, with units), the evidence, a sentence."""

    form: str
    params: dict                                   # name -> value (SI)
    units: dict                                    # name -> unit
    text: str
    delta_bic: float = math.nan
    rms_reduction: float = 0.0
    significant: bool = False
    parts: list | None = None                      # fitted part per record (regressor forms)
    k: int = 0
    selected_step: int | None = None               # position in the forward selection (1 = first)
    info: dict = field(default_factory=dict)       # anything else worth reporting

    def to_dict(self) -> dict:
        out = {"kind": self.form, **self.params, "units": self.units, "significant": self.significant,
               "text": self.full_text, "extra_parameters": self.k, "selected_step": self.selected_step,
               "draftable": bool(form_of(self.form).draft is not Form.draft), **self.info}
        if math.isfinite(self.delta_bic):
            out.update({"delta_bic": self.delta_bic, "rms_reduction": self.rms_reduction})
        return out

    @property
    def full_text(self) -> str:
        if not math.isfinite(self.delta_bic):
            return self.text
        return self.text + f" (RMS error −{100 * self.rms_reduction:.0f} %, ΔBIC {self.delta_bic:.3g})"


class Form:
    """A residual form (see the package doc)."""

    id: ClassVar[str]
    title: ClassVar[str]

    def fit(self, res: Residual) -> FormFit | None:
        """The form fitted to ``res`` (None: the records cannot show it)."""
        raise NotImplementedError

    def draft(self, ff: FormFit, res: Residual):
        """An :class:`..draft.EffectDraft` writing ``ff`` as an effect (None: not as an effect)."""
        return None

    def scored(self, res: Residual, reg: Regression, params: dict, units: dict, text: str, **info) -> FormFit:
        """A :class:`FormFit` from a regression, with its evidence and significance."""
        rms0 = math.sqrt(sum(res.rss) / res.n_total)
        rms1 = math.sqrt(sum(reg.rss) / res.n_total)
        gain = 1.0 - rms1 / rms0 if rms0 > 0 else 0.0
        sig = bool(reg.delta_bic <= -SIGNIFICANT_BIC and gain >= MIN_GAIN)
        return FormFit(self.id, params, units, text, reg.delta_bic, gain, sig, reg.parts, reg.k, info=info)


def best_on_grid(res: Residual, grid, columns) -> tuple[float, Regression]:
    """(grid value, regression) with the lowest ΔBIC; ``columns(value)`` gives the regressors."""
    best = None
    for g in grid:
        reg = res.regress(columns(g))
        if best is None or reg.delta_bic < best[1].delta_bic:
            best = (float(g), reg)
    return best


def lowpass(x: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """First-order lag 1/(1 + sτ) [τ in s] of ``x`` sampled at ``fs`` [Hz] (exact for a
    zero-order hold), started in the steady state of the first sample."""
    a = math.exp(-1.0 / (tau * fs))
    b, den = [1.0 - a], [1.0, -a]
    return lfilter(b, den, x, zi=lfilter_zi(b, den) * x[0])[0]


from .dependence import AmplitudeDependence, RHDependence  # noqa: E402
from .drift import Drift  # noqa: E402
from .output_lowpass import OutputLowPass  # noqa: E402
from .play import Play  # noqa: E402
from .saturation import OutputSaturation  # noqa: E402
from .slow_pole import SlowPole  # noqa: E402

#: Every form, in the order they are reported when their evidence ties.
FORMS: tuple[type[Form], ...] = (SlowPole, OutputLowPass, Drift, Play, OutputSaturation, AmplitudeDependence,
                                 RHDependence)


def titles() -> str:
    """The forms' titles, for a sentence."""
    return ", ".join(f.title for f in FORMS)


def form_of(form_id: str) -> type[Form]:
    return next(f for f in FORMS if f.id == form_id)


def describe(fit, records: Sequence) -> list[FormFit]:
    """Every form fitted to the residual of ``fit`` on ``records``, forward-selected (package
    doc): the selected forms first, in order, then the rest by ΔBIC."""
    res = Residual.of(fit, records)
    fits = {f.id: ff for f in FORMS if (ff := f().fit(res)) is not None}
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
        for k in list(fits):
            if fits[k].parts is not None and k not in {c.form for c in chain}:
                refit = form_of(k)().fit(remaining)
                if refit is not None:
                    fits[k] = refit
    rest = sorted((ff for ff in fits.values() if ff.selected_step is None),
                  key=lambda ff: (ff.delta_bic if math.isfinite(ff.delta_bic) else math.inf))
    return chain + rest


def selected(forms: Sequence[FormFit]) -> list[FormFit]:
    """The forward-selected forms (in order)."""
    return [f for f in forms if f.selected_step is not None]


def residual_of(fit, records: Sequence) -> Residual:
    return Residual.of(fit, records)


__all__ = ["FORMS", "Form", "FormFit", "Residual", "Regression", "describe", "selected", "form_of", "lowpass",
           "best_on_grid", "titles", "SIGNIFICANT_BIC", "MIN_GAIN"]
