"""Fitting (bounded least squares, the thesis Nelder–Mead) and Jacobian-based uncertainty."""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import optimize, stats

from ..effects import ensure_registered, user_effect_files
from ..errors import InputError, ModelError
from ..execution.parallel import ParallelSettings, map_tasks
from .problem import IdentificationProblem
from .settings import COND_LIMIT, CORR_LIMIT, REL_SE_LIMIT, THESIS_MAX_ITER, THESIS_TOL

#: Evaluations per free parameter of a screened start's short run (:func:`fit_lsq` ``keep``).
SCREEN_NFEV_PER_PARAM = 10


@dataclass
class Fit:
    """One fit's result: values θ (SI), search coordinates x, uncertainties and diagnostics."""

    method: str
    theta: np.ndarray
    x: np.ndarray
    cost: float                     # 0.5‖r‖² of the method's own residual (J_err for Nelder–Mead)
    j_err: float                    # eq. 13 at θ [m/V]
    nfev: int                       # model evaluations (finite-difference ones included)
    nit: int | None
    success: bool
    message: str
    wall_s: float
    std_error: np.ndarray           # SI, 1σ (inf when not determined)
    rel_std_error: np.ndarray
    ci95: np.ndarray                # (p, 2) SI
    correlation: np.ndarray         # (p, p), NaN when undetermined
    singular_values: np.ndarray
    condition: float
    s2: float                       # residual variance (reduced chi-square with coherence weights)
    dof: int
    warnings: list[str] = field(default_factory=list)
    starts: list[dict] = field(default_factory=list)
    residual_kind: str = ""


def jacobian(fun, x, steps) -> tuple[np.ndarray, np.ndarray]:
    """(r(x), central-difference Jacobian ∂r/∂x) with per-coordinate ``steps``."""
    r0 = fun(x)
    J = np.empty((r0.size, x.size))
    for i in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[i] += steps[i]
        xm[i] -= steps[i]
        J[:, i] = (fun(xp) - fun(xm)) / (2 * steps[i])
    return r0, J


