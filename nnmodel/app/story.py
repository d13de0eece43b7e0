"""The page of ``eap run``: the whole story on one self-contained page.

Devices and their physics → the dataset → the networks → the loop (records of an actuator
with an effect the user's model lacks → where the model fails → the diagnosis → the model
with the effect added → the error before and after) → beyond the catalog (lab-like records
with physics no catalog effect has → "not explained; here is what remains" → a drafted
effect file → the diagnosis again with it → the error before and after).  Every section
opens with one sentence computed from the results; figures are embedded (the page works
offline, alone).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from physics.pages.plotting import legend_outside, plt, save
from physics.io.fileio import jsonable
from physics.pages.report import Report, colour

#: The loop's hidden effect and records (the demo of :mod:`physics.testbeds.demo`).
LOOP_EFFECT, LOOP_DEVICE, LOOP_SEED, LOOP_DURATION_S = "solvent_diffusion", "ipmc_pt_eg", 0, 40.0
#: The out-of-catalog loop: the physics in its lab-like records (:func:`physics.testbeds.demo.outside_catalog_case`).
OUTSIDE_KIND, OUTSIDE_SEED, OUTSIDE_FS_HZ, OUTSIDE_DURATION_S = "creep", 0, 200.0, 60.0


def loop_stage(d: Path) -> dict:
    """Records with a hidden effect, the diagnosis of the model without it, and the figure
    of the error before and after (``d/loop.png``); returns the figures as a dict."""
    from physics.diagnose.confidence import calibration_notes, calibration_rows, calibration_summary, calibration_text
    from physics.testbeds.demo import hidden_effect_case
    from physics.diagnose.diagnosis import diagnose
    case = hidden_effect_case(LOOP_EFFECT, LOOP_SEED, device=LOOP_DEVICE, duration=LOOP_DURATION_S)
    res = diagnose(case.measurements, LOOP_DEVICE, case.base_effects)
    v, w, b = res.verdict, res.winner, res.base
    after = w.fit if w is not None else None
    _loop_figure(res, d / "loop.png")
    return {"hidden_effect": case.hidden, "device": LOOP_DEVICE, "base_effects": list(case.base_effects),
            "records": [m.source for m in case.measurements], "noise_floor_m": res.noise_floor,
            "findings": list(res.analysis_base.findings),
            "ranking": [{"effect": c.effect, "rmse_um": 1e6 * c.fit.rmse, "delta_bic": c.comparison.delta_bic,
                         "evidence": c.evidence(b)} for c in res.ranking],
            "verdict": v.to_dict(), "adequacy": res.adequacy.to_dict() if res.adequacy else None,
            "calibration": calibration_text(), "calibration_table": calibration_rows(),
            "calibration_notes": calibration_notes(), "calibration_summary": calibration_summary(),
            "rmse_before_um": 1e6 * b.rmse, "rmse_after_um": None if after is None else 1e6 * after.rmse,
            "fit_before_pct": b.fit_pct, "fit_after_pct": None if after is None else after.fit_pct,
            "effect_parameters": {} if w is None else {k: float(x) for k, x in w.fit.values.items()}}


def _loop_figure(res, path: Path) -> None:
    """Measured vs the base and vs the model with the effect added, on the last record."""
    w = res.winner
    curves = [("model (base)", res.base, colour("base"))]
    if w is not None:
        curves.append((f"+ {w.effect}", w.fit, colour(f"+{w.effect}")))
    _before_after_figure(res.records[-1], curves, "measured vs model before and after", path)


def _before_after_figure(r, curves, title: str, path: Path) -> None:
    """Record ``r``'s measured tip (mean removed) with each curve's prediction above and its
    residual below, in µm; ``curves`` are (label, fit, colour), the fits' last records."""
    t = np.arange(r.y_d.size) / r.fs_d
    fig, ax = plt.subplots(2, 1, figsize=(9, 5.2), sharex=True)
    ax[0].plot(t, 1e6 * (r.y_d - r.y_d.mean()), color=colour("measurement"), lw=1.0, label="measurement")
    for label, fit, c in curves:
        p = fit.pred_d[-1]
        ax[0].plot(t, 1e6 * (p - p.mean()), color=c, lw=0.9, label=label)
        ax[1].plot(t, 1e6 * fit.resid_d[-1], color=c, lw=0.7, label=label)
    ax[0].set_ylabel("deflection [µm]")
    ax[1].set_ylabel("residual [µm]")
    ax[1].set_xlabel("time [s]")
    legend_outside(ax[0])
    legend_outside(ax[1])
    ax[0].set_title(f"{Path(str(r.source)).name}: {title}")
    save(fig, path)


