"""Grey-box study (``eap benchmark --suite greybox``): does the hybrid beat both of its
parents, and how much data does each model need?

Data: ``configs/datasets/greybox.yaml`` (generated into ``OUT/dataset`` unless ``--data``):
the default humidity dataset with **every** record generated with ``nonlinear_charge``
(a large-signal double layer) on top of the device's default effects.  The hybrid's
physics part has the default effects only, so the data contain physics it lacks.

1. **Full data**: ``eap train-compare`` of the hybrid and the pure networks with their
   recipes (``OUT/compare``), plus the hybrid's physics part alone (``physics_base``).
   Score: free-run NRMSE on the held-out RH levels.
2. **Data efficiency**: the same models trained on nested subsets of the training
   records (1, 2, 4, 8 and all 18 by default; chosen round-robin over the RH levels and
   excitation kinds, so a subset of 4 has one record per training RH level), every
   training capped at ``curve_budget_s`` seconds; the validation records (early
   stopping) and the test records are the same for every point.

Outputs: ``greybox.json``, ``greybox.csv``, ``index.html`` (``greybox.html`` redirects to it), ``greybox_efficiency.png``.
"""
from __future__ import annotations

import json
import os
import time
import warnings
from pathlib import Path

from physics.errors import InputError
from physics.execution.parallel import map_tasks
from physics.io.fileio import atomic_path, write_json, write_text

from . import common

DEFAULT_MODELS = ("hybrid", "narx", "ff")
SIZES = (1, 2, 4, 8, None)          # None: every training record
CURVE_BUDGET_S = 180.0
QUICK_CURVE_BUDGET_S = 30.0
QUICK_SIZES = (1, 4, None)


def subset_order(entries: list[dict]) -> list[dict]:
    """Training entries in the order the subsets take them: round-robin over the constant
    RH levels (each level's records in excitation order, rotated per level so that the
    first records cover different excitations), then the drifting-RH records."""
    const = [e for e in entries if not isinstance(e["rh_pct"], dict)]
    drift = [e for e in entries if isinstance(e["rh_pct"], dict)]
    levels = sorted({float(e["rh_pct"]) for e in const})
    # extreme levels first, then the inner ones: two records already span the RH range
    order_levels = [levels[0], levels[-1]] + levels[1:-1] if len(levels) > 1 else levels
    per = {lv: sorted([e for e in const if float(e["rh_pct"]) == lv], key=lambda e: e["path"])
           for lv in order_levels}
    for i, lv in enumerate(order_levels):
        k = i % max(1, len(per[lv]))
        per[lv] = per[lv][k:] + per[lv][:k]
    out = []
    while any(per.values()):
        for lv in order_levels:
            if per[lv]:
                out.append(per[lv].pop(0))
    return out + sorted(drift, key=lambda e: e["path"])


def run(models=None, out: str | os.PathLike = "greybox-study", *, quick: bool = False,
        overrides: dict[str, dict] | None = None, progress: bool = True,
        data: str | os.PathLike | None = None, limit: int | None = None, save_models: bool = True,
        sizes=None, curve_budget_s: float | None = None, settings=None, echo=print) -> dict:
    """Run the grey-box study into ``out``; returns the report (``out/greybox.json``)."""
    from ..dataset import load_dataset
    from ..traincompare import train_compare
    from .eap import _dataset

    if limit is not None:
        raise InputError("--limit truncates the Silverbox data only; pass a small dataset with --data")
    names, overrides, out = common.start(models, DEFAULT_MODELS, overrides, out)
    if "hybrid" not in names:
        raise InputError("the grey-box study compares the hybrid with pure networks: include 'hybrid' in --models")
    t_start = time.perf_counter()
    ds_path = _dataset(out, data, "greybox", echo)
    ds = load_dataset(ds_path)
    gen = ds.meta["generator"]
    layered = {n: {"progress_bar": bool(progress), **({"max_time": 60.0} if quick else {}),
                   **overrides.get(n, {})} for n in names}

    # 1. full data, recipes
    echo("== full training data, recipes ==")
    full = train_compare(ds_path, names, out / "compare", overrides=layered, progress=progress,
                         settings=settings)

    # 2. data efficiency
    sizes = tuple(sizes) if sizes is not None else (QUICK_SIZES if quick else SIZES)
    budget = float(curve_budget_s if curve_budget_s is not None else
                   (QUICK_CURVE_BUDGET_S if quick else CURVE_BUDGET_S))
    order = subset_order(ds.entries("train"))
    tasks = []
    for size in sizes:
        n = len(order) if size is None else min(int(size), len(order))
        for name in names:
            ov = {**layered[name], "progress_bar": False}
            ov["max_time"] = min(float(ov.get("max_time") or budget), budget)
            if name == "hybrid":
                ov.setdefault("device", gen["device"])
            tasks.append({"model": name, "overrides": ov, "dataset": str(ds_path), "records": order[:n]})
    curve = map_tasks(_curve_point, tasks, settings, desc="data-efficiency curve", progress=False)
    for row in curve:
        echo(f"[{row['n_records']} record(s), {row['train_seconds_of_data']:.0f} s of data] {row['model']}: "
             f"held-out RH {row['nrmse_pct']['heldout_rh']:.2f} %  ({row['fit_time_s']:.0f} s)")
    report = _report(full, curve, names, quick, budget, ds_path, time.perf_counter() - t_start, out)
    _write_outputs(out, report)
    common.finish(echo, format_table(report), report["findings"],
                  "report: index.html (JSON greybox.json) in the output folder")
    return report