def _autocorr_time(e: np.ndarray, max_lag: int = 2000) -> float:
    """Integrated autocorrelation time 1 + 2 Σ ρ_k (summed until ρ first drops below 0.05)."""
    e = e - e.mean()
    n = e.size
    if n < 4 or not np.any(e):
        return 1.0
    f = np.fft.rfft(e, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[:min(n, max_lag)]
    ac /= ac[0]
    tau = 1.0
    for k in range(1, ac.size):
        if ac[k] < 0.05:
            break
        tau += 2 * ac[k]
    return float(tau)


def uncertainty(problem: IdentificationProblem, x: np.ndarray, fun, *, inflate: float = 1.0,
                labels: Sequence[str] | None = None) -> dict:
    """Bates–Watts linearised uncertainty at ``x`` for residual function ``fun(x)`` (see
    the module doc).  Returns std errors (x and SI), correlations, s², singular values,
    condition number and the list of identifiability warnings."""
    params = problem.params
    labels = list(labels or problem.labels)
    lo, hi = problem.x_bounds
    steps = np.array([1e-4 if p.scale == "log" else 1e-4 * max(hi[i] - lo[i], 1e-12)
                      for i, p in enumerate(params)])
    # keep the stencil inside the bounds
    xc = np.clip(x, lo + steps, hi - steps)
    r, J = jacobian(fun, xc, steps)
    n, p = J.shape
    dof = n - p
    if dof <= 0:
        raise InputError(f"{n} residuals cannot determine {p} parameters; give more frequencies or records")
    s2 = float(r @ r / dof) * inflate
    U, S, Vt = np.linalg.svd(J, full_matrices=False)
    smax = S[0] if S.size and S[0] > 0 else 1.0
    good = S > smax * 1e-12
    inv_s2 = np.where(good, 1.0 / np.where(good, S, 1.0) ** 2, np.inf)
    cond = float(smax / S[-1]) if S[-1] > 0 else math.inf
    with np.errstate(invalid="ignore", over="ignore"):
        if np.all(good):
            cov = s2 * (Vt.T * inv_s2) @ Vt
        else:
            cov = np.full((p, p), np.nan)
            cov_g = s2 * (Vt[good].T * inv_s2[good]) @ Vt[good]
            for i in range(p):
                for j in range(p):
                    cov[i, j] = cov_g[i, j]
            weak = np.abs(Vt[~good]).max(axis=0) > 1e-3
            for i in np.flatnonzero(weak):
                cov[i, :] = np.nan
                cov[:, i] = np.nan
                cov[i, i] = np.inf
    se_x = np.sqrt(np.diag(cov))
    theta = problem.from_x(x)
    tq = float(stats.t.ppf(0.975, dof))
    se, rel, ci = np.empty(p), np.empty(p), np.empty((p, 2))
    for i, par in enumerate(params):
        if par.scale == "log":
            se[i] = theta[i] * se_x[i]
            rel[i] = se_x[i]
            with np.errstate(over="ignore", invalid="ignore"):
                ci[i] = theta[i] * np.exp(-tq * se_x[i]), theta[i] * np.exp(tq * se_x[i])
        else:
            se[i] = se_x[i]
            ref = abs(theta[i]) if abs(theta[i]) > 1e-3 * (par.upper - par.lower) else (par.upper - par.lower)
            rel[i] = se_x[i] / ref
            ci[i] = theta[i] - tq * se_x[i], theta[i] + tq * se_x[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    warns = []
    for i, lab in enumerate(labels):
        if not np.isfinite(rel[i]) or rel[i] > REL_SE_LIMIT:
            warns.append(f"{lab} is not identifiable from these data: relative standard error "
                         f"{'∞' if not np.isfinite(rel[i]) else f'{100 * rel[i]:.3g} %'} (> {100 * REL_SE_LIMIT:g} %)")
        if x[i] <= lo[i] + 1e-6 * max(1.0, abs(lo[i])) or x[i] >= hi[i] - 1e-6 * max(1.0, abs(hi[i])):
            warns.append(f"{lab} ended on a bound of its search range [{params[i].lower:g}, {params[i].upper:g}] "
                         f"{params[i].unit}: widen the bounds or fix it; its interval is not meaningful")
    for i in range(p):
        for j in range(i + 1, p):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > CORR_LIMIT:
                warns.append(f"{labels[i]} and {labels[j]} are strongly correlated (ρ = {corr[i, j]:+.4f}): "
                             "only a combination of them is determined by these data")
    if not math.isfinite(cond) or cond > COND_LIMIT:
        v = Vt[-1]
        names = [labels[i] for i in np.argsort(-np.abs(v)) if abs(v[i]) > 0.2]
        warns.append(f"the Jacobian is near-singular (condition number {cond:.3g}); the weakest direction "
                     f"involves {', '.join(names)}")
    return {"r": r, "J": J, "s2": s2, "dof": dof, "se_x": se_x, "std_error": se, "rel_std_error": rel,
            "ci95": ci, "correlation": corr, "singular_values": S, "condition": cond, "warnings": warns}


def _starts(problem: IdentificationProblem, n_starts: int, seed: int, spread: float) -> list[np.ndarray]:
    x0 = problem.to_x(problem.theta0)
    lo, hi = problem.x_bounds
    out = [x0]
    if n_starts <= 1:
        return out
    sampler = stats.qmc.LatinHypercube(d=x0.size, seed=seed)
    u = sampler.random(n_starts - 1)
    for row in u:
        x = np.empty_like(x0)
        for i, p in enumerate(problem.params):
            if p.scale == "log":
                a = max(lo[i], x0[i] - spread * math.log(10))
                b = min(hi[i], x0[i] + spread * math.log(10))
            else:
                a, b = lo[i], hi[i]
            x[i] = a + row[i] * (b - a)
        out.append(x)
    return out


def _screened(tasks: list[dict], keep: int, budget: int, settings, lo, hi) -> list:
    """The runs of :func:`fit_lsq`'s screened starts: each task a short way (``budget``
    evaluations), the ``keep`` lowest on from their short run's end unless it converged there.
    One run per task; its record says how it was screened, its evaluations count both legs."""
    short = map_tasks(_fit_start, [{**t, "max_nfev": min(budget, t["max_nfev"] or budget)} for t in tasks],
                      settings, desc="starts", progress=False)
    runs = []
    for rec, res, n in short:
        if res is not None:
            how = "converged" if rec["status"] else "stopped"
            rec = {**rec, "screened": f"{how} after {rec['nfev']} evaluations, cost {rec['cost']:.6g}: "
                                      f"not among the {keep} lowest"}
        runs.append((rec, None, n))
    ranked = sorted((k for k, (_, res, _) in enumerate(short) if res is not None), key=lambda k: short[k][1].cost)
    on = [k for k in ranked[:keep] if short[k][1].status == 0]     # stopped by the budget
    for k in ranked[:keep]:
        if k not in on:
            runs[k] = ({**short[k][0], "screened": "converged within the short run"}, short[k][1], short[k][2])
    more = map_tasks(_fit_start, [{**tasks[k], "x": _interior(short[k][1].x, lo, hi)} for k in on], settings,
                     desc="starts", progress=False)
    for k, (rec, res, n) in zip(on, more):
        runs[k] = ({**rec, "start": tasks[k]["start"], "theta_start": short[k][0]["theta_start"],
                    "screened": f"continued from its short run's end (cost {short[k][0]['cost']:.6g})"},
                   res, short[k][2] + n)
    return runs


def _interior(x, lo, hi):
    span = hi - lo
    return np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)


def _fit_start(task: dict):
    """One start of :func:`fit_lsq` (a task of :func:`physics.execution.parallel.map_tasks`): (record
    for the card, the optimiser's result or None, model evaluations spent)."""
    ensure_registered(task["effect_files"])
    problem, xs = task["problem"], task["x"]
    n0 = problem.n_eval
    rec = {"start": task["start"], "theta_start": problem.from_x(xs).tolist()}
    try:
        res = optimize.least_squares(problem.residuals_x, xs, bounds=problem.x_bounds, method="trf",
                                     x_scale=1.0, max_nfev=task["max_nfev"] or 100 * xs.size)
    except (ModelError, FloatingPointError) as exc:  # a start where the model cannot be solved
        return {**rec, "error": str(exc)}, None, problem.n_eval - n0
    rec.update(theta=problem.from_x(res.x).tolist(), cost=float(res.cost), nfev=int(res.nfev), status=int(res.status))
    return rec, res, problem.n_eval - n0


def fit_lsq(problem: IdentificationProblem, *, n_starts: int = 5, seed: int = 0, start_spread: float = 1.0,
            max_nfev: int | None = None, extra_starts: Sequence[Sequence[float]] = (),
            settings: ParallelSettings | None = None, keep: int | None = None) -> Fit:
    """Bounded multi-start least squares (see the module doc).  ``extra_starts``: further
    start points θ (SI, one value per free parameter, in ``problem.labels`` order) tried
    after the usual ones (e.g. a grid over a parameter whose scale is unknown).  ``keep``:
    when there are more starts than this, every start first runs
    :data:`SCREEN_NFEV_PER_PARAM` evaluations per free parameter and only the ``keep`` lowest
    go on to convergence, from where they stopped (starts that meet in one narrow valley each
    take hundreds of evaluations to crawl along it; None: every start to convergence).  The
    starts are independent tasks of :func:`physics.execution.parallel.map_tasks` (``settings``:
    workers or a Dask scheduler); the result does not depend on where they ran."""
    t0 = time.perf_counter()
    n0 = problem.n_eval
    lo, hi = problem.x_bounds
    points = _starts(problem, n_starts, seed, start_spread)
    for th in extra_starts:
        th = np.asarray(th, dtype=float)
        if th.shape != (len(problem.params),):
            raise InputError(f"extra start {th.tolist()} needs one value per free parameter ({', '.join(problem.labels)})")
        points.append(problem.to_x(th))
    remote = settings is not None and not settings.serial
    tasks = [{"problem": problem, "x": _interior(xs, lo, hi), "max_nfev": max_nfev, "start": k,
              "effect_files": user_effect_files() if remote else []} for k, xs in enumerate(points)]
    if keep is not None and len(tasks) > keep:
        runs = _screened(tasks, keep, SCREEN_NFEV_PER_PARAM * len(problem.params), settings, lo, hi)
    else:
        runs = map_tasks(_fit_start, tasks, settings, desc="starts", progress=False)
    problem.n_eval = n0 + sum(n for _, _, n in runs)
    starts = [rec for rec, _, _ in runs]
    best = min((res for _, res, _ in runs if res is not None), key=lambda r: r.cost, default=None)
    if best is None:
        raise ModelError("every start of the least-squares fit failed: " + "; ".join(s.get("error", "") for s in starts))
    x = best.x
    inflate = 1.0
    if problem.residual == "time":
        inflate = _autocorr_time(problem.residuals_x(x))
    unc = uncertainty(problem, x, problem.residuals_x, inflate=inflate)
    theta = problem.from_x(x)
    return Fit("lsq", theta, x, float(best.cost), problem.j_err(theta), problem.n_eval - n0, None,
               bool(best.success), str(best.message), time.perf_counter() - t0, unc["std_error"],
               unc["rel_std_error"], unc["ci95"], unc["correlation"], unc["singular_values"], unc["condition"],
               unc["s2"], unc["dof"], unc["warnings"], starts,
               {"frf": "complex log FRF", "time": "time record", "both": "complex log FRF + time record"}[problem.residual]
               + (f" (covariance × {inflate:.3g}, residual autocorrelation time)" if inflate != 1.0 else ""))


def fit_nelder_mead(problem: IdentificationProblem, *, max_iter: int = THESIS_MAX_ITER,
                    tol: float = THESIS_TOL) -> Fit:
    """The thesis procedure: Nelder–Mead on J_err (eq. 13), see the module doc."""
    t0 = time.perf_counter()
    n0 = problem.n_eval
    theta0 = problem.theta0
    scale = np.where(theta0 != 0, np.abs(theta0), 1.0)
    bnds = [(p.lower / s, p.upper / s) for p, s in zip(problem.params, scale)]
    res = optimize.minimize(lambda z: problem.normalised_jerr(z, scale), theta0 / scale, method="Nelder-Mead",
                            bounds=bnds, options={"maxiter": max_iter, "xatol": tol, "fatol": tol,
                                                  "adaptive": False})
    theta = res.x * scale
    # uncertainty with the residuals of eq. 13 (|H_model| − |H_meas|), in the search coordinates
    unc = uncertainty(problem, problem.to_x(theta), lambda x: problem.magnitude_residuals(problem.from_x(x)))
    return Fit("nelder-mead", theta, problem.to_x(theta), float(res.fun * problem._mag_rms), problem.j_err(theta),
               problem.n_eval - n0, int(res.nit), bool(res.success), str(res.message), time.perf_counter() - t0,
               unc["std_error"], unc["rel_std_error"], unc["ci95"], unc["correlation"], unc["singular_values"],
               unc["condition"], unc["s2"], unc["dof"], unc["warnings"], [],
               "FRF magnitude, eq. 13 (|H_model| − |H_meas|)")


# ============================================================================ driver


