"""The pieces every residual form builds on (:mod:`physics.diagnose.forms`): the residual a
form is fitted to, the shared-gain regression and its ΔBIC, a form's fit and the form base
class, the grid scan, the fitted linear model's response to another input and a first-order lag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Sequence

import numpy as np
from scipy.signal import lfilter, lfilter_zi

from ...analysis import stats
from ...analysis.metrics import remove_nuisance
from ..effect_draft import EffectDraft, Param
from ..records import rh_levels

#: A form is significant at ΔBIC ≤ −this (very strong evidence, Kass & Raftery) ...
SIGNIFICANT_BIC = 10.0
#: ... and when it lowers the RMS error by at least this fraction.
MIN_GAIN = 0.10
#: Forward selection stops after this many forms.
MAX_SELECTED = 3
#: Range of the gain a of a form e ≈ a·x whose regressor x is the whole of what it names (a
#: low-pass of the output, a nonlinearity of the input): a = 1 for the pure form, the base's
#: re-tuned parameters take up part of it; far outside, the regressor only happens to fit a
#: band of error, and the form is not significant.
PURE = (0.5, 1.5)


@dataclass
class Residual:
    """What a form is fitted to: the residual, the model's prediction, the records, (a linear
    model) ``respond(k, u)``: the fitted model's deflection [m] for record k driven by the voltage
    ``u`` [V] at its ``fs_d`` instead of its own (:func:`linear_response`), and ``gain_groups``:
    per record, the group of records whose gain the fit set together (one group, None, unless
    parameters were fitted per RH level: then one group per level)."""

    records: list
    resid: list                  # per record, decimated [m], nuisance terms removed
    preds: list                  # model prediction per record, decimated [m]
    n_eff: list                  # effective sample size per record
    respond: Callable | None = None
    gain_groups: list | None = None

    @classmethod
    def of(cls, fit, records: Sequence) -> "Residual":
        resid = [remove_nuisance(e) for e in fit.resid_d]
        preds = [np.asarray(p, float) for p in fit.pred_d]
        n_eff = [e.size / max(stats.integrated_time(e), 1.0) for e in resid]
        model = getattr(fit, "model", None)
        respond = linear_response(model, records) if has_response(model) else None
        return cls(list(records), resid, preds, n_eff, respond, gain_groups(fit, records))

    def minus(self, parts: list) -> "Residual":
        """The residual with a fitted part removed (its own effective sample sizes)."""
        resid = [e - p for e, p in zip(self.resid, parts)]
        return Residual(self.records, resid, self.preds, [e.size / max(stats.integrated_time(e), 1.0) for e in resid],
                        self.respond, self.gain_groups)

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
        regressors of record r (their nuisance terms removed here, as the fit removes each
        record's offset and linear drift, :func:`physics.analysis.metrics.remove_nuisance`);
        ``k_grid`` nonlinear parameters scanned outside (counted in ΔBIC with the gains)."""
        X = [np.column_stack([remove_nuisance(x) for x in cols]) for cols in columns]
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
    rss: list | None = None                        # RSS per record left by the form (regressor forms)
    admissible: bool = True                        # False: the fit is not the form it names (never significant)
    selected_step: int | None = None               # position in the forward selection (1 = first)
    draftable: bool = False                        # its form can be written as an effect (Form.draft)
    info: dict = field(default_factory=dict)       # anything else worth reporting

    def to_dict(self) -> dict:
        out = {"kind": self.form, **self.params, "units": self.units, "significant": self.significant,
               "text": self.full_text, "extra_parameters": self.k, "selected_step": self.selected_step,
               "draftable": self.draftable, **self.info}
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
    #: The form follows the input (a slow pole, a low-pass, a play…): what it describes is the
    #: model's error, never a sensor's wander.
    input_driven: ClassVar[bool] = True
    #: The form is written through the fitted model's linear response (:attr:`Residual.respond`),
    #: which a large-signal model does not have.
    needs_response: ClassVar[bool] = False

    def fit(self, res: Residual) -> FormFit | None:
        """The form fitted to ``res`` (None: the records cannot show it)."""
        raise NotImplementedError

    def draft(self, ff: FormFit, res: Residual) -> list:
        """The :class:`..effect_draft.EffectDraft` writing ``ff`` as an effect ([]: not as an
        effect), or each version of the form when the residual cannot choose between them (the
        fit with the model does)."""
        return []

    def scored(self, res: Residual, reg: Regression, params: dict, units: dict, text: str, **info) -> FormFit:
        """A :class:`FormFit` from a regression, with its evidence and significance (on the
        residual's own n_eff; :func:`describe` scores the forms again on a common one)."""
        rms0 = math.sqrt(sum(res.rss) / res.n_total)
        rms1 = math.sqrt(sum(reg.rss) / res.n_total)
        gain = 1.0 - rms1 / rms0 if rms0 > 0 else 0.0
        sig = bool(reg.delta_bic <= -SIGNIFICANT_BIC and gain >= MIN_GAIN)
        return FormFit(self.id, params, units, text, reg.delta_bic, gain, sig, reg.parts, reg.k, reg.rss, info=info,
                       draftable=type(self).draft is not Form.draft)