def outside_stage(d: Path) -> dict:
    """The out-of-catalog loop (:func:`physics.testbeds.demo.outside_loop`): lab-like records
    (``d/outside/records``, tip in mm, no excitation or sensor metadata) with physics no catalog
    effect has → the diagnosis of the bare model → drafts of what remains (``d/outside/drafts``,
    checked against the effect contract) → the diagnosis again with the kept drafts → the
    figure ``d/outside.png``; returns the figures as a dict."""
    from physics.testbeds.demo import outside_loop, outside_truth_text
    t0 = time.perf_counter()
    lp = outside_loop(OUTSIDE_KIND, OUTSIDE_SEED, d / "outside", device=LOOP_DEVICE, fs=OUTSIDE_FS_HZ,
                      duration=OUTSIDE_DURATION_S)
    before, after = lp.before, lp.after
    _outside_figure(before, after, d / "outside.png")
    drafted = [{"file": f"outside/drafts/{x.file_name}", "summary": x.summary, "seen": x.seen, "text": x.evidence["text"],
                "contract": "; ".join(lp.checks[x.file_name]) or "passed",
                "parameters": {p.name: {"value": p.default, "unit": p.unit} for p in x.params}} for x in lp.outcome.kept]
    again = None
    if after is not None:
        again = {"verdict": after.verdict.to_dict(), "rmse_m": after.final.rmse,
                 "ranking": [{"effect": c.effect, "rmse_um": 1e6 * c.fit.rmse, "delta_bic": c.comparison.delta_bic}
                             for c in after.ranking[:4]]}
    return jsonable({"kind": OUTSIDE_KIND, "truth": lp.truth, "truth_text": outside_truth_text(OUTSIDE_KIND, lp.truth),
                     "device": LOOP_DEVICE, "true_error_m": lp.true_error, "runtime_s": time.perf_counter() - t0,
                     "records": [f"outside/records/{f.name}" for f in lp.files],
                     "before": {"verdict": before.verdict.to_dict(), "rmse_m": before.base.rmse,
                                "noise_floor_m": before.noise_floor,
                                "remaining": [x["text"] for x in before.adequacy.remaining()] if before.adequacy else []},
                     "drafts": drafted, "not_kept": [f"{x.effect_id}: {why}" for x, why in lp.outcome.rejected],
                     "after": again})


def _outside_figure(before, after, path: Path) -> None:
    """The pulse record (the last): measured vs the bare model and vs the model with the
    diagnosis's picks once the drafts are passed back, and the residuals."""
    curves = [("model (base)", before.base, colour("base"))]
    picks = [c.effect for c in after.picks] if after is not None else []
    if picks:
        curves.append(("+ " + " + ".join(picks), after.final, colour(f"+{picks[0]}")))
    _before_after_figure(before.records[-1], curves, "measured vs the bare model and with the drafted effect", path)


def _outside_section(rep: Report, d: Path, out: dict) -> None:
    """The page's out-of-catalog loop (from :func:`outside_stage`)."""
    b, a = out["before"], out["after"]
    vb = b["verdict"]
    nf = b["noise_floor_m"]
    floor = f"the noise floor eap diagnose estimates from them: {1e6 * nf:.3g} µm" if nf is not None else \
        "no noise floor could be estimated"
    rep.heading("Beyond the catalog: physics no effect models")
    rep.lead(f"Lab-like records of {out['device']} (tip in mm with 3 µm noise, an offset and a drift, no excitation "
             f"or sensor metadata: {', '.join(Path(f).name for f in out['records'])}) with physics no catalog effect "
             f"has — {out['truth_text']}. The bare model misses them by {1e6 * b['rmse_m']:.3g} µm RMS ({floor}; the "
             f"true model's error is {1e6 * out['true_error_m']:.3g} µm).")
    rep.heading("Not explained; what remains", level=3)
    rep.lead(f"Verdict of eap diagnose ({vb['status']}):")
    rep.bullets(vb["text"])
    rep.heading("The drafted effect", level=3)
    if not out["drafts"]:
        rep.lead("No draft lowered the error: " + "; ".join(out["not_kept"]))
    for x in out["drafts"]:
        rep.lead(f"eap diagnose … --draft-effects wrote {x['file']}: {x['summary']}; {x['text']}. "
                 f"Contract check: {x['contract']}.")
        rep.table([{"parameter": f"{k} [{v['unit']}]", "value": v["value"]} for k, v in x["parameters"].items()],
                  caption=f"{Path(x['file']).name}: its parameters, fitted with the model (the file's defaults), "
                          "each in its row's unit")
        rep.paragraph("What was seen: " + x["seen"], note=True)
    if out["not_kept"]:
        rep.bullets([f"not kept: {t}" for t in out["not_kept"]])
    if a is not None:
        va = a["verdict"]
        rep.heading("Diagnosed again, with the draft", level=3)
        rep.lead(f"Verdict ({va['status']}): "
                 + (f"{va['missing_effect']}, confidence {va['confidence_label']}; " if va["missing_effect"] else "")
                 + f"RMS error {1e6 * b['rmse_m']:.3g} → {1e6 * a['rmse_m']:.3g} µm (the true model: "
                   f"{1e6 * out['true_error_m']:.3g} µm).")
        rep.bullets(va["text"])
        rep.table(a["ranking"], caption="candidates with the drafts passed back: RMS error after adding each [µm], "
                                        "ΔBIC (negative: better)")
    rep.paragraph("The same loop from the command line, in the output folder:", note=True)
    rep.preformatted("\n".join(
        [f"eap diagnose {' '.join(out['records'])} --effects none --draft-effects outside/drafts"]
        + [f"eap diagnose {' '.join(out['records'])} --effects none --effects-path {x['file']}" for x in out["drafts"]]))
    rep.image(d / "outside.png", "pulse record: measured vs model deflection [µm] (the bare model and with the "
                                 "drafted effect), and the residuals [µm]")


