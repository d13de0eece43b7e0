"""Humidity suite (``eap benchmark --suite eap``): FF, RBF, NARX, LSTM and the grey-box
hybrid on the default humidity dataset, scored on held-out RH.

The dataset is ``configs/datasets/default.yaml`` (``quick.yaml`` with ``--quick``),
generated into ``OUT/dataset`` unless a dataset folder is given (``--data``; an existing
``OUT/dataset`` made from the same configuration is reused).  Every model is trained with
its recipe (``configs/train/NAME.yaml``) through ``eap train-compare`` (bundles, plots and
the full report in ``OUT/compare``); ``--quick`` caps every model at 60 s of training.
Scores: free-run NRMSE (RMSE / std of the measurement, pooled over the records of a
group; the first 50 samples of each record only initialise the state) on the test
records at held-out RH levels (the suite's score), at the training RH levels, with a
drifting RH, and on "measurement-like" records generated with physics the generator's
model lacks.  The physics simulator that generated the data is scored beside the
networks (its error is the sensor noise).  There are no published figures for these
synthetic data; the table states which model wins where.

Outputs: ``eap.json``, ``eap.csv``, ``index.html`` (self-contained; ``eap.html`` redirects to it) and ``eap.png``.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from physics.errors import InputError
from physics.io.fileio import atomic_path, write_json, write_text
from physics.pages.plotting import legend_outside

from . import common

DEFAULT_MODELS = ("ff", "rbf", "narx", "lstm", "hybrid")
#: ``--quick``: the quick dataset and one minute of training per model
QUICK_BUDGET_S = 60.0
GROUPS = ("heldout_rh", "train_rh", "varying_rh", "measurement_like")
GROUP_LABELS = {"heldout_rh": "held-out RH", "train_rh": "training RH", "varying_rh": "drifting RH",
                "measurement_like": "measurement-like"}
HEADER = ["model", "held-out RH %", "training RH %", "drifting RH %", "meas.-like %", "one-step %",
          "train s", "free-run samples/s", "parameters"]


def _dataset(out: Path, data, config: str, echo) -> Path:
    from ..dataset import generate, load_config, load_dataset

    if data:
        load_dataset(data)  # checks the folder and its hashes
        return Path(data)
    target = out / "dataset"
    cfg = load_config(config)
    if (target / "dataset.json").is_file():
        try:
            meta = load_dataset(target).meta
            if meta["generator"]["config"] == json.loads(json.dumps(cfg)):
                echo(f"reusing the dataset in {target} (same configuration {config!r})")
                return target
        except InputError:
            pass
    echo(f"generating the {config!r} dataset into {target} ...")
    return generate(target, config, overwrite=True)


def run(models=None, out: str | os.PathLike = "eap-benchmark", *, quick: bool = False,
        overrides: dict[str, dict] | None = None, progress: bool = True,
        data: str | os.PathLike | None = None, limit: int | None = None, save_models: bool = True,
        config: str | None = None, settings=None, echo=print) -> dict:
    """Run the humidity suite into ``out`` and return the report (also ``out/eap.json``).

    ``data``: an existing dataset folder (default: generate ``config``, i.e. ``default``,
    or ``quick`` with ``quick=True``).  ``overrides``: per-model hyper-parameters.
    ``save_models`` is accepted for the common suite interface; train-compare always saves
    the bundles (``out/compare/models``)."""
    from ..traincompare import train_compare

    if limit is not None:
        raise InputError("--limit truncates the Silverbox data only; for a small eap run pass a small "
                         "dataset folder with --data (e.g. one made with `eap generate --config quick`)")
    names, overrides, out = common.start(models, DEFAULT_MODELS, overrides, out)
    config = config or ("quick" if quick else "default")
    t0 = time.perf_counter()
    ds_path = _dataset(out, data, config, echo)
    layered = {}
    for n in names:
        layer = {"progress_bar": bool(progress)}
        if quick:
            layer["max_time"] = QUICK_BUDGET_S
        layer.update(overrides.get(n, {}))
        layered[n] = layer
    summary = train_compare(ds_path, names, out / "compare", overrides=layered, progress=progress,
                            settings=settings)
    report = _report(summary, names, quick, ds_path, time.perf_counter() - t0, out)
    _write_outputs(out, report)
    common.finish(echo, format_table(report), report["winners_text"],
                  "report: index.html (JSON eap.json; train-compare report compare/index.html) in the output folder")
    return report


def _pct(row: dict, group: str, which: str = "free_run"):
    g = row.get(which, {}).get(group)
    return None if g is None else 100.0 * g["nrmse"]


def _report(summary: dict, names, quick: bool, ds_path: Path, wall: float, out: Path) -> dict:
    from ..traincompare import is_reference   # physics rows and the linear yardstick
    rows = []
    for key, r in summary["models"].items():
        rows.append({"model": key, "role": "reference" if is_reference(key, r) else "model",
                     "kind": r.get("kind"),
                     "nrmse_pct": {g: _pct(r, g) for g in GROUPS + ("test",)},
                     "nrmse_by_rh_pct": {k: 100.0 * v for k, v in r["free_run"].get("by_rh", {}).items()},
                     "one_step_test_pct": _pct(r, "test", "one_step"),
                     "train_time_s": r.get("train_time_s"),
                     "samples_per_s": r.get("inference_samples_per_s"),
                     "n_parameters": r.get("n_parameters")})
    nets = [r for r in rows if r["role"] == "model"]
    winners, text = {}, []
    for g in GROUPS:
        cands = [r for r in nets if r["nrmse_pct"].get(g) is not None]
        if cands:
            best = min(cands, key=lambda r: r["nrmse_pct"][g])
            winners[g] = {"model": best["model"], "nrmse_pct": best["nrmse_pct"][g]}
            text.append(f"{GROUP_LABELS[g]}: {best['model']} wins ({best['nrmse_pct'][g]:.2f} % free-run NRMSE)")
    for label, key, pick in (("fastest free run", "samples_per_s", max), ("fastest training", "train_time_s", min),
                             ("fewest parameters", "n_parameters", min)):
        cands = [r for r in nets if r[key] is not None]
        if cands:
            best = pick(cands, key=lambda r: r[key])
            winners[key] = {"model": best["model"], "value": best[key]}
            text.append(f"{label}: {best['model']} ({common.fmt(best[key], 1)})")
    ranking = sorted((r for r in nets if r["nrmse_pct"]["heldout_rh"] is not None),
                     key=lambda r: r["nrmse_pct"]["heldout_rh"])
    text.insert(0, "ranking on held-out RH: " + " < ".join(
        f"{r['model']} {r['nrmse_pct']['heldout_rh']:.2f} %" for r in ranking))
    return {"suite": "eap", "quick": quick, "dataset": {"path": str(ds_path), "hash": summary["dataset_hash"],
                                                        "generator": summary["generator"],
                                                        "noise_floor_m": summary["noise_floor_m"]},
            "score": "free-run NRMSE (RMSE / std of the measurement, pooled over the records of a group), "
                     f"first {summary['skip_samples']} samples of each record only initialise the state",
            "models": list(names), "results": rows, "ranking_heldout": [r["model"] for r in ranking],
            "winners": winners, "winners_text": text, "published": None,
            "published_note": "synthetic data of this project: no published figures exist",
            "wall_time_s": wall, "environment": common.environment(),
            "train_compare": str(out / "compare")}


def _table_rows(report: dict) -> list[list]:
    out = []
    for r in report["results"]:
        p = r["nrmse_pct"]
        sps = r["samples_per_s"]
        out.append([r["model"] + (" (reference)" if r["role"] == "reference" else ""),
                    p.get("heldout_rh"), p.get("train_rh"), p.get("varying_rh"), p.get("measurement_like"),
                    r["one_step_test_pct"], "-" if r["train_time_s"] is None else f"{r['train_time_s']:.1f}",
                    "-" if sps is None else f"{sps:,.0f}",
                    "-" if r["n_parameters"] is None else int(r["n_parameters"])])
    return out


def format_table(report: dict) -> str:
    """The suite's table as text (free-run NRMSE in % per group)."""
    return common.text_table(HEADER, _table_rows(report))