def _curve_point(task: dict) -> dict:
    """Train one model on the first records of the subset order and score it (a task of
    :func:`physics.execution.parallel.map_tasks`; the dataset is read from its path)."""
    from ..dataset import load_dataset
    from ..traincompare import _score, network_runner
    from ..recipes import make_model

    ds = load_dataset(task["dataset"])
    chosen = task["records"]
    recs = [ds.record(e) for e in chosen]
    model = make_model(task["model"], task["overrides"])
    t0 = time.perf_counter()
    model.fit(recs, ds.records("validation"))
    fit_s = time.perf_counter() - t0
    with warnings.catch_warnings():   # small subsets see few RH levels: extrapolation is the point
        warnings.filterwarnings("ignore", message=".*outside the range seen in training.*")
        sc = _score(network_runner(model), ds, ds.entries("test"))
    return {"model": task["model"], "n_records": len(chosen), "train_seconds_of_data": sum(len(r) for r in recs) / ds.fs,
            "rh_levels": sorted({float(e["rh_pct"]) for e in chosen if not isinstance(e["rh_pct"], dict)}),
            "drifting_rh_records": sum(isinstance(e["rh_pct"], dict) for e in chosen),
            "records": [e["path"] for e in chosen], "fit_time_s": fit_s,
            "nrmse_pct": {g: 100 * sc[g]["nrmse"] for g in ("heldout_rh", "train_rh", "varying_rh", "test") if g in sc}}


def _report(full: dict, curve: list, names, quick, budget, ds_path, wall, out) -> dict:
    rows = []
    for key, r in full["models"].items():
        fr = r["free_run"]
        rows.append({"model": key, "kind": r.get("kind"),
                     "heldout_rh_pct": 100 * fr["heldout_rh"]["nrmse"] if "heldout_rh" in fr else None,
                     "train_rh_pct": 100 * fr["train_rh"]["nrmse"] if "train_rh" in fr else None,
                     "varying_rh_pct": 100 * fr["varying_rh"]["nrmse"] if "varying_rh" in fr else None,
                     "train_time_s": r.get("train_time_s"), "n_parameters": r.get("n_parameters"),
                     "samples_per_s": r.get("inference_samples_per_s")})
    by = {r["model"]: r for r in rows}
    findings = []
    hyb = by.get("hybrid", {}).get("heldout_rh_pct")
    phys = by.get("physics_base", by.get("physics", {})).get("heldout_rh_pct")
    pure = {n: by[n]["heldout_rh_pct"] for n in names if n != "hybrid" and n in by}
    best_pure = min(pure, key=pure.get) if pure else None
    checks = {}
    if hyb is not None and phys is not None:
        checks["hybrid_beats_physics"] = hyb < phys
        findings.append(f"held-out RH, full data: hybrid {hyb:.2f} % vs its physics alone {phys:.2f} % -> "
                        + ("hybrid better" if hyb < phys else "hybrid NOT better"))
    if hyb is not None and best_pure is not None:
        checks["hybrid_beats_best_pure_network"] = hyb < pure[best_pure]
        findings.append(f"held-out RH, full data: hybrid {hyb:.2f} % vs best pure network {best_pure} "
                        f"{pure[best_pure]:.2f} % -> " + ("hybrid better" if hyb < pure[best_pure] else "hybrid NOT better"))
    sizes = sorted({c["n_records"] for c in curve})
    for n in sizes:
        pts = {c["model"]: c["nrmse_pct"]["heldout_rh"] for c in curve if c["n_records"] == n}
        if "hybrid" in pts and len(pts) > 1:
            others = {k: v for k, v in pts.items() if k != "hybrid"}
            b = min(others, key=others.get)
            findings.append(f"{n} training record(s): hybrid {pts['hybrid']:.2f} % vs best pure {b} {others[b]:.2f} %")
    return {"suite": "greybox", "quick": quick, "dataset": {"path": str(ds_path), "hash": full["dataset_hash"],
                                                            "generator": full["generator"]},
            "score": "free-run NRMSE on held-out RH (pooled; first 50 samples only initialise the state)",
            "full_data": rows, "checks": checks, "curve": curve, "curve_budget_s": budget,
            "findings": findings, "wall_time_s": wall, "environment": common.environment(),
            "train_compare": str(out / "compare")}


