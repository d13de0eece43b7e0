"""Plots and the report folder of a comparison."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Sequence

import numpy as np

from ..pages.columns import reading_unit
from ..io.record import DEFLECTION, OutputQuantity
from .comparison import ComparisonResult, RecordComparison


def _display(output: OutputQuantity, magnitude: float | None = None) -> tuple[float, str, str]:
    """(scale, unit, name) the output is plotted in: its reading unit (a tip deflection in µm),
    or the one that shows ``magnitude`` as 0.1–1000 (:func:`~physics.pages.columns.reading_unit`)."""
    unit, scale = reading_unit(output.unit, magnitude)
    return scale, unit, output.name


def _magnitude(res: ComparisonResult) -> float | None:
    """The largest measured output of the time records: the page reads every output value
    in the unit that shows it as 0.1–1000."""
    peaks = [max(abs(float(np.max(r.measured)) - r.offset), abs(float(np.min(r.measured)) - r.offset))
             for r in res.records if r.kind == "timeseries" and r.measured is not None and np.size(r.measured)]
    return max(peaks) if peaks else None


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(text).stem)[:60] or "record"


def plot_time_overlay(r: RecordComparison, path, title: str = "", zoom_s: float | None = None,
                      output: OutputQuantity = DEFLECTION, magnitude: float | None = None) -> None:
    """Measured and model output (a deflection in µm), the residual below, and a zoom on the
    last ``zoom_s`` seconds (default: 2 s or a tenth of the record, the shorter)."""
    import matplotlib.pyplot as plt
    from ..pages.plotting import envelope, legend_outside, save
    k, unit, name = _display(output, magnitude)
    fig, ax = plt.subplots(3, 1, figsize=(8, 6.4), gridspec_kw={"height_ratios": [2, 1, 1.6]})

    def line(a, t, y, shift=0.0, **kw):   # thinned, then shifted and scaled: no copy of a long record
        tt, yy = envelope(t, y)
        a.plot(tt, k * (yy - shift), **kw)
    line(ax[0], r.time, r.measured, r.offset, lw=0.7, label="measured")     # aligned with the model
    line(ax[0], r.time, r.predicted, lw=0.7, label="model")
    ax[0].set_ylabel(f"{name} [{unit}]")
    legend_outside(ax[0])
    line(ax[1], r.time, r.measured - r.predicted, r.offset, lw=0.6, color="k")
    ax[1].set_ylabel(f"residual [{unit}]")
    ax[1].sharex(ax[0])
    span = float(r.time[-1] - r.time[0])
    zoom = min(2.0, 0.1 * span) if zoom_s is None else float(zoom_s)
    z = r.time >= r.time[-1] - zoom
    line(ax[2], r.time[z], r.measured[z], r.offset, lw=0.9, label="measured")
    line(ax[2], r.time[z], r.predicted[z], lw=0.9, ls="--", label="model")
    ax[2].set_ylabel(f"last {zoom:.3g} s [{unit}]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.grid(alpha=0.3)
    tm = r.summary["time_metrics"]
    ax[0].set_title(title or f"{Path(r.source).name}: fit {tm['fit_percent']:.1f} %, "
                    f"corr {100 * tm['correlation']:.1f} %, RH {r.rh:.3g} %", fontsize=10)
    fig.tight_layout()
    save(fig, path)


def _plot_bode_record(r: RecordComparison, path, output: OutputQuantity = DEFLECTION):
    from ..pages.plotting import plot_bode_curves
    v = r.valid
    curves = {"measured (H1)" if r.kind == "timeseries" else "measured": (r.freq[v], r.H_meas[v], {"lw": 1.2})}
    if r.H_model_est is not None:
        curves["model (H1 of simulated output)"] = (r.freq[v], r.H_model_est[v], {"lw": 0.9, "ls": "--"})
    if r.H_model_closed is not None:
        f = r.freq[v]
        curves["model (closed form)"] = (f, r.H_model_closed[v], {"lw": 1.0})
    coh = (r.freq[v], r.coherence[v]) if r.coherence is not None else None
    bounds = (r.freq[v], r.mag_bounds[0][v], r.mag_bounds[1][v]) if r.mag_bounds is not None else None
    fe = r.summary["frf_metrics"]
    je = fe.get("j_err_m_per_V")
    unit, k = reading_unit(f"{output.unit}/V")
    title = f"{Path(r.source).name}, RH {r.rh:.3g} %" + (f": J_err {k * je:.3g} {unit}" if je is not None else "")
    plot_bode_curves(curves, path, coherence=coh, bounds=bounds, title=title)


def _plot_bands(res: ComparisonResult, path):
    import matplotlib.pyplot as plt
    from ..pages.columns import band
    from ..pages.plotting import legend_outside, save
    bands = res.settings["bands_Hz"]
    if not bands:
        return False
    labels = [band(a, b) for a, b in bands]
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.4))
    width = 0.8 / max(len(res.records), 1)
    x = np.arange(len(bands))
    for i, r in enumerate(res.records):
        rows = r.summary["bands"]
        nr = [100 * (row.get("nrmse_in_band") or 0.0) for row in rows]
        lm = [row.get("log_mag_rms_dB") or 0.0 for row in rows]
        name = Path(r.source).name[:25]
        if r.kind == "timeseries":
            ax[0].bar(x + i * width, nr, width, label=name)
        ax[1].bar(x + i * width, lm, width, label=name)
    ax[0].set_ylabel("residual NRMSE in band [%]")
    ax[1].set_ylabel("|H| error RMS [dB]")
    for a in ax:
        a.set_xticks(x + 0.4 - width / 2)
        a.set_xticklabels(labels, fontsize=8)
        a.grid(alpha=0.3, axis="y")
    legend_outside(ax[1])
    fig.tight_layout()
    save(fig, path)
    return True


def _plot_rh(res: ComparisonResult, path):
    import matplotlib.pyplot as plt
    from ..pages.plotting import rh_axis, save
    rows = res.by_rh
    rh = [r["rh_pct"] for r in rows]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    fit = [r["fit_percent"] for r in rows]
    if any(v is not None for v in fit):
        ax[0].plot(rh, [np.nan if v is None else v for v in fit], "o-")
    ax[0].set_ylabel("fit [%]")
    je = [r["j_err_m_per_V"] for r in rows]
    ax[1].plot(rh, [np.nan if v is None else 1e3 * v for v in je], "s-", color="C1")
    ax[1].set_ylabel("J_err (eq. 13) [mm/V]")
    for a in ax:
        rh_axis(a, rh)
        a.grid(alpha=0.3)
    fig.tight_layout()
    save(fig, path)


def write_comparison_report(res: ComparisonResult, out_dir, *, provenance: dict | None = None,
                            title: str = "Model vs measurement", output: OutputQuantity = DEFLECTION,
                            overwrite: bool = False, inputs: Sequence = ()) -> dict:
    """Write ``report.json``, ``metrics.csv``, ``bands.csv``, PNGs and the page ``index.html``
    into the new folder ``out_dir``; returns the JSON dict.  ``output``: what the compared
    output is (axis labels and units; default the tip deflection).

    The folder is written under the output policy (:func:`physics.io.outputs.output_folder`):
    atomically, ``overwrite`` replaces only a folder eap wrote, and neither ``inputs`` (the
    files the comparison read) nor the records' source files are replaced."""
    from ..io.outputs import OUT_DIR, output_folder, with_sources
    inputs = with_sources(inputs, (r.source for r in res.records))
    with output_folder(out_dir, inputs=inputs, overwrite=overwrite, flag=OUT_DIR) as d:
        return _write_report(res, d, provenance, title, output)