def _write_outputs(out: Path, report: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    write_json(out / "eap.json", report)
    lines = [",".join(h.replace(" ", "_").replace("%", "pct").replace(".", "") for h in HEADER)]
    for r in _table_rows(report):
        lines.append(",".join(f'"{c}"' if isinstance(c, str) else common.fmt(c, 4) for c in r))
    write_text(out / "eap.csv", "\n".join(lines) + "\n")

    rows = report["results"]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    x = np.arange(len(GROUPS))
    w = 0.8 / max(1, len(rows))
    for i, r in enumerate(rows):
        v = [r["nrmse_pct"].get(g) or np.nan for g in GROUPS]
        axes[0].bar(x + (i - (len(rows) - 1) / 2) * w, v, w, label=r["model"],
                    hatch="//" if r["role"] == "reference" else None, edgecolor="k", linewidth=0.4)
    axes[0].set_yscale("log")
    axes[0].set_xticks(x, [GROUP_LABELS[g] for g in GROUPS])
    axes[0].set_ylabel("free-run NRMSE [%]")
    axes[0].axhline(5.0, color="r", lw=0.8, ls="--", label="5 % target (held-out RH)")
    axes[0].legend(fontsize=7, ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)
    axes[0].grid(axis="y", which="both", alpha=0.3)
    axes[0].set_title("eap suite: free-run error by test group")
    for r in rows:
        by = r["nrmse_by_rh_pct"]
        if by:
            axes[1].plot([float(k) for k in by], list(by.values()), marker="o", label=r["model"],
                         ls="--" if r["role"] == "reference" else "-")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("RH [%] (nominal level)")
    axes[1].set_ylabel("free-run NRMSE [%]")
    axes[1].set_title("error by RH level (held-out levels: 50, 70, 90 % by default)")
    axes[1].grid(alpha=0.3, which="both")
    legend_outside(axes[1], fontsize=7)
    fig.tight_layout()
    with atomic_path(out / "eap.png") as tmp:
        fig.savefig(tmp, dpi=110, format="png", bbox_inches="tight")
    plt.close(fig)

    hrows = [{"class": "pub" if r["role"] == "reference" else "", "cells": c}
             for r, c in zip(rows, _table_rows(report))]
    blocks = [
        ("p", f"Dataset: {report['dataset']['path']} (hash {report['dataset']['hash'][:12]}), generator "
              f"{report['dataset']['generator']['device']} with {', '.join(report['dataset']['generator']['effects'])}; "
              f"sensor noise floor {1e6 * report['dataset']['noise_floor_m']:.2f} µm."
              + (" QUICK run (quick dataset, 60 s per model)." if report["quick"] else "")),
        ("p", "Score: " + report["score"] + ". The reference row is the physics simulator that generated "
              "the data. " + report["published_note"] + "."),
        ("h2", "Results"),
        ("table", (HEADER, hrows)),
        ("pre", "\n".join(report["winners_text"])),
        ("img", (out / "eap.png", "free-run NRMSE [%] by test group and by nominal RH level, per model "
                                  "(hatched, dashed: the physics reference)")),
        ("p", ("Full train-compare report (overlays, Bode plots, bundles): compare/index.html",
               {"compare/index.html": "compare/index.html"})),
        ("pre", json.dumps(report["environment"], indent=1)),
    ]
    common.page("eap benchmark: humidity suite", blocks).write_index(out, old_name="eap.html")
