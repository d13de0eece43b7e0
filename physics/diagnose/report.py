"""Diagnosis outputs: ``diagnosis.json``, PNG figures, one self-contained HTML page and,
with ``apply``, the extended device file.

Figures: ``where_it_fails.png`` (residual FRF against its 1 % noise floor, measured/model
gain and phase, residual autocorrelation and input–residual cross-correlation with 99 %
bands — before and after the winner), ``ranking.png`` (ΔBIC and RMS error per
candidate), ``overlay.png`` (measured, base and winner in time, zoomed where the base
fails, and the errors over whole records), ``error_breakdown.png`` (error by frequency
band, amplitude and RH, before and after).  All files are written atomically
(:mod:`physics.io.fileio`); inputs are never overwritten.
"""
from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import arg
from ..pages.columns import ONE, Column, band
from ..io.fileio import jsonable, write_json, write_text
from ..identify import write_device
from ..identify.free_parameters import switchable
from ..io.outputs import component, final_path
from ..pages.report import Report, header
from .confidence import calibration_notes, calibration_rows, calibration_summary
from .diagnosis import DiagnosisResult
from .signatures import excitation


def _plot_where(res: DiagnosisResult, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import save
    fig, ax = plt.subplots(2, 2, figsize=(11, 7))
    sets = [("base", res.analysis_base, "C3")]
    if res.analysis_after is not None:
        sets.append((res.analysis_after.label, res.analysis_after, "C2"))
    a = ax[0, 0]
    for lab, ra, col in sets:
        if ra.frf is not None:
            a.loglog(ra.frf.freq, np.abs(ra.frf.H_e), color=col, label=f"|residual FRF| {lab}")
            a.loglog(ra.frf.freq, ra.frf.floor, color=col, ls=":", lw=1, label=f"1 % noise floor {lab}")
            sig = ra.frf.significant
            a.loglog(ra.frf.freq[sig], np.abs(ra.frf.H_e[sig]), "o", ms=3, color=col)
    a.set_xlabel("frequency [Hz]")
    a.set_ylabel("input → residual [m/V]")
    a.set_title("residual frequency response (dots: above the noise floor)", fontsize=9)
    a.legend(fontsize=7)
    a.grid(alpha=0.3, which="both")
    a = ax[0, 1]
    a2 = a.twinx()
    for lab, ra, col in sets:
        if ra.frf is not None:
            a.semilogx(ra.frf.freq, 100 * (np.abs(ra.frf.ratio) - 1), color=col, label=f"gain error {lab}")
            a2.semilogx(ra.frf.freq, np.degrees(np.angle(ra.frf.ratio)), color=col, ls="--", lw=0.9,
                        label=f"phase {lab}")
    a.set_xlabel("frequency [Hz]")
    a.set_ylabel("measured/model gain − 1 [%]")
    a2.set_ylabel("measured − model phase [deg] (dashed)")
    a.axhline(0, color="k", lw=0.6)
    a.legend(fontsize=7, loc="upper left")
    a.grid(alpha=0.3, which="both")
    _correlation_panel(ax[1, 0], [(lab, ra.lag_s, ra.acf, ra.acf_band, col) for lab, ra, col in sets],
                       "lag [s]", "ρ_ee", "residual autocorrelation, 99 % band (MATLAB resid)")
    _correlation_panel(ax[1, 1], [(lab, ra.ccf_lag_s, ra.ccf, ra.ccf_band, col) for lab, ra, col in sets],
                       "lag [s] (positive: residual after input)", "ρ_ue",
                       "input–residual cross-correlation, 99 % band")
    fig.tight_layout()
    save(fig, path)


def _plot_ranking(res: DiagnosisResult, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import legend_outside, save
    rk = res.ranking
    fig, ax = plt.subplots(1, 2, figsize=(11, 0.6 + 0.45 * max(len(rk), 1)), sharey=True)
    names = [c.effect for c in rk]
    y = np.arange(len(rk))[::-1]
    d = [c.comparison.delta_bic for c in rk]
    col = ["C2" if c.effect in res.verdict.chain else ("C1" if c.comparison.delta_bic <= -10 else "C7")
           for c in rk]
    ax[0].barh(y, d, color=col)
    ax[0].set_xscale("symlog", linthresh=10)
    ax[0].axvline(-10, color="k", ls=":", lw=0.8)
    ax[0].set_yticks(y)
    ax[0].set_yticklabels(names)
    ax[0].set_xlabel("ΔBIC vs base (negative: supported; dotted: −10)")
    ax[0].grid(alpha=0.3, axis="x")
    ax[1].barh(y, [1e6 * c.fit.rmse for c in rk], color=col)
    ax[1].axvline(1e6 * res.base.rmse, color="C3", lw=1.2, label="base")
    if math.isfinite(res.noise_floor):
        ax[1].axvline(1e6 * res.noise_floor, color="k", ls="--", lw=0.9, label="noise floor")
    ax[1].set_xscale("log")
    ax[1].set_xlabel("RMS error after adding [µm]")
    legend_outside(ax[1])
    ax[1].grid(alpha=0.3, axis="x", which="both")
    fig.tight_layout()
    save(fig, path)


def _plot_overlay(res: DiagnosisResult, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import save
    recs = res.records[:4]
    shown = res.picks[-1] if res.picks else res.best
    fig, axes = plt.subplots(len(recs), 2, figsize=(12, 2.6 * len(recs)), squeeze=False)
    for k, r in enumerate(recs):
        t = np.arange(r.y_d.size) / r.fs_d
        eb = res.base.resid_d[k]
        ym = r.y_d - r.y_d.mean()
        # zoom: 4 s (or 10 periods) around the base's largest error
        i = int(np.argmax(np.convolve(eb ** 2, np.ones(max(1, int(r.fs_d))), mode="same")))
        w = max(int(2.0 * r.fs_d), 10)
        sl = slice(max(0, i - w), min(t.size, i + w))
        a = axes[k, 0]
        a.plot(t[sl], 1e6 * ym[sl], color="k", lw=1.2, label="measured")
        a.plot(t[sl], 1e6 * (ym - eb)[sl], color="C3", lw=1, label="base")
        if shown is not None:
            a.plot(t[sl], 1e6 * (ym - shown.fit.resid_d[k])[sl], color="C2", lw=1, ls="--", label=_label(res, shown))
        a.set_ylabel("deflection [µm]")
        a.set_title(f"{Path(r.source).name}: zoom where the base fails most", fontsize=9)
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
        a = axes[k, 1]
        a.plot(t, 1e6 * eb, color="C3", lw=0.7, label=f"error base ({1e6 * res.base.rmse_records[k]:.3g} µm RMS)")
        if shown is not None:
            a.plot(t, 1e6 * shown.fit.resid_d[k], color="C2", lw=0.7,
                   label=f"error {_label(res, shown)} ({1e6 * shown.fit.rmse_records[k]:.3g} µm RMS)")
        a.set_ylabel("error [µm]")
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("time [s]")
    axes[-1, 1].set_xlabel("time [s]")
    fig.tight_layout()
    save(fig, path)


def _label(res: DiagnosisResult, shown) -> str:
    return "+" + " +".join(p.effect for p in res.picks) if res.picks else f"+{shown.effect} (not picked)"


def _plot_breakdown(res: DiagnosisResult, path) -> None:
    import matplotlib.pyplot as plt
    from ..pages.plotting import save
    sets = [("base", res.analysis_base, "C3")]
    if res.analysis_after is not None:
        sets.append((res.analysis_after.label, res.analysis_after, "C2"))
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.2))
    width = 0.38
    for j, (lab, ra, col) in enumerate(sets):
        x = np.arange(len(ra.by_band))
        ax[0].bar(x + (j - 0.5) * width, [1e6 * b["residual_rms_m"] for b in ra.by_band], width, color=col, label=lab)
        ax[0].set_xticks(x)
        ax[0].set_xticklabels([band(*b["band_Hz"]) for b in ra.by_band], fontsize=7)
        xa = np.arange(len(ra.by_amplitude))
        ax[1].bar(xa + (j - 0.5) * width, [1e6 * b["residual_rms_m"] for b in ra.by_amplitude], width, color=col,
                  label=lab)
        ax[1].set_xticks(xa)
        ax[1].set_xticklabels([f"{b['amplitude_V']:.3g} V" for b in ra.by_amplitude], fontsize=7)
        xr = np.arange(len(ra.by_rh))
        ax[2].bar(xr + (j - 0.5) * width, [1e6 * b["residual_rms_m"] for b in ra.by_rh], width, color=col, label=lab)
        ax[2].set_xticks(xr)
        ax[2].set_xticklabels([f"RH {round(b['rh_pct']):.0f} %" for b in ra.by_rh], fontsize=7)
    for a, t in zip(ax, ("by frequency band", "by amplitude", "by nominal RH level")):
        a.set_title(f"RMS error {t}", fontsize=9)
        a.set_ylabel("RMS error [µm]")
        a.set_yscale("log")
        a.grid(alpha=0.3, axis="y")
        a.legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)


