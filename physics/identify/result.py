"""The identification result and the ``identify`` entry point."""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Sequence


from ..compare import load_measurements, source_name
from ..device import Device, load_device
from ..errors import InputError, arg
from ..execution.parallel import warm_up
from ..execution.threads import single_threaded
from .fitting import Fit, fit_lsq, fit_nelder_mead
from .options import FitOptions, LsqOptions
from .free_parameters import IdentifiabilityWarning, held_per_rh, parse_assignments, parse_names
from .problem import IdentificationProblem, build_targets
from .settings import THESIS_MAX_ITER, THESIS_SECONDS_PER_FREQUENCY, THESIS_TOL




@dataclass
class IdentificationResult:
    """Everything :func:`identify` found; ``fit`` is the one the fitted ``device`` uses."""

    problem: IdentificationProblem
    fits: dict[str, Fit]
    primary: str
    device: Device
    j_err_initial: float
    sources: list[str]
    settings: dict
    wall_s: float
    #: The check of the fit on the time records (:func:`_check_against_start`): the RMS error
    #: [m] at the start and at the fit, and whether the start values were kept.
    check: dict = field(default_factory=dict)

    @property
    def kept_start(self) -> bool:
        """True when the fit made the time records worse and the device keeps the start values."""
        return bool(self.check.get("kept_start"))

    @property
    def fit(self) -> Fit:
        return self.fits[self.primary]

    @property
    def values(self) -> dict[str, float]:
        """Fitted values {label: SI value}."""
        return dict(zip(self.problem.labels, self.fit.theta.tolist()))

    @property
    def std_errors(self) -> dict[str, float]:
        return dict(zip(self.problem.labels, self.fit.std_error.tolist()))

    @property
    def warnings(self) -> list[str]:
        return ([self.check["message"]] if self.kept_start else []) + list(self.fit.warnings)

    @property
    def n_evaluations(self) -> int:
        return self.problem.n_eval

    def thesis_equivalent_s(self, iterations: int = THESIS_MAX_ITER) -> float:
        """Wall time of the thesis loop for the same data: ``iterations`` × 15 min per
        frequency × number of fitted frequencies (one model evaluation per iteration —
        a lower bound: Nelder–Mead needs 1–2 evaluations per iteration plus shrinks)."""
        n_f = sum(t.freq.size for t in self.problem.targets)
        return iterations * THESIS_SECONDS_PER_FREQUENCY * n_f

    def param_rows(self, fit: Fit | None = None) -> list[dict]:
        fit = fit or self.fit
        rows = []
        for i, p in enumerate(self.problem.params):
            rows.append({"parameter": p.label, "name": p.name, "rh_pct": p.rh, "unit": p.unit, "scale": p.scale,
                         "initial": p.initial, "value": float(fit.theta[i]), "std_error": float(fit.std_error[i]),
                         "rel_std_error": float(fit.rel_std_error[i]), "ci95_lo": float(fit.ci95[i, 0]),
                         "ci95_hi": float(fit.ci95[i, 1]), "lower_bound": p.lower, "upper_bound": p.upper})
        return rows

    def to_dict(self) -> dict:
        from ..io.fileio import jsonable
        fits = {}
        for name, f in self.fits.items():
            fits[name] = {"method": f.method, "residual": f.residual_kind, "parameters": self.param_rows(f),
                          "correlation": {"labels": self.problem.labels, "matrix": f.correlation.tolist()},
                          "cost": f.cost, "j_err_m_per_V": f.j_err, "model_evaluations": f.nfev,
                          "iterations": f.nit, "success": f.success, "message": f.message, "wall_s": f.wall_s,
                          "residual_variance_s2": f.s2, "dof": f.dof, "condition_number": f.condition,
                          "singular_values": f.singular_values.tolist(), "warnings": f.warnings,
                          "starts": f.starts}
        return jsonable({
            "device": self.problem.device.name, "device_file": self.problem.device.path,
            "effects": list(self.problem.effects), "free": self.problem.free, "per_rh": self.problem.per_rh,
            "rh_levels_pct": self.problem.levels, "primary": self.primary, "fits": fits,
            "j_err_initial_m_per_V": self.j_err_initial, "j_err_final_m_per_V": self.fit.j_err,
            "criterion": {"name": self.fit.residual_kind, "start": self.check.get("cost_start"),
                          "fitted": self.fit.cost},
            "time_check": self.check,
            "model_evaluations": self.n_evaluations, "wall_s": self.wall_s,
            "thesis_loop_equivalent_s": self.thesis_equivalent_s(),
            "thesis_loop_assumption": "100 Nelder-Mead iterations x 1 model evaluation x 15 min per frequency "
                                      "point x number of fitted frequencies (COMSOL, thesis ch. 1 §5)",
            "speedup_vs_thesis_loop": self.thesis_equivalent_s() / max(self.wall_s, 1e-9),
            "targets": [{"source": t.source, "rh_pct": t.rh, "frequencies": int(t.freq.size),
                         "f_min_Hz": float(t.freq.min()), "f_max_Hz": float(t.freq.max()),
                         "sensor_bandwidth_Hz": t.sensor_bandwidth, "estimator": t.estimator}
                        for t in self.problem.targets],
            "settings": self.settings, "warnings": self.warnings})