def _write_report(res: ComparisonResult, d: Path, provenance, title, output) -> dict:
    from ..io.fileio import jsonable, write_json
    from ..pages.report import write_csv
    magnitude = _magnitude(res)
    extra = _write_plots(res, d, output, magnitude)
    out = jsonable(res.to_dict())
    out["plots"] = extra
    out["output"] = output.to_dict()
    if provenance:
        out["provenance"] = provenance
    write_json(d / "report.json", out)
    rows, brows = _metric_rows(res), _band_rows(res)
    write_csv(rows, d / "metrics.csv")
    if brows:
        write_csv(brows, d / "bands.csv")
    write_csv(res.by_rh, d / "by_rh.csv")
    _write_page(res, d, rows, brows, extra, provenance, title, output, magnitude)
    return out


def _write_plots(res: ComparisonResult, d: Path, output: OutputQuantity, magnitude) -> list[str]:
    """Each record's figures (their names in its ``summary["plots"]``), then the bands and RH
    figures: the names of the latter."""
    for k, r in enumerate(res.records):
        slug = f"{k:02d}_{_slug(r.source)}"
        files = []
        if r.kind == "timeseries":
            plot_time_overlay(r, d / f"time_{slug}.png", output=output, magnitude=magnitude)
            files.append(f"time_{slug}.png")
        if r.valid is not None and r.valid.any():
            _plot_bode_record(r, d / f"bode_{slug}.png", output)
            files.append(f"bode_{slug}.png")
        r.summary["plots"] = files
    extra = []
    if _plot_bands(res, d / "bands.png"):
        extra.append("bands.png")
    if len(res.by_rh) >= 2:
        _plot_rh(res, d / "rh.png")
        extra.append("rh.png")
    return extra