def write_diagnosis(res: DiagnosisResult, out_dir, *, apply: bool = False, name: str | None = None,
                    provenance: dict | None = None, best: dict | None = None, measurements: Sequence[str] = (),
                    drafts: Sequence = (), overwrite: bool = False, inputs: Sequence = ()) -> dict:
    """Write ``diagnosis.json``, the PNGs and the page ``index.html`` into the new folder
    ``out_dir``; with ``apply`` also the device file ``NAME.yaml`` of the best model: ``best``
    ({"fit": a ModelFit, "effect_files": [paths], "text": ...}, e.g. the model fitted with drafted
    effects) or the diagnosis's final model (the base with every pick of the chain and without
    every removal; nothing when it is the base itself) — its values as fitted and refined on the
    time records, its effects as ``default_effects``.  The usage printed runs as printed: the
    ``measurements`` and the ``--effects-path`` of every effect file the model needs.
    ``drafts``: drafted effects (:class:`~physics.diagnose.effect_draft.EffectDraft`) written
    into ``drafts/`` (:func:`~physics.diagnose.draft.write_drafts`; their contract checks in the
    JSON's ``drafts``).  Returns the JSON dict.

    The folder is written under the output policy (:func:`physics.io.outputs.output_folder`):
    atomically, ``overwrite`` replaces only a folder eap wrote, and neither ``inputs`` (the
    device file and measurements read) nor the records' source files are replaced; paths in
    the outputs are the final ones."""
    from ..io.outputs import OUT_DIR, output_folder, with_sources
    if apply and name is not None:
        component(name, arg("name"), "the device file NAME.yaml")
    inputs = with_sources(inputs, [r.source for r in res.records] + [res.device.path])
    with output_folder(out_dir, inputs=inputs, overwrite=overwrite, flag=OUT_DIR) as d:
        checks = {}
        if drafts:
            from .draft import write_drafts
            checks = write_drafts(drafts, d / "drafts", inputs=inputs)
        out = _write_folder(res, d, apply, name, provenance, best, measurements)
        out["drafts"] = checks
        write_json(d / "diagnosis.json", jsonable(out))
        _html(res, d, out, provenance)
    return out


