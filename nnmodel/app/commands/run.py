"""``eap run``: the end-to-end job on built-in defaults (the README's first command)."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from physics import signals
from physics.io.fileio import write_json
from physics.solvers.frequency import frequency_response
from physics.model import ActuatorModel
from physics.pages.plotting import plot_bode, plot_timeseries
from physics.solvers.timedomain import simulate
from physics.io.timeseries import write_timeseries

from ._common import add_output_options, provenance, writing

#: Epoch budgets of the main job (reproducible on any machine, unlike a time budget).
RUN_SETS = ("narx.max_epochs=20", "hybrid.max_epochs=10", "lstm.structures=null")
NAME = "run"
#: argument destinations that name files or folders this command reads (never replaced by its outputs)
INPUTS = ()
HELP = "run the end-to-end job on built-in defaults and write a report folder"


def add_arguments(p):
    add_output_options(p, "runs/quickstart", "report folder")
    p.add_argument("--models", default="ff,rbf,narx,lstm,hybrid",
                   help="models to train and compare (the hybrid: physics simulator + neural correction)")
    p.add_argument("--dataset-config", default="quick", help="dataset preset (configs/datasets)")
    p.add_argument("--set", action="append", default=None, metavar="MODEL.KEY=VALUE",
                   help="override a recipe hyper-parameter (repeatable); default: "
                        + " ".join(RUN_SETS) + " (an epoch budget, and the LSTM fitted once with its memory "
                        "filters instead of with and without them, which keep eap run near 3 minutes)")
    p.add_argument("--max-time-s", type=float, default=None,
                   help="wall-clock guard per model [s] (default: the recipes'; budgets are epochs)")
    p.add_argument("--physics-only", action="store_true",
                   help="skip the dataset and neural-model stages (the physics and the diagnosis loop only)")
    p.add_argument("--quiet", action="store_true", help="no progress output (the summary is still printed)")


def _physics_stage(d: Path) -> dict:
    """Thesis experiments on both devices: FRFs over RH 40–100 % and a 4 Vpp sweep."""
    out = {}
    rhs = (40.0, 60.0, 80.0, 100.0)
    for dev in ("ipmc_pt_eg", "ip2c_pedot_water"):
        model = ActuatorModel(dev, "default")
        f = np.logspace(-1, np.log10(50.0), 500)
        frs = {rh: frequency_response(model, None, f, rh=rh) for rh in rhs}
        plot_bode(f, {f"RH {rh:g} %": fr.deflection for rh, fr in frs.items()}, d / f"{dev}_bode.png",
                  title=f"{dev}: {', '.join(model.effect_ids)}")
        sig = signals.sweep(2.0, 0.1, 50.0, 100.0, 1000.0)
        t0 = time.perf_counter()
        res = simulate(model, None, sig.t, sig.v, rh=60.0)
        elapsed = time.perf_counter() - t0
        ts = res.to_timeseries()
        ts.meta.update({"signal": sig.describe(), "provenance": provenance()})
        write_timeseries(ts, d / f"{dev}_sweep_rh60.csv", overwrite=True)
        plot_timeseries(res.time, {"voltage": (res.voltage, "V"), "deflection": (1e3 * res.deflection, "mm"),
                                   "current": (1e3 * res.current, "mA")}, d / f"{dev}_sweep_rh60.png",
                        title=f"{dev}, 4 Vpp sweep 0.1–50 Hz, RH 60 %")
        out[dev] = {"effects": list(model.effect_ids),
                    "resonance_Hz_by_rh": {f"{rh:g}": (frs[rh].resonance() or (float("nan"),))[0] for rh in rhs},
                    "gain_at_1Hz_mm_per_V_by_rh": {
                        f"{rh:g}": float(1e3 * np.interp(1.0, f, frs[rh].magnitude)) for rh in rhs},
                    "sweep_simulation_runtime_s": elapsed,
                    "sweep_deflection_peak_to_peak_mm": float(1e3 * np.ptp(res.deflection))}
    return out


def _neural_stage(d: Path, args) -> dict:
    """generate (preset) → train-compare; returns the comparison summary."""
    from nnmodel.dataset import generate
    from nnmodel.traincompare import format_table, train_compare
    ds = generate(d / "dataset", args.dataset_config, progress=not args.quiet)
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    from nnmodel.app.commands.train_compare import parse_overrides
    summary = train_compare(ds, models, d / "compare", max_time_s=args.max_time_s, progress=not args.quiet,
                            overrides=parse_overrides(RUN_SETS if args.set is None else args.set))
    print(format_table(summary))
    return summary


def run(args) -> int:
    from nnmodel.app.story import story_line
    t0 = time.perf_counter()
    with writing(args) as d:
        report = _write_report(d, args, t0)
    d = Path(args.out)
    for dev, r in report["physics"].items():
        print(f"{dev}: resonance by RH " + ", ".join(f"{k}%→{v:.1f} Hz" for k, v in r["resonance_Hz_by_rh"].items()))
    print(f"report: {d / 'index.html'} (JSON: {d / 'report.json'}); total {report['runtime_s']:.1f} s")
    print(story_line(report))
    return 0


def _write_report(d: Path, args, t0: float) -> dict:
    from nnmodel.explain import notes
    from nnmodel.app.story import DIAGNOSIS_ANCHOR, dataset_facts, loop_stage, outside_stage, write_page
    from nnmodel.traincompare import page_rows
    report = {"physics": _physics_stage(d)}
    if not args.physics_only:
        summary = _neural_stage(d, args)
        report["neural"] = {k: v for k, v in summary.items() if k != "models"}
        report["neural"].update({"table": page_rows(summary["models"]), "report": "compare/index.html",
                                 "dataset": dataset_facts(d / "dataset"),
                                 "notes": notes(summary, diagnosis=DIAGNOSIS_ANCHOR)})
    report["loop"] = loop_stage(d)
    report["outside"] = outside_stage(d)
    report["runtime_s"] = time.perf_counter() - t0
    report["provenance"] = provenance()
    write_json(d / "report.json", report)
    write_page(d, report, report["provenance"])
    return report