@single_threaded
def identify(measurements: Sequence, device, effects=None, free: Sequence[str] | str = (), *,
             options: FitOptions | None = None, method: str = "lsq", residual: str = "frf", fit_phase: bool = True,
             skip_s: float = 0.0, lsq: LsqOptions | None = None, warn: bool = True,
             **shared) -> IdentificationResult:
    """Identify ``free`` (shared) and ``per_rh`` parameters of ``device`` with ``effects``
    from ``measurements`` (paths, :class:`TimeSeries` or :class:`FRFData`).

    ``options``: the measurement and fit options shared with ``diagnose``
    (:class:`~physics.identify.options.FitOptions`: ``per_rh``, ``start``/``bounds`` as
    {name: SI value} / {name: (lo, hi)} or ``"kf=0.004,Y=0.2 GPa"`` / ``"kf=1e-4:1e-1"``,
    ``n_starts`` (default 5 for FRF residuals, 1 for time residuals), ``seed``, ``frf``,
    ``rh``, ``rh_tolerance``, ``sensor_bandwidth``, ``min_coherence``, ``weighting``,
    ``n_modes``, ``settings``: where the least-squares starts run); its fields may also be
    given as keywords.  ``method``: ``"lsq"`` (default), ``"nelder-mead"`` (thesis) or
    ``"both"`` (the device uses the least-squares fit); ``lsq``: the least-squares search
    (:class:`~physics.identify.options.LsqOptions`: ``start_spread``, ``max_nfev``).
    Identifiability problems are listed in the result and, with ``warn``, issued as
    :class:`IdentifiabilityWarning`.  A fit worse than its start is not written
    (:func:`_check_against_start`).  See the module doc."""
    t0 = time.perf_counter()
    opts = FitOptions.merged(options, **({"free": free} if free not in (None, "", ()) else {}), **shared)
    lsq = lsq if lsq is not None else LsqOptions()
    if method not in ("lsq", "nelder-mead", "both"):
        raise InputError(f"method {method!r}: expected lsq, nelder-mead or both")
    n_starts = opts.n_starts if opts.n_starts is not None else (5 if residual == "frf" else 1)
    if int(n_starts) < 1:
        raise InputError(f"{arg('n_starts')}={n_starts!r} must be at least 1")
    settings = opts.settings
    warm_up(settings)   # the workers start while the measurements are read and the FRFs estimated
    ms = load_measurements(measurements, rh=opts.rh)
    targets = build_targets(ms, frf_options=opts.frf, min_coherence=opts.min_coherence, weighting=opts.weighting,
                            rh_tolerance=opts.rh_tolerance, sensor_bandwidth=opts.sensor_bandwidth, default_rh=opts.rh)
    device = load_device(device)
    levels = sorted({t.level for t in targets})
    device, free_l, per_l, notes = held_per_rh(device, parse_names(opts.free or ()),
                                               parse_names(opts.per_rh, arg("per_rh")), levels, targets[0].rh)
    problem = IdentificationProblem(device, effects, targets, free_l, per_l, start=parse_assignments(opts.start),
                                    bounds=parse_assignments(opts.bounds, ranges=True, what=arg("bounds")),
                                    n_modes=opts.n_modes, fit_phase=fit_phase, residual=residual, skip_s=skip_s)
    seed = opts.seed
    j0 = problem.j_err(problem.theta0)
    fits: dict[str, Fit] = {}
    if method in ("nelder-mead", "both"):
        fits["nelder-mead"] = fit_nelder_mead(problem)
    if method in ("lsq", "both"):
        fits["lsq"] = fit_lsq(problem, n_starts=int(n_starts), seed=seed, start_spread=lsq.start_spread,
                              max_nfev=lsq.max_nfev, settings=settings, keep=opts.keep_starts)
    primary = "lsq" if "lsq" in fits else "nelder-mead"
    check = _check_against_start(problem, fits[primary])
    dev = problem.device_for(problem.theta0 if check.get("kept_start") else fits[primary].theta)
    sources = [source_name(m, k) for k, m in enumerate(ms)]
    settings = {"method": method, "n_starts": n_starts, "seed": seed, "start_spread_decades": lsq.start_spread,
                "residual": residual, "fit_phase": fit_phase, "weighting": opts.weighting,
                "min_coherence": opts.min_coherence, "rh_tolerance_pct": opts.rh_tolerance,
                "sensor_bandwidth": opts.sensor_bandwidth, "n_modes": opts.n_modes, "skip_s": skip_s,
                "frf": vars(opts.frf).copy(), "notes": notes,
                "thesis_nelder_mead": {"max_iter": THESIS_MAX_ITER, "xatol": THESIS_TOL, "fatol": THESIS_TOL,
                                       "tolerance_on": "parameters / start values and J_err / RMS |H_meas|"}}
    res = IdentificationResult(problem, fits, primary, dev, j0, sources, settings, time.perf_counter() - t0, check)
    if warn:
        for w in res.warnings:
            warnings.warn(w, IdentifiabilityWarning, stacklevel=2)
    return res