def _write_folder(res: DiagnosisResult, d: Path, apply: bool, name, provenance, best, measurements) -> dict:
    """The figures and, with ``apply``, the device file written into ``d``: the JSON dict."""
    out = res.to_dict()
    pngs = {"where_it_fails.png": _plot_where, "ranking.png": _plot_ranking, "overlay.png": _plot_overlay,
            "error_breakdown.png": _plot_breakdown}
    written = []
    for fn, fun in pngs.items():
        if fn == "ranking.png" and not res.ranking:
            continue
        fun(res, d / fn)
        written.append(fn)
    applied = None
    fit = best["fit"] if best else res.final
    files = list(best.get("effect_files", [])) if best else []
    if apply:
        if fit is res.base:
            applied = {"written": None, "reason": "the diagnosis kept the model as it was (nothing added, removed or "
                                                  "drafted): nothing to apply"}
        else:
            added = [e for e in fit.effects if e not in res.base.effects]
            gone = [e for e in res.base.effects if e not in fit.effects]
            what = " ".join([f"+{e}" for e in added] + [f"-{e}" for e in gone]) or "refitted"
            dev_name = component(name or ("_".join([res.device.name] + added) if added else f"{res.device.name}_refitted"),
                                 arg("name"), "the device file NAME.yaml")
            path = write_device(fit.result, d / f"{dev_name}.yaml", name=dev_name,
                                date=_dt.date.today().isoformat())
            text = path.read_text(encoding="utf-8").replace(
                "written by eap identify on", f"written by eap diagnose ({what}) on", 1)
            write_text(path, text)
            recs = " ".join(_quote(m) for m in measurements) or "MEASUREMENT"
            paths = "".join(f" --effects-path {_quote(f)}" for f in files)
            applied = {"written": path.name, "path": str(final_path(path)),
                       "effects": list(switchable(fit.effects)), "effect_files": files,
                       "rmse_m": fit.rmse, "parameters": dict(fit.values),
                       "usage": f"eap compare {recs} --model {_quote(str(final_path(path)))} --effects default{paths}"}
            written.append(path.name)
    out["applied"] = applied
    out["best_model"] = None if not best else {"effects": list(fit.effects), "rmse_m": fit.rmse,
                                               "effect_files": files, "text": best["text"],
                                               "draft_rounds": list(best.get("draft_rounds", []))}
    out["files"] = ["diagnosis.json", "index.html", "report.html"] + written
    if provenance:
        out["provenance"] = provenance
    return out


