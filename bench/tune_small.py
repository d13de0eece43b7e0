"""Tuning on a small slow, saturating plant: `--tune` never ends worse than the recipe on its own
cross-validation, and the spread says how much a validation score can be trusted.

The plant of bench/slow_plant.py (0.25 Hz; lags of 2 min and 30 s, then tanh(GAIN x)), through
the generic path: CSV files, ``eap dataset`` (1 000 training samples, the last 20 % of them
validating; a 1 024-sample test record of its own seed), then ``train_compare`` with the
default recipes and again with ``--tune N``.  With 200 validation samples (a few independent
windows) every fit is cross-validated (nnmodel/models/crossval.py: 3 rolling-origin folds).
Prints, per model: the recipe's cross-validated score (trial 0: mean ± spread over the folds),
the kept trial's, the rule that kept it, and the free-run test RMSE of the default and the tuned
bundle beside the linear row's; and, for comparison, the test RMSE of ``--tune N`` scored on
one validation tail (``cv_folds: 1``, the protocol before cross-validation).

    python bench/tune_small.py [--models ff,rbf] [--tune 8] [--gain 1.5] [--out runs/tune-small]
"""
from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _dataset(root: Path, gain: float) -> Path:
    from nnmodel.measured import build_dataset
    from physics.io.record import OutputQuantity
    from physics.io.timeseries import TimeSeries, write_timeseries
    from slow_plant import FS, plant

    files = {}
    for split, (n, seed) in {"train": (1000, 1), "test": (1024, 3)}.items():
        u, y = plant(n, seed, gain)
        files[split] = root / f"{split}.csv"
        write_timeseries(TimeSeries(time=np.arange(n) / FS, voltage=u, deflection=y,
                                    output=OutputQuantity.parse("y:V")), files[split], overwrite=True)
    return build_dataset(root / "ds", train=[str(files["train"])], test=[str(files["test"])], output="y:V",
                         val_fraction=0.2, overwrite=True)


def _cv(row: dict) -> str:
    cv = (row.get("validation") or {}).get("cross_validation")
    return "-" if not cv else f"{100 * cv['mean']:.2f} ± {100 * cv['spread']:.2f} %"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="ff,rbf")
    ap.add_argument("--tune", type=int, default=8)
    ap.add_argument("--gain", type=float, default=1.5)
    ap.add_argument("--out", default="runs/tune-small")
    args = ap.parse_args()
    from nnmodel.traincompare import train_compare, vs_linear_text
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ds = _dataset(out, args.gain)
    runs = {}
    one = {m: {"cv_folds": 1} for m in models}
    for label, tune, over in (("default", None, None), ("tuned", args.tune, None), ("one-split", args.tune, one)):
        t0 = time.perf_counter()
        runs[label] = train_compare(ds, models, out / label, progress=False, tune=tune, overwrite=True,
                                    overrides=over)
        print(f"{label}: {time.perf_counter() - t0:.0f} s wall (shared, loaded 2-core machine)", flush=True)
    d, t, o = runs["default"]["models"], runs["tuned"]["models"], runs["one-split"]["models"]
    print(f"slow plant, tanh({args.gain:g} x), 1 000 training samples (200 validate), test 1 024 samples; "
          f"--tune {args.tune}")
    head = (f"{'model':7s} {'recipe CV (trial 0)':>20s} {'kept trial CV':>16s} {'kept':>5s} "
            f"{'default RMSE':>13s} {'vs linear':>10s} {'tuned RMSE':>11s} {'vs linear':>10s}")
    print(head)
    print("-" * len(head))
    lin = d["linear"]["free_run"]["test"]["rmse_m"]
    print(f"{'linear':7s} {'-':>20s} {'-':>16s} {'-':>5s} {lin:13.4f} {'–':>10s} "
          f"{t['linear']['free_run']['test']['rmse_m']:11.4f} {'–':>10s}")
    for m in models:
        tu = t[m]["tuning"]
        rec = tu["trials"][0]
        rec_cv = "-" if rec.get("spread") is None else f"{100 * rec['validation_nrmse']:.2f} ± {100 * rec['spread']:.2f} %"
        kept = tu["best"]
        kept_cv = "-" if kept.get("spread") is None else \
            f"{100 * kept['validation_nrmse']:.2f} ± {100 * kept['spread']:.2f} %"
        print(f"{m:7s} {rec_cv:>20s} {kept_cv:>16s} {kept['trial']:5d} {d[m]['free_run']['test']['rmse_m']:13.4f} "
              f"{vs_linear_text(d[m].get('vs_linear_pct')):>10s} {t[m]['free_run']['test']['rmse_m']:11.4f} "
              f"{vs_linear_text(t[m].get('vs_linear_pct')):>10s}")
        print(f"        rule: {tu['rule']}; default recipe's own CV score in its row: {_cv(d[m])}")
        never_worse = kept["validation_nrmse"] <= rec["validation_nrmse"]
        print(f"        kept trial's CV mean <= the recipe's: {'yes' if never_worse else 'NO'}")
        ob = o[m]["tuning"]["best"]
        print(f"        --tune {args.tune} on one tail (cv_folds 1): kept trial {ob['trial']}, validation "
              f"{100 * ob['validation_nrmse']:.2f} %, test RMSE {o[m]['free_run']['test']['rmse_m']:.4f} "
              f"({vs_linear_text(o[m].get('vs_linear_pct'))} vs linear)")
    shutil.rmtree(out / "ds", ignore_errors=True)


if __name__ == "__main__":
    main()