def _check_against_start(problem: IdentificationProblem, fit: Fit) -> dict:
    """The fit is never written as the result when it is worse than its start: on its own
    criterion (the method's cost) and, with time records, on the time-domain RMS error of
    the records (what a user compares; an FRF fit can improve its FRF cost on biased
    estimates while the records get worse).  Then the start values are kept and the
    message says so plainly."""
    start_cost = problem.criterion(problem.theta0, fit.method)
    out: dict = {"cost_start": start_cost, "cost_fitted": fit.cost, "kept_start": False}
    worse = []
    if fit.cost > start_cost * (1 + 1e-9):
        worse.append(f"its criterion ({fit.residual_kind}) rose from {start_cost:.4g} to {fit.cost:.4g}")
    if any(t.record is not None for t in problem.targets):
        e0, e1 = problem.time_rmse(problem.theta0), problem.time_rmse(fit.theta)
        out.update(time_rmse_start_m=e0, time_rmse_fitted_m=e1)
        if e1 > e0 * (1 + 1e-3):
            worse.append(f"the RMS error of the time records rose from {1e6 * e0:.4g} to {1e6 * e1:.4g} µm")
    if worse:
        out["kept_start"] = True
        out["message"] = ("the fit is worse than its start: " + "; ".join(worse) + ". The device file keeps the "
                          "start values (the rejected fit is in report.json); check the free parameters, the FRF "
                          "method (--frf-method) and the records")
    return out


# ============================================================================ device file