def _metric_rows(res: ComparisonResult) -> list[dict]:
    """One row of time and FRF metrics per record (``metrics.csv``)."""
    rows = []
    for r in res.records:
        tm = r.summary.get("time_metrics", {})
        fe = r.summary["frf_metrics"]
        rows.append({"source": r.source, "kind": r.kind, "rh_pct": r.rh, "fit_percent": tm.get("fit_percent"),
                     "nrmse": tm.get("nrmse"), "rmse_m": tm.get("rmse"), "correlation": tm.get("correlation"),
                     "j_err_m_per_V": fe.get("j_err_m_per_V"), "log_mag_rms_dB": fe.get("log_mag_rms_dB"),
                     "phase_rms_deg": fe.get("phase_rms_deg"), "frf_points": fe.get("n_points")})
    return rows


def _band_rows(res: ComparisonResult) -> list[dict]:
    """One row per record and frequency band (``bands.csv``)."""
    brows = []
    for r in res.records:
        for b in r.summary["bands"]:
            brows.append({"source": r.source, "rh_pct": r.rh, "f_lo_Hz": b["band_Hz"][0], "f_hi_Hz": b["band_Hz"][1],
                          "residual_rms_m": b.get("residual_rms_m"), "nrmse_in_band": b.get("nrmse_in_band"),
                          "j_err_m_per_V": b.get("j_err_m_per_V"), "log_mag_rms_dB": b.get("log_mag_rms_dB"),
                          "phase_rms_deg": b.get("phase_rms_deg"), "frf_points": b.get("n_points")})
    return brows


def _write_page(res: ComparisonResult, d: Path, rows, brows, extra, provenance, title, output, magnitude) -> None:
    """The page ``index.html``: summary, errors by RH and by band, each record's figures, settings."""
    from ..io.fileio import jsonable
    from ..pages.report import Report, format_value, header
    rep = Report(title, subtitle=f"model: {res.predictor.get('name')}; {len(res.records)} measurement(s)",
                 provenance=header(provenance), output={**output.to_dict(), "magnitude": magnitude})
    for w in res.warnings:
        rep.warning(w)
    rep.heading("Summary")
    rep.table(jsonable(res.overall), caption="all records (fit, NRMSE, correlation: time records; J_err: eq. 13 "
                                             "over every compared frequency)")
    rep.table([{k: v for k, v in row.items() if k != "source"} | {"record": Path(row["source"]).name}
               for row in rows], columns=["record", "kind", "rh_pct", "fit_percent", "nrmse", "rmse_m",
                                          "correlation", "j_err_m_per_V", "log_mag_rms_dB", "phase_rms_deg",
                                          "frf_points"],
              caption="metrics per measurement" + ("" if output.is_deflection else f" (output {output.label()})"),
              missing="not defined for this kind of record (a frequency-response file has no time metrics)")
    if len(res.by_rh) >= 2:
        rep.heading("Error by relative humidity")
        rep.table(res.by_rh, missing="no record of that kind at this RH")
        rep.image(d / "rh.png", caption="fit [%] and J_err [mm/V] by nominal RH level")
    if brows:
        rep.heading("Error by frequency band")
        rep.table([{"record": Path(b["source"]).name, "band_Hz": [b["f_lo_Hz"], b["f_hi_Hz"]]}
                   | {k: v for k, v in b.items() if k not in ("source", "rh_pct", "f_lo_Hz", "f_hi_Hz")}
                   for b in brows], missing="no compared frequency, or no time record, in this band")
        if "bands.png" in extra:
            rep.image(d / "bands.png", caption="residual NRMSE [%] and |H| error [dB] by frequency band, per record")
    for r in res.records:
        name = Path(r.source).name
        rep.heading(f"{name} (RH {r.rh:.3g} %)", level=3)
        est = r.summary["frf_metrics"].get("estimator")
        if est:
            rep.paragraph("FRF estimate: " + (", ".join(f"{k} {format_value(v)}" for k, v in est.items())
                                              if isinstance(est, dict) else str(est)), note=True)
        for f in r.summary["plots"]:
            rep.image(d / f, caption=_caption(f, name))
    rep.heading("Model and settings")
    rep.json_block(jsonable(res.predictor), "model")
    rep.json_block(jsonable(res.settings), "settings")
    if provenance:
        rep.json_block(provenance, "provenance")
    rep.write_index(d)


def _caption(png: str, record: str) -> str:
    """What a per-record figure shows."""
    if png.startswith("time_"):
        return f"{record}: measured and model deflection [µm], the residual [µm] and a zoom on the record's end"
    return f"{record}: measured and model frequency response |H| [mm/V], phase [°] and coherence"