def _range_sentence(physics: dict) -> str:
    parts = []
    for dev, r in physics.items():
        res = r["resonance_Hz_by_rh"]
        lo, hi = min(res, key=float), max(res, key=float)
        parts.append(f"{dev}: the first resonance moves from {res[lo]:.1f} Hz at {lo} % RH to {res[hi]:.1f} Hz at "
                     f"{hi} % RH, the 1 Hz gain from {r['gain_at_1Hz_mm_per_V_by_rh'][lo]:.2f} to "
                     f"{r['gain_at_1Hz_mm_per_V_by_rh'][hi]:.2f} mm/V")
    return "; ".join(parts) + "."


def story_line(report: dict) -> str:
    """The one-line story for the console (and the page's opening)."""
    loop = report.get("loop")
    if not loop:
        return "physics only"
    v = loop["verdict"]
    after = "" if loop["rmse_after_um"] is None else f" → {loop['rmse_after_um']:.3g} µm"
    named = v["missing_effect"] or f"no catalog effect ({v['status']})"
    line = (f"measurement-like records: base model {loop['rmse_before_um']:.3g} µm RMS → diagnosis: {named}"
            f"{after} (noise floor {1e6 * loop['noise_floor_m']:.3g} µm)")
    out = report.get("outside")
    if out:
        drafted = ", ".join(Path(x["file"]).name for x in out["drafts"]) or "no draft kept"
        after = f" → {1e6 * out['after']['rmse_m']:.3g} µm" if out["after"] else ""
        line += (f"; beyond the catalog, lab-like records: {1e6 * out['before']['rmse_m']:.3g} µm "
                 f"({out['before']['verdict']['status']}) → drafted {drafted}{after} (true model "
                 f"{1e6 * out['true_error_m']:.3g} µm)")
    return line


