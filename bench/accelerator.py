"""Where a network trains: the same recipe and epochs on the CPU and, when torch sees one, a GPU.

Trains one model (default: the LSTM recipe, its structure search off, a fixed epoch budget,
no early stopping) on the Silverbox training record (``--data SNLS80mV.csv``: the standard
split's training part, 15 % validation tail) or, without it, on the slow plant of
bench/slow_plant.py, once per accelerator; on a GPU twice, to show that the same seed and
device give the same weights.  Prints wall time, validation NRMSE and a weights hash per
run, then runs ``train_compare(..., accelerator="auto")`` on a small dataset and prints the
device its card records.  Nothing is timed against a target; on a shared machine the CPU
time is inflated by whatever else runs.

    python bench/accelerator.py [--data SNLS80mV.csv] [--model lstm] [--epochs 20]
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _records(data: str | None):
    from nnmodel.data import Experiment
    if data:
        import pandas as pd
        df = pd.read_csv(data)
        u, y = df["V1"].to_numpy(float)[40650:105712], df["V2"].to_numpy(float)[40650:105712]
        return [Experiment(u, y, None, 610.35)], "Silverbox training part [40650:105712], 15 % validation tail", 0.15
    from slow_plant import FS, plant
    u, y = plant(1500, 1)
    return [Experiment(u, y, None, FS)], "slow plant, 1 500 samples, 20 % validation tail", 0.2


def _weights_hash(model) -> str:
    h = hashlib.sha256()
    for k, v in sorted(model.net_.state_dict().items()):
        h.update(k.encode())
        h.update(v.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None, help="SNLS80mV.csv (else the slow plant)")
    ap.add_argument("--model", default="lstm")
    ap.add_argument("--epochs", type=int, default=20)
    args = ap.parse_args()
    import torch

    from nnmodel.models.structure import validation_nrmse
    from nnmodel.recipes import make_model
    from nnmodel.training import device_name, resolve_accelerator

    auto = resolve_accelerator("auto")
    print(f"torch {torch.__version__}; --accelerator auto resolves to {auto} ({device_name(auto)})")
    train, what, vf = _records(args.data)
    print(f"{args.model} recipe, {args.epochs} epochs (no early stopping, no structure search, one split) on {what}")
    runs = ["cpu"] + (["gpu", "gpu"] if auto == "gpu" else [])
    for acc in runs:
        m = make_model(args.model, {"accelerator": acc, "max_epochs": args.epochs, "patience": args.epochs + 1,
                                    "structures": None, "cv_folds": 1, "val_fraction": vf, "progress_bar": False,
                                    "max_time": None})
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m.fit(train, None)
        wall = time.perf_counter() - t0
        print(f"  {device_name(acc):28s} {wall:7.1f} s  validation NRMSE {100 * validation_nrmse(m, train, None):.3f} %"
              f"  epochs {m.training_summary_['epochs_run']}  weights {_weights_hash(m)}", flush=True)
    from nnmodel.measured import build_dataset
    from nnmodel.traincompare import train_compare
    from physics.io.timeseries import TimeSeries, write_timeseries
    with tempfile.TemporaryDirectory() as d:
        from slow_plant import FS, plant
        files = []
        for name, (n, seed) in {"train": (1200, 1), "test": (600, 3)}.items():
            u, y = plant(n, seed)
            write_timeseries(TimeSeries(time=np.arange(n) / FS, voltage=u, deflection=1e-3 * y), Path(d) / f"{name}.csv")
            files.append(str(Path(d) / f"{name}.csv"))
        ds = build_dataset(Path(d) / "ds", train=[files[0]], test=[files[1]])
        s = train_compare(ds, [args.model], Path(d) / "run", progress=False, accelerator="auto",
                          overrides={args.model: {"max_epochs": 3, "structures": None}})
        card = json.loads((Path(d) / "run" / "models" / args.model / "card.json").read_text())
        print(f"train_compare(accelerator='auto'): compare.json accelerator {s['accelerator']!r}, card training.device "
              f"{card['training'].get('device')!r}")


if __name__ == "__main__":
    main()