HEADER = ["model", "held-out RH %", "training RH %", "drifting RH %", "train s", "samples/s", "parameters"]


def _table_rows(report: dict) -> list[list]:
    out = []
    for r in report["full_data"]:
        out.append([r["model"], r["heldout_rh_pct"], r["train_rh_pct"], r["varying_rh_pct"],
                    "-" if r["train_time_s"] is None else f"{r['train_time_s']:.1f}",
                    "-" if r["samples_per_s"] is None else f"{r['samples_per_s']:,.0f}",
                    "-" if r["n_parameters"] is None else int(r["n_parameters"])])
    return out


def _curve_rows(report: dict) -> tuple[list[str], list[list]]:
    models = list(dict.fromkeys(c["model"] for c in report["curve"]))
    sizes = sorted({c["n_records"] for c in report["curve"]})
    header = ["training records", "seconds of data"] + [f"{m} held-out %" for m in models]
    rows = []
    for n in sizes:
        pts = {c["model"]: c for c in report["curve"] if c["n_records"] == n}
        secs = next(iter(pts.values()))["train_seconds_of_data"]
        rows.append([n, f"{secs:.0f}"] + [pts[m]["nrmse_pct"]["heldout_rh"] if m in pts else None for m in models])
    return header, rows


def format_table(report: dict) -> str:
    h, r = _curve_rows(report)
    return (common.text_table(HEADER, _table_rows(report)) + "\n\ndata efficiency (free-run NRMSE on held-out RH, "
            f"training capped at {report['curve_budget_s']:.0f} s):\n" + common.text_table(h, r))


def _missing_physics(report: dict) -> str:
    """The generator's effects that the hybrid's physics (the device's default effects) lacks."""
    from physics.device import load_device
    gen = report["dataset"]["generator"]
    own = load_device(gen["device"]).default_effects
    return ", ".join(e for e in gen["effects"] if e not in own) or "nothing"


def _write_outputs(out: Path, report: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from physics.pages.plotting import legend_outside

    write_json(out / "greybox.json", report)
    h, r = _curve_rows(report)
    lines = [",".join(x.replace(" ", "_").replace("%", "pct") for x in h)]
    lines += [",".join(common.fmt(c, 4) if not isinstance(c, str) else c for c in row) for row in r]
    write_text(out / "greybox.csv", "\n".join(lines) + "\n")

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    models = list(dict.fromkeys(c["model"] for c in report["curve"]))
    for m in models:
        pts = sorted((c["train_seconds_of_data"], c["nrmse_pct"]["heldout_rh"]) for c in report["curve"]
                     if c["model"] == m)
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", label=m, lw=2 if m == "hybrid" else 1.2)
    for r_ in report["full_data"]:
        if r_["model"] in ("physics_base", "physics") and r_["heldout_rh_pct"] is not None:
            lab = "hybrid's physics alone" if r_["model"] == "physics_base" else "generator physics (reference)"
            ax.axhline(r_["heldout_rh_pct"], ls="--", color="k" if r_["model"] == "physics_base" else "0.6",
                       lw=0.9, label=lab)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("training data [s] (1, 2, 4, 8, all records)")
    ax.set_ylabel("free-run NRMSE on held-out RH [%]")
    ax.set_title(f"grey-box study: data efficiency ({_missing_physics(report)} missing from the hybrid's physics)")
    ax.grid(alpha=0.3, which="both")
    legend_outside(ax)
    fig.tight_layout()
    with atomic_path(out / "greybox_efficiency.png") as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)

    blocks = [
        ("p", f"Dataset: {report['dataset']['path']} (hash {report['dataset']['hash'][:12]}), generator "
              f"{report['dataset']['generator']['device']} with {', '.join(report['dataset']['generator']['effects'])}."),
        ("p", "Score: " + report["score"] + ". physics_base is the hybrid's physics part alone (default effects, "
              f"no {_missing_physics(report)}); physics is the generator itself (a reference no model can beat "
              "except by noise)."),
        ("h2", "Full training data (recipes)"),
        ("table", (HEADER, _table_rows(report))),
        ("pre", "\n".join(report["findings"])),
        ("h2", "Data efficiency"),
        ("table", _curve_rows(report)),
        ("img", (out / "greybox_efficiency.png", "free-run NRMSE on held-out RH [%] against the seconds of training "
                                                 "data, per model; dashed: the physics alone")),
        ("pre", json.dumps(report["environment"], indent=1)),
    ]
    common.page("eap benchmark: grey-box study", blocks).write_index(out, old_name="greybox.html")