def time_path_draft(ff: FormFit, name: str, summary: str, model: str, params: list[Param], returns: str,
                    excitation: str, signature: str, imports: tuple[str, ...] = ()) -> list[EffectDraft]:
    """The draft of a form written as a map of the simulated deflection that leaves the frequency
    response at 1 (an even map, a gain that averages out over a record, a play): its parameters
    are fitted on the time records (:func:`physics.contract.time_only_params`), so it is offered
    only where the form is significant (every draft offered is fitted with the model in each
    draft round).  ``returns``: the expression ``filter_output`` returns, of ``y`` (an array [m]),
    ``fs`` and ``p``; the last parameter is scanned (its value, a third and three times it), the first
    off at 0."""
    if not ff.significant:
        return []
    first = params[0].name
    return [EffectDraft(
        form=ff.form, effect_id=f"drafted_{name}", class_name="Drafted" + "".join(w.title() for w in name.split("_")),
        summary=summary, model=model + "  Its frequency response is left at 1, so its parameters are fitted on the "
                                       f"time records; {first} = 0 is the model without it.",
        params=params, scan=params[-1].name, off={first: 0.0}, excitation=excitation, reveal={},
        signature=[(signature, 1.0)],
        body=('    def filter_output(self, y, fs, p):\n'
              '        y = np.asarray(y, float)\n'
              f'        return {returns}\n'
              '\n'
              '    def output_response(self, s, p):\n'
              '        return np.ones_like(np.asarray(s), dtype=complex)\n'),
        imports=("import numpy as np",) + imports)]


def best_on_grid(res: Residual, grid, columns, k_grid: int = 1,
                 admit: Callable[[Regression], bool] | None = None) -> tuple[float, Regression] | None:
    """(grid value, regression) with the lowest ΔBIC; ``columns(value)`` gives the regressors;
    ``k_grid`` parameters are scanned (counted in ΔBIC); ``admit``: only regressions it accepts
    compete (None when it accepts none)."""
    best = None
    for g in grid:
        reg = res.regress(columns(g), k_grid)
        if (admit is None or admit(reg)) and (best is None or reg.delta_bic < best[1].delta_bic):
            best = (float(g), reg)
    return best


def refined(res: Residual, x0, bounds, columns, k_grid: int,
            admit: Callable[[Regression], bool] | None = None) -> tuple[list[float], Regression]:
    """(parameters, regression): the scanned parameters ``x0`` (a grid's best point) refined
    within ``bounds`` to the lowest ΔBIC (Nelder–Mead, at most 60 regressions); ``columns(x)``
    gives the regressors; ``admit``: the regressions it refuses score +∞ (an admitted ``x0`` stays
    admitted)."""
    from scipy.optimize import minimize

    def cost(x):
        reg = res.regress(columns(x), k_grid)
        return reg.delta_bic if admit is None or admit(reg) else math.inf
    sol = minimize(cost, np.asarray(x0, float), method="Nelder-Mead",
                   bounds=bounds, options={"maxfev": 60, "xatol": 1e-3, "fatol": 0.1})
    x = [float(v) for v in sol.x]
    return x, res.regress(columns(x), k_grid)


def has_response(model) -> bool:
    """Whether ``model`` has the linear response :attr:`Residual.respond` needs: a linear model
    that does not map the voltage first (its frequency response is then not its own)."""
    return model is not None and model.is_linear and not model.inputs


def gain_groups(fit, records: Sequence) -> list[int] | None:
    """Per record, the index of the group whose gain ``fit`` set together: its RH level when the
    fit freed parameters per RH level (each level's stiffness and coupling then take up on their
    own what the records at that level lack), else None (one group)."""
    spec = getattr(fit, "spec", None)
    if not getattr(spec, "per_rh", None):
        return None
    levels = rh_levels(records)
    return [levels.index(r.rh) for r in records] if len(levels) > 1 else None


def linear_response(model, records: Sequence) -> Callable:
    """respond(k, u): the deflection [m] of the linear ``model`` (and record k's sensor) for the
    voltage ``u`` [V] sampled at record k's ``fs_d``, from rest at u[0]: its frequency response
    (400 log-spaced frequencies up to fs_d/2, interpolated) applied in the frequency domain,
    zero-padded to twice the length.  Each record's response is computed once, when first used."""
    from ...compare.frf import sensor_response
    from ...solvers.frequency import frequency_response
    cache: dict = {}

    def respond(k: int, u: np.ndarray) -> np.ndarray:
        r = records[k]
        n = u.size
        nfft = 1 << int(math.ceil(math.log2(2 * n)))
        if (k, nfft) not in cache:
            f = np.fft.rfftfreq(nfft, 1.0 / r.fs_d)
            grid = np.geomspace(max(f[1], 1e-3), f[-1], 400)
            H = frequency_response(model, None, grid, rh=float(r.rh)).deflection
            lg = np.log(np.maximum(f, grid[0]))
            cache[(k, nfft)] = (np.interp(lg, np.log(grid), H.real) + 1j * np.interp(lg, np.log(grid), H.imag)) \
                * sensor_response(f, r.sensor_bandwidth)
        return np.fft.irfft(np.fft.rfft(u - u[0], nfft) * cache[(k, nfft)], nfft)[:n]
    return respond


def lowpass(x: np.ndarray, tau: float, fs: float) -> np.ndarray:
    """First-order lag 1/(1 + sτ) [τ in s] of ``x`` sampled at ``fs`` [Hz] (exact for a
    zero-order hold), started in the steady state of the first sample."""
    a = math.exp(-1.0 / (tau * fs))
    b, den = [1.0 - a], [1.0, -a]
    return lfilter(b, den, x, zi=lfilter_zi(b, den) * x[0])[0]