def write_page(d: Path, report: dict, provenance: dict) -> Path:
    """``d/index.html`` from the results of ``eap run`` (``report`` as in report.json)."""
    from physics.diagnose.report import calibration_table
    rep = Report("eap-model: the whole story", "what the package does, on built-in defaults",
                 provenance={"command": provenance.get("command"), "version": provenance.get("version"),
                             "runtime": f"{report['runtime_s']:.0f} s"})
    rep.lead(story_line(report))
    rep.heading("Devices and their physics")
    rep.lead(_range_sentence(report["physics"]))
    for dev, r in report["physics"].items():
        rep.paragraph(f"{dev}: effects {', '.join(r['effects'])}; a 4 Vpp sweep of 100 s at 1 kHz simulates in "
                      f"{r['sweep_simulation_runtime_s']:.2f} s.")
        rep.image(d / f"{dev}_bode.png", f"{dev}: tip deflection per volt |H| [mm/V] and phase [°] against "
                                         f"frequency [Hz], one curve per RH level ({_levels(r)} %)")
    nn = report.get("neural")
    if nn:
        ds = nn.get("dataset", {})
        rep.heading("The dataset")
        rep.lead(f"{ds.get('records', '?')} records at {ds.get('fs_Hz', 0):g} Hz from the physics simulator with a "
                 f"realistic sensor: training RH {_join(ds.get('train_rh'))} %, held-out RH "
                 f"{_join(ds.get('heldout_rh'))} % (never trained on).")
        rows = nn["table"]
        rep.heading("The networks")
        best = nn.get("best_heldout") or {}
        if best:
            rep.lead(f"Best on held-out RH: {best['model']} at {100 * best['nrmse']:.2f} % free-run NRMSE; the "
                     f"physics simulator itself scores {rows[0]['nrmse_heldout_rh_pct']:.2f} % on the same records.")
        rep.table(rows, caption="free-run test RMSE and NRMSE by test group (NRMSE = RMSE / std of the measurement)",
                  missing="the dataset has no record of this group, or the row has nothing to count (physics rows)")
        for n in nn.get("notes", []):
            rep.why(n["text"], n["links"])
        for img, cap in (("error_by_rh.png", "free-run NRMSE [%] by nominal RH level, per model (grey: held-out "
                                             "levels)"),
                         ("overlay_heldout_rh.png", "a held-out-RH test record: measured and predicted deflection "
                                                    "[µm], and the residual of each network")):
            if (d / "compare" / img).is_file():
                rep.image(d / "compare" / img, cap)
        rep.paragraph("Full comparison (every test group, Bode plots, training curves): compare/index.html.",
                      note=True, links={"compare/index.html": "compare/index.html"})
    loop = report.get("loop")
    if loop:
        v = loop["verdict"]
        rep.heading("The loop: a measurement the model cannot fit")
        rep.lead(f"Records of {loop['device']} with a hidden effect ({loop['hidden_effect']}); the user's model "
                 f"[{', '.join(loop['base_effects'])}] misses it by {loop['rmse_before_um']:.3g} µm RMS, "
                 f"{loop['rmse_before_um'] / (1e6 * loop['noise_floor_m']):.1f}× the sensor's noise floor.")
        rep.heading("Where the model fails")
        rep.lead(loop["findings"][0] if loop["findings"] else "No structured residual was found.")
        rep.bullets(loop["findings"][1:])
        rep.heading("The diagnosis")
        rep.lead(f"Verdict ({v['status']}): "
                 + (f"{v['missing_effect']}, confidence {v['confidence_label']}." if v["missing_effect"]
                    else "no catalog effect named.") + f" {v['reason']}")
        rep.table(loop["ranking"], caption="candidates: RMS error after adding each [µm], ΔBIC (negative: better)")
        calibration_table(rep, loop["calibration_table"], loop["calibration_notes"], loop.get("calibration_summary"))
        rep.paragraph("A label is not the weight: over thousands of correlated samples every weight is 1.000. "
                      "\"high\" needs a pick that changes the model by several noise floors, leaves at most a couple, "
                      "clearly beats its closest rival, lowers the error on every record and has no quality flag "
                      "(docs/reference/diagnosis.md).", note=True)
        rep.heading("Before and after")
        if loop["rmse_after_um"] is not None:
            rep.lead(f"Adding {v['missing_effect']} lowers the RMS error from {loop['rmse_before_um']:.3g} to "
                     f"{loop['rmse_after_um']:.3g} µm (fit {loop['fit_before_pct']:.1f} → {loop['fit_after_pct']:.1f} %).")
        else:
            rep.lead(v.get("remaining") or "The error did not fall: see the diagnosis above.")
        rep.image(d / "loop.png", "measured vs model deflection [µm] before and after, and the residuals [µm]")
    if report.get("outside"):
        _outside_section(rep, d, report["outside"])
    rep.json_block(report, "report.json")
    return rep.write(d / "index.html")


def _join(levels) -> str:
    return ", ".join(f"{float(x):g}" for x in levels) if isinstance(levels, (list, tuple)) else str(levels)


def _levels(physics_row: dict) -> str:
    return _join(sorted(physics_row["resonance_Hz_by_rh"], key=float))


#: Where the run page's diagnosis is (the notes of the networks link to it).
DIAGNOSIS_ANCHOR = "#" + Report.anchor("The diagnosis")


def dataset_facts(ds_path: Path) -> dict:
    from ..dataset import load_dataset
    ds = load_dataset(ds_path, verify=False)
    return {"records": len(ds.meta["files"]), "fs_Hz": ds.fs, "train_rh": ds.meta["rh_levels"]["train"],
            "heldout_rh": ds.meta["rh_levels"]["held_out"]}


__all__ = ["loop_stage", "outside_stage", "write_page", "story_line", "dataset_facts"]