def _quote(text: str) -> str:
    import shlex
    return shlex.quote(str(text))


def _fmt(x, unit="", scale=1.0, digits=4):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x * scale:.{digits}g}{(' ' + unit) if unit else ''}"


def calibration_table(rep: Report, rows: Sequence[dict] | None = None, notes: Sequence[str] | None = None,
                      summary: str | None = None) -> None:
    """What the confidence labels have meant on held-out physics (:func:`.confidence.calibration_rows`,
    or the ``rows``, ``notes`` and ``summary`` a run stored): the draws summed
    (:func:`.confidence.calibration_summary`), then a table with the draws' caveats under it."""
    rep.paragraph("What the confidence labels mean: how often a pick of each label named the hidden effect "
                  "(right, or a near twin's relative) on records from truth families held out of the choice of "
                  "the rules (python bench/diagnose_lofo.py; docs/reference/truth-families.md), newest first. "
                  + (calibration_summary() if summary is None else summary), note=True)
    rep.table(list(calibration_rows() if rows is None else rows), caption="the labels on held-out physics",
              notes=list(calibration_notes() if notes is None else notes))


def _html(res: DiagnosisResult, d: Path, out: dict, provenance) -> None:
    v = res.verdict
    b = res.base
    rep = Report("Diagnosis: where the model fails and which effect is missing",
                 subtitle=f"{res.device.name} [{', '.join(b.effects)}] against {len(res.records)} record(s)",
                 provenance=header(provenance))
    rep.heading("Verdict")
    for line in v.lines():
        rep.paragraph(line)
    calibration_table(rep)
    if out.get("best_model"):
        rep.paragraph(f"Best model: {out['best_model']['text']}.")
        if out["best_model"]["draft_rounds"]:
            rep.paragraph("How the drafts were chosen (fitted with the model, round by round):")
            rep.bullets(out["best_model"]["draft_rounds"])
    if out.get("applied") and out["applied"].get("written"):
        rep.paragraph(f"Device file of the best model written: {out['applied']['path']} (use it: "
                      f"{out['applied']['usage']}).")
    rep.table({"base effects": ", ".join(b.effects), "free parameters": ", ".join(b.spec.free + b.spec.per_rh),
               "RMS error [µm]": 1e6 * b.rmse, "fit [%]": b.fit_pct, "BIC (effective n)": b.bic,
               "noise floor [µm]": 1e6 * res.noise_floor if math.isfinite(res.noise_floor) else None,
               "first resonance [Hz]": res.resonance_hz, "wall time [s]": res.timings.get("total"),
               **({"draft rounds' wall time [s]": res.timings["draft rounds"]} if "draft rounds" in res.timings
                  else {})},
              caption="base model")
    rep.heading("Where the base model fails")
    rep.bullets(res.analysis_base.findings)
    rep.image(d / "where_it_fails.png", caption="residual FRF vs its 1 % coherence-based noise floor; measured/model "
                                                "gain and phase; residual auto- and cross-correlation with 99 % bands")
    rep.image(d / "error_breakdown.png", caption="RMS error by frequency band, amplitude and RH, before and after")
    lb = res.analysis_base.ljung_box
    rep.paragraph(f"Ljung–Box on 20 lags of the base residual: Q = {lb['Q']:.4g}, p = {lb['p_value']:.2g} "
                  "(a sensor drift alone also makes the residual coloured; the cross-correlation with the input is "
                  "what points to missing dynamics).", note=True)
    rep.heading("Candidate effects, ranked")
    if res.ranking:
        rep.image(d / "ranking.png", caption="ΔBIC (effective sample size) and RMS error after adding each effect")
    for s in res.steps:
        if not s.ranking:
            continue
        w = s.decision.weights
        rep.table([{"effect": c.effect, "weight": w.get(c.effect), "RMS after [µm]": 1e6 * c.fit.rmse,
                    "fit after [%]": c.fit.fit_pct, "ΔBIC": c.comparison.delta_bic, "p": c.comparison.p_value,
                    "evidence": c.evidence(s.base), "quality flags": len(c.quality),
                    "signature": (c.signature or {}).get("score"),
                    "cannot be told apart from": ", ".join(c.indistinguishable_from)} for c in s.ranking],
                  caption=f"step {s.index}: on top of [{', '.join(s.base.effects)}] (RMS {1e6 * s.base.rmse:.4g} µm; "
                          f"weight of staying with it {w.get('base', 0):.3g})",
                  headers={"weight": Column("weight", ONE), "quality flags": Column("quality flags", ONE)})
        for c in s.ranking:
            rep.paragraph(f"{c.effect}: {c.explanation}")
    ne = [c for c in res.candidates if not c.evaluated]
    if ne:
        rep.table([{"effect": c.effect, "status": c.status, "why": c.reason,
                    "excitation that would reveal it": excitation(c.effect)} for c in ne],
                  caption="effects not evaluated")
    rep.heading("Before and after")
    rep.image(d / "overlay.png", caption="measured, base and the top candidate; errors over the whole records")
    if res.support:
        rep.heading("Effects in the model: do the data support them?")
        rep.table([{"effect": s.effect, "supported": s.supported, "ΔBIC if removed": s.delta_bic_if_removed,
                    "RMS without [µm]": None if s.rmse_without is None else 1e6 * s.rmse_without,
                    "explanation": s.explanation} for s in res.support])
    if b.warnings:
        rep.heading("Identifiability of the base fit")
        for w_ in b.warnings:
            rep.warning(w_)
    rep.heading("Records")
    rep.table([{k: r.describe()[k] for k in ("kind", "duration_s", "fs_Hz", "amplitude_level_V", "rh_pct",
                                               "band_Hz", "fs_analysis_Hz", "white_noise_m", "white_noise_source")}
               | {"record": Path(r.source).name} for r in res.records],
              columns=["record", "kind", "duration_s", "fs_Hz", "amplitude_level_V", "rh_pct", "band_Hz",
                       "fs_analysis_Hz", "white_noise_m", "white_noise_source"],
              caption=f"the records; each record's own white noise level, pooled into the one noise floor of "
                      f"{_fmt(res.noise_floor, 'µm', 1e6, 3)} every verdict compares with")
    rep.heading("How the statistics work")
    rep.bullets([f"{k}: {t}" for k, t in out["statistics"].items()])
    rep.json_block(out["settings"], "settings")
    if provenance:
        rep.json_block(jsonable(provenance), "provenance")
    rep.write_index(d)


def _correlation_panel(a, curves, xlabel: str, ylabel: str, title: str) -> None:
    """One correlation plot: each (label, lag [s], correlation, 99 % band, colour) curve
    with its ± band as dotted lines."""
    for lab, lag, rho, band, col in curves:
        a.plot(lag, rho, color=col, label=lab)
        a.axhline(band, color=col, ls=":", lw=0.8)
        a.axhline(-band, color=col, ls=":", lw=0.8)
    a.set_xlabel(xlabel)
    a.set_ylabel(ylabel)
    a.set_title(title, fontsize=9)
    a.legend(fontsize=7)
    a.grid(alpha=0.3)
