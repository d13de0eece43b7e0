"""Plots and the report folder of an identification."""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Sequence

import numpy as np

from .devicefile import write_device
from .result import IdentificationResult




def _plot_target(result: IdentificationResult, k: int, path) -> None:
    from ..pages.plotting import plot_bode_curves
    prob = result.problem
    t = prob.targets[k]
    H0 = prob.responses(prob.theta0)[k]
    curves = {"measured": (t.freq, t.response, {"lw": 1.3, "marker": ".", "ms": 3, "ls": "none"}),
              "start": (t.freq, H0, {"lw": 0.9, "ls": ":"})}
    for name, f in result.fits.items():
        curves[f"fitted ({name})"] = (t.freq, prob.responses(f.theta)[k], {"lw": 1.1})
    coh = (t.freq, t.coherence) if t.coherence is not None else None
    plot_bode_curves(curves, path, coherence=coh,
                         title=f"{Path(t.source).name}, RH {t.rh:.3g} %")


def _plot_corr(labels, corr, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import save
    p = len(labels)
    fig, ax = plt.subplots(figsize=(1.0 + 0.7 * p, 0.8 + 0.6 * p))
    im = ax.imshow(np.nan_to_num(corr), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(p))
    ax.set_yticks(range(p))
    ax.set_xticklabels(labels, rotation=45, ha="right", fontsize=8)
    ax.set_yticklabels(labels, fontsize=8)
    for i in range(p):
        for j in range(p):
            c = corr[i, j]
            ax.text(j, i, "–" if not np.isfinite(c) else f"{c:.2f}", ha="center", va="center", fontsize=7,
                    color="white" if np.isfinite(c) and abs(c) > 0.6 else "black")
    fig.colorbar(im, ax=ax, shrink=0.8)
    ax.set_title("parameter correlation", fontsize=9)
    save(fig, path)


def _plot_rh_maps(result: IdentificationResult, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import legend_outside, rh_axis, save
    prob, fit = result.problem, result.fit
    names = prob.per_rh
    fig, axes = plt.subplots(1, len(names), figsize=(4 * len(names), 3.2), squeeze=False)
    for ax, name in zip(axes[0], names):
        idx = [i for i, p in enumerate(prob.params) if p.name == name]
        rh = [prob.params[i].rh for i in idx]
        ax.errorbar(rh, fit.theta[idx], yerr=1.96 * fit.std_error[idx], fmt="o-", capsize=3, label="identified")
        ax.plot(rh, [prob.params[i].initial for i in idx], "x:", color="gray", label="start")
        rh_axis(ax, rh)
        ax.set_ylabel(f"{name} [{prob.params[idx[0]].unit}]")
        ax.grid(alpha=0.3)
        legend_outside(ax)
    fig.tight_layout()
    save(fig, path)


def write_identification(result: IdentificationResult, out_dir, *, name: str | None = None,
                         provenance: dict | None = None, overwrite: bool = False, inputs: Sequence = ()) -> dict:
    """Write the fitted device ``NAME.yaml``, ``report.json``, ``parameters.csv``, PNGs and
    the page ``index.html`` into the new folder ``out_dir``; returns the JSON dict (with the
    file names).

    The folder is written under the output policy (:func:`physics.io.outputs.output_folder`):
    atomically, ``overwrite`` replaces only a folder eap wrote, and neither ``inputs`` (the
    device file and measurements read) nor the measurement files of ``result`` are replaced."""
    from ..errors import arg
    from ..io.outputs import OUT_DIR, component, output_folder, with_sources
    dev_name = component(name or f"{result.problem.device.name}_identified", arg("name"), "the device file NAME.yaml")
    inputs = with_sources(inputs, list(result.sources) + [result.problem.device.path])
    with output_folder(out_dir, inputs=inputs, overwrite=overwrite, flag=OUT_DIR) as d:
        return _write_folder(result, d, dev_name, provenance)


def _write_folder(result: IdentificationResult, d: Path, dev_name: str, provenance) -> dict:
    from ..io.fileio import jsonable, write_json
    from ..pages.report import write_csv
    date = _dt.date.today().isoformat()
    dev_path = write_device(result, d / f"{dev_name}.yaml", name=dev_name, date=date)
    files = [dev_path.name]
    pngs = _write_plots(result, d)
    rows = result.param_rows()
    write_csv(rows, d / "parameters.csv")
    files += ["parameters.csv", "report.json", "index.html", "report.html"] + pngs
    out = result.to_dict()
    out["files"] = files
    out["device_written"] = dev_path.name
    if provenance:
        out["provenance"] = provenance
    write_json(d / "report.json", jsonable(out))
    _write_page(result, d, dev_path, rows, pngs, provenance)
    return out


def _write_plots(result: IdentificationResult, d: Path) -> list[str]:
    """A Bode figure per target, the correlation matrix and the per-RH maps: their names."""
    pngs = []
    for k, t in enumerate(result.problem.targets):
        fn = f"bode_{k:02d}_{Path(t.source).stem[:40]}.png".replace(" ", "_")
        _plot_target(result, k, d / fn)
        pngs.append(fn)
    if len(result.problem.params) > 1:
        _plot_corr(result.problem.labels, result.fit.correlation, d / "correlation.png")
        pngs.append("correlation.png")
    if result.problem.per_rh:
        _plot_rh_maps(result, d / "rh_maps.png")
        pngs.append("rh_maps.png")
    return pngs


def _write_page(result: IdentificationResult, d: Path, dev_path: Path, rows, pngs, provenance) -> None:
    """The page ``index.html``: the result, the parameters, per-RH values, other fits,
    the multi-start, the fitted responses and the settings."""
    from ..io.fileio import jsonable
    from ..pages.report import Report, header
    fit = result.fit
    rep = Report("Parameter identification",
                 subtitle=f"{result.problem.device.name} [{', '.join(result.problem.effects)}] from "
                          f"{len(result.sources)} measurement(s); fitted device: {dev_path.name}",
                 provenance=header(provenance))
    for w in result.warnings:
        rep.warning(w)
    rep.heading("Result")
    rep.table({"method": fit.method, "residual": fit.residual_kind, "J_err at the start (eq. 13) [mm/V]":
               1e3 * result.j_err_initial, "J_err fitted [mm/V]": 1e3 * fit.j_err,
               "model evaluations": result.n_evaluations, "wall time [s]": result.wall_s,
               "residual variance s²": fit.s2, "degrees of freedom": fit.dof,
               "condition number of J": fit.condition, "converged": fit.success, "message": fit.message,
               "thesis loop, same data [days]": result.thesis_equivalent_s() / 86400},
              notes=[f"s²: variance of the normalised ({fit.residual_kind}) residual at the fit, dimensionless; "
                     "J_err: eq. 13 of the thesis."])
    rep.table([_shown(r) for r in rows], columns=["parameter", "initial", "value", "std_error", "rel_std_error",
                                                  "ci95_lo", "ci95_hi", "lower_bound", "upper_bound"],
              caption="identified parameters, each in its row's unit (SI); 1σ: Bates & Watts linear "
                      "approximation scaled by s²; 95 % interval")
    if result.problem.per_rh:
        rep.heading("Per-RH values (Table V style)")
        rep.table(_per_rh_rows(result), digits=4)
        rep.image(d / "rh_maps.png", caption="identified per-RH values with 95 % intervals, and their starts, "
                                             "by nominal RH level")
    if "correlation.png" in pngs:
        rep.image(d / "correlation.png", caption="correlation matrix of the estimates (−1 … 1)")
    _other_fits(rep, result)
    rep.heading("Measured and fitted frequency responses")
    for fn, t in zip([f for f in pngs if f.startswith("bode_")], result.problem.targets):
        rep.image(d / fn, caption=f"{Path(t.source).name} (RH {t.rh:.3g} %): measured, start and fitted |H| "
                                  "[mm/V], phase [°] and coherence")
    rep.heading("Settings")
    rep.json_block(jsonable(result.settings), "settings")
    if provenance:
        rep.json_block(provenance, "provenance")
    rep.write_index(d)


def _per_rh_rows(result: IdentificationResult) -> list[dict]:
    """One row per RH level with the values and 1σ of the per-RH parameters (thesis Table V)."""
    fit = result.fit
    table_v = []
    for lv in result.problem.levels:
        row = {"rh_pct": lv}
        for i, p in enumerate(result.problem.params):
            if p.rh == lv:
                row[f"{p.name} [{p.unit}]"] = float(fit.theta[i])
                row[f"{p.name} 1σ [{p.unit}]"] = float(fit.std_error[i])
        table_v.append(row)
    return table_v


def _other_fits(rep, result: IdentificationResult) -> None:
    """The page's sections on the fits not written (another method) and on the multi-start."""
    fit = result.fit
    for name_, f in result.fits.items():
        if name_ != result.primary:
            rep.heading(f"Also fitted: {name_}")
            rep.table([_shown(r) for r in result.param_rows(f)],
                      columns=["parameter", "value", "std_error", "rel_std_error"],
                      caption=f"{f.method}: J_err {1e3 * f.j_err:.3g} mm/V, {f.nfev} evaluations, {f.nit} "
                              f"iterations, {f.message}")
            for w in f.warnings:
                rep.warning(f"{name_}: {w}")
    if fit.starts:
        rep.heading("Multi-start")
        units = [p.unit for p in result.problem.params]
        rep.table([{"start": s["start"], "cost": s.get("cost"), "evaluations": s.get("nfev"),
                    **{f"{lab} [{u}]": v for lab, u, v in zip(result.problem.labels, units, s.get("theta", []))}}
                   for s in fit.starts], digits=4)


def _shown(row: dict) -> dict:
    """A parameter row for the page: its name with its unit, values in that unit."""
    return {**row, "parameter": f"{row['parameter']} [{row['unit']}]"}
